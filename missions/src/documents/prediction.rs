//! `predict --json`: per cycle the parent and every child, per step every
//! estimate a step sets, every scan station, the planned network adjusted
//! (also `plan --json`'s `adjusted`).
// The keys are documented in docs/json.md, key by key.
#![allow(missing_docs)]

use serde::Serialize;

use super::Document;
use super::records::{Ellipse, Pose, Position};

#[derive(Debug, Serialize, schemars::JsonSchema)]
pub struct ChildJson {
    pub name: String,
    pub position: Pose,
    /// 3×3, order (x, y, z), m².
    pub covariance: [[f64; 3]; 3],
    pub sigma_xy_m: f64,
    pub ellipse_95_m: Ellipse,
}

#[derive(Debug, Serialize, schemars::JsonSchema)]
pub struct StepJson {
    pub step: usize,
    pub cycle: usize,
    pub action: &'static str,
    pub robot: String,
    /// Deprecated: the same as `position`.
    #[schemars(extend("deprecated" = true))]
    pub position_m: [f64; 3],
    /// Where the robot is.
    pub position: Position,
    /// 4×4, order (x, y, z, θ), for the parent, 3×3 (x, y, z) for a
    /// child; m², m·rad, rad².
    pub covariance: Vec<Vec<f64>>,
    pub sigma_xy_m: f64,
    pub ellipse_95_m: Ellipse,
}

#[derive(Debug, Serialize, schemars::JsonSchema)]
pub struct ScanJson {
    pub step: usize,
    pub station: usize,
    pub pose: Pose,
    /// 4×4, order (x, y, z, θ), m², m·rad, rad².
    pub covariance: Vec<Vec<f64>>,
    pub sigma_xy_m: f64,
    pub sigma_heading_rad: f64,
    pub ellipse_95_m: Ellipse,
}

#[derive(Debug, Serialize, schemars::JsonSchema)]
pub struct CycleJson {
    pub cycle: usize,
    pub distance_m: f64,
    pub parent: Pose,
    /// 4×4, order (x, y, z, θ), m², m·rad, rad².
    pub covariance: [[f64; 4]; 4],
    pub ellipse_1sigma_m: Ellipse,
    pub ellipse_95_m: Ellipse,
    pub sigma_xy2_m2: f64,
    pub sigma_heading_rad: f64,
    /// Deprecated: the same as `sigma_drift_percent` (`report.json` once
    /// used the name for a true error).
    #[schemars(extend("deprecated" = true))]
    pub drift_percent: f64,
    /// The predicted horizontal σ (√(σx² + σy²)) in % of the distance.
    pub sigma_drift_percent: f64,
    pub children: Vec<ChildJson>,
}

#[derive(Debug, Serialize, schemars::JsonSchema)]
pub struct FinalJson {
    pub distance_m: f64,
    pub sigma_xy2_m2: f64,
    pub sigma_xy_m: f64,
    pub sigma_heading_rad: f64,
    /// Deprecated: the same as `sigma_drift_percent`.
    #[schemars(extend("deprecated" = true))]
    pub drift_percent: f64,
    /// The predicted horizontal σ in % of the distance.
    pub sigma_drift_percent: f64,
    pub ellipse_95_m: Ellipse,
    pub max_final_sigma_xy_m: Option<f64>,
    pub accepted: bool,
}

/// `predict --json`: per cycle the parent and every child, per step every
/// estimate a step sets, every scan station, the planned network adjusted.
#[derive(Debug, Serialize, schemars::JsonSchema)]
pub struct PredictionJson {
    pub mission: String,
    pub children: Vec<String>,
    pub cycles: Vec<CycleJson>,
    pub steps: Vec<StepJson>,
    pub scans: Vec<ScanJson>,
    #[serde(rename = "final")]
    pub final_: Option<FinalJson>,
    pub adjusted: Option<AdjustedJson>,
    pub adjusted_error: Option<String>,
}

#[derive(Debug, Serialize, schemars::JsonSchema)]
pub struct AdjustedStationJson {
    pub index: usize,
    pub x_m: f64,
    pub y_m: f64,
    pub z_m: f64,
    pub heading_rad: f64,
    /// 4×4, order (x, y, z, θ), m², m·rad, rad².
    pub covariance: [[f64; 4]; 4],
    pub sigma_xy_m: f64,
    pub filter_sigma_xy_m: Option<f64>,
    pub ellipse_95_m: Ellipse,
    pub control: Vec<String>,
}

#[derive(Debug, Serialize, schemars::JsonSchema)]
pub struct PlannedObservationJson {
    pub station: usize,
    pub target: String,
    pub kind: &'static str,
    pub sigma: f64,
    pub redundancy: f64,
    pub mdb: Option<f64>,
    pub station_shift_m: Option<f64>,
}

/// The pre-analysis: the planned network adjusted.
#[derive(Debug, Serialize, schemars::JsonSchema)]
pub struct AdjustedJson {
    pub stations: Vec<AdjustedStationJson>,
    pub worst_station: Option<usize>,
    pub worst_sigma_xy_m: Option<f64>,
    pub redundancy: usize,
    pub unchecked: usize,
    pub observations: Vec<PlannedObservationJson>,
    pub max_station_sigma_xy_m: Option<f64>,
    pub accepted: bool,
}

impl Document for PredictionJson {
    const NAME: &'static str = "predict";
    const VERSION: u32 = 1;
}
