//! The `--json` documents of `predict`, `plan` and `montecarlo`, typed
//! and versioned (docs/json.md and docs/commands.md document each key, and
//! `docs/schemas/` their schemas).

use std::io::Write;

use cps::{CHI2_2D_95_SQRT, ErrorEllipse};
use planner::{Action, Robot, StepEstimate};
use serde::Serialize;

use crate::mission::Mission;
use crate::planning::Planned;
use crate::planning::analysis::{self, PlanReport};
use crate::planning::montecarlo::MonteCarlo;
use crate::view::document::{Document, write_line};

/// A position: x, y, z, metres (the shape of every position in every
/// document; poses add `heading_rad`).
#[derive(Serialize, schemars::JsonSchema)]
struct PositionJson {
    x_m: f64,
    y_m: f64,
    z_m: f64,
}

#[derive(Serialize, schemars::JsonSchema)]
struct PoseJson {
    x_m: f64,
    y_m: f64,
    z_m: f64,
    heading_rad: f64,
}

impl PoseJson {
    fn of(p: &cps::ParentPose) -> Self {
        Self { x_m: p.position.x, y_m: p.position.y, z_m: p.position.z, heading_rad: p.heading_rad }
    }
}

#[derive(Serialize, schemars::JsonSchema)]
struct EllipseJson {
    semi_major_m: f64,
    semi_minor_m: f64,
    orientation_rad: f64,
}

impl From<ErrorEllipse> for EllipseJson {
    fn from(e: ErrorEllipse) -> Self {
        Self { semi_major_m: e.semi_major_m, semi_minor_m: e.semi_minor_m, orientation_rad: e.orientation_rad }
    }
}

#[derive(Serialize, schemars::JsonSchema)]
struct ChildJson {
    name: String,
    position: PoseJson,
    /// 3×3, order (x, y, z), m².
    covariance: [[f64; 3]; 3],
    sigma_xy_m: f64,
    ellipse_95_m: EllipseJson,
}

#[derive(Serialize, schemars::JsonSchema)]
struct StepJson {
    step: usize,
    cycle: usize,
    action: &'static str,
    robot: String,
    /// Deprecated: the same as `position`.
    #[schemars(extend("deprecated" = true))]
    position_m: [f64; 3],
    /// Where the robot is.
    position: PositionJson,
    /// 4×4, order (x, y, z, θ), for the parent, 3×3 (x, y, z) for a
    /// child; m², m·rad, rad².
    covariance: Vec<Vec<f64>>,
    sigma_xy_m: f64,
    ellipse_95_m: EllipseJson,
}

#[derive(Serialize, schemars::JsonSchema)]
struct ScanJson {
    step: usize,
    station: usize,
    pose: PoseJson,
    /// 4×4, order (x, y, z, θ), m², m·rad, rad².
    covariance: Vec<Vec<f64>>,
    sigma_xy_m: f64,
    sigma_heading_rad: f64,
    ellipse_95_m: EllipseJson,
}

#[derive(Serialize, schemars::JsonSchema)]
struct CycleJson {
    cycle: usize,
    distance_m: f64,
    parent: PoseJson,
    /// 4×4, order (x, y, z, θ), m², m·rad, rad².
    covariance: [[f64; 4]; 4],
    ellipse_1sigma_m: EllipseJson,
    ellipse_95_m: EllipseJson,
    sigma_xy2_m2: f64,
    sigma_heading_rad: f64,
    /// Deprecated: the same as `sigma_drift_percent` (`report.json` once
    /// used the name for a true error).
    #[schemars(extend("deprecated" = true))]
    drift_percent: f64,
    /// The predicted horizontal σ (√(σx² + σy²)) in % of the distance.
    sigma_drift_percent: f64,
    children: Vec<ChildJson>,
}

