//! `cps-survey predict`: the covariance after every dance cycle of a mission.

use std::io::Write;

use cps::{CHI2_2D_95_SQRT, ErrorEllipse, RAD_PER_ARCSEC};
use planner::{Action, Dance, PlanError, Prediction, Robot, StepEstimate};
use serde::Serialize;

use crate::diagnostics::{Diagnostic, Diagnostics};
use crate::mission::{Mission, MissionError};

/// Builds the mission's dance; plan errors point at the mission file.
pub fn dance(mission: &Mission) -> Result<Dance, MissionError> {
    dance_or_diagnostics(mission).map_err(|d| MissionError::invalid(mission, d))
}

fn dance_or_diagnostics(mission: &Mission) -> Result<Dance, Diagnostics> {
    let dance = schedule(mission)?;
    if let Some(instrument) = &mission.total_station {
        let violations = dance.range_violations(instrument);
        if !violations.is_empty() {
            return Err(plan_diagnostics(mission, violations));
        }
    }
    Ok(dance)
}

/// Builds the mission's schedule without checking ranges (`plan` reports
/// them as violations); route, stride, formation and scan-list errors
/// point at the mission file.
pub fn schedule(mission: &Mission) -> Result<Dance, Diagnostics> {
    let plan = &mission.plan;
    let stations = planner::stations(&plan.route_m, plan.stride_m).map_err(|e| plan_diagnostics(mission, vec![e]))?;
    let dance = match &mission.total_station {
        None => planner::solo(stations),
        Some(_) => planner::schedule(stations, &plan.formation_m, plan.strategy)
            .map_err(|e| plan_diagnostics(mission, vec![e]))?,
    };
    if let (Some(list), Some(span)) = (&mission.scan.stations, &mission.spans.scan_stations)
        && let Some(k) = list.iter().find(|k| **k >= dance.stations.len())
    {
        let message = format!(
            "station {k} does not exist; expected indices 0 to {} (the plan has {} stations)",
            dance.stations.len() - 1,
            dance.stations.len()
        );
        return Err(Diagnostics(vec![mission.diagnostic(span, "scan.stations", message)]));
    }
    Ok(dance)
}

/// Predicts the mission's accuracy: the CPS dance, or for a robot alone
/// its dead reckoning (the random part of the `[backend]` odometry error).
pub fn prediction(mission: &Mission) -> Result<Prediction, MissionError> {
    let dance = dance(mission)?;
    match &mission.total_station {
        Some(instrument) => planner::predict(&dance, instrument, &mission.plan.start_covariance)
            .map_err(|e| MissionError::invalid(mission, plan_diagnostics(mission, vec![e]))),
        None => {
            let o = &mission.backend.odometry;
            let noise = planner::OdometryNoise {
                sigma_distance_m_per_sqrt_m: o.sigma_distance_m_per_sqrt_m,
                sigma_heading_rad_per_sqrt_m: o.sigma_heading_rad_per_sqrt_m,
            };
            Ok(planner::predict_odometry(&dance, &noise, &mission.plan.start_covariance))
        }
    }
}

/// Writes `--plot` for the mission as written.
pub fn plot(
    mission: &Mission,
    prediction: &Prediction,
    path: &std::path::Path,
) -> anyhow::Result<crate::plot::PlotSummary> {
    let dance = dance(mission)?;
    let steps = dance.steps(|k| mission.scan.scans_at(k));
    let plan = crate::plot::PlotPlan { label: "as written", dance: &dance, prediction, steps: &steps, violations: &[] };
    let scene = crate::plan::scene(mission)?;
    crate::plot::write_svg(path, &format!("cps-survey predict — mission {}", mission.name), &[plan], scene.as_ref())
}

/// The steps of `dance` with the mission's scan stations, and every
/// robot's predicted estimate along them: each child after its placement,
/// the parent after each fix, and the parent at each scan station (see
/// [`planner::step_estimates`]).
pub fn steps_and_estimates(
    mission: &Mission,
    dance: &Dance,
    prediction: &Prediction,
) -> (Vec<planner::Step>, Vec<StepEstimate>) {
    let steps = dance.steps(|k| mission.scan.scans_at(k));
    let estimates = planner::step_estimates(dance, prediction, &steps, &mission.plan.start_covariance);
    (steps, estimates)
}

/// [`steps_and_estimates`] of the mission's own schedule: its estimates.
pub fn step_estimates(mission: &Mission, prediction: &Prediction) -> Result<Vec<StepEstimate>, MissionError> {
    Ok(steps_and_estimates(mission, &dance(mission)?, prediction).1)
}

