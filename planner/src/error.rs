//! The one error type of the `planner` crate.

use thiserror::Error;

/// When in a cycle a sight line is taken.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Phase {
    /// The standing parent measures the child that has just moved.
    Placement,
    /// The parent, at its next station, measures the standing child.
    Fix,
}

impl std::fmt::Display for Phase {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Phase::Placement => "while being placed from the standing parent",
            Phase::Fix => "during the parent's fix at its next station",
        })
    }
}

/// Everything that makes a plan impossible.
#[derive(Debug, Clone, PartialEq, Error)]
#[non_exhaustive]
pub enum PlanError {
    /// A route needs at least two waypoints.
    #[error("route_m has {got} waypoint(s); expected at least 2")]
    RouteTooShort {
        /// Waypoints given.
        got: usize,
    },
    /// Two consecutive waypoints coincide.
    #[error("route_m[{waypoint}] repeats the previous waypoint; expected a segment of non-zero length")]
    ZeroLengthSegment {
        /// Index of the second waypoint of the segment.
        waypoint: usize,
    },
    /// A segment that only rises or falls: robots drive on the ground.
    #[error(
        "the route's segment to waypoint {waypoint} is vertical (it rises {rise_m} m in place); expected a segment the robots can drive along"
    )]
    VerticalSegment {
        /// Index of the second waypoint of the segment.
        waypoint: usize,
        /// Its rise, metres.
        rise_m: f64,
    },
    /// More stations than a plan may have.
    #[error(
        "the route and stride give {} stations; expected at most {limit} (a longer stride, or a shorter route)",
        station_count(*count)
    )]
    TooManyStations {
        /// Stations the route and stride would give.
        count: f64,
        /// The limit.
        limit: usize,
    },
    /// The stride must be a positive, finite length.
    #[error("stride_m = {value}; expected a finite value > 0")]
    BadStride {
        /// The stride given.
        value: f64,
    },
    /// Parent hops need at least one move per placement.
    #[error("hops = {value}; expected an integer ≥ 1")]
    BadHops {
        /// The value given.
        value: usize,
    },
    /// The search needs a positive, finite longest sight line.
    #[error("max_sight_line_m = {value}; expected a finite value > 0 (and a total station range > 0)")]
    BadSightLine {
        /// The value given.
        value: f64,
    },
    /// A formation needs one offset per child.
    #[error("formation_m has {got} offsets but the team has {expected} children")]
    FormationSize {
        /// Offsets given.
        got: usize,
        /// Children in the team.
        expected: usize,
    },
    /// A team needs at least two children for a parent fix.
    #[error("the team has {got} child(ren); a parent fix needs at least 2")]
    TooFewChildren {
        /// Children in the team.
        got: usize,
    },
    /// A sight line is outside the total station's range, or closer to a
    /// limit than [`crate::range::RANGE_MARGIN_M`].
    #[error(
        "cycle {cycle}: child {child} is {range_m:.3} m from the parent {phase}; \
         expected between min_range_m = {min_m} m and max_range_m = {max_m} m, at least \
         {margin} m inside (a drive errs by centimetres: a prism planned on a limit lands outside it)",
        margin = crate::range::RANGE_MARGIN_M
    )]
    ChildOutOfRange {
        /// Dance cycle (1-based).
        cycle: usize,
        /// Child index (team order).
        child: usize,
        /// When the sight line is taken.
        phase: Phase,
        /// Slope distance of the sight line.
        range_m: f64,
        /// Instrument minimum range.
        min_m: f64,
        /// Instrument maximum range.
        max_m: f64,
    },
    /// The CPS model rejected a step (degenerate geometry and the like).
    #[error("cycle {cycle}: {source}")]
    Model {
        /// Dance cycle (1-based, 0 for the start).
        cycle: usize,
        /// The model's error.
        #[source]
        source: cps::CpsError,
    },
}

/// A station count as a person reads it: whole up to a trillion, then in
/// scientific notation (a stride of 1e-300 m gave 230 digits).
fn station_count(count: f64) -> String {
    if count.is_finite() && count < 1e12 { format!("{count:.0}") } else { format!("{count:.3e}") }
}
