//! Formation, stride, strategy and control search: the plan with the
//! smallest predicted final horizontal variance — or the fewest cycles that
//! meet a tolerance, at the last station (the filter's) or at every station
//! (the batch adjustment's) — that breaks no constraint.
//!
//! The search predicts every candidate of a grid (strategies × strides ×
//! symmetric formations (forward a, lateral ±b) within the longest allowed
//! sight line) in parallel, checks the constraints of the best ones in order
//! of their score until one passes (range first; the scene checks are the
//! expensive part), then refines (a, b) of the winner by a pattern search
//! that only accepts feasible improvements.
//!
//! With control points, every candidate is tried with each of the
//! problem's `control_at` choices; one that leaves a control point unseen
//! is no plan. Among plans of as many cycles that meet an every-station
//! tolerance, fewer control setups win.

use nalgebra::{Matrix4, Point3};
use rayon::prelude::*;

use cps::Instrument;
use cps::geom::Scene;

use crate::constraints::{Limits, Violation, check};
use crate::control::{ControlAt, ControlPoint};
use crate::dance::{Dance, FormationKind, Strategy, schedule};
use crate::error::PlanError;
use crate::predict::predict;
use crate::route::stations;
use crate::sighting::{attach, setups};

/// One plan the search considers.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Candidate {
    /// How the team advances.
    pub strategy: Strategy,
    /// Distance between parent stations, metres.
    pub stride_m: f64,
    /// The children's formation.
    pub formation: FormationKind,
    /// The children's prism height relative to the parent's instrument, metres.
    pub up_m: f64,
    /// Which of the problem's `control_at` choices (0 without control).
    pub control_at: usize,
}

/// What is fixed while searching.
#[allow(missing_debug_implementations)] // `scan_at` is a closure
pub struct Problem<'a> {
    /// Parent waypoints, world frame, metres.
    pub route_m: &'a [Point3<f64>],
    /// The total station.
    pub instrument: &'a Instrument,
    /// Covariance of the start pose.
    pub start_covariance: Matrix4<f64>,
    /// Number of children.
    pub n_children: usize,
    /// The scene the plan must fit (None: open space, ranges only).
    pub scene: Option<&'a Scene>,
    /// The limits every step must keep.
    pub limits: Limits,
    /// Whether the parent scans at a station.
    pub scan_at: &'a (dyn Fn(usize) -> bool + Sync),
    /// The control points (none: an open traverse).
    pub control: &'a [ControlPoint],
    /// Where the parent may sight them: the choices the search tries.
    pub control_at: &'a [ControlAt],
}

/// What may change.
#[derive(Debug, Clone, PartialEq)]
pub struct SearchSpace {
    /// Strategies to try.
    pub strategies: Vec<Strategy>,
    /// Strides to try, metres.
    pub strides_m: Vec<f64>,
    /// Longest sight line a formation may need, metres (also the range
    /// limit during the search).
    pub max_sight_line_m: f64,
    /// Prism height of the generated formations relative to the instrument.
    pub up_m: f64,
}

/// What the search minimises.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Objective {
    /// The final σx² + σy².
    MinVariance,
    /// The fewest dance cycles whose final √(σx² + σy²) is at most the
    /// tolerance; ties by fewer control setups, then (and plans that all
    /// miss it) by the final variance.
    FewestCycles {
        /// The tolerance, metres.
        max_sigma_xy_m: f64,
    },
    /// The fewest dance cycles whose every station's adjusted (batch)
    /// √(σx² + σy²) is at most the tolerance; ties by fewer control
    /// setups, then by the worst station's variance.
    FewestCyclesEveryStation {
        /// The tolerance, metres.
        max_sigma_xy_m: f64,
    },
}

impl Objective {
    fn every_station(&self) -> bool {
        matches!(self, Objective::FewestCyclesEveryStation { .. })
    }
}

/// A candidate with its schedule and predicted accuracy.
#[derive(Debug, Clone)]
pub struct Evaluated {
    /// The plan.
    pub candidate: Candidate,
    /// Its schedule.
    pub dance: Dance,
    /// Predicted final σx² + σy², m².
    pub sigma_xy2_m2: f64,
    /// The worst station's adjusted √(σx² + σy²), metres (computed for an
    /// every-station objective).
    pub worst_station_sigma_xy_m: Option<f64>,
}

impl Evaluated {
    /// Number of dance cycles.
    pub fn cycles(&self) -> usize {
        self.dance.cycles.len()
    }

    /// Orders two plans under `objective`: better first.
    /// Stations that sight control.
    pub fn control_setups(&self) -> usize {
        setups(&self.dance)
    }