/// What a step that sets an estimate does, in words.
fn step_kind(steps: &[planner::Step], e: &StepEstimate) -> &'static str {
    match steps.get(e.step).map(|s| &s.action) {
        Some(Action::Measure { .. }) => "placement",
        Some(Action::Fix { .. }) => "fix",
        Some(Action::Scan { .. }) => "scan",
        Some(Action::MoveParent { .. }) => "odometry",
        _ => "estimate",
    }
}

/// Turns planner errors into diagnostics at the responsible field. Range
/// violations are grouped per child and phase (first cycle and count).
fn plan_diagnostics(mission: &Mission, errors: Vec<PlanError>) -> Diagnostics {
    let spans = &mission.spans;
    let mut out: Vec<Diagnostic> = Vec::new();
    let mut seen: Vec<(usize, planner::Phase, usize)> = Vec::new();
    for e in &errors {
        if let PlanError::ChildOutOfRange { child, phase, .. } = e {
            match seen.iter_mut().find(|(c, p, _)| c == child && p == phase) {
                Some(entry) => entry.2 += 1,
                None => seen.push((*child, *phase, 1)),
            }
        }
    }
    for e in errors {
        let (span, field) = match &e {
            PlanError::ChildOutOfRange { child, phase, .. } => {
                let Some(entry) = seen.iter().position(|(c, p, _)| c == child && p == phase) else { continue };
                let count = seen.remove(entry).2;
                let span = spans.formation_m.get(*child).cloned().unwrap_or(spans.plan.clone());
                let name = mission.children.get(*child).map_or(String::new(), |n| format!("child \"{n}\": "));
                let more = if count > 1 { format!(" — and in {} more cycle(s)", count - 1) } else { String::new() };
                out.push(mission.diagnostic(&span, &format!("plan.formation_m[{child}]"), format!("{name}{e}{more}")));
                continue;
            }
            PlanError::ZeroLengthSegment { waypoint } => (
                spans.route_m.get(*waypoint).cloned().unwrap_or(spans.plan.clone()),
                format!("plan.route_m[{waypoint}]"),
            ),
            PlanError::BadStride { .. } => (spans.stride_m.clone(), "plan.stride_m".to_string()),
            PlanError::BadHops { .. } => (spans.hops.clone().unwrap_or(spans.plan.clone()), "plan.hops".to_string()),
            PlanError::FormationSize { .. } | PlanError::TooFewChildren { .. } => {
                (spans.formation_m.first().cloned().unwrap_or(spans.plan.clone()), "plan.formation_m".to_string())
            }
            _ => (spans.plan.clone(), "plan".to_string()),
        };
        out.push(mission.diagnostic(&span, &field, e.to_string()));
    }
    Diagnostics(out)
}

#[derive(Serialize)]
struct PoseJson {
    x_m: f64,
    y_m: f64,
    z_m: f64,
    heading_rad: f64,
}

#[derive(Serialize)]
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

#[derive(Serialize)]
struct ChildJson {
    name: String,
    position: PoseJson,
    covariance: [[f64; 3]; 3],
    sigma_xy_m: f64,
    ellipse_95_m: EllipseJson,
}

#[derive(Serialize)]
struct StepJson {
    step: usize,
    cycle: usize,
    action: &'static str,
    robot: String,
    position_m: [f64; 3],
    /// 4×4 (x, y, z, θ) for the parent, 3×3 (x, y, z) for a child.
    covariance: Vec<Vec<f64>>,
    sigma_xy_m: f64,
    ellipse_95_m: EllipseJson,
}

#[derive(Serialize)]
struct ScanJson {
    step: usize,
    station: usize,
    pose: PoseJson,
    covariance: Vec<Vec<f64>>,
    sigma_xy_m: f64,
    sigma_heading_rad: f64,
    ellipse_95_m: EllipseJson,
}

#[derive(Serialize)]
struct CycleJson {
    cycle: usize,
    distance_m: f64,
    parent: PoseJson,
    covariance: [[f64; 4]; 4],
    ellipse_1sigma_m: EllipseJson,
    ellipse_95_m: EllipseJson,
    sigma_xy2_m2: f64,
    sigma_heading_rad: f64,
    drift_percent: f64,
    children: Vec<ChildJson>,
}

#[derive(Serialize)]
struct FinalJson {
    distance_m: f64,
    sigma_xy2_m2: f64,
    sigma_xy_m: f64,
    sigma_heading_rad: f64,
    drift_percent: f64,
    ellipse_95_m: EllipseJson,
    max_final_sigma_xy_m: Option<f64>,
    accepted: bool,
}

#[derive(Serialize)]
struct PredictionJson {
    mission: String,
    children: Vec<String>,
    cycles: Vec<CycleJson>,
    steps: Vec<StepJson>,
    scans: Vec<ScanJson>,
    #[serde(rename = "final")]
    final_: Option<FinalJson>,
}

