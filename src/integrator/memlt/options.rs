//! MEMLT's options, and which mutators they enable.

use super::Mutator;
use serde::Serialize;

/// Options of MEMLT (`--integrator memlt`).
#[derive(Clone, Debug, Serialize, clap::Args)]
pub struct MemltOptions {
    /// MIS heuristic of the BDPT bootstrap.
    #[arg(long, value_enum, default_value_t = crate::integrator::bidir::mis::Heuristic::default())]
    pub heuristic: crate::integrator::bidir::mis::Heuristic,
    #[command(flatten)]
    pub chain: crate::integrator::metropolis::ChainOptions,
    /// Two-stage Metropolis (Mitsuba 0.6's `twoStage`): a first stage of BDPT samples
    /// estimates the image at a reduced resolution, and the chains sample paths in
    /// proportion to their luminance over it, so that dim pixels get as many mutations as
    /// bright ones.
    #[arg(long, default_value_t = MemltOptions::default().two_stage, action = clap::ArgAction::Set)]
    pub two_stage: bool,
    /// Samples per pixel of a separate direct-lighting estimate by the path tracer (paths of
    /// one edge, and of two through a rough vertex; those through a Dirac lobe are the
    /// chains'); -1 leaves every path to the Markov chains.
    #[arg(long, default_value_t = MemltOptions::default().direct_samples, allow_negative_numbers = true)]
    pub direct_samples: i32,
    /// With --time: the direct-light pass goes on past --direct-samples for the share of the
    /// time that balances its noise against the chains' (both measured, each from two
    /// independent halves, a tenth into the chains' time; at most half of the time then left).
    #[arg(long, default_value_t = MemltOptions::default().direct_balance, action = clap::ArgAction::Set)]
    pub direct_balance: bool,
    /// Beside the direct-light pass: samples per pixel, in stratified cells, of a specular
    /// pass that renders the paths through Dirac lobes alone (the light seen in mirrors and
    /// through glass); 0 leaves them to the chains.
    #[arg(long, default_value_t = MemltOptions::default().specular_samples)]
    pub specular_samples: u32,
    /// With --time: the BDPT bootstrap goes on in batches of --bootstrap samples until this
    /// fraction of the time is spent (`b`, the image's brightness, is its estimate).
    #[arg(long, default_value_t = MemltOptions::default().bootstrap_fraction)]
    pub bootstrap_fraction: f64,
    /// The bidirectional mutation among the mutations.
    #[arg(long, default_value_t = MemltOptions::default().bidirectional_mutation, action = clap::ArgAction::Set)]
    pub bidirectional_mutation: bool,
    /// Veach's lens perturbation among the mutations.
    #[arg(long, default_value_t = MemltOptions::default().lens_perturbation, action = clap::ArgAction::Set)]
    pub lens_perturbation: bool,
    /// Veach's caustic perturbation among the mutations.
    #[arg(long, default_value_t = MemltOptions::default().caustic_perturbation, action = clap::ArgAction::Set)]
    pub caustic_perturbation: bool,
    /// Veach's multi-chain perturbation among the mutations.
    #[arg(long, default_value_t = MemltOptions::default().multichain_perturbation, action = clap::ArgAction::Set)]
    pub multichain_perturbation: bool,
    /// The multi-chain perturbation re-traced on to the light, for paths whose light end no
    /// shadow ray joins (`L S+ D S+ E`: a caustic seen in glass; `L S+ E`); not Mitsuba 0.6's.
    #[arg(long, default_value_t = MemltOptions::default().light_hit_perturbation, action = clap::ArgAction::Set)]
    pub light_hit_perturbation: bool,
    /// The manifold perturbation among the mutations (`false` gives Veach's MLT).
    #[arg(long, default_value_t = MemltOptions::default().manifold_perturbation, action = clap::ArgAction::Set)]
    pub manifold_perturbation: bool,
    /// The independent mutation among the mutations (a whole new path from the
    /// bidirectional generator, Kelemen's large step in path space; not Mitsuba 0.6's).
    ///
    /// Default `auto`: on where `--bootstrap` camera walks to the first light find at least
    /// 1.5% of their light in paths that only such a walk makes (no edge takes a shadow ray:
    /// a caustic seen in a glass ball at its rim), off elsewhere (the statistics print the
    /// share and the choice).
    #[arg(long, action = clap::ArgAction::Set)]
    pub independent_mutation: Option<bool>,
    /// The share of the independent mutation's path lengths and splits drawn as the start
    /// paths' generator draws them (length ∝ 2^-k, split uniform); the rest follow what each
    /// length and split found among the start-path candidates. 1: all uniform.
    #[arg(long, default_value_t = MemltOptions::default().independent_defensive)]
    pub independent_defensive: f64,
    /// The share of the learned generator's draws (the independent mutation's and the
    /// learned start paths') that are camera walks going on until they find a light, making
    /// a path of any length, as a path tracer's sample does; the rest draw a length and a
    /// split.
    #[arg(long, default_value_t = MemltOptions::default().independent_camera_walks)]
    pub independent_camera_walks: f64,
    /// Draw the chains' start paths from a second set of candidates made by the learned
    /// generator of the independent mutation (their weights spread less), instead of the
    /// first set (lengths ∝ 2^-k, uniform splits).
    #[arg(long, default_value_t = MemltOptions::default().learned_starts, action = clap::ArgAction::Set)]
    pub learned_starts: bool,
    /// The manifold perturbation's sharpness (its von Mises–Fisher lobe's peak density is the
    /// current direction's scattering density times λ²; an area light's point moved by the
    /// perturbation gets a Gaussian whose peak is the point's density times λ²).
    #[arg(long, default_value_t = MemltOptions::default().lambda)]
    pub lambda: f64,
    /// The half-vector change, in degrees, against which the manifold perturbation judges a
    /// glossy lobe (a lobe much wider than it is treated as diffuse, one much narrower as
    /// specular; 0: glossy vertices are never treated as specular).
    #[arg(long, default_value_t = MemltOptions::default().theta_diff)]
    pub theta_diff: f64,
}

