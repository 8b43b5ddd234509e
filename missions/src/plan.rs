//! `cps-survey plan`: the mission's schedule checked step by step against
//! the scene and the instruments, what its final error is made of, and
//! with `--optimize` the best formation, stride and strategy.

use std::io::Write;
use std::path::Path;
use std::time::Instant;

use anyhow::{Context, Result};
use cps::geom::Scene;
use cps::{Instrument, RAD_PER_ARCSEC};
use nalgebra::Vector3;
use planner::analysis::{FixReliability, Sensitivity, UNCHECKED_REDUNDANCY};
use planner::search::Evaluated;
use planner::{Dance, FormationKind, Limits, Objective, Prediction, Robot, SearchSpace, Strategy, Violation};
use serde_json::{Value, json};

use crate::diagnostics::Diagnostics;
use crate::mission::{Mission, MissionError};
use crate::recording::{PlanLog, Recorder, Viewer};

/// Longest sight line `--optimize` considers when neither the mission nor
/// the instrument sets a shorter one, metres.
pub const DEFAULT_MAX_SIGHT_LINE_M: f64 = 200.0;

/// The scene the plan is checked against: the backend's, when the file
/// has a `[backend]` table; open space otherwise.
pub fn scene(mission: &Mission) -> Result<Option<Scene>> {
    if !mission.backend.given {
        return Ok(None);
    }
    Ok(Some(mission.scene().with_context(|| format!("scene of mission {}", mission.source.file.display()))?))
}

/// The limits of the mission's plan (the total station's range, the
/// scanner's range when the mission scans, slope, footprint, tracking).
pub fn limits(mission: &Mission) -> Limits {
    let (min, max) = mission.total_station.as_ref().map_or((0.0, f64::INFINITY), |i| (i.min_range_m, i.max_range_m));
    let scans = mission.scan.stations.as_ref().is_some_and(|l| !l.is_empty()) || mission.scan.every_n_stations > 0;
    Limits {
        min_range_m: min,
        max_range_m: max,
        max_slope_rad: mission.plan.max_slope_rad,
        footprint_radius_m: Some(mission.plan.footprint_radius_m),
        track: mission.plan.track,
        scanner_max_range_m: scans.then(|| scanner::sim::LmsRangeMode::Mm32.max_range_m()),
    }
}

/// "the parent" or `child "name"`.
pub fn robot_name(mission: &Mission) -> impl Fn(Robot) -> String + '_ {
    |r| match r {
        Robot::Parent => "the parent".to_string(),
        Robot::Child(j) => mission.children.get(j).map_or(format!("child {j}"), |n| format!("child \"{n}\"")),
    }
}

/// "parent" or the child's name, as in the recording's entity paths.
pub fn robot_label(mission: &Mission) -> impl Fn(Robot) -> String + '_ {
    |r| match r {
        Robot::Parent => "parent".to_string(),
        Robot::Child(j) => mission.children.get(j).cloned().unwrap_or_else(|| format!("child{j}")),
    }
}

/// Every constraint the schedule breaks.
pub fn violations(mission: &Mission, dance: &Dance, scene: Option<&Scene>) -> Vec<Violation> {
    planner::check(dance, scene, &limits(mission), |k| mission.scan.scans_at(k))
}

/// Refuses a plan that breaks a constraint against the scene: `run` and
/// `validate` call this, pointing at `[plan]` with each violation's step.
pub fn refuse_violations(mission: &Mission, dance: &Dance) -> Result<()> {
    let scene = scene(mission)?;
    let v = violations(mission, dance, scene.as_ref());
    if v.is_empty() {
        return Ok(());
    }
    let name = robot_name(mission);
    let shown = 10;
    let mut problems: Vec<_> =
        v.iter().take(shown).map(|v| mission.diagnostic(&mission.spans.plan, "plan", v.describe(&name))).collect();
    if v.len() > shown {
        let message = format!("… and {} more violation(s); `cps-survey plan` lists them all", v.len() - shown);
        problems.push(mission.diagnostic(&mission.spans.plan, "plan", message));
    }
    Err(MissionError::invalid(mission, Diagnostics(problems)).into())
}

