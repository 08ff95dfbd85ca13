//! The integrators in one table ([`integrators!`]): one line each names the integrator,
//! its options type (one struct, read alike by the command line, experiment files and the
//! library; the type implements [`Integrator`](crate::integrator::run::Integrator), which renders with them) and the scene-file
//! plugins that select it. From that table come [`IntegratorKind`], [`Method`] (an integrator
//! with its options, what a render is given), [`INTEGRATORS`] and the dispatch of a render.

use crate::error::Error;
use crate::integrator::bidir::mis::Heuristic;
use crate::integrator::budget::BudgetOptions;
use crate::integrator::eorr::EorrOptions;
use crate::integrator::lvc::LvcOptions;
use crate::integrator::memlt::MemltOptions;
use crate::integrator::metropolis::ChainOptions;
use crate::integrator::pcbpt::{PcbptOptions, PoolOptions};
use crate::integrator::pssmlt::PssmltOptions;
use crate::integrator::run::{Integrator, Iterations, Rendered, RunOptions};
use crate::integrator::spcbpt::SpcbptOptions;
use crate::scene::Scene;
use serde::Serialize;

/// One integrator's entry in [`INTEGRATORS`].
pub struct Registration {
    pub kind: IntegratorKind,
    /// Adds the integrator's options to a command (their flags, help and defaults).
    pub args: fn(clap::Command) -> clap::Command,
    /// Reads the integrator's options from arguments parsed by a command `args` made.
    pub parse: fn(&clap::ArgMatches) -> Result<Method, clap::Error>,
    /// The integrator with its default options.
    pub default: fn() -> Method,
}