    /// What ranks it, without its schedule.
    fn score(&self) -> Score {
        Score {
            sigma_xy2_m2: self.sigma_xy2_m2,
            worst_station_sigma_xy_m: self.worst_station_sigma_xy_m,
            cycles: self.cycles(),
            control_setups: self.control_setups(),
        }
    }

    fn cmp_by(&self, other: &Self, objective: &Objective) -> std::cmp::Ordering {
        self.score().cmp_by(&other.score(), objective)
    }
}

/// What ranks a candidate: the grid's thousands are ranked by it, their
/// schedules dropped (a schedule is rebuilt only for the few checked
/// against the scene: memory stays that of one schedule per thread).
#[derive(Debug, Clone, Copy)]
struct Score {
    sigma_xy2_m2: f64,
    worst_station_sigma_xy_m: Option<f64>,
    cycles: usize,
    control_setups: usize,
}

impl Score {
    fn cmp_by(&self, other: &Self, objective: &Objective) -> std::cmp::Ordering {
        let (a, b) = (self.key(objective), other.key(objective));
        a.0.cmp(&b.0).then(a.1.cmp(&b.1)).then(a.2.cmp(&b.2)).then(a.3.total_cmp(&b.3))
    }

    fn key(&self, objective: &Objective) -> (u8, usize, usize, f64) {
        match objective {
            Objective::MinVariance => (0, 0, 0, self.sigma_xy2_m2),
            Objective::FewestCycles { max_sigma_xy_m } => {
                if self.sigma_xy2_m2.sqrt() <= *max_sigma_xy_m {
                    (0, self.cycles, self.control_setups, self.sigma_xy2_m2)
                } else {
                    (1, 0, 0, self.sigma_xy2_m2)
                }
            }
            Objective::FewestCyclesEveryStation { max_sigma_xy_m } => {
                let worst = self.worst_station_sigma_xy_m.unwrap_or(f64::INFINITY);
                if worst <= *max_sigma_xy_m { (0, self.cycles, self.control_setups, worst) } else { (1, 0, 0, worst) }
            }
        }
    }
}

/// The search's answer.
#[derive(Debug, Clone)]
pub struct SearchResult {
    /// The best plan that breaks no constraint, if any does.
    pub best: Option<Evaluated>,
    /// Candidates predicted.
    pub predicted: usize,
    /// Candidates whose constraints were checked against the scene.
    pub checked: usize,
}

/// Grid size per (strategy, stride): forward offsets from −L to L, lateral
/// offsets from L/N² to L (quadratically spaced), with L the longest sight
/// line or the scene's horizontal diagonal, whichever is shorter.
const GRID_FORWARD: usize = 25;
const GRID_LATERAL: usize = 20;

impl Problem<'_> {
    /// The instrument with the search's sight-line limit.
    fn instrument_within(&self, max_sight_line_m: f64) -> Instrument {
        let mut inst = self.instrument.clone();
        inst.max_range_m = inst.max_range_m.min(max_sight_line_m);
        inst
    }

    /// Schedules and predicts `candidate` (with the batch adjustment for
    /// an every-station `objective`); `None` when it breaks a range limit,
    /// leaves a control point unseen, names a station it does not have or
    /// the model rejects it.
    pub fn evaluate(&self, candidate: &Candidate, instrument: &Instrument, objective: &Objective) -> Option<Evaluated> {
        let st = stations(self.route_m, candidate.stride_m).ok()?;
        let offsets = candidate.formation.offsets(self.n_children, candidate.up_m);
        let mut dance = schedule(st, &offsets, candidate.strategy).ok()?;
        if !dance.range_violations(instrument).is_empty() {
            return None;
        }
        if !self.control.is_empty() {
            let at = self.control_at.get(candidate.control_at)?;
            if at.missing(dance.stations.len()).is_some() {
                return None;
            }
            dance = attach(dance, self.control, at, instrument, self.scene).ok()?;
        }
        let prediction = predict(&dance, instrument, &self.start_covariance).ok()?;
        let sigma_xy2_m2 = prediction.last()?.sigma_xy2_m2();
        if !sigma_xy2_m2.is_finite() {
            return None;
        }
        let worst_station_sigma_xy_m = if objective.every_station() {
            let (_, adjusted) = crate::network::pre_analysis(&dance, instrument, &self.start_covariance).ok()?;
            Some(crate::network::worst_station(&adjusted)?.1)
        } else {
            None
        };
        Some(Evaluated { candidate: *candidate, dance, sigma_xy2_m2, worst_station_sigma_xy_m })
    }

    /// Every constraint `dance` breaks, with the search's sight-line limit.
    pub fn violations(&self, dance: &Dance, max_sight_line_m: f64) -> Vec<Violation> {
        let limits = Limits { max_range_m: self.limits.max_range_m.min(max_sight_line_m), ..self.limits };
        check(dance, self.scene, &limits, self.scan_at)
    }
}