impl Default for MemltOptions {
    fn default() -> MemltOptions {
        MemltOptions {
            heuristic: Default::default(),
            chain: crate::integrator::metropolis::ChainOptions::default(),
            two_stage: true,
            direct_samples: 16,
            direct_balance: true,
            specular_samples: 0,
            bootstrap_fraction: 0.1,
            bidirectional_mutation: true,
            lens_perturbation: true,
            caustic_perturbation: true,
            multichain_perturbation: true,
            light_hit_perturbation: true,
            manifold_perturbation: true,
            independent_mutation: None,
            independent_defensive: 0.2,
            independent_camera_walks: 0.5,
            learned_starts: true,
            lambda: 50.0,
            theta_diff: 5.0,
        }
    }
}

/// The mutators the options enable, in [`Mutator::ALL`]'s order, with the independent
/// mutation as `independent` resolves `--independent-mutation auto`
/// ([`independent_mutation_on`]).
pub fn enabled(o: &MemltOptions, independent: bool) -> [bool; Mutator::ALL.len()] {
    [
        o.bidirectional_mutation,
        o.lens_perturbation,
        o.caustic_perturbation,
        o.multichain_perturbation,
        o.light_hit_perturbation,
        o.manifold_perturbation,
        independent,
    ]
}

/// The share of the light that `--bootstrap` camera walks to the first light find (their
/// summed `f / p`) above which `--independent-mutation auto` turns the independent mutation
/// on: light in paths that only camera walks make.
pub const AUTO_INDEPENDENT_SHARE: f64 = 0.015;

/// Whether the independent mutation runs: as `--independent-mutation` says, or with `auto`
/// (`None`) where a share `walk_only` of at least [`AUTO_INDEPENDENT_SHARE`] of the light
/// that camera walks to the first light find is in paths that only such a walk makes (no
/// edge takes a shadow ray: [`path::joined_nowhere`]); the split generator proposes those
/// at its one length's `s = 0` rate, the camera walks at a path tracer's (what it buys:
/// `docs/results/memlt.md`).
pub fn independent_mutation_on(option: Option<bool>, walk_only: f64) -> bool {
    option.unwrap_or(walk_only >= AUTO_INDEPENDENT_SHARE)
}