/// Makes, from one line per integrator (`Variant("name", plugins: [..]) => OptionsType`,
/// after the doc comment that `--help` shows), the enum of integrators, [`Method`], the
/// table of registrations and the dispatch of a render.
macro_rules! integrators {
    ($($(#[doc = $doc:literal])* $variant:ident($name:literal, plugins: [$($plugin:literal),*]) => $options:ty,)*) => {
        /// The integrators selectable with `--integrator`.
        #[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum, Serialize)]
        pub enum IntegratorKind {
            $($(#[doc = $doc])* #[value(name = $name)] #[serde(rename = $name)] $variant,)*
        }

        impl IntegratorKind {
            /// The integrator a scene file's plugin name selects.
            pub fn from_plugin(plugin: &str) -> Option<IntegratorKind> {
                match plugin {
                    $($($plugin => Some(IntegratorKind::$variant),)*)*
                    _ => None,
                }
            }

            /// Every scene-file plugin that selects an integrator.
            pub const PLUGINS: &'static [&'static str] = &[$($($plugin,)*)*];

            /// The name `--integrator` takes.
            pub fn name(self) -> &'static str {
                match self {
                    $(IntegratorKind::$variant => $name,)*
                }
            }

            /// Whether the integrator samples with the bidirectional core's strategies (and
            /// reports connections and light paths).
            pub fn is_bidirectional(self) -> bool {
                match self {
                    $(IntegratorKind::$variant => <$options as Integrator>::BIDIRECTIONAL,)*
                }
            }

            /// Whether the integrator renders iterations in the render loop (every one but
            /// the Markov chains).
            pub fn is_iterative(self) -> bool {
                match self {
                    $(IntegratorKind::$variant => <$options as Integrator>::ITERATIVE,)*
                }
            }
        }

        /// An integrator and its options (serialized as the options alone).
        #[derive(Clone, Debug, Serialize)]
        #[serde(untagged)]
        pub enum Method {
            $($variant($options),)*
        }

        /// Every integrator, in the order `--help` lists them.
        pub static INTEGRATORS: &[Registration] = &[
            $(Registration {
                kind: IntegratorKind::$variant,
                args: <$options as clap::Args>::augment_args,
                parse: |m| <$options as clap::FromArgMatches>::from_arg_matches(m).map(Method::$variant),
                default: || Method::$variant(<$options>::default()),
            },)*
        ];

        impl Method {
            pub fn kind(&self) -> IntegratorKind {
                match self {
                    $(Method::$variant(_) => IntegratorKind::$variant,)*
                }
            }

            /// Whether the integrator renders participating media ([`Integrator::MEDIA`]).
            pub fn renders_media(&self) -> bool {
                match self {
                    $(Method::$variant(_) => <$options as Integrator>::MEDIA,)*
                }
            }

            /// The MIS heuristic, for the integrators that weigh strategies.
            pub fn heuristic_mut(&mut self) -> Option<&mut Heuristic> {
                match self {
                    $(Method::$variant(o) => o.heuristic_mut(),)*
                }
            }

            /// Renders with the integrator (see [`Integrator::render`]); the statistics
            /// name it and its options.
            pub(crate) fn render(&self, scene: &Scene, run: &RunOptions, iterations: Iterations) -> Rendered {
                if scene.volumetric && !self.renders_media() {
                    return Err(Error::Usage(format!(
                        "{}: the scene has participating media or null (medium boundary) surfaces, which --integrator {} does not render; use --integrator path",
                        scene.path.display(),
                        self.kind().name()
                    )));
                }
                let mut out = match self {
                    $(Method::$variant(o) => o.render(scene, run, iterations),)*
                }?;
                out.stats.integrator = self.kind().name();
                out.stats.options = serde_json::to_value(self).unwrap_or(serde_json::Value::Null);
                Ok(out)
            }
        }
    };
}

integrators! {
    /// Unidirectional path tracing with next-event estimation and MIS.
    Path("path", plugins: ["path", "volpath", "volpath_simple"]) => crate::integrator::path::PathOptions,
    /// Path tracing guided by a spatio-directional tree learnt in doubling training passes.
    Guided("guided", plugins: []) => crate::integrator::guided::GuidedOptions,
    /// Light tracing: light subpaths connected to the camera (`t = 1`) only.
    Lighttrace("lighttrace", plugins: ["ptracer"]) => crate::integrator::bidir::bdpt::LighttraceOptions,
    /// Bidirectional path tracing with every strategy.
    Bdpt("bdpt", plugins: ["bdpt"]) => crate::integrator::bidir::bdpt::BdptOptions,
    /// BDPT with efficiency-optimised Russian roulette on connections.
    Eorr("eorr", plugins: []) => EorrOptions,
    /// Light-vertex-cache BDPT: a shared pool of light paths, uniform connections.
    Lvc("lvc", plugins: []) => LvcOptions,
    /// Primary-sample-space Metropolis light transport over BDPT (or the path tracer).
    Pssmlt("pssmlt", plugins: ["pssmlt"]) => PssmltOptions,
    /// Probabilistic connections: a shared pool, connections drawn from cached PMFs.
    Pcbpt("pcbpt", plugins: []) => PcbptOptions,
    /// Subspace-based probabilistic connections: connections drawn from a trained matrix
    /// over eye and light subspaces.
    Spcbpt("spcbpt", plugins: []) => SpcbptOptions,
    /// Path-space Metropolis with Manifold Exploration's mutations.
    Memlt("memlt", plugins: ["mlt"]) => MemltOptions,
    /// Vertex connection and merging: BDPT's connections and photon merging, weighed together.
    Vcm("vcm", plugins: []) => crate::integrator::vcm::VcmOptions,
    /// Bidirectional photon mapping: VCM's merges alone.
    Bpm("bpm", plugins: []) => crate::integrator::vcm::BpmOptions,
}

/// The registration of `kind`.
pub fn registration(kind: IntegratorKind) -> &'static Registration {
    INTEGRATORS.iter().find(|r| r.kind == kind).expect("every integrator is registered")
}

/// A command whose arguments are `kind`'s options alone (no binary name).
pub fn options_command(kind: IntegratorKind) -> clap::Command {
    (registration(kind).args)(clap::Command::new(kind.name()).no_binary_name(true))
}

/// Whether `kind`'s options include the flag `--long` (an option's name or alias).
pub fn reads(kind: IntegratorKind, long: &str) -> bool {
    options_command(kind)
        .get_arguments()
        .any(|a| a.get_long() == Some(long) || a.get_all_aliases().is_some_and(|v| v.contains(&long)))
}

/// The integrators whose options include the flag `--long`.
pub fn readers(long: &str) -> Vec<IntegratorKind> {
    INTEGRATORS.iter().map(|r| r.kind).filter(|&k| reads(k, long)).collect()
}

/// What to say of `flag` (`--name`), an option `kind` does not read: the integrators that
/// read it, or that none does.
pub fn not_an_option_of(flag: &str, kind: IntegratorKind) -> String {
    let readers = readers(flag.trim_start_matches('-'));
    let names: Vec<&str> = readers.iter().map(|k| k.name()).collect();
    match names.as_slice() {
        [] => format!("{flag} is not an option of any integrator"),
        [one] => format!("{flag} is an option of {one}, not of {}", kind.name()),
        more => format!("{flag} is an option of {}, not of {}", more.join(", "), kind.name()),
    }
}

/// `kind`'s options from command-line arguments (`--name value`, …); an argument that is not
/// one of them is an error naming the integrators it belongs to.
pub fn parse_options(kind: IntegratorKind, args: &[String]) -> Result<Method, String> {
    let err = |e: clap::Error| {
        use clap::error::{ContextKind, ContextValue, ErrorKind};
        if e.kind() == ErrorKind::UnknownArgument
            && let Some(ContextValue::String(flag)) = e.get(ContextKind::InvalidArg)
        {
            let flag = flag.split('=').next().unwrap_or(flag);
            return not_an_option_of(flag, kind);
        }
        let text = e.to_string();
        let first = text.lines().next().unwrap_or_default();
        first.trim_start_matches("error: ").to_string()
    };
    let matches = options_command(kind).try_get_matches_from(args).map_err(err)?;
    (registration(kind).parse)(&matches).map_err(err)
}

/// The panic of an accessor asked for options the method does not have (a caller's error).
fn not_the(what: &str, m: &Method) -> ! {
    panic!("{what} asked of a {:?} render", m.kind())
}

impl Method {
    /// `kind` with its default options.
    pub fn default_for(kind: IntegratorKind) -> Method {
        (registration(kind).default)()
    }

    /// PCBPT's options. Panics for another integrator.
    pub fn pcbpt_mut(&mut self) -> &mut PcbptOptions {
        match self {
            Method::Pcbpt(o) => o,
            m => not_the("PCBPT's options", m),
        }
    }

    /// SPCBPT's options. Panics for another integrator.
    pub fn spcbpt_mut(&mut self) -> &mut SpcbptOptions {
        match self {
            Method::Spcbpt(o) => o,
            m => not_the("SPCBPT's options", m),
        }
    }

    /// PSSMLT's options. Panics for another integrator.
    pub fn pssmlt_mut(&mut self) -> &mut PssmltOptions {
        match self {
            Method::Pssmlt(o) => o,
            m => not_the("PSSMLT's options", m),
        }
    }

    /// MEMLT's options. Panics for another integrator.
    pub fn memlt_mut(&mut self) -> &mut MemltOptions {
        match self {
            Method::Memlt(o) => o,
            m => not_the("MEMLT's options", m),
        }
    }

    /// EORR's options. Panics for another integrator.
    pub fn eorr_mut(&mut self) -> &mut EorrOptions {
        match self {
            Method::Eorr(o) => o,
            m => not_the("EORR's options", m),
        }
    }

    /// The path tracer's options. Panics for another integrator.
    pub fn path_mut(&mut self) -> &mut crate::integrator::path::PathOptions {
        match self {
            Method::Path(o) => o,
            m => not_the("the path tracer's options", m),
        }
    }

    /// The guided path tracer's options. Panics for another integrator.
    pub fn guided_mut(&mut self) -> &mut crate::integrator::guided::GuidedOptions {
        match self {
            Method::Guided(o) => o,
            m => not_the("the guided path tracer's options", m),
        }
    }

    /// LVC's options. Panics for another integrator.
    pub fn lvc_mut(&mut self) -> &mut LvcOptions {
        match self {
            Method::Lvc(o) => o,
            m => not_the("LVC's options", m),
        }
    }

    /// The light pool of PCBPT or SPCBPT. Panics for another integrator.
    pub fn pool_mut(&mut self) -> &mut PoolOptions {
        match self {
            Method::Pcbpt(o) => &mut o.pc.pool,
            Method::Spcbpt(o) => &mut o.sp.pool,
            m => not_the("a light pool's options", m),
        }
    }

    /// The budget of PCBPT or SPCBPT. Panics for another integrator.
    pub fn budget_mut(&mut self) -> &mut BudgetOptions {
        match self {
            Method::Pcbpt(o) => &mut o.pc.budget,
            Method::Spcbpt(o) => &mut o.sp.budget,
            m => not_the("the budget's options", m),
        }
    }

    /// The chains of PSSMLT or MEMLT. Panics for another integrator.
    pub fn chain_mut(&mut self) -> &mut ChainOptions {
        match self {
            Method::Pssmlt(o) => &mut o.chain,
            Method::Memlt(o) => &mut o.chain,
            m => not_the("Markov chains' options", m),
        }
    }

    /// Whether PSSMLT or MEMLT runs two-stage Metropolis. Panics for another integrator.
    pub fn two_stage_mut(&mut self) -> &mut bool {
        match self {
            Method::Pssmlt(o) => &mut o.two_stage,
            Method::Memlt(o) => &mut o.two_stage,
            m => not_the("two-stage Metropolis", m),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::ValueEnum;

    /// Every integrator of `--integrator` is registered once, and its options parse from
    /// an empty command line to its defaults.
    #[test]
    fn every_integrator_is_registered_once_with_defaults() {
        for kind in IntegratorKind::value_variants() {
            assert_eq!(INTEGRATORS.iter().filter(|r| r.kind == *kind).count(), 1, "{kind:?}");
            let r = registration(*kind);
            let cmd = (r.args)(clap::Command::new("test").no_binary_name(true));
            let m = cmd.try_get_matches_from(Vec::<String>::new()).unwrap();
            let parsed = (r.parse)(&m).unwrap();
            assert_eq!(parsed.kind(), *kind);
            let (a, b) = (serde_json::to_value(&parsed).unwrap(), serde_json::to_value((r.default)()).unwrap());
            assert_eq!(a, b, "{kind:?}: the command line's defaults are not the options' Default");
        }
    }

    /// An option of another integrator is refused, naming the integrators that read it;
    /// one of none is refused as such; a value that does not parse names the option.
    #[test]
    fn options_of_other_integrators_are_refused_by_name() {
        let args = |a: &[&str]| a.iter().map(|s| s.to_string()).collect::<Vec<_>>();
        let e = parse_options(IntegratorKind::Bdpt, &args(&["--pc-cache-stride", "8"])).unwrap_err();
        assert_eq!(e, "--pc-cache-stride is an option of pcbpt, not of bdpt");
        let e = parse_options(IntegratorKind::Bdpt, &args(&["--connections", "8"])).unwrap_err();
        assert_eq!(e, "--connections is an option of lvc, pcbpt, spcbpt, not of bdpt");
        let e = parse_options(IntegratorKind::Path, &args(&["--heuristic=balance"])).unwrap_err();
        assert!(e.starts_with("--heuristic is an option of bdpt, eorr, lvc, pssmlt, pcbpt, spcbpt, memlt"), "{e}");
        let e = parse_options(IntegratorKind::Pcbpt, &args(&["--no-such-option", "1"])).unwrap_err();
        assert_eq!(e, "--no-such-option is not an option of any integrator");
        let e = parse_options(IntegratorKind::Pcbpt, &args(&["--pc-mis", "sideways"])).unwrap_err();
        assert!(e.contains("sideways") && e.contains("--pc-mis"), "{e}");
        // The old names of shared options still read them.
        let Method::Spcbpt(o) = parse_options(IntegratorKind::Spcbpt, &args(&["--pc-connections", "2"])).unwrap()
        else {
            panic!("not SPCBPT")
        };
        assert_eq!(o.sp.pool.connections, 2);
    }
}
