//! The mission → plan step: the dance scheduled from `[plan]`, its steps
//! with the scan stations, the scene it is checked against, and the
//! predicted covariance of every robot at every step — built once per
//! command ([`Planned`]) and passed down.
//!
//! [`constraints`] checks a plan against the scene and the instruments;
//! [`preanalysis`] adjusts the planned network (every station's covariance,
//! every reading's reliability); [`analysis`] is what `plan` reports (what
//! the error is made of, what-ifs, reliability, the search); [`edit`]
//! writes an optimized plan back into the mission file; [`montecarlo`]
//! checks the prediction by seeded simulated executions.

pub mod analysis;
pub mod constraints;
pub mod edit;
pub mod montecarlo;
pub mod preanalysis;

use std::sync::Arc;

use cps::Instrument;
use cps::geom::Scene;
use planner::{Dance, PlanError, Prediction, StepEstimate};

use planner::ControlPoint;
use planner::sighting::Unseen;

use crate::mission::diagnostics::{Diagnostic, Diagnostics};
use crate::mission::{Mission, MissionError};
use preanalysis::PreAnalysis;

/// A mission's plan: everything the commands share, built once.
#[derive(Debug, Clone)]
pub struct Planned {
    /// The scene the plan is checked against: the `[backend]`'s when the
    /// file has that table, open space (`None`) otherwise.
    pub scene: Option<Arc<Scene>>,
    /// The schedule.
    pub dance: Dance,
    /// Its steps, with the mission's scan stations ([`Dance::steps`]).
    pub steps: Vec<planner::Step>,
    /// The predicted covariance after every cycle: the CPS dance, or for a
    /// robot alone its dead reckoning.
    pub prediction: Prediction,
    /// Every robot's predicted estimate along the steps: each child after
    /// its placement, the parent after each fix and at each scan station
    /// ([`planner::step_estimates`]).
    pub estimates: Vec<StepEstimate>,
    /// The planned network adjusted (none for a robot alone, or when it
    /// cannot be adjusted: then `adjusted_error` says why).
    pub adjusted: Option<PreAnalysis>,
    /// Why the planned network could not be adjusted (the filter's
    /// prediction stands; a run reports its own network's adjustment).
    pub adjusted_error: Option<String>,
}

impl Planned {
    /// The mission's plan for `predict`, `run`, `montecarlo`, `validate`:
    /// the schedule (route, stride, formation and scan-list errors point at
    /// the mission file), every sight line within the instrument's range
    /// (a violation points at the child's `formation_m` entry), and the
    /// prediction.
    pub fn new(mission: &Mission) -> Result<Self, MissionError> {
        let invalid = |d| MissionError::invalid(mission, d);
        let dance = schedule(mission).map_err(invalid)?;
        if let Some(instrument) = &mission.total_station {
            let violations = dance.range_violations(instrument);
            if !violations.is_empty() {
                return Err(invalid(plan_diagnostics(mission, violations)));
            }
        }
        Self::predicted(mission, dance, mission.total_station.clone())
    }

    /// The plan as written, for `plan`: range violations are reported by
    /// the constraint check, not refused, and the prediction lifts the
    /// instrument's range limits (to compare a plan that breaks them).
    pub fn as_written(mission: &Mission) -> Result<Self, MissionError> {
        let dance = schedule(mission).map_err(|d| MissionError::invalid(mission, d))?;
        let unlimited = mission.total_station.as_ref().map(|i| Instrument {
            min_range_m: 0.0,
            max_range_m: f64::INFINITY,
            ..i.clone()
        });
        Self::predicted(mission, dance, unlimited)
    }

    /// Another schedule of the same mission (e.g. the optimized one),
    /// predicted with the mission's instrument.
    pub fn with_dance(mission: &Mission, dance: Dance) -> Result<Self, MissionError> {
        Self::predicted(mission, dance, mission.total_station.clone())
    }