/// What `plan` found.
#[derive(Debug)]
pub struct PlanReport {
    /// The schedule as written.
    pub dance: Dance,
    /// Its steps.
    pub steps: usize,
    /// Its violations.
    pub violations: Vec<Violation>,
    /// The prediction as written (range limits lifted).
    pub prediction: Option<Prediction>,
    /// Predicted final σx² + σy² as written (range limits lifted), m².
    pub sigma_xy2_m2: Option<f64>,
    /// Predicted final σθ as written, rad.
    pub sigma_heading_rad: Option<f64>,
    /// What the final error is made of.
    pub sensitivity: Option<Sensitivity>,
    /// Final σx² + σy² with one more child straight ahead.
    pub one_more_child_m2: Option<f64>,
    /// Cycles and final σx² + σy² with a 25 % longer stride.
    pub longer_stride: Option<(f64, usize, f64)>,
    /// Redundancy numbers of every fix.
    pub reliability: Vec<FixReliability>,
    /// With `--optimize`: the chosen plan.
    pub optimized: Option<Optimized>,
}

/// The plan `--optimize` chose.
#[derive(Debug)]
pub struct Optimized {
    /// The plan, its schedule and prediction.
    pub best: Evaluated,
    /// Candidates predicted.
    pub predicted: usize,
    /// Candidates checked against the constraints.
    pub checked: usize,
    /// Wall time of the search, seconds.
    pub seconds: f64,
}

/// The instrument with its range limits lifted (to predict a plan that
/// breaks them, for comparison).
fn unlimited(instrument: &Instrument) -> Instrument {
    Instrument { min_range_m: 0.0, max_range_m: f64::INFINITY, ..instrument.clone() }
}

/// Schedules, checks and analyses the mission's plan; with `optimize`
/// searches `[plan.search]` for a better one.
pub fn plan(mission: &Mission, optimize: bool) -> Result<PlanReport> {
    let dance = crate::predict::schedule(mission).map_err(|d| MissionError::invalid(mission, d))?;
    let scene = scene(mission)?;
    let violations = violations(mission, &dance, scene.as_ref());
    let steps = dance.steps(|k| mission.scan.scans_at(k)).len();
    let plan = &mission.plan;
    let mut report = PlanReport {
        steps,
        violations,
        prediction: None,
        sigma_xy2_m2: None,
        sigma_heading_rad: None,
        sensitivity: None,
        one_more_child_m2: None,
        longer_stride: None,
        reliability: Vec::new(),
        optimized: None,
        dance,
    };
    let Some(instrument) = &mission.total_station else {
        if optimize {
            anyhow::bail!(
                "mission {} has no children: a robot alone has no formation to optimise",
                mission.source.file.display()
            );
        }
        let p = crate::predict::prediction(mission)?;
        report.sigma_xy2_m2 = p.last().map(|l| l.sigma_xy2_m2());
        report.sigma_heading_rad = p.last().map(|l| l.sigma_heading_rad());
        report.prediction = Some(p);
        return Ok(report);
    };
    let free = unlimited(instrument);
    let start = plan.start_covariance;
    let last = planner::predict(&report.dance, &free, &start)
        .map_err(|e| anyhow::anyhow!("mission {}: {e}", mission.source.file.display()))?;
    report.sigma_xy2_m2 = last.last().map(|l| l.sigma_xy2_m2());
    report.sigma_heading_rad = last.last().map(|l| l.sigma_heading_rad());
    report.prediction = Some(last);
    report.sensitivity = planner::analysis::sensitivity(&report.dance, &free, &start).ok();
    report.one_more_child_m2 =
        planner::analysis::with_one_more_child(&report.dance, &plan.formation_m, plan.strategy, &free, &start);
    report.longer_stride = planner::stations(&plan.route_m, plan.stride_m * 1.25)
        .ok()
        .and_then(|st| planner::schedule(st, &plan.formation_m, plan.strategy).ok())
        .and_then(|d| Some((d.cycles.len(), planner::predict(&d, &free, &start).ok()?.last()?.sigma_xy2_m2())))
        .map(|(n, s)| (plan.stride_m * 1.25, n, s));
    report.reliability = planner::analysis::reliability(&report.dance, &free, &start).unwrap_or_default();
    if optimize {
        report.optimized = Some(search(mission, instrument, scene.as_ref())?);
    }
    Ok(report)
}

