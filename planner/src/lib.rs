//! Route → dance → predicted accuracy, and the search for the plan.
//!
//! - [`route`]: a route (a polyline of parent waypoints) becomes
//!   [`Station`]s every stride ([`stations`]).
//! - [`dance`]: a formation turns the stations into a leapfrog [`Dance`]
//!   ([`leapfrog`], [`schedule`] for the other strategies, [`solo`] for a
//!   robot alone), spelled out as the runner's [`Step`]s, and executed on
//!   given readings ([`run_dance`]).
//! - [`control`]: control points and the stations asked to sight them;
//!   [`sighting`]: which station sees which, within the instrument's usable
//!   [`range`] and in line of sight.
//! - [`predict`](mod@predict): the CPS equations on the dance's nominal readings, the
//!   covariance after every cycle ([`Prediction`]); [`network`]: the whole
//!   dance as one adjustment's pre-analysis (reliability, MDB);
//!   [`analysis`]: per-cycle figures from them; [`montecarlo`]: the dance
//!   executed with noisy readings to check the prediction.
//! - [`constraints`]: the limits a plan must keep (ranges, distances,
//!   speeds); [`search`](mod@search): formations and strides searched for the best
//!   predicted accuracy within them.
//! - [`error`]: what a plan can get wrong, naming the cycle and the robot.
#![warn(missing_docs)]

pub mod analysis;
pub mod constraints;
pub mod control;
pub mod dance;
pub mod error;
pub mod montecarlo;
pub mod network;
pub mod predict;
pub mod range;
pub mod route;
pub mod search;
pub mod sighting;

pub use constraints::{Check, Limits, Violation, check, check_steps};
pub use control::ControlPoint;
pub use dance::{
    Action, Dance, DanceCycle, Formation, FormationKind, Robot, STRATEGIES, Sighted, Step, Strategy, leapfrog,
    nominal_reading, run_dance, schedule, solo,
};
pub use error::{Phase, PlanError};
pub use predict::{
    CyclePrediction, OdometryNoise, Prediction, StepEstimate, predict, predict_odometry, step_estimates,
};
pub use route::{Station, stations};
pub use search::{Candidate, Objective, Problem, SearchResult, SearchSpace, search};
