//! MEMLT's statistics: per mutator, of the manifold walks, of the normalisation and the
//! direct light's balance, and their lines in the render's summary.

use super::Mutator;
use super::{direct_balance, manifold_perturbation};
use crate::integrator::metropolis::first_stage_line;
use crate::integrator::metropolis::stays::LongestStay;
use crate::integrator::stats::{IntegratorStats, RenderStats};
use serde::Serialize;

/// Proposals and acceptances of one mutator.
#[derive(Clone, Copy, Debug, Serialize)]
pub struct MutatorStats {
    pub mutator: Mutator,
    pub proposed: u64,
    pub accepted: u64,
    pub acceptance: f64,
}

/// MEMLT's statistics, under `memlt` in the JSON.
#[derive(Clone, Debug, Serialize)]
pub struct MemltDetails {
    pub memlt: MemltStats,
}

impl IntegratorStats for MemltDetails {
    fn lines(&self, _: &RenderStats) -> Vec<String> {
        let m = &self.memlt;
        let acceptance: Vec<String> = m
            .mutators
            .iter()
            .map(|x| format!("{:?} {:.1}% of {}", x.mutator, x.acceptance * 100.0, x.proposed))
            .collect();
        let w = &m.manifold_walks;
        let mut lines = vec![
            format!(
                "  MEMLT: b = {:.5} ± {:.5} (start paths: {:.5}, effective {:.0} of {}), {} chains, {} mutations ({:.3} M/s), paths of {}..={} edges, acceptance: {}; manifold walks: {} tried, {} converged, {} irreversible; {} perturbations kept glossy half-vectors, {} moved the light point, {} the line light from infinity arrives along; bootstrap {:.2} s",
                m.normalisation,
                m.normalisation_error,
                m.seed_normalisation,
                m.start_ess,
                m.start_candidates,
                m.chains,
                m.mutations,
                m.mutations_per_second / 1e6,
                m.min_edges,
                m.max_edges,
                acceptance.join(", "),
                w.tried,
                w.converged,
                w.irreversible,
                w.glossy,
                w.light_points,
                w.sky_points,
                m.bootstrap_seconds
            ),
            format!(
                "  MEMLT: {:.2}% of the light camera walks find in paths only such a walk makes; independent mutation {}",
                m.walk_only_share * 100.0,
                if m.independent_mutation { "on" } else { "off" }
            ),
        ];
        if let Some(d) = &m.direct_balance {
            lines.push(format!(
                "  MEMLT: direct light {} samples per pixel in {:.2} s ({} added after {:.2} s of the chains: relative variance per second, direct {:.3e}, chains {:.3e})",
                m.direct_samples, m.direct_seconds, d.extra_samples, d.measured_after, d.direct_noise, d.chain_noise
            ));
        }
        lines.extend(first_stage_line(m.first_stage_samples, m.mean_luminance));
        lines.extend(m.longest_stay.iter().flat_map(|l| l.lines("memlt")));
        lines
    }
}

/// Statistics of a MEMLT render.
#[derive(Clone, Debug, Default, Serialize)]
pub struct MemltStats {
    /// `b` from the BDPT bootstrap, and its standard error (the image's brightness is
    /// uncertain by as much).
    pub normalisation: f64,
    pub normalisation_error: f64,
    /// `b` from the start-path candidates (an independent check of the path densities).
    pub seed_normalisation: f64,
    /// The effective sample size `(Σw)² / Σw²` of the start-path candidates' weights `f / p`
    /// (of `--bootstrap` candidates): how many distinct paths the chains' starts are drawn
    /// from, in effect.
    pub start_ess: f64,
    pub start_candidates: usize,
    /// With `--independent-mutation auto`, the share of the light that `--bootstrap` camera
    /// walks to the first light find in paths that only such a walk makes
    /// ([`path::joined_nowhere`]), and whether the independent mutation ran (`auto` turns it
    /// on from [`AUTO_INDEPENDENT_SHARE`] of it).
    pub walk_only_share: f64,
    pub independent_mutation: bool,
    pub bootstrap_samples: u64,
    pub chains: usize,
    pub mutations: u64,
    pub mutators: Vec<MutatorStats>,
    /// The manifold perturbation's walks.
    pub manifold_walks: manifold_perturbation::WalkStats,
    pub mutations_per_second: f64,
    pub bootstrap_seconds: f64,
    /// The path lengths (edges) the chains visit.
    pub min_edges: usize,
    pub max_edges: usize,
    /// The longest any chain's current path stayed in one pixel.
    pub longest_stay: Option<LongestStay>,
    /// Two-stage Metropolis: the first stage's BDPT samples (0 without it). `normalisation`
    /// is then the mean of luminance over the first stage's map, not the mean luminance.
    pub first_stage_samples: u64,
    /// The bootstrap's mean luminance of the chains' paths, with its standard error: the
    /// chains' part of the image has this mean (`normalisation` without a first stage).
    pub mean_luminance: f64,
    pub mean_luminance_error: f64,
    /// The separate direct-light pass: its samples per pixel in all (0 without it), its
    /// seconds, and with `--direct-balance` under a time budget what the balance measured
    /// and added ([`direct_balance`]).
    pub direct_samples: u32,
    pub direct_seconds: f64,
    pub direct_balance: Option<direct_balance::DirectBalance>,
}
