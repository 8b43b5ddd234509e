//! The adjustment: `adjust --json`, `report.json`'s `adjustment` (the
//! same object, or why there is none).

use nalgebra::Matrix4;
use serde::{Deserialize, Serialize};

use super::records::Ellipse;

/// The version of the adjustment report's shape.
pub const SCHEMA_VERSION: u32 = 1;

/// `adjust --json`, nested whole as `report.json`'s `adjustment`: it
/// carries its own header.
impl super::Document for AdjustmentReport {
    const NAME: &'static str = "adjust";
    const VERSION: u32 = SCHEMA_VERSION;
    const SELF_VERSIONED: bool = true;
}

/// The report of an adjustment (`adjust --json`, `report.json`'s
/// `adjustment`). Covariances and w use the a-priori variance factor.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
pub struct AdjustmentReport {
    /// The version of this document's schema.
    pub schema_version: u32,
    /// The cps-survey version that wrote it.
    #[serde(default)]
    pub tool_version: String,
    /// vᵀPv / redundancy.
    pub sigma0_squared: f64,
    /// Observations minus unknowns.
    pub redundancy: usize,
    /// Unknowns.
    pub unknowns: usize,
    /// Gauss–Newton iterations.
    pub iterations: usize,
    /// Whether they converged.
    pub converged: bool,
    /// The global model test of every observation, before data snooping.
    pub global_test: GlobalTestReport,
    /// The same test after snooping's removals (none when nothing was
    /// removed; only its upper bound means something).
    #[serde(default)]
    pub global_test_after_snooping: Option<GlobalTestReport>,
    /// Whether the model holds: the global test passes, or snooping found
    /// the cause and what is left stays below the upper bound.
    #[serde(default)]
    pub model_accepted: bool,
    /// The tests' settings.
    pub testing: TestingReport,
    /// Every station.
    pub stations: Vec<StationAdjusted>,
    /// Every point: child placements and control points.
    pub points: Vec<PointAdjusted>,
    /// Every reading's (r, φ, ψ), removed ones included.
    pub observations: Vec<ObservationReport>,
    /// The weighted prior coordinates (the start's, the control points').
    pub coordinate_observations: Vec<CoordinateReport>,
    /// Data snooping's removals of readings, in order (indices into
    /// `observations`).
    pub removed: Vec<usize>,
    /// Data snooping's removals of weighted prior coordinates, in order
    /// (indices into `coordinate_observations`).
    #[serde(default)]
    pub removed_coordinates: Vec<usize>,
    /// Why snooping stopped early, if it did.
    pub snooping_stopped: Option<String>,
    /// The misclosure at each control point the others can check (module docs).
    pub misclosures: Vec<Misclosure>,
    /// The largest MDB's effect: the observation and the station it moves most.
    pub worst_mdb: Option<WorstMdb>,
}

/// The global test as reported.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
pub struct GlobalTestReport {
    /// vᵀPv.
    pub statistic: f64,
    /// Degrees of freedom.
    pub dof: usize,
    /// Significance level, two-sided.
    pub alpha: f64,
    /// χ²_dof(α/2).
    pub lower: Option<f64>,
    /// χ²_dof(1 − α/2).
    pub upper: Option<f64>,
    /// lower ≤ statistic ≤ upper.
    pub passed: bool,
}

impl From<&cps::batch::GlobalTest> for GlobalTestReport {
    fn from(g: &cps::batch::GlobalTest) -> Self {
        Self { statistic: g.statistic, dof: g.dof, alpha: g.alpha, lower: g.lower, upper: g.upper, passed: g.passed }
    }
}

/// The tests' settings.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
pub struct TestingReport {
    /// Global test level.
    pub alpha: f64,
    /// w-test level.
    pub alpha0: f64,
    /// w-test power.
    pub beta0: f64,
    /// Non-centrality λ0.
    pub lambda0: f64,
    /// Critical |w|.
    pub w_critical: f64,
    /// Whether data snooping ran.
    pub snooping: bool,
}

/// An adjusted station.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
pub struct StationAdjusted {
    /// Station index.
    pub index: usize,
    /// x, metres.
    pub x_m: f64,
    /// y, metres.
    pub y_m: f64,
    /// z, metres.
    pub z_m: f64,
    /// Heading, radians.
    pub heading_rad: f64,
    /// 4×4 (x, y, z, θ), m², m·rad, rad².
    pub covariance: [[f64; 4]; 4],
    /// √(σx² + σy²), metres.
    pub sigma_xy_m: f64,
    /// The absolute 95 % ellipse.
    pub ellipse_95: Ellipse,
    /// The 95 % ellipse relative to the previous station (none for the first).
    pub relative_ellipse_95: Option<Ellipse>,
}

