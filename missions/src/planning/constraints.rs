//! A plan checked step by step against the scene and the instruments
//! (`planner::check`): the limits a mission sets, every violation, and the
//! refusal `run` and `validate` give a plan that breaks one.

use planner::{Limits, Violation};

use super::Planned;
use crate::mission::diagnostics::Diagnostics;
use crate::mission::{Mission, MissionError};

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

/// Every constraint the plan breaks, in schedule order.
pub fn violations(mission: &Mission, planned: &Planned) -> Vec<Violation> {
    planner::check_steps(&planned.dance, &planned.steps, planned.checked_scene(), &limits(mission))
}

/// Refuses a plan that breaks a constraint against the scene: `run` and
/// `validate` call this, pointing at `[plan]` with each violation's step.
pub fn refuse_violations(mission: &Mission, planned: &Planned) -> Result<(), MissionError> {
    let v = violations(mission, planned);
    if v.is_empty() {
        return Ok(());
    }
    let name = |r| mission.robot_name(r);
    let shown = 10;
    let mut problems: Vec<_> =
        v.iter().take(shown).map(|v| mission.diagnostic(&mission.spans.plan, "plan", v.describe(&name))).collect();
    if v.len() > shown {
        let message = format!("… and {} more violation(s); `cps-survey plan` lists them all", v.len() - shown);
        problems.push(mission.diagnostic(&mission.spans.plan, "plan", message));
    }
    Err(MissionError::invalid(mission, Diagnostics(problems)))
}