    fn predicted(mission: &Mission, dance: Dance, instrument: Option<Instrument>) -> Result<Self, MissionError> {
        let start = &mission.plan.start_covariance;
        let prediction = match &instrument {
            Some(instrument) => planner::predict(&dance, instrument, start)
                .map_err(|e| MissionError::invalid(mission, plan_diagnostics(mission, vec![e])))?,
            None => {
                let o = &mission.backend.odometry;
                let noise = planner::OdometryNoise {
                    sigma_distance_m_per_sqrt_m: o.sigma_distance_m_per_sqrt_m,
                    sigma_heading_rad_per_sqrt_m: o.sigma_heading_rad_per_sqrt_m,
                };
                planner::predict_odometry(&dance, &noise, start)
            }
        };
        // A network the batch adjustment cannot take (e.g. a traverse so
        // long that its far end is known to kilometres, beyond what double
        // precision separates from undetermined) keeps its prediction.
        let (adjusted, adjusted_error) = match &instrument {
            Some(instrument) => match PreAnalysis::of(mission, &dance, instrument, start) {
                Ok(a) => (Some(a), None),
                Err(e) => (None, Some(format!("the planned network cannot be adjusted: {e}"))),
            },
            None => (None, None),
        };
        let steps = dance.steps(|k| mission.scan.scans_at(k));
        let estimates = planner::step_estimates(&dance, &prediction, &steps);
        let scene = mission.backend.given.then(|| Arc::clone(mission.scene()));
        Ok(Self { scene, dance, steps, prediction, estimates, adjusted, adjusted_error })
    }

    /// The filter's covariance of station `k` (the start's, or the cycle's
    /// that ends there).
    pub fn filter_covariance(&self, k: usize) -> Option<nalgebra::Matrix4<f64>> {
        if k == 0 {
            return Some(self.prediction.start);
        }
        // Cycles reach the stations in order.
        let i = self.dance.cycles.binary_search_by_key(&k, |c| c.to).ok()?;
        self.prediction.cycles.get(i).map(|c| c.covariance)
    }

    /// The control points station `k` sights (their names).
    pub fn control_sighted_at(&self, k: usize) -> Vec<&str> {
        self.dance.sighted_at(k).iter().filter_map(|&c| self.dance.control.get(c)).map(|c| c.name.as_str()).collect()
    }

    /// The worst station's adjusted √(σx² + σy²) (its index, metres).
    pub fn worst_station(&self) -> Option<(usize, f64)> {
        self.adjusted.as_ref()?.worst().map(|s| (s.index, s.sigma_xy_m()))
    }

    /// The number of parent stations.
    pub fn stations(&self) -> usize {
        self.dance.stations.len()
    }

    /// The scene checked against, if any.
    pub fn checked_scene(&self) -> Option<&Scene> {
        self.scene.as_deref()
    }
}

/// The mission's schedule, unchecked against the instrument's range; route,
/// stride, formation and scan-list errors point at the mission file.
fn schedule(mission: &Mission) -> Result<Dance, Diagnostics> {
    let plan = &mission.plan;
    let stations = planner::stations(&plan.route_m, plan.stride_m).map_err(|e| plan_diagnostics(mission, vec![e]))?;
    let dance = match &mission.total_station {
        None => planner::solo(stations),
        Some(_) => planner::schedule(stations, &plan.formation_m, plan.strategy)
            .map_err(|e| plan_diagnostics(mission, vec![e]))?,
    };
    let n = dance.stations.len();
    let missing = |list: &[usize]| list.iter().find(|k| **k >= n).copied();
    let exist =
        |k: usize| format!("station {k} does not exist; expected indices 0 to {} (the plan has {n} stations)", n - 1);
    if let (Some(list), Some(span)) = (&mission.scan.stations, &mission.spans.scan_stations)
        && let Some(k) = missing(list)
    {
        return Err(Diagnostics(vec![mission.diagnostic(span, "scan.stations", exist(k))]));
    }
    if let (Some(k), Some(span)) = (mission.plan.control_at.missing(n), &mission.spans.control_at) {
        return Err(Diagnostics(vec![mission.diagnostic(span, "plan.control_at", exist(k))]));
    }
    with_control(mission, dance)
}