/// An adjusted point.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
pub struct PointAdjusted {
    /// Its name: a control point's, or `child@cycle` for a placement.
    pub id: String,
    /// Whether it is a control point.
    pub control: bool,
    /// x, metres.
    pub x_m: f64,
    /// y, metres.
    pub y_m: f64,
    /// z, metres.
    pub z_m: f64,
    /// 3×3 (x, y, z), m².
    pub covariance: [[f64; 3]; 3],
}

/// One scalar observation's statistics.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
pub struct ObservationReport {
    /// Its index in this list.
    pub index: usize,
    /// The station it was measured from.
    pub station: usize,
    /// The point it was measured to (an `id` of `points`).
    pub target: String,
    /// `slope_distance`, `azimuth` or `elevation`.
    pub kind: String,
    /// The observation as adjusted (prism constant applied), m or rad.
    pub value: f64,
    /// Its a-priori σ.
    pub sigma: f64,
    /// Adjusted minus observed.
    pub residual: f64,
    /// Redundancy number.
    pub redundancy: f64,
    /// Baarda's w (at its removal for a removed one); null unchecked.
    pub w: Option<f64>,
    /// Minimal detectable bias; null unchecked.
    pub mdb: Option<f64>,
    /// Bias-to-noise ratio: an undetected MDB's largest effect on any
    /// unknown, in its σ.
    pub bnr: Option<f64>,
    /// How far an error of MDB moves its station horizontally, metres.
    pub station_shift_m: Option<f64>,
    /// Removed by data snooping.
    pub removed: bool,
}

/// A weighted prior coordinate's statistics.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
pub struct CoordinateReport {
    /// `station N` or the control point's name.
    pub of: String,
    /// `x`, `y`, `z` or `heading`.
    pub coordinate: String,
    /// Its σ.
    pub sigma: f64,
    /// Adjusted minus given.
    pub residual: f64,
    /// Redundancy number.
    pub redundancy: f64,
    /// Baarda's w.
    pub w: Option<f64>,
    /// Minimal detectable bias.
    pub mdb: Option<f64>,
    /// Removed by data snooping (its w then, its residual at the final
    /// estimate; no redundancy or MDB).
    #[serde(default)]
    pub removed: bool,
}

/// A misclosure at a control point.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
pub struct Misclosure {
    /// The control point.
    pub control: String,
    /// Surveyed minus given, x, metres.
    pub dx_m: f64,
    /// … y.
    pub dy_m: f64,
    /// … z.
    pub dz_m: f64,
    /// √(dx² + dy²).
    pub horizontal_m: f64,
    /// Its σ: √(σx² + σy²) of the difference.
    pub sigma_horizontal_m: f64,
    /// σ of dz.
    pub sigma_z_m: f64,
    /// dᵀ Σ⁻¹ d of the horizontal part (χ²₂ without a blunder).
    pub chi2_horizontal: Option<f64>,
}

/// The observation whose MDB moves its station the most.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
pub struct WorstMdb {
    /// Index into `observations`.
    pub observation: usize,
    /// The station it moves.
    pub station: usize,
    /// By how much, metres.
    pub shift_m: f64,
}

/// The adjustment at the end of a run, as `report.json` has it: the report,
/// or why the network could not be adjusted.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(untagged)]
pub enum AdjustmentOutcome {
    /// The adjustment.
    Adjusted(Box<AdjustmentReport>),
    /// Why there is none.
    Failed {
        /// The reason.
        error: String,
    },
}

impl AdjustmentOutcome {
    /// The report, if the network was adjusted.
    pub fn report(&self) -> Option<&AdjustmentReport> {
        match self {
            AdjustmentOutcome::Adjusted(r) => Some(r),
            AdjustmentOutcome::Failed { .. } => None,
        }
    }
}

/// The adjusted covariance of station `k` from a report.
pub fn station_covariance(report: &AdjustmentReport, k: usize) -> Option<Matrix4<f64>> {
    report.stations.get(k).map(|s| super::records::matrix4(&s.covariance))
}