/// Searches `space` for the best plan under `objective`.
pub fn search(problem: &Problem<'_>, space: &SearchSpace, objective: Objective) -> Result<SearchResult, PlanError> {
    if problem.n_children < 2 {
        return Err(PlanError::TooFewChildren { got: problem.n_children });
    }
    let reach = space.max_sight_line_m.min(problem.instrument.max_range_m);
    if !(reach.is_finite() && reach > 0.0) {
        return Err(PlanError::BadSightLine { value: space.max_sight_line_m });
    }
    let instrument = problem.instrument_within(reach);
    // Formations need not reach beyond the scene.
    let span = problem.scene.map_or(reach, |s| s.bounds().extent().xy().norm());
    let extent = reach.min(span);
    // Pairs k stand at ±b(k+1): the outermost pair sets the lateral reach.
    let pairs = problem.n_children.div_ceil(2).max(1) as f64;
    // Quadratic spacing: dense near the parent, where compact formations
    // differ most.
    let half = (GRID_FORWARD / 2) as f64;
    let mut grid = Vec::new();
    let control_choices = if problem.control.is_empty() { 1 } else { problem.control_at.len() };
    for control_at in 0..control_choices {
        for &strategy in &space.strategies {
            for &stride_m in &space.strides_m {
                for i in 0..GRID_FORWARD {
                    let u = (i as f64 - half) / half;
                    let forward_m = extent * u * u.abs();
                    for k in 1..=GRID_LATERAL {
                        let v = k as f64 / GRID_LATERAL as f64;
                        let lateral_m = extent / pairs * v * v;
                        let formation = FormationKind::Symmetric { forward_m, lateral_m };
                        grid.push(Candidate { strategy, stride_m, formation, up_m: space.up_m, control_at });
                    }
                }
            }
        }
    }
    let predicted = grid.len();
    let mut ranked: Vec<(Candidate, Score)> = grid
        .par_iter()
        .filter_map(|c| problem.evaluate(c, &instrument, &objective).map(|e| (e.candidate, e.score())))
        .collect();
    ranked.sort_by(|a, b| a.1.cmp_by(&b.1, &objective));

    // The best feasible candidate, checking a batch at a time in parallel
    // (each schedule rebuilt, checked and dropped unless it wins).
    let mut checked = 0;
    let mut best = None;
    for batch in ranked.chunks(16) {
        checked += batch.len();
        let feasible: Vec<Option<Evaluated>> = batch
            .par_iter()
            .map(|(c, _)| {
                problem.evaluate(c, &instrument, &objective).filter(|e| problem.violations(&e.dance, reach).is_empty())
            })
            .collect();
        if let Some(e) = feasible.into_iter().flatten().next() {
            best = Some(e);
            break;
        }
    }
    let Some(mut best) = best else { return Ok(SearchResult { best: None, predicted, checked }) };

    // Pattern search on (a, b) around the winner.
    // Steps of about the grid spacing around the winner, halved down to a
    // millimetre.
    let (a0, b0) = match best.candidate.formation {
        FormationKind::Symmetric { forward_m, lateral_m } => (forward_m, lateral_m),
        _ => (0.0, 0.0),
    };
    let mut step = (
        (2.0 * extent * (a0.abs() / extent).sqrt() / half).max(extent / (half * half)),
        (2.0 * extent / pairs * (b0 * pairs / extent).sqrt() / GRID_LATERAL as f64)
            .max(extent / pairs / (GRID_LATERAL * GRID_LATERAL) as f64),
    );
    let mut extra = 0;
    while step.0.max(step.1) > 1e-3 && extra < 400 {
        let FormationKind::Symmetric { forward_m: a, lateral_m: b } = best.candidate.formation else { break };
        let moves = [(step.0, 0.0), (-step.0, 0.0), (0.0, step.1), (0.0, -step.1)];
        let trials: Vec<Candidate> = moves
            .iter()
            .filter(|(da, db)| b + db > 0.0 && (a + da).abs() <= reach)
            .map(|(da, db)| Candidate {
                formation: FormationKind::Symmetric { forward_m: a + da, lateral_m: b + db },
                ..best.candidate
            })
            .collect();
        extra += trials.len();
        let better: Vec<Evaluated> = trials
            .par_iter()
            .filter_map(|c| problem.evaluate(c, &instrument, &objective))
            .filter(|e| e.cmp_by(&best, &objective).is_lt())
            .filter(|e| problem.violations(&e.dance, reach).is_empty())
            .collect();
        checked += trials.len();
        match better.into_iter().min_by(|x, y| x.cmp_by(y, &objective)) {
            Some(e) => best = e,
            None => step = (step.0 / 2.0, step.1 / 2.0),
        }
    }
    Ok(SearchResult { best: Some(best), predicted: predicted + extra, checked })
}