#[derive(Serialize, schemars::JsonSchema)]
struct FinalJson {
    distance_m: f64,
    sigma_xy2_m2: f64,
    sigma_xy_m: f64,
    sigma_heading_rad: f64,
    /// Deprecated: the same as `sigma_drift_percent`.
    #[schemars(extend("deprecated" = true))]
    drift_percent: f64,
    /// The predicted horizontal σ in % of the distance.
    sigma_drift_percent: f64,
    ellipse_95_m: EllipseJson,
    max_final_sigma_xy_m: Option<f64>,
    accepted: bool,
}

/// `predict --json`: per cycle the parent and every child, per step every
/// estimate a step sets, every scan station, the planned network adjusted.
#[derive(Serialize, schemars::JsonSchema)]
pub(crate) struct PredictionJson {
    mission: String,
    children: Vec<String>,
    cycles: Vec<CycleJson>,
    steps: Vec<StepJson>,
    scans: Vec<ScanJson>,
    #[serde(rename = "final")]
    final_: Option<FinalJson>,
    adjusted: Option<AdjustedJson>,
    adjusted_error: Option<String>,
}

#[derive(Serialize, schemars::JsonSchema)]
struct AdjustedStationJson {
    index: usize,
    x_m: f64,
    y_m: f64,
    z_m: f64,
    heading_rad: f64,
    /// 4×4, order (x, y, z, θ), m², m·rad, rad².
    covariance: [[f64; 4]; 4],
    sigma_xy_m: f64,
    filter_sigma_xy_m: Option<f64>,
    ellipse_95_m: EllipseJson,
    control: Vec<String>,
}

#[derive(Serialize, schemars::JsonSchema)]
struct PlannedObservationJson {
    station: usize,
    target: String,
    kind: &'static str,
    sigma: f64,
    redundancy: f64,
    mdb: Option<f64>,
    station_shift_m: Option<f64>,
}

/// The pre-analysis: the planned network adjusted.
#[derive(Serialize, schemars::JsonSchema)]
struct AdjustedJson {
    stations: Vec<AdjustedStationJson>,
    worst_station: Option<usize>,
    worst_sigma_xy_m: Option<f64>,
    redundancy: usize,
    unchecked: usize,
    observations: Vec<PlannedObservationJson>,
    max_station_sigma_xy_m: Option<f64>,
    accepted: bool,
}

fn adjusted_json(mission: &Mission, planned: &Planned) -> Option<AdjustedJson> {
    let pre = planned.adjusted.as_ref()?;
    let worst = planned.worst_station();
    let stations = pre
        .stations
        .iter()
        .map(|s| {
            let p = &s.pose;
            AdjustedStationJson {
                index: s.index,
                x_m: p.position.x,
                y_m: p.position.y,
                z_m: p.position.z,
                heading_rad: p.heading_rad,
                covariance: std::array::from_fn(|i| std::array::from_fn(|j| s.covariance[(i, j)])),
                sigma_xy_m: s.sigma_xy_m(),
                filter_sigma_xy_m: planned.filter_covariance(s.index).map(|c| cps::sigma_xy2(&c).sqrt()),
                ellipse_95_m: ErrorEllipse::from_covariance(&s.covariance.fixed_view::<2, 2>(0, 0).into_owned())
                    .scaled(CHI2_2D_95_SQRT)
                    .into(),
                control: planned.control_sighted_at(s.index).into_iter().map(String::from).collect(),
            }
        })
        .collect();
    let observations = pre
        .observations
        .iter()
        .map(|o| PlannedObservationJson {
            station: o.station,
            target: o.target.clone(),
            kind: o.kind,
            sigma: o.sigma,
            redundancy: o.redundancy,
            mdb: o.mdb,
            station_shift_m: o.station_shift_m,
        })
        .collect();
    let max = mission.acceptance.max_station_sigma_xy_m;
    Some(AdjustedJson {
        stations,
        worst_station: worst.map(|w| w.0),
        worst_sigma_xy_m: worst.map(|w| w.1),
        redundancy: pre.redundancy,
        unchecked: pre.unchecked().count(),
        observations,
        max_station_sigma_xy_m: max,
        accepted: match (max, worst) {
            (Some(max), Some((_, s))) => s <= max,
            _ => true,
        },
    })
}

