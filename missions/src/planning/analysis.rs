//! What `plan` reports about a mission's plan: its violations, what its
//! final error is made of, what one more child or a longer stride would
//! change, the redundancy of every fix observation — and with `--optimize`
//! the best formation, stride and strategy of `[plan.search]`.

use std::time::Instant;

use anyhow::Result;
use cps::Instrument;
use planner::analysis::{FixReliability, Sensitivity, UNCHECKED_REDUNDANCY};
use planner::search::Evaluated;
use planner::sighting::attach;
use planner::{FormationKind, Objective, SearchSpace, Strategy, Violation};

use super::Planned;
use super::constraints::{limits, violations};
use crate::mission::{ControlAt, Mission};

/// Longest sight line `--optimize` considers when neither the mission nor
/// the instrument sets a shorter one, metres.
pub const DEFAULT_MAX_SIGHT_LINE_M: f64 = 200.0;

/// What `plan` found.
#[derive(Debug)]
pub struct PlanReport {
    /// The plan as written (ranges lifted in its prediction).
    pub written: Planned,
    /// Its violations.
    pub violations: Vec<Violation>,
    /// Predicted final σx² + σy² as written, m².
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
    /// Which stations see which control point.
    pub control: Vec<ControlSeen>,
    /// With `--optimize`: the chosen plan.
    pub optimized: Option<Optimized>,
}

/// A control point and the stations that sight it.
#[derive(Debug, Clone, PartialEq)]
pub struct ControlSeen {
    /// Its name.
    pub name: String,
    /// Whether every coordinate is held fixed.
    pub fixed: bool,
    /// The stations that sight it, with the slope distance (metres).
    pub from: Vec<(usize, f64)>,
}

/// Which stations of `planned` sight each control point.
pub fn control_seen(planned: &Planned) -> Vec<ControlSeen> {
    let dance = &planned.dance;
    dance
        .control
        .iter()
        .enumerate()
        .map(|(c, point)| ControlSeen {
            name: point.name.clone(),
            fixed: point.covariance.diagonal().iter().all(|v| *v == 0.0),
            from: (0..dance.stations.len())
                .filter(|&k| dance.sighted_at(k).contains(&c))
                .map(|k| {
                    let at = planned.dance.station_pose(k);
                    (k, cps::observe(&at, &point.position).map_or(f64::NAN, |r| r.slope_m))
                })
                .collect(),
        })
        .collect()
}

/// The plan `--optimize` chose.
#[derive(Debug)]
pub struct Optimized {
    /// The plan, its schedule and final variance.
    pub best: Evaluated,
    /// The chosen plan, predicted with the mission's instrument.
    pub planned: Planned,
    /// Where it sights control (the mission's unless the search chose
    /// another).
    pub control_at: ControlAt,
    /// Candidates predicted.
    pub predicted: usize,
    /// Candidates checked against the constraints.
    pub checked: usize,
    /// Wall time of the search, seconds.
    pub seconds: f64,
}

impl Optimized {
    /// The chosen formation's offsets, team order.
    pub fn offsets(&self, mission: &Mission) -> Vec<nalgebra::Vector3<f64>> {
        let c = &self.best.candidate;
        c.formation.offsets(mission.children.len(), c.up_m)
    }
}

/// Checks and analyses the mission's plan as written; with `optimize`
/// searches `[plan.search]` for a better one.
pub fn analyse(mission: &Mission, written: Planned, optimize: bool) -> Result<PlanReport> {
    let violations = violations(mission, &written);
    let last = written.prediction.last();
    let mut report = PlanReport {
        violations,
        sigma_xy2_m2: last.map(|l| l.sigma_xy2_m2()),
        sigma_heading_rad: last.map(|l| l.sigma_heading_rad()),
        sensitivity: None,
        one_more_child_m2: None,
        longer_stride: None,
        reliability: Vec::new(),
        control: control_seen(&written),
        optimized: None,
        written,
    };
    let Some(instrument) = &mission.total_station else {
        if optimize {
            anyhow::bail!(
                "mission {} has no children: a robot alone has no formation to optimise",
                mission.source.file.display()
            );
        }
        return Ok(report);
    };
    let plan = &mission.plan;
    let free = Instrument { min_range_m: 0.0, max_range_m: f64::INFINITY, ..instrument.clone() };
    let start = plan.start_covariance;
    let dance = &report.written.dance;
    report.sensitivity = planner::analysis::sensitivity(dance, &free, &start).ok();
    report.one_more_child_m2 =
        planner::analysis::with_one_more_child(dance, &plan.formation_m, plan.strategy, &free, &start);
    let control = super::control_points(mission);
    let scene = report.written.checked_scene();
    report.longer_stride = planner::stations(&plan.route_m, plan.stride_m * 1.25)
        .ok()
        .and_then(|st| planner::schedule(st, &plan.formation_m, plan.strategy).ok())
        .and_then(|d| {
            let at = same_places(&plan.control_at, &report.written.dance, &d);
            attach(d, &control, &at, &free, scene).ok()
        })
        .and_then(|d| Some((d.cycles.len(), planner::predict(&d, &free, &start).ok()?.last()?.sigma_xy2_m2())))
        .map(|(n, s)| (plan.stride_m * 1.25, n, s));
    report.reliability = planner::analysis::reliability(dance, &free, &start).unwrap_or_default();
    if optimize {
        report.optimized = Some(search(mission, instrument, report.written.checked_scene())?);
    }
    Ok(report)
}

