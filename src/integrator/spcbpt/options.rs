//! SPCBPT's options: its pool, the budget and its own (`--sp-*`).

use crate::integrator::bidir::mis::Heuristic;
use crate::integrator::budget::{
    BudgetOptions, Prices, SPCBPT_PRICES, SPCBPT_RESAMPLING_PRICES, SPCBPT_SUBSPACE_PRICES,
};
use crate::integrator::pcbpt::{PcMis, PoolOptions};
use crate::integrator::spcbpt::subspace::TrainingSample;
use serde::Serialize;

/// Options of SPCBPT (`--integrator spcbpt`).
#[derive(Clone, Debug, Default, Serialize, clap::Args)]
pub struct SpcbptOptions {
    /// MIS heuristic.
    #[arg(long, value_enum, default_value_t = Heuristic::default())]
    pub heuristic: Heuristic,
    #[command(flatten)]
    #[serde(flatten)]
    pub sp: SpOptions,
}

/// Options of SPCBPT: its light pool and connections (as PCBPT's), its subspaces and their
/// matrix, the MIS counts of its connections, and the budget (PCBPT's).
#[derive(Clone, Debug, Serialize, clap::Args)]
pub struct SpOptions {
    #[command(flatten)]
    pub pool: PoolOptions,
    /// Eye subspaces (leaves of the k-d tree over camera vertices' positions and normals).
    #[arg(long = "sp-eye-subspaces", default_value_t = SpOptions::default().eye_subspaces)]
    pub eye_subspaces: usize,
    /// Light subspaces (leaves of the k-d tree over light vertices).
    #[arg(long = "sp-light-subspaces", default_value_t = SpOptions::default().light_subspaces)]
    pub light_subspaces: usize,
    /// Iterations whose connections train the subspace matrix Γ (0: it stays uniform).
    #[arg(long = "sp-training-iterations", default_value_t = SpOptions::default().training_iterations)]
    pub training_iterations: u32,
    /// Share of the uniform distribution mixed into each trained row of the matrix.
    #[arg(long = "sp-uniform", default_value_t = SpOptions::default().uniform)]
    pub uniform: f32,
    /// MIS strategy counts of the connections (as PCBPT's --pc-mis; resampling is the
    /// selection density itself, subspace the same with the draw within a light subspace
    /// taken as uniform).
    #[arg(long = "sp-mis", value_enum, default_value_t = SpOptions::default().mis)]
    pub mis: PcMis,
    /// Memory limit of the matrix and the training samples, in MiB.
    #[arg(long = "sp-max-mb", default_value_t = SpOptions::default().max_mb)]
    pub max_mb: usize,
    /// Whether the budget measures the last training iterations (the choice comes that many
    /// iterations sooner, and the training samples are the same) or the iterations after
    /// them.
    #[arg(long = "sp-budget-in-training", default_value_t = SpOptions::default().budget_in_training, action = clap::ArgAction::Set)]
    pub budget_in_training: bool,
    #[command(flatten)]
    pub budget: BudgetOptions,
}

impl Default for SpOptions {
    fn default() -> SpOptions {
        SpOptions {
            pool: PoolOptions::default(),
            eye_subspaces: 64,
            light_subspaces: 64,
            training_iterations: 4,
            uniform: 0.2,
            mis: PcMis::Subspace,
            max_mb: 1024,
            budget_in_training: true,
            budget: BudgetOptions::default(),
        }
    }
}

/// Pixels per side of the pilot grid whose camera vertices build the eye tree.
pub(super) const PILOT_STRIDE: u32 = 4;
/// Camera vertices per pilot pixel.
pub(super) const PILOT_DEPTH: u32 = 5;
/// The light tree is built from a pilot of this many times the iteration's light paths.
pub(super) const PILOT_POOLS: usize = 4;
/// Training samples come from at most about this many pixels per iteration (every k-th
/// pixel on larger films), so that their memory does not grow with the resolution.
pub(super) const TRAINING_PIXELS: usize = 65_536;
/// Bytes of one training sample.
pub(super) const SAMPLE_BYTES: f64 = std::mem::size_of::<TrainingSample>() as f64;

impl SpOptions {
    /// Checks the options, naming the one at fault.
    pub fn validate(&self) -> Result<(), String> {
        self.pool.validate()?;
        self.budget.validate(self.pool.connections)?;
        if !(1..=65_536).contains(&self.eye_subspaces) {
            return Err(format!("--sp-eye-subspaces must be between 1 and 65536, not {}", self.eye_subspaces));
        }
        if !(1..=65_536).contains(&self.light_subspaces) {
            return Err(format!("--sp-light-subspaces must be between 1 and 65536, not {}", self.light_subspaces));
        }
        if !(self.uniform > 0.0 && self.uniform <= 1.0) {
            return Err(format!(
                "--sp-uniform must be in (0, 1] (it keeps every light subspace reachable), not {}",
                self.uniform
            ));
        }
        Ok(())
    }

    /// The budget's prices: a connection's weight costs more with the counts that follow
    /// the path's subspaces ([`crate::integrator::budget::cost`]).
    pub(super) fn prices(&self) -> Prices {
        match self.mis {
            PcMis::Subspace => SPCBPT_SUBSPACE_PRICES,
            PcMis::Resampling => SPCBPT_RESAMPLING_PRICES,
            PcMis::Uniform | PcMis::Harmonic | PcMis::Correlated => SPCBPT_PRICES,
        }
    }

    /// MiB of the matrix (probabilities and running sums).
    pub(super) fn matrix_mb(&self) -> f64 {
        (self.eye_subspaces * self.light_subspaces * 8) as f64 / (1024.0 * 1024.0)
    }
}