fn nested(m: &nalgebra::DMatrix<f64>) -> Vec<Vec<f64>> {
    m.row_iter().map(|r| r.iter().copied().collect()).collect()
}

fn ellipse_95(e: &StepEstimate) -> EllipseJson {
    e.ellipse_1sigma().scaled(CHI2_2D_95_SQRT).into()
}

/// What a step that sets an estimate does, in words.
pub fn step_kind(steps: &[planner::Step], e: &StepEstimate) -> &'static str {
    match steps.get(e.step).map(|s| &s.action) {
        Some(Action::Measure { .. }) => "placement",
        Some(Action::Fix { .. }) => "fix",
        Some(Action::Scan { .. }) => "scan",
        Some(Action::MoveParent { .. }) => "odometry",
        _ => "estimate",
    }
}

/// `predict --json`: per cycle the parent and every child, per step every
/// estimate a step sets, and every scan station.
pub fn prediction(out: &mut dyn Write, mission: &Mission, planned: &Planned) -> std::io::Result<()> {
    let (dance, prediction, steps) = (&planned.dance, &planned.prediction, &planned.steps);
    let cycles = prediction
        .cycles
        .iter()
        .map(|c| CycleJson {
            cycle: c.cycle,
            distance_m: c.distance_m,
            parent: PoseJson::of(&c.parent),
            covariance: std::array::from_fn(|i| std::array::from_fn(|j| c.covariance[(i, j)])),
            ellipse_1sigma_m: c.ellipse_1sigma().into(),
            ellipse_95_m: c.ellipse_1sigma().scaled(CHI2_2D_95_SQRT).into(),
            sigma_xy2_m2: c.sigma_xy2_m2(),
            sigma_heading_rad: c.sigma_heading_rad(),
            drift_percent: c.drift_percent(),
            sigma_drift_percent: c.drift_percent(),
            children: c
                .children_covariance
                .iter()
                .enumerate()
                .map(|(j, cov)| {
                    let p = dance.cycles[c.cycle - 1].children[j];
                    let e = ErrorEllipse::from_covariance(&cov.fixed_view::<2, 2>(0, 0).into_owned());
                    ChildJson {
                        name: mission.robot_label(Robot::Child(j)),
                        position: PoseJson { x_m: p.x, y_m: p.y, z_m: p.z, heading_rad: 0.0 },
                        covariance: std::array::from_fn(|r| std::array::from_fn(|s| cov[(r, s)])),
                        sigma_xy_m: (cov[(0, 0)] + cov[(1, 1)]).sqrt(),
                        ellipse_95_m: e.scaled(CHI2_2D_95_SQRT).into(),
                    }
                })
                .collect(),
        })
        .collect();
    let scans = planned
        .estimates
        .iter()
        .filter_map(|e| {
            let Action::Scan { station } = steps.get(e.step)?.action else { return None };
            Some(ScanJson {
                step: e.step,
                station,
                pose: PoseJson::of(&dance.station_pose(station)),
                covariance: nested(&e.covariance),
                sigma_xy_m: e.sigma_xy2_m2().sqrt(),
                sigma_heading_rad: e.covariance[(3, 3)].sqrt(),
                ellipse_95_m: ellipse_95(e),
            })
        })
        .collect();
    let step_rows = planned
        .estimates
        .iter()
        .filter(|e| !e.scan)
        .map(|e| StepJson {
            step: e.step,
            cycle: e.cycle,
            action: step_kind(steps, e),
            robot: mission.robot_label(e.robot),
            position_m: [e.position.x, e.position.y, e.position.z],
            position: PositionJson { x_m: e.position.x, y_m: e.position.y, z_m: e.position.z },
            covariance: nested(&e.covariance),
            sigma_xy_m: e.sigma_xy2_m2().sqrt(),
            ellipse_95_m: ellipse_95(e),
        })
        .collect();
    let final_ = prediction.last().map(|l| FinalJson {
        distance_m: l.distance_m,
        sigma_xy2_m2: l.sigma_xy2_m2(),
        sigma_xy_m: l.sigma_xy2_m2().sqrt(),
        sigma_heading_rad: l.sigma_heading_rad(),
        drift_percent: l.drift_percent(),
        sigma_drift_percent: l.drift_percent(),
        ellipse_95_m: l.ellipse_1sigma().scaled(CHI2_2D_95_SQRT).into(),
        max_final_sigma_xy_m: mission.acceptance.max_final_sigma_xy_m,
        accepted: crate::planning::accepted(mission, planned),
    });
    let doc = PredictionJson {
        mission: mission.name.clone(),
        children: mission.children.clone(),
        cycles,
        steps: step_rows,
        scans,
        final_,
        adjusted: adjusted_json(mission, planned),
        adjusted_error: planned.adjusted_error.clone(),
    };
    write_line(out, &doc)
}