/// `at` of the `written` dance for another schedule `other` of the same
/// route: a list of stations becomes the stations of `other` nearest to the
/// listed ones (the same places along the route).
pub fn same_places(at: &ControlAt, written: &planner::Dance, other: &planner::Dance) -> ControlAt {
    let ControlAt::Stations(list) = at else { return at.clone() };
    let mut out: Vec<usize> = list
        .iter()
        .filter_map(|&k| {
            let p = written.stations.get(k)?.position;
            (0..other.stations.len()).min_by(|&a, &b| {
                let d = |i: usize| (other.stations[i].position - p).norm();
                d(a).total_cmp(&d(b))
            })
        })
        .collect();
    out.sort_unstable();
    out.dedup();
    ControlAt::Stations(out)
}

/// Runs the search of `[plan.search]`.
fn search(mission: &Mission, instrument: &Instrument, scene: Option<&cps::geom::Scene>) -> Result<Optimized> {
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
    let a = &mission.acceptance;
    let objective = match (a.max_station_sigma_xy_m, a.max_final_sigma_xy_m) {
        (Some(max_sigma_xy_m), _) => Objective::FewestCyclesEveryStation { max_sigma_xy_m },
        (None, Some(max_sigma_xy_m)) => Objective::FewestCycles { max_sigma_xy_m },
        (None, None) => Objective::MinVariance,
    };
    // The mission's control_at; targeting every station's σ (or when a
    // list of stations cannot follow another stride) the search may also
    // choose the ends only or every station.
    let control = super::control_points(mission);
    let mut control_at = vec![plan.control_at.clone()];
    if a.max_station_sigma_xy_m.is_some() || matches!(plan.control_at, ControlAt::Stations(_)) {
        for other in [ControlAt::StartEnd, ControlAt::Every] {
            if !control_at.contains(&other) {
                control_at.push(other);
            }
        }
    }
    let scan_at = |k: usize| mission.scan.scans_at(k);
    let problem = planner::Problem {
        route_m: &plan.route_m,
        instrument,
        start_covariance: plan.start_covariance,
        n_children: mission.children.len(),
        scene,
        limits: limits(mission),
        scan_at: &scan_at,
        control: &control,
        control_at: &control_at,
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
        if let Some(e) = problem.evaluate(&c, &within, &objective)
            && problem.violations(&e.dance, max_sight_line_m).is_empty()
        {
            best = e;
        }
    }
    let seconds = started.elapsed().as_secs_f64();
    let planned = Planned::with_dance(mission, best.dance.clone())
        .map_err(|e| anyhow::anyhow!("mission {}: optimized plan: {e}", mission.source.file.display()))?;
    let control_at = control_at.get(best.candidate.control_at).cloned().unwrap_or_default();
    Ok(Optimized { best, planned, control_at, predicted: result.predicted, checked: result.checked, seconds })
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

/// The smallest redundancy number of any fix observation.
pub fn min_redundancy(report: &PlanReport) -> Option<f64> {
    report.reliability.iter().flat_map(|f| f.redundancy_numbers.iter().flatten()).copied().reduce(f64::min)
}

/// Whether the plan passes: no violations (of the chosen plan, with
/// `--optimize`) and the acceptance tolerances met.
pub fn accepted(mission: &Mission, report: &PlanReport) -> bool {
    match &report.optimized {
        Some(o) => super::accepted(mission, &o.planned),
        None => report.violations.is_empty() && super::accepted(mission, &report.written),
    }
}