/// The optimized plan's prediction (it keeps every range limit).
pub fn optimized_prediction(mission: &Mission, o: &Optimized) -> Result<Prediction> {
    let instrument = mission.total_station.as_ref().context("an optimized plan has children")?;
    planner::predict(&o.best.dance, instrument, &mission.plan.start_covariance)
        .map_err(|e| anyhow::anyhow!("mission {}: optimized plan: {e}", mission.source.file.display()))
}

/// Logs a plan under `world/<root>/` (see [`Recorder::plan`]): its steps,
/// every robot's predicted estimate and `violations` described.
pub fn log_plan(
    rec: &mut Recorder,
    mission: &Mission,
    root: &str,
    dance: &Dance,
    prediction: &Prediction,
    violations: &[Violation],
) -> Result<()> {
    let (steps, estimates) = crate::predict::steps_and_estimates(mission, dance, prediction);
    let name = robot_name(mission);
    let described: Vec<(Violation, String)> = violations.iter().map(|v| (v.clone(), v.describe(&name))).collect();
    let names = robot_names(mission);
    rec.plan(&PlanLog { root, dance, steps: &steps, estimates: &estimates, violations: &described, names: &names })
}

/// "parent" and the children's names, in team order.
pub fn robot_names(mission: &Mission) -> Vec<String> {
    std::iter::once("parent".to_string()).chain(mission.children.iter().cloned()).collect()
}

/// Writes `--rrd`: the scene and each plan (root, schedule, prediction,
/// violations) on the `plan_step` timeline.
pub fn write_rrd(mission: &Mission, path: &Path, plans: &[(&str, &Dance, &Prediction, &[Violation])]) -> Result<()> {
    let mut rec = Recorder::new(&mission.name, Some(path), &Viewer::None, robot_names(mission))?;
    rec.layout(crate::recording::Layout::Plan)?;
    rec.world(scene(mission)?.as_ref())?;
    for (root, dance, prediction, violations) in plans {
        log_plan(&mut rec, mission, root, dance, prediction, violations)?;
    }
    rec.finish()
}

/// `plan --rrd`: the plan as written with its violations, and the
/// optimized plan under `world/plan_optimized/` if any.
pub fn record(mission: &Mission, report: &PlanReport, path: &Path) -> Result<()> {
    let Some(written) = &report.prediction else { anyhow::bail!("the plan has no prediction to record") };
    let optimized = report.optimized.as_ref().map(|o| optimized_prediction(mission, o)).transpose()?;
    let mut plans: Vec<(&str, &Dance, &Prediction, &[Violation])> =
        vec![("plan", &report.dance, written, &report.violations)];
    if let (Some(o), Some(p)) = (&report.optimized, &optimized) {
        plans.push(("plan_optimized", &o.best.dance, p, &[]));
    }
    write_rrd(mission, path, &plans)
}

/// Writes `--plot`: the plan as written, and the optimized one if any.
pub fn plot(mission: &Mission, report: &PlanReport, path: &Path) -> Result<crate::plot::PlotSummary> {
    let Some(written) = &report.prediction else { anyhow::bail!("the plan has no prediction to plot") };
    let scan_at = |k: usize| mission.scan.scans_at(k);
    let steps = report.dance.steps(scan_at);
    let mut plans = vec![crate::plot::PlotPlan {
        label: "as written",
        dance: &report.dance,
        prediction: written,
        steps: &steps,
        violations: &report.violations,
    }];
    let optimized = report.optimized.as_ref().map(|o| optimized_prediction(mission, o)).transpose()?;
    let optimized_steps = report.optimized.as_ref().map(|o| o.best.dance.steps(scan_at));
    if let (Some(o), Some(p), Some(steps)) = (&report.optimized, &optimized, &optimized_steps) {
        plans.push(crate::plot::PlotPlan {
            label: "optimized",
            dance: &o.best.dance,
            prediction: p,
            steps,
            violations: &[],
        });
    }
    let scene = scene(mission)?;
    crate::plot::write_svg(path, &format!("cps-survey plan — mission {}", mission.name), &plans, scene.as_ref())
}

