//! The budget's options (`--budget`, `--budget-*`), shared by PCBPT and SPCBPT.

use serde::Serialize;

/// Whether the pool integrators choose their budget (`--pc-budget`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum, Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum BudgetMode {
    /// `--pc-connections` and the pool's light paths, as given.
    Off,
    /// Chosen after `--pc-budget-iterations` measured iterations.
    Auto,
}

/// How a candidate's variance is predicted (`--pc-budget-model`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum, Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum BudgetModel {
    /// The measured variance plus the change of the contributions' second moments
    /// (`Σ v² / (u + a k + c l)`), the connections' part times `--pc-budget-independence`.
    Moments,
    /// The variance of each camera sample re-weighted as the candidate would weigh it, with
    /// its draws' spread for a changed number of connections, plus light tracing's second
    /// moment ([`Realized`]).
    Realized,
}

/// How much of the connections' predicted change of second moment counts
/// (`--pc-budget-independence`): a fixed share, or the share measured from their spread
/// within camera vertices ([`Spread`]).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, serde::Deserialize)]
#[serde(untagged)]
pub enum Independence {
    Fixed(f32),
    Measured(MeasuredWord),
}

/// The word `measured` (of [`Independence`] in experiment files).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum MeasuredWord {
    Measured,
}

impl Independence {
    pub const MEASURED: Independence = Independence::Measured(MeasuredWord::Measured);

    /// The fixed share, `None` when measured.
    pub fn fixed(&self) -> Option<f32> {
        match *self {
            Independence::Fixed(f) => Some(f),
            Independence::Measured(_) => None,
        }
    }
}

impl std::str::FromStr for Independence {
    type Err = String;
    fn from_str(s: &str) -> Result<Independence, String> {
        if s == "measured" {
            return Ok(Independence::MEASURED);
        }
        s.parse::<f32>()
            .map(Independence::Fixed)
            .map_err(|_| format!("expected a number from 0 to 1 or `measured`, not `{s}`"))
    }
}

impl std::fmt::Display for Independence {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self.fixed() {
            Some(x) => write!(f, "{x}"),
            None => f.write_str("measured"),
        }
    }
}

/// Connections per camera vertex a budget may choose.
pub const CONNECTION_CHOICES: [u32; 5] = [0, 1, 2, 4, 8];

/// Samples per pixel the choice plans for without `--pc-budget-horizon`: with `--time`, and
/// the least with `--spp`. [`measure::typical`] treats each measured sample as a region of
/// its own, and where many such samples carry a pixel's light together a short render misses
/// all of them more often than it predicts, so a horizon of a few samples per pixel gives up
/// connections that pay. The predictions were checked against renders at this horizon
/// (`docs/results/budget.md`).
pub const DEFAULT_HORIZON: u32 = 256;

