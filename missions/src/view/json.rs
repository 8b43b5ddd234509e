//! The `--json` documents of `predict`, `plan` and `montecarlo`, typed
//! and versioned (docs/json.md and docs/commands.md document each key, and
//! `docs/schemas/` their schemas).

use std::io::Write;

use cps::{CHI2_2D_95_SQRT, ErrorEllipse};
use planner::{Action, Robot, StepEstimate};

use crate::documents::montecarlo::*;
use crate::documents::plan::*;
use crate::documents::prediction::*;
use crate::documents::records::{Ellipse, Pose, Position, nested, rows};
use crate::documents::write_line;
use crate::mission::Mission;
use crate::planning::Planned;
use crate::planning::analysis::{self, PlanReport};
use crate::planning::montecarlo::MonteCarlo;

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
                covariance: rows(&s.covariance),
                sigma_xy_m: s.sigma_xy_m(),
                filter_sigma_xy_m: planned.filter_covariance(s.index).map(|c| cps::sigma_xy2(&c).sqrt()),
                ellipse_95_m: Ellipse::of_95(&s.covariance.fixed_view::<2, 2>(0, 0).into_owned()),
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

fn ellipse_95(e: &StepEstimate) -> Ellipse {
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
            parent: Pose::from(&c.parent),
            covariance: rows(&c.covariance),
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
                        position: Pose { x_m: p.x, y_m: p.y, z_m: p.z, heading_rad: 0.0 },
                        covariance: rows(cov),
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
                pose: Pose::from(&dance.station_pose(station)),
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
            position: Position { x_m: e.position.x, y_m: e.position.y, z_m: e.position.z },
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