/// Runs the search of `[plan.search]`.
fn search(mission: &Mission, instrument: &Instrument, scene: Option<&Scene>) -> Result<Optimized> {
    let plan = &mission.plan;
    let s = &plan.search;
    let mut strategies = Vec::new();
    for name in &s.strategies {
        match name.as_str() {
            "parent-hops" => strategies.extend((2..=s.max_hops).map(|hops| Strategy::ParentHops { hops })),
            _ => strategies.push(Strategy::Leapfrog),
        }
    }
    let up_m = plan.formation_m.iter().map(|o| o.z).sum::<f64>() / plan.formation_m.len().max(1) as f64;
    let max_sight_line_m = if s.max_sight_line_m.is_finite() { s.max_sight_line_m } else { DEFAULT_MAX_SIGHT_LINE_M }
        .min(instrument.max_range_m);
    let space = SearchSpace { strategies, strides_m: s.strides_m.clone(), max_sight_line_m, up_m };
    let objective = match mission.acceptance.max_final_sigma_xy_m {
        Some(max_sigma_xy_m) => Objective::FewestCycles { max_sigma_xy_m },
        None => Objective::MinVariance,
    };
    let scan_at = |k: usize| mission.scan.scans_at(k);
    let problem = planner::Problem {
        route_m: &plan.route_m,
        instrument,
        start_covariance: plan.start_covariance,
        n_children: mission.children.len(),
        scene,
        limits: limits(mission),
        scan_at: &scan_at,
    };
    let started = Instant::now();
    let result = planner::search(&problem, &space, objective)
        .map_err(|e| anyhow::anyhow!("mission {}: {e}", mission.source.file.display()))?;
    let Some(mut best) = result.best else {
        anyhow::bail!(
            "mission {}: no plan in [plan.search] keeps every constraint ({} candidates predicted, {} checked); \
             allow longer sight lines (max_sight_line_m), other strides or strategies",
            mission.source.file.display(),
            result.predicted,
            result.checked
        );
    };
    // Round the formation to millimetres for the mission file, if the
    // rounded plan still keeps every constraint.
    if let FormationKind::Symmetric { forward_m, lateral_m } = best.candidate.formation {
        let round = |x: f64| (x * 1e3).round() / 1e3;
        let c = planner::Candidate {
            formation: FormationKind::Symmetric { forward_m: round(forward_m), lateral_m: round(lateral_m) },
            up_m: round(best.candidate.up_m),
            ..best.candidate
        };
        let within = Instrument { max_range_m: instrument.max_range_m.min(max_sight_line_m), ..instrument.clone() };
        if let Some(e) = problem.evaluate(&c, &within)
            && problem.violations(&e.dance, max_sight_line_m).is_empty()
        {
            best = e;
        }
    }
    Ok(Optimized {
        best,
        predicted: result.predicted,
        checked: result.checked,
        seconds: started.elapsed().as_secs_f64(),
    })
}

fn offsets_of(mission: &Mission, c: &planner::Candidate) -> Vec<Vector3<f64>> {
    c.formation.offsets(mission.children.len(), c.up_m)
}

fn formation_json(kind: &FormationKind, up_m: f64) -> Value {
    match *kind {
        FormationKind::Symmetric { forward_m, lateral_m } => {
            json!({"kind": "symmetric", "forward_m": forward_m, "lateral_m": lateral_m, "up_m": up_m})
        }
        FormationKind::Fan { radius_m, spread_deg } => {
            json!({"kind": "fan", "radius_m": radius_m, "spread_deg": spread_deg, "up_m": up_m})
        }
        FormationKind::Line { ahead_m, spacing_m } => {
            json!({"kind": "line", "ahead_m": ahead_m, "spacing_m": spacing_m, "up_m": up_m})
        }
    }
}

fn robot_json(mission: &Mission, r: Robot) -> Value {
    match r {
        Robot::Parent => json!("parent"),
        Robot::Child(j) => json!(mission.children.get(j).cloned().unwrap_or_else(|| j.to_string())),
    }
}