/// The budget's options, shared by PCBPT and SPCBPT (`--budget*`; the `--pc-budget*` names
/// are accepted too).
#[derive(Clone, Debug, Serialize, clap::Args)]
pub struct BudgetOptions {
    /// Choose the connections per camera vertex (0-8) and the light paths that are light
    /// traced from the second moments and costs of measured iterations (auto), or keep
    /// --connections and the pool's light paths (off).
    #[arg(id = "budget", long = "budget", alias = "pc-budget", value_enum, default_value_t = BudgetOptions::default().mode)]
    pub mode: BudgetMode,
    /// Iterations measured before the budget is chosen.
    #[arg(id = "budget_iterations", value_name = "N", long = "budget-iterations", alias = "pc-budget-iterations", default_value_t = BudgetOptions::default().iterations)]
    pub iterations: u32,
    /// The share of the connections' predicted change of second moment between budgets
    /// that counts, 0 to 1 (1 if the draws of a camera vertex were independent), or
    /// `measured` (from their spread about each camera vertex's mean).
    #[arg(id = "budget_independence", value_name = "SHARE", long = "budget-independence", alias = "pc-budget-independence", default_value_t = BudgetOptions::default().independence)]
    pub independence: Independence,
    /// Measured pixels each side whose means are averaged for the relMSE weights of the
    /// budget's choice (0: each pixel's own mean).
    #[arg(id = "budget_smoothing", value_name = "PIXELS", long = "budget-smoothing", alias = "pc-budget-smoothing", default_value_t = BudgetOptions::default().smoothing)]
    pub smoothing: u32,
    /// How the budget predicts a plan's variance: the change of the contributions' second
    /// moments (moments), or each measured camera sample re-weighted as the plan would weigh
    /// it, with its connections' spread (realized).
    #[arg(id = "budget_model", long = "budget-model", alias = "pc-budget-model", value_enum, default_value_t = BudgetOptions::default().model)]
    pub model: BudgetModel,
    /// Samples per pixel the budget plans for (default: the render's --spp but at least
    /// 256, which --time takes). A path that a plan would sample less than (measured
    /// iterations / horizon) times as densely as the measured plan counts by its chance of
    /// being found in the render, as the typical render shows it, not by its expected
    /// variance; 0 counts every path by its expected variance.
    #[arg(id = "budget_horizon", value_name = "SPP", long = "budget-horizon", alias = "pc-budget-horizon")]
    pub horizon: Option<u32>,
    /// The least predicted efficiency gain over the measured plan for which the budget
    /// leaves it (1: any gain; the predictions are within about a third of what renders
    /// measure, so smaller gains are noise).
    #[arg(id = "budget_margin", value_name = "GAIN", long = "budget-margin", alias = "pc-budget-margin", default_value_t = BudgetOptions::default().margin)]
    pub margin: f32,
    /// Pixels whose moments the budget measures, at most about (those of every k-th row and
    /// column).
    #[arg(id = "budget_pixels", value_name = "PIXELS", long = "budget-pixels", alias = "pc-budget-pixels", default_value_t = BudgetOptions::default().pixels)]
    pub pixels: usize,
    /// Whether each measured pixel's largest contribution counts, at the horizon, as rarely
    /// as its value against the pixel's mean says (false: as a region the measured
    /// iterations found once, like every other sample).
    #[arg(id = "budget_rarity", long = "budget-rarity", alias = "pc-budget-rarity", default_value_t = BudgetOptions::default().rarity, action = clap::ArgAction::Set)]
    pub rarity: bool,
}

impl Default for BudgetOptions {
    fn default() -> BudgetOptions {
        BudgetOptions {
            mode: BudgetMode::Auto,
            iterations: 2,
            independence: Independence::Fixed(0.35),
            smoothing: 2,
            model: BudgetModel::Realized,
            horizon: None,
            margin: 1.1,
            pixels: 16_384,
            rarity: true,
        }
    }
}

impl BudgetOptions {
    /// Checks the options, naming the one at fault; `connections` are those the budget is
    /// measured with.
    pub fn validate(&self, connections: u32) -> Result<(), String> {
        if connections == 0 && self.mode == BudgetMode::Auto {
            return Err(
                "--connections 0 needs --budget off: the budget (on by default) measures the connections it then chooses among".into(),
            );
        }
        if let Some(f) = self.independence.fixed()
            && !(0.0..=1.0).contains(&f)
        {
            return Err(format!("--budget-independence must be between 0 and 1, not {f}"));
        }
        if self.smoothing > 64 {
            return Err(format!("--budget-smoothing must be at most 64, not {}", self.smoothing));
        }
        if !(self.margin >= 1.0 && self.margin.is_finite()) {
            return Err(format!(
                "--budget-margin must be at least 1 and finite (a predicted gain below 1 is a loss), not {}",
                self.margin
            ));
        }
        if self.pixels == 0 {
            return Err("--budget-pixels must be at least 1".into());
        }
        if self.iterations < 2 {
            return Err("--budget-iterations must be at least 2 (the variance is measured across them)".into());
        }
        Ok(())
    }
}