#[derive(Serialize, schemars::JsonSchema)]
struct ViolationJson {
    step: usize,
    cycle: usize,
    station: usize,
    robot: String,
    constraint: &'static str,
    value: f64,
    limit: f64,
    message: String,
}

#[derive(Serialize, schemars::JsonSchema)]
#[serde(tag = "kind", rename_all = "snake_case")]
enum FormationJson {
    Symmetric { forward_m: f64, lateral_m: f64, up_m: f64 },
    Fan { radius_m: f64, spread_deg: f64, up_m: f64 },
    Line { ahead_m: f64, spacing_m: f64, up_m: f64 },
}

impl FormationJson {
    fn of(kind: &planner::FormationKind, up_m: f64) -> Self {
        match *kind {
            planner::FormationKind::Symmetric { forward_m, lateral_m } => {
                Self::Symmetric { forward_m, lateral_m, up_m }
            }
            planner::FormationKind::Fan { radius_m, spread_deg } => Self::Fan { radius_m, spread_deg, up_m },
            planner::FormationKind::Line { ahead_m, spacing_m } => Self::Line { ahead_m, spacing_m, up_m },
        }
    }
}

#[derive(Serialize, schemars::JsonSchema)]
struct OptimizedJson {
    strategy: &'static str,
    hops: usize,
    stride_m: f64,
    formation: FormationJson,
    formation_m: Vec<[f64; 3]>,
    cycles: usize,
    sigma_xy2_m2: f64,
    sigma_xy_m: f64,
    improvement_factor: Option<f64>,
    candidates_predicted: usize,
    candidates_checked: usize,
    seconds: f64,
    control_at: Option<String>,
    worst_station_sigma_xy_m: Option<f64>,
}

#[derive(Serialize, schemars::JsonSchema)]
struct PredictedJson {
    sigma_xy2_m2: Option<f64>,
    sigma_xy_m: Option<f64>,
    sigma_heading_rad: Option<f64>,
}

#[derive(Serialize, schemars::JsonSchema)]
struct SensitivityJson {
    total_m2: f64,
    range_m2: f64,
    angle_m2: f64,
    centring_m2: f64,
    start_m2: f64,
    dominant: &'static str,
}

#[derive(Serialize, schemars::JsonSchema)]
struct LongerStrideJson {
    stride_m: f64,
    cycles: usize,
    sigma_xy2_m2: f64,
}

#[derive(Serialize, schemars::JsonSchema)]
struct WhatIfJson {
    one_more_child_sigma_xy2_m2: Option<f64>,
    longer_stride: Option<LongerStrideJson>,
}

#[derive(Serialize, schemars::JsonSchema)]
struct UncheckedJson {
    cycle: usize,
    child: String,
    observation: &'static str,
    redundancy_number: f64,
}

#[derive(Serialize, schemars::JsonSchema)]
struct ReliabilityJson {
    min_redundancy_number: Option<f64>,
    unchecked: Vec<UncheckedJson>,
}