/// Whether the prediction meets `[acceptance]`.
pub fn accepted(mission: &Mission, prediction: &Prediction) -> bool {
    match (mission.acceptance.max_final_sigma_xy_m, prediction.last()) {
        (Some(max), Some(last)) => last.sigma_xy2_m2().sqrt() <= max,
        _ => true,
    }
}

fn nested(m: &nalgebra::DMatrix<f64>) -> Vec<Vec<f64>> {
    m.row_iter().map(|r| r.iter().copied().collect()).collect()
}

fn ellipse_95(e: &StepEstimate) -> EllipseJson {
    e.ellipse_1sigma().scaled(CHI2_2D_95_SQRT).into()
}

/// Writes the prediction as one JSON object: per cycle the parent and every
/// child, per step every estimate a step sets, and every scan station.
pub fn write_json(out: &mut dyn Write, mission: &Mission, prediction: &Prediction) -> anyhow::Result<()> {
    let name = crate::plan::robot_label(mission);
    let dance = dance(mission)?;
    let (steps, estimates) = steps_and_estimates(mission, &dance, prediction);
    let cycles = prediction
        .cycles
        .iter()
        .map(|c| CycleJson {
            cycle: c.cycle,
            distance_m: c.distance_m,
            parent: PoseJson {
                x_m: c.parent.position.x,
                y_m: c.parent.position.y,
                z_m: c.parent.position.z,
                heading_rad: c.parent.heading_rad,
            },
            covariance: std::array::from_fn(|i| std::array::from_fn(|j| c.covariance[(i, j)])),
            ellipse_1sigma_m: c.ellipse_1sigma().into(),
            ellipse_95_m: c.ellipse_1sigma().scaled(CHI2_2D_95_SQRT).into(),
            sigma_xy2_m2: c.sigma_xy2_m2(),
            sigma_heading_rad: c.sigma_heading_rad(),
            drift_percent: c.drift_percent(),
            children: c
                .children_covariance
                .iter()
                .enumerate()
                .map(|(j, cov)| {
                    let p = dance.cycles[c.cycle - 1].children[j];
                    let e = cps::ErrorEllipse::from_covariance(&cov.fixed_view::<2, 2>(0, 0).into_owned());
                    ChildJson {
                        name: name(Robot::Child(j)),
                        position: PoseJson { x_m: p.x, y_m: p.y, z_m: p.z, heading_rad: 0.0 },
                        covariance: std::array::from_fn(|r| std::array::from_fn(|s| cov[(r, s)])),
                        sigma_xy_m: (cov[(0, 0)] + cov[(1, 1)]).sqrt(),
                        ellipse_95_m: e.scaled(CHI2_2D_95_SQRT).into(),
                    }
                })
                .collect(),
        })
        .collect();
    let scans = estimates
        .iter()
        .filter_map(|e| {
            let Action::Scan { station } = steps.get(e.step)?.action else { return None };
            let pose = dance.station_pose(station);
            Some(ScanJson {
                step: e.step,
                station,
                pose: PoseJson {
                    x_m: pose.position.x,
                    y_m: pose.position.y,
                    z_m: pose.position.z,
                    heading_rad: pose.heading_rad,
                },
                covariance: nested(&e.covariance),
                sigma_xy_m: e.sigma_xy2_m2().sqrt(),
                sigma_heading_rad: e.covariance[(3, 3)].sqrt(),
                ellipse_95_m: ellipse_95(e),
            })
        })
        .collect();
    let step_rows = estimates
        .iter()
        .filter(|e| !e.scan)
        .map(|e| StepJson {
            step: e.step,
            cycle: e.cycle,
            action: step_kind(&steps, e),
            robot: name(e.robot),
            position_m: [e.position.x, e.position.y, e.position.z],
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
        ellipse_95_m: l.ellipse_1sigma().scaled(CHI2_2D_95_SQRT).into(),
        max_final_sigma_xy_m: mission.acceptance.max_final_sigma_xy_m,
        accepted: accepted(mission, prediction),
    });
    let doc = PredictionJson {
        mission: mission.name.clone(),
        children: mission.children.clone(),
        cycles,
        steps: step_rows,
        scans,
        final_,
    };
    serde_json::to_writer(&mut *out, &doc)?;
    writeln!(out)?;
    Ok(())
}