/// Observations whose redundancy number is below [`UNCHECKED_REDUNDANCY`]:
/// (cycle, child, observation name, redundancy number).
pub fn unchecked(report: &PlanReport) -> Vec<(usize, usize, &'static str, f64)> {
    let mut out = Vec::new();
    for f in &report.reliability {
        for (j, r) in f.redundancy_numbers.iter().enumerate() {
            for (k, name) in ["distance", "Hz", "V"].iter().enumerate() {
                if r[k] < UNCHECKED_REDUNDANCY {
                    out.push((f.cycle, j, *name, r[k]));
                }
            }
        }
    }
    out
}

fn min_redundancy(report: &PlanReport) -> Option<f64> {
    report.reliability.iter().flat_map(|f| f.redundancy_numbers.iter().flatten()).copied().reduce(f64::min)
}

/// Whether the plan passes: no violations (of the chosen plan, with
/// `--optimize`) and the acceptance tolerance met.
pub fn accepted(mission: &Mission, report: &PlanReport) -> bool {
    let within = |s2: Option<f64>| match (mission.acceptance.max_final_sigma_xy_m, s2) {
        (Some(max), Some(s2)) => s2.sqrt() <= max,
        _ => true,
    };
    match &report.optimized {
        Some(o) => within(Some(o.best.sigma_xy2_m2)),
        None => report.violations.is_empty() && within(report.sigma_xy2_m2),
    }
}

/// The report as one JSON object.
pub fn write_json(out: &mut dyn Write, mission: &Mission, report: &PlanReport) -> std::io::Result<()> {
    let name = robot_name(mission);
    let plan = &mission.plan;
    let violations: Vec<Value> = report
        .violations
        .iter()
        .map(|v| {
            json!({"step": v.step, "cycle": v.cycle, "station": v.station, "robot": robot_json(mission, v.robot),
                "constraint": v.check.name(), "value": v.value, "limit": v.limit, "message": v.describe(&name)})
        })
        .collect();
    let optimized = report.optimized.as_ref().map(|o| {
        let c = &o.best.candidate;
        json!({
            "strategy": c.strategy.name(), "hops": c.strategy.hops(), "stride_m": c.stride_m,
            "formation": formation_json(&c.formation, c.up_m),
            "formation_m": offsets_of(mission, c).iter().map(|o| [o.x, o.y, o.z]).collect::<Vec<_>>(),
            "cycles": o.best.cycles(), "sigma_xy2_m2": o.best.sigma_xy2_m2, "sigma_xy_m": o.best.sigma_xy2_m2.sqrt(),
            "improvement_factor": report.sigma_xy2_m2.map(|s| s / o.best.sigma_xy2_m2),
            "candidates_predicted": o.predicted, "candidates_checked": o.checked, "seconds": o.seconds,
        })
    });
    let doc = json!({
        "mission": mission.name,
        "strategy": plan.strategy.name(),
        "hops": plan.strategy.hops(),
        "stride_m": plan.stride_m,
        "formation_m": plan.formation_m.iter().map(|o| [o.x, o.y, o.z]).collect::<Vec<_>>(),
        "scene": if mission.backend.given { json!(mission.backend.scene) } else { Value::Null },
        "stations": report.dance.stations.len(),
        "cycles": report.dance.cycles.len(),
        "steps": report.steps,
        "violations": violations,
        "predicted": {
            "sigma_xy2_m2": report.sigma_xy2_m2, "sigma_xy_m": report.sigma_xy2_m2.map(f64::sqrt),
            "sigma_heading_rad": report.sigma_heading_rad,
        },
        "sensitivity": report.sensitivity.map(|s| json!({
            "total_m2": s.total_m2, "range_m2": s.range_m2, "angle_m2": s.angle_m2,
            "centring_m2": s.centring_m2, "start_m2": s.start_m2, "dominant": s.dominant(),
        })),
        "what_if": {
            "one_more_child_sigma_xy2_m2": report.one_more_child_m2,
            "longer_stride": report.longer_stride.map(|(stride, n, s)| json!({"stride_m": stride, "cycles": n, "sigma_xy2_m2": s})),
        },
        "reliability": {
            "min_redundancy_number": min_redundancy(report),
            "unchecked": unchecked(report).iter().map(|(c, j, o, r)| json!({"cycle": c, "child": robot_json(mission, Robot::Child(*j)), "observation": o, "redundancy_number": r})).collect::<Vec<_>>(),
        },
        "optimized": optimized,
        "accepted": accepted(mission, report),
    });
    serde_json::to_writer(&mut *out, &doc)?;
    writeln!(out)
}