/// `plan --json`: the plan as written (its violations, the analysis) and
/// the optimized plan.
#[derive(Serialize, schemars::JsonSchema)]
pub(crate) struct PlanJson {
    mission: String,
    strategy: &'static str,
    hops: usize,
    stride_m: f64,
    formation_m: Vec<[f64; 3]>,
    scene: Option<String>,
    /// Deprecated: the same as `station_count` (`stations` is a list in
    /// every other document).
    #[schemars(extend("deprecated" = true))]
    stations: usize,
    /// Deprecated: the same as `cycle_count`.
    #[schemars(extend("deprecated" = true))]
    cycles: usize,
    /// Deprecated: the same as `step_count`.
    #[schemars(extend("deprecated" = true))]
    steps: usize,
    /// Parent stations, the start included.
    station_count: usize,
    /// Dance cycles.
    cycle_count: usize,
    /// Steps of the plan.
    step_count: usize,
    violations: Vec<ViolationJson>,
    predicted: PredictedJson,
    sensitivity: Option<SensitivityJson>,
    what_if: WhatIfJson,
    reliability: ReliabilityJson,
    control_at: String,
    control: Vec<ControlSeenJson>,
    adjusted: Option<AdjustedJson>,
    optimized: Option<OptimizedJson>,
    accepted: bool,
}

#[derive(Serialize, schemars::JsonSchema)]
struct ControlSightingJson {
    station: usize,
    slope_distance_m: f64,
}

#[derive(Serialize, schemars::JsonSchema)]
struct ControlSeenJson {
    name: String,
    fixed: bool,
    seen_from: Vec<ControlSightingJson>,
}

/// `plan --json`: the plan as written (its violations, the analysis) and
/// the optimized plan.
pub fn plan(out: &mut dyn Write, mission: &Mission, report: &PlanReport) -> std::io::Result<()> {
    let plan = &mission.plan;
    let written = &report.written;
    let violations = report
        .violations
        .iter()
        .map(|v| ViolationJson {
            step: v.step,
            cycle: v.cycle,
            station: v.station,
            robot: mission.robot_label(v.robot),
            constraint: v.check.name(),
            value: v.value,
            limit: v.limit,
            message: v.describe(&|r| mission.robot_name(r)),
        })
        .collect();
    let optimized = report.optimized.as_ref().map(|o| {
        let c = &o.best.candidate;
        OptimizedJson {
            strategy: c.strategy.name(),
            hops: c.strategy.hops(),
            stride_m: c.stride_m,
            formation: FormationJson::of(&c.formation, c.up_m),
            formation_m: o.offsets(mission).iter().map(|o| [o.x, o.y, o.z]).collect(),
            cycles: o.best.cycles(),
            sigma_xy2_m2: o.best.sigma_xy2_m2,
            sigma_xy_m: o.best.sigma_xy2_m2.sqrt(),
            improvement_factor: report.sigma_xy2_m2.map(|s| s / o.best.sigma_xy2_m2),
            candidates_predicted: o.predicted,
            candidates_checked: o.checked,
            seconds: o.seconds,
            control_at: (!mission.control.is_empty()).then(|| o.control_at.to_string()),
            worst_station_sigma_xy_m: o.planned.worst_station().map(|w| w.1),
        }
    });
    let doc = PlanJson {
        mission: mission.name.clone(),
        strategy: plan.strategy.name(),
        hops: plan.strategy.hops(),
        stride_m: plan.stride_m,
        formation_m: plan.formation_m.iter().map(|o| [o.x, o.y, o.z]).collect(),
        scene: mission.backend.given.then(|| mission.backend.scene.clone()),
        stations: written.stations(),
        cycles: written.dance.cycles.len(),
        steps: written.steps.len(),
        station_count: written.stations(),
        cycle_count: written.dance.cycles.len(),
        step_count: written.steps.len(),
        violations,
        predicted: PredictedJson {
            sigma_xy2_m2: report.sigma_xy2_m2,
            sigma_xy_m: report.sigma_xy2_m2.map(f64::sqrt),
            sigma_heading_rad: report.sigma_heading_rad,
        },
        sensitivity: report.sensitivity.map(|s| SensitivityJson {
            total_m2: s.total_m2,
            range_m2: s.range_m2,
            angle_m2: s.angle_m2,
            centring_m2: s.centring_m2,
            start_m2: s.start_m2,
            dominant: s.dominant(),
        }),
        what_if: WhatIfJson {
            one_more_child_sigma_xy2_m2: report.one_more_child_m2,
            longer_stride: report.longer_stride.map(|(stride_m, cycles, sigma_xy2_m2)| LongerStrideJson {
                stride_m,
                cycles,
                sigma_xy2_m2,
            }),
        },
        reliability: ReliabilityJson {
            min_redundancy_number: analysis::min_redundancy(report),
            unchecked: analysis::unchecked(report)
                .into_iter()
                .map(|(cycle, j, observation, redundancy_number)| UncheckedJson {
                    cycle,
                    child: mission.robot_label(Robot::Child(j)),
                    observation,
                    redundancy_number,
                })
                .collect(),
        },
        control_at: plan.control_at.to_string(),
        control: report
            .control
            .iter()
            .map(|c| ControlSeenJson {
                name: c.name.clone(),
                fixed: c.fixed,
                seen_from: c
                    .from
                    .iter()
                    .map(|&(station, slope_distance_m)| ControlSightingJson { station, slope_distance_m })
                    .collect(),
            })
            .collect(),
        adjusted: adjusted_json(mission, written),
        optimized,
        accepted: analysis::accepted(mission, report),
    };
    write_line(out, &doc)
}