/// The children right after each placement: √(σx² + σy²) per child, one
/// row per cycle that placed any.
fn write_children(
    out: &mut dyn Write,
    mission: &Mission,
    prediction: &Prediction,
    estimates: &[StepEstimate],
) -> std::io::Result<()> {
    if mission.children.is_empty() || prediction.cycles.is_empty() {
        return Ok(());
    }
    writeln!(out)?;
    writeln!(out, "children after placement, √(σx² + σy²) in mm:")?;
    write!(out, "{:>6}", "cycle")?;
    for name in &mission.children {
        write!(out, " {name:>12}")?;
    }
    writeln!(out)?;
    for c in &prediction.cycles {
        let placed: Vec<&StepEstimate> =
            estimates.iter().filter(|e| e.cycle == c.cycle && matches!(e.robot, Robot::Child(_))).collect();
        if placed.is_empty() {
            continue;
        }
        write!(out, "{:>6}", c.cycle)?;
        for j in 0..mission.children.len() {
            match placed.iter().find(|e| e.robot == Robot::Child(j)) {
                Some(e) => write!(out, " {:>12.3}", 1e3 * e.sigma_xy2_m2().sqrt())?,
                None => write!(out, " {:>12}", "stays")?,
            }
        }
        writeln!(out)?;
    }
    Ok(())
}

/// The scan stations' covariance: what a direct transformation inherits.
fn write_scans(out: &mut dyn Write, estimates: &[StepEstimate]) -> std::io::Result<()> {
    let scans: Vec<&StepEstimate> = estimates.iter().filter(|e| e.scan).collect();
    if scans.is_empty() {
        return Ok(());
    }
    writeln!(out)?;
    writeln!(out, "scan stations:")?;
    writeln!(out, "{:>6} {:>9} {:>9} {:>9} {:>10}", "step", "x_m", "y_m", "σxy_mm", "σθ_arcsec")?;
    for e in scans {
        writeln!(
            out,
            "{:>6} {:>9.2} {:>9.2} {:>9.3} {:>10.2}",
            e.step,
            e.position.x,
            e.position.y,
            1e3 * e.sigma_xy2_m2().sqrt(),
            e.covariance[(3, 3)].sqrt() / RAD_PER_ARCSEC
        )?;
    }
    Ok(())
}

/// Writes the per-cycle table, the children after each placement, the scan
/// stations and the final summary.
pub fn write_table(out: &mut dyn Write, mission: &Mission, prediction: &Prediction) -> anyhow::Result<()> {
    let n = prediction.cycles.len();
    let dist = prediction.last().map_or(0.0, |l| l.distance_m);
    writeln!(out, "mission {}: {n} cycles, {} children, {dist:.1} m of route", mission.name, mission.children.len())?;
    writeln!(
        out,
        "{:>6} {:>9} {:>9} {:>9} {:>9} {:>10} {:>9} {:>9} {:>7} {:>8}",
        "cycle", "dist_m", "σx_mm", "σy_mm", "σz_mm", "σθ_arcsec", "a95_mm", "b95_mm", "az95_°", "drift_%"
    )?;
    for c in &prediction.cycles {
        let e = c.ellipse_1sigma().scaled(CHI2_2D_95_SQRT);
        writeln!(
            out,
            "{:>6} {:>9.2} {:>9.3} {:>9.3} {:>9.3} {:>10.2} {:>9.3} {:>9.3} {:>7.1} {:>8.4}",
            c.cycle,
            c.distance_m,
            1e3 * c.covariance[(0, 0)].sqrt(),
            1e3 * c.covariance[(1, 1)].sqrt(),
            1e3 * c.covariance[(2, 2)].sqrt(),
            c.sigma_heading_rad() / RAD_PER_ARCSEC,
            1e3 * e.semi_major_m,
            1e3 * e.semi_minor_m,
            e.orientation_rad.to_degrees(),
            c.drift_percent(),
        )?;
    }
    let estimates = step_estimates(mission, prediction)?;
    write_children(out, mission, prediction, &estimates)?;
    write_scans(out, &estimates)?;
    if let Some(l) = prediction.last() {
        let e = l.ellipse_1sigma().scaled(CHI2_2D_95_SQRT);
        writeln!(out)?;
        writeln!(out, "final after {:.1} m:", l.distance_m)?;
        writeln!(out, "  σx² + σy²      {:.6} m²  (√ = {:.4} m)", l.sigma_xy2_m2(), l.sigma_xy2_m2().sqrt())?;
        writeln!(out, "  σz             {:.4} m", l.covariance[(2, 2)].sqrt())?;
        writeln!(out, "  σθ             {:.2}″", l.sigma_heading_rad() / RAD_PER_ARCSEC)?;
        writeln!(
            out,
            "  95 % ellipse   {:.4} m × {:.4} m, major axis at {:.1}°",
            e.semi_major_m,
            e.semi_minor_m,
            e.orientation_rad.to_degrees()
        )?;
        writeln!(out, "  drift          {:.4} % of distance", l.drift_percent())?;
        if let Some(max) = mission.acceptance.max_final_sigma_xy_m {
            let verdict = if accepted(mission, prediction) { "PASS" } else { "FAIL" };
            writeln!(
                out,
                "  acceptance     {verdict}: √(σx² + σy²) = {:.4} m, limit {max} m",
                l.sigma_xy2_m2().sqrt()
            )?;
        }
    }
    Ok(())
}
