//! `plan --json`: the plan as written (its violations, the analysis) and
//! the optimized plan.
// The keys are documented in docs/json.md, key by key.
#![allow(missing_docs)]

use serde::Serialize;

use super::Document;
use super::prediction::AdjustedJson;

#[derive(Debug, Serialize, schemars::JsonSchema)]
pub struct ViolationJson {
    pub step: usize,
    pub cycle: usize,
    pub station: usize,
    pub robot: String,
    pub constraint: &'static str,
    pub value: f64,
    pub limit: f64,
    pub message: String,
}

#[derive(Debug, Serialize, schemars::JsonSchema)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum FormationJson {
    Symmetric { forward_m: f64, lateral_m: f64, up_m: f64 },
    Fan { radius_m: f64, spread_deg: f64, up_m: f64 },
    Line { ahead_m: f64, spacing_m: f64, up_m: f64 },
}

impl FormationJson {
    pub fn of(kind: &planner::FormationKind, up_m: f64) -> Self {
        match *kind {
            planner::FormationKind::Symmetric { forward_m, lateral_m } => {
                Self::Symmetric { forward_m, lateral_m, up_m }
            }
            planner::FormationKind::Fan { radius_m, spread_deg } => Self::Fan { radius_m, spread_deg, up_m },
            planner::FormationKind::Line { ahead_m, spacing_m } => Self::Line { ahead_m, spacing_m, up_m },
        }
    }
}

#[derive(Debug, Serialize, schemars::JsonSchema)]
pub struct OptimizedJson {
    pub strategy: &'static str,
    pub hops: usize,
    pub stride_m: f64,
    pub formation: FormationJson,
    pub formation_m: Vec<[f64; 3]>,
    pub cycles: usize,
    pub sigma_xy2_m2: f64,
    pub sigma_xy_m: f64,
    pub improvement_factor: Option<f64>,
    pub candidates_predicted: usize,
    pub candidates_checked: usize,
    pub seconds: f64,
    pub control_at: Option<String>,
    pub worst_station_sigma_xy_m: Option<f64>,
}

#[derive(Debug, Serialize, schemars::JsonSchema)]
pub struct PredictedJson {
    pub sigma_xy2_m2: Option<f64>,
    pub sigma_xy_m: Option<f64>,
    pub sigma_heading_rad: Option<f64>,
}

#[derive(Debug, Serialize, schemars::JsonSchema)]
pub struct SensitivityJson {
    pub total_m2: f64,
    pub range_m2: f64,
    pub angle_m2: f64,
    pub centring_m2: f64,
    pub start_m2: f64,
    pub dominant: &'static str,
}

#[derive(Debug, Serialize, schemars::JsonSchema)]
pub struct LongerStrideJson {
    pub stride_m: f64,
    pub cycles: usize,
    pub sigma_xy2_m2: f64,
}

#[derive(Debug, Serialize, schemars::JsonSchema)]
pub struct WhatIfJson {
    pub one_more_child_sigma_xy2_m2: Option<f64>,
    pub longer_stride: Option<LongerStrideJson>,
}

#[derive(Debug, Serialize, schemars::JsonSchema)]
pub struct UncheckedJson {
    pub cycle: usize,
    pub child: String,
    pub observation: &'static str,
    pub redundancy_number: f64,
}

#[derive(Debug, Serialize, schemars::JsonSchema)]
pub struct ReliabilityJson {
    pub min_redundancy_number: Option<f64>,
    pub unchecked: Vec<UncheckedJson>,
}

/// `plan --json`: the plan as written (its violations, the analysis) and
/// the optimized plan.
#[derive(Debug, Serialize, schemars::JsonSchema)]
pub struct PlanJson {
    pub mission: String,
    pub strategy: &'static str,
    pub hops: usize,
    pub stride_m: f64,
    pub formation_m: Vec<[f64; 3]>,
    pub scene: Option<String>,
    /// Deprecated: the same as `station_count` (`stations` is a list in
    /// every other document).
    #[schemars(extend("deprecated" = true))]
    pub stations: usize,
    /// Deprecated: the same as `cycle_count`.
    #[schemars(extend("deprecated" = true))]
    pub cycles: usize,
    /// Deprecated: the same as `step_count`.
    #[schemars(extend("deprecated" = true))]
    pub steps: usize,
    /// Parent stations, the start included.
    pub station_count: usize,
    /// Dance cycles.
    pub cycle_count: usize,
    /// Steps of the plan.
    pub step_count: usize,
    pub violations: Vec<ViolationJson>,
    pub predicted: PredictedJson,
    pub sensitivity: Option<SensitivityJson>,
    pub what_if: WhatIfJson,
    pub reliability: ReliabilityJson,
    pub control_at: String,
    pub control: Vec<ControlSeenJson>,
    pub adjusted: Option<AdjustedJson>,
    pub optimized: Option<OptimizedJson>,
    pub accepted: bool,
}

#[derive(Debug, Serialize, schemars::JsonSchema)]
pub struct ControlSightingJson {
    pub station: usize,
    pub slope_distance_m: f64,
}

#[derive(Debug, Serialize, schemars::JsonSchema)]
pub struct ControlSeenJson {
    pub name: String,
    pub fixed: bool,
    pub seen_from: Vec<ControlSightingJson>,
}

impl Document for PlanJson {
    const NAME: &'static str = "plan";
    const VERSION: u32 = 1;
}