#[derive(Serialize, schemars::JsonSchema)]
struct McStationJson {
    index: usize,
    predicted_sigma_xy2_m2: f64,
    empirical_sigma_xy2_m2: f64,
    ratio: f64,
    nees_mean: f64,
}

impl McStationJson {
    fn of(s: &planner::montecarlo::CycleStatistics) -> Self {
        Self {
            index: s.cycle,
            predicted_sigma_xy2_m2: cps::sigma_xy2(&s.predicted),
            empirical_sigma_xy2_m2: cps::sigma_xy2(&s.empirical),
            ratio: s.ratio_xy(),
            nees_mean: s.nees_mean,
        }
    }
}

/// `montecarlo --json`: the final station's figures and every station's.
#[derive(Serialize, schemars::JsonSchema)]
pub(crate) struct MonteCarloJson {
    mission: String,
    seed: u64,
    trials: usize,
    predicted_sigma_xy2_m2: f64,
    empirical_sigma_xy2_m2: f64,
    ratio: f64,
    nees_mean: f64,
    nees_interval: [f64; 2],
    consistent: bool,
    stations: Vec<McStationJson>,
    adjusted: Vec<McStationJson>,
    adjusted_interval: Option<[f64; 2]>,
}

/// `montecarlo --json`: the final station's figures and every station's.
pub fn montecarlo(out: &mut dyn Write, mission: &Mission, mc: &MonteCarlo) -> anyhow::Result<()> {
    let last = mc.last().ok_or_else(|| anyhow::anyhow!("the mission has no dance cycle"))?;
    let doc = MonteCarloJson {
        mission: mission.name.clone(),
        seed: mc.seed,
        trials: mc.trials,
        predicted_sigma_xy2_m2: cps::sigma_xy2(&last.predicted),
        empirical_sigma_xy2_m2: cps::sigma_xy2(&last.empirical),
        ratio: last.ratio_xy(),
        nees_mean: last.nees_mean,
        nees_interval: [mc.nees_interval.0, mc.nees_interval.1],
        consistent: mc.consistent(),
        stations: mc.stations.iter().map(McStationJson::of).collect(),
        adjusted: mc.adjusted.iter().map(McStationJson::of).collect(),
        adjusted_interval: (!mc.adjusted.is_empty()).then_some([mc.adjusted_interval.0, mc.adjusted_interval.1]),
    };
    Ok(write_line(out, &doc)?)
}

impl Document for PredictionJson {
    const NAME: &'static str = "predict";
    const VERSION: u32 = 1;
}

impl Document for PlanJson {
    const NAME: &'static str = "plan";
    const VERSION: u32 = 1;
}

impl Document for MonteCarloJson {
    const NAME: &'static str = "montecarlo";
    const VERSION: u32 = 1;
}