/// The report as text.
pub fn write_table(out: &mut dyn Write, mission: &Mission, report: &PlanReport) -> std::io::Result<()> {
    let plan = &mission.plan;
    let name = robot_name(mission);
    let scene =
        if mission.backend.given { format!("scene \"{}\"", mission.backend.scene) } else { "open space".into() };
    writeln!(
        out,
        "mission {}: {}, stride {} m, {} stations, {} cycles, {} steps, checked in {scene}",
        mission.name,
        plan.strategy,
        plan.stride_m,
        report.dance.stations.len(),
        report.dance.cycles.len(),
        report.steps
    )?;
    if report.violations.is_empty() {
        writeln!(out, "constraints: every step keeps every constraint")?;
    } else {
        writeln!(out, "constraints: {} violation(s)", report.violations.len())?;
        for v in &report.violations {
            writeln!(out, "  {}", v.describe(&name))?;
        }
    }
    if let (Some(s2), Some(h)) = (report.sigma_xy2_m2, report.sigma_heading_rad) {
        writeln!(
            out,
            "predicted final: σx² + σy² = {s2:.6} m² (√ = {:.4} m), σθ = {:.2}″",
            s2.sqrt(),
            h / RAD_PER_ARCSEC
        )?;
    }
    if let Some(s) = report.sensitivity {
        let pct = |x: f64| 100.0 * x / s.total_m2;
        writeln!(
            out,
            "what dominates: {} — range {:.1} %, angle {:.1} %, centring {:.1} %, start {:.1} % of σx² + σy²",
            s.dominant(),
            pct(s.range_m2),
            pct(s.angle_m2),
            pct(s.centring_m2),
            pct(s.start_m2)
        )?;
    }
    if let (Some(m), Some(s2)) = (report.one_more_child_m2, report.sigma_xy2_m2) {
        writeln!(out, "one more child (straight ahead): σx² + σy² = {m:.6} m² ({:.2}× as written)", m / s2)?;
    }
    if let (Some((stride, n, m)), Some(s2)) = (report.longer_stride, report.sigma_xy2_m2) {
        writeln!(out, "stride {stride} m ({n} cycles): σx² + σy² = {m:.6} m² ({:.2}× as written)", m / s2)?;
    }
    if let Some(min) = min_redundancy(report) {
        let u = unchecked(report);
        writeln!(
            out,
            "reliability: smallest redundancy number of a fix observation {min:.3}; {} observation(s) checked by nothing{}",
            u.len(),
            if u.is_empty() { "" } else { " (see --json)" }
        )?;
        writeln!(out, "  each child's placement rests on one pointing: checked only through the next fix")?;
    }
    if let Some(o) = &report.optimized {
        let c = &o.best.candidate;
        writeln!(out)?;
        writeln!(
            out,
            "optimized ({} candidates predicted, {} checked, {:.2} s): {}, stride {} m, {} cycles",
            o.predicted,
            o.checked,
            o.seconds,
            c.strategy,
            c.stride_m,
            o.best.cycles()
        )?;
        let offsets: Vec<String> =
            offsets_of(mission, c).iter().map(|o| format!("[{:.3}, {:.3}, {:.3}]", o.x, o.y, o.z)).collect();
        writeln!(out, "  formation_m = [{}]", offsets.join(", "))?;
        let s2 = o.best.sigma_xy2_m2;
        write!(out, "  predicted final: σx² + σy² = {s2:.6} m² (√ = {:.4} m)", s2.sqrt())?;
        match report.sigma_xy2_m2 {
            Some(w) => writeln!(out, ", {:.2}× better than as written", w / s2)?,
            None => writeln!(out)?,
        }
    }
    if let Some(max) = mission.acceptance.max_final_sigma_xy_m {
        writeln!(
            out,
            "acceptance (max_final_sigma_xy_m = {max} m): {}",
            if accepted(mission, report) { "PASS" } else { "FAIL" }
        )?;
    } else if !accepted(mission, report) {
        writeln!(out, "FAIL: the plan breaks constraints")?;
    }
    Ok(())
}