/// The mission's control points, for the planner.
pub fn control_points(mission: &Mission) -> Vec<ControlPoint> {
    mission
        .control
        .iter()
        .map(|c| ControlPoint { name: c.name.clone(), position: c.position_m, covariance: c.covariance })
        .collect()
}

/// The dance with the mission's control points and the stations that see
/// them (`[plan] control_at`, within the instrument's range, in line of
/// sight against the scene checked); a control point no station sees is an
/// error that says why from the station nearest to it.
fn with_control(mission: &Mission, dance: Dance) -> Result<Dance, Diagnostics> {
    let Some(instrument) = mission.total_station.as_ref().filter(|_| !mission.control.is_empty()) else {
        return Ok(dance);
    };
    let control = control_points(mission);
    // The simulator sights control through its scene whether or not the
    // mission names one (the built-in hall by default): the plan checks
    // the same sight lines (issue 34, S14: planned "seen" at 152 m, then
    // blocked by the hall's wall in the run). On real instruments without
    // a `[backend]` scene there is no model to check against.
    let simulated = mission.backend.serial.is_none();
    let scene = (mission.backend.given || simulated).then(|| mission.scene().as_ref());
    let at = &mission.plan.control_at;
    let unseen = match planner::sighting::attach(dance.clone(), &control, at, instrument, scene) {
        Ok(dance) => return Ok(dance),
        Err(unseen) => unseen,
    };
    let n = dance.stations.len();
    let mut problems = Vec::new();
    for c in unseen {
        let point = &control[c];
        let nearest = (0..n).filter(|&k| at.includes(k, n)).min_by(|&a, &b| {
            let d = |k: usize| (dance.stations[k].position - point.position).norm();
            d(a).total_cmp(&d(b))
        });
        let why = match nearest {
            None => "no station sights control (control_at)".to_string(),
            Some(k) => {
                match planner::sighting::visibility(&dance.station_pose(k), &point.position, instrument, scene) {
                    Err(Unseen::OutOfRange(r)) => format!(
                        "the nearest station that sights control, {k}, is {r:.1} m away, outside the instrument's range [{}, {}] m",
                        instrument.min_range_m, instrument.max_range_m
                    ),
                    Err(Unseen::Blocked(object, at)) => {
                        format!(
                            "from the nearest station that sights control, {k}, \"{object}\" blocks the sight line {at:.1} m out"
                        )
                    }
                    Err(Unseen::Vertical) => format!("it stands straight above or below station {k}"),
                    Err(Unseen::NotScheduled) | Ok(_) => format!("station {k} does not sight it"),
                }
            }
        };
        let span = mission.spans.control.get(c).cloned().unwrap_or(mission.spans.plan.clone());
        let message = format!("control point \"{}\" is seen from no station: {why}", point.name);
        problems.push(mission.diagnostic(&span, &format!("control[{c}]"), message));
    }
    Err(Diagnostics(problems))
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
            PlanError::ZeroLengthSegment { waypoint } | PlanError::VerticalSegment { waypoint, .. } => (
                spans.route_m.get(*waypoint).cloned().unwrap_or(spans.plan.clone()),
                format!("plan.route_m[{waypoint}]"),
            ),
            PlanError::BadStride { .. } | PlanError::TooManyStations { .. } => {
                (spans.stride_m.clone(), "plan.stride_m".to_string())
            }
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

/// Whether the plan meets `[acceptance]`: the prediction's last station
/// `max_final_sigma_xy_m` (the filter's), every station
/// `max_station_sigma_xy_m` (the adjustment's).
pub fn accepted(mission: &Mission, planned: &Planned) -> bool {
    let a = &mission.acceptance;
    let last = planned.prediction.last().map(|l| l.sigma_xy2_m2().sqrt());
    let worst = planned.worst_station().map(|w| w.1);
    let within = |max: Option<f64>, value: Option<f64>| match (max, value) {
        (Some(max), Some(v)) => v <= max,
        _ => true,
    };
    // Every station's σ cannot be vouched for without the adjustment.
    let stations_known = a.max_station_sigma_xy_m.is_none() || planned.adjusted_error.is_none();
    within(a.max_final_sigma_xy_m, last) && within(a.max_station_sigma_xy_m, worst) && stations_known
}