/// Writes the mission file with the chosen plan filled in: the input text
/// with `stride_m`, the formation (`formation_m` or `formation`),
/// `strategy` and `hops` replaced or added, and a relative `scene_file`
/// made absolute when the new file lives elsewhere. Comments and every
/// other key are kept.
pub fn write_mission(mission: &Mission, optimized: &Optimized, path: &Path) -> Result<()> {
    let text = &mission.source.text;
    let spans = &mission.spans;
    let c = &optimized.best.candidate;
    let mut edits: Vec<(std::ops::Range<usize>, String)> = Vec::new();
    edits.push((spans.stride_m.clone(), format!("{}", c.stride_m)));
    let formation = if text[spans.formation_value.clone()].trim_start().starts_with('{') {
        let FormationKind::Symmetric { forward_m, lateral_m } = c.formation else {
            anyhow::bail!("the search returns symmetric formations only");
        };
        format!("{{ kind = \"symmetric\", forward_m = {forward_m}, lateral_m = {lateral_m}, up_m = {} }}", c.up_m)
    } else {
        let items: Vec<String> =
            offsets_of(mission, c).iter().map(|o| format!("[{}, {}, {}]", o.x, o.y, o.z)).collect();
        format!("[{}]", items.join(", "))
    };
    edits.push((spans.formation_value.clone(), formation));
    let strategy = format!("\"{}\"", c.strategy.name());
    let line_end = |at: usize| text[at..].find('\n').map_or(text.len(), |i| at + i);
    // New keys go on one line each after `stride_m` (`hops` after `strategy`).
    let mut added = String::new();
    match &spans.strategy {
        Some(span) => edits.push((span.clone(), strategy)),
        None => added.push_str(&format!("\nstrategy = {strategy}")),
    }
    match (c.strategy, &spans.hops) {
        (Strategy::ParentHops { hops }, Some(span)) => edits.push((span.clone(), hops.to_string())),
        (Strategy::ParentHops { hops }, None) => match &spans.strategy {
            Some(span) => {
                let at = line_end(span.end);
                edits.push((at..at, format!("\nhops = {hops}")));
            }
            None => added.push_str(&format!("\nhops = {hops}")),
        },
        (Strategy::Leapfrog, Some(span)) => {
            let start = text[..span.start].rfind('\n').map_or(0, |i| i + 1);
            edits.push((start..(line_end(span.end) + 1).min(text.len()), String::new()));
        }
        (Strategy::Leapfrog, None) => {}
    }
    if !added.is_empty() {
        let at = line_end(spans.stride_m.end);
        edits.push((at..at, added));
    }
    if let (Some(span), Some((resolved, _))) = (&spans.scene_file, &mission.backend.scene_file) {
        let same_dir = path.parent().map(Path::to_path_buf).unwrap_or_default()
            == mission.source.file.parent().map(Path::to_path_buf).unwrap_or_default();
        if !same_dir {
            let absolute = std::fs::canonicalize(resolved).unwrap_or_else(|_| resolved.clone());
            edits.push((span.clone(), toml_string(&absolute.display().to_string())));
        }
    }
    edits.sort_by_key(|(r, _)| std::cmp::Reverse(r.start));
    let mut s = text.clone();
    for (range, with) in edits {
        s.replace_range(range, &with);
    }
    let header = format!(
        "# Plan chosen by `cps-survey plan --optimize` from {}: {}, stride {} m, {} cycles,\n\
         # predicted final σx² + σy² = {:.6} m².\n",
        mission.source.file.display(),
        c.strategy,
        c.stride_m,
        optimized.best.cycles(),
        optimized.best.sigma_xy2_m2
    );
    std::fs::write(path, header + &s).with_context(|| format!("cannot write {}", path.display()))?;
    Ok(())
}

fn toml_string(s: &str) -> String {
    let mut out = String::from("\"");
    for ch in s.chars() {
        match ch {
            '"' => out.push_str("\\\""),
            '\\' => out.push_str("\\\\"),
            c => out.push(c),
        }
    }
    out.push('"');
    out
}
