//! Route → dance → predicted accuracy.
//!
//! A route (a polyline of parent waypoints) becomes [`Station`]s every stride
//! ([`stations`]); a formation turns them into a leapfrog [`Dance`]
//! ([`leapfrog`]); [`predict`] runs the CPS equations on the dance's nominal
//! readings and returns the covariance after every cycle ([`Prediction`]);
//! [`montecarlo`] executes the dance with noisy readings to check it.
#![warn(missing_docs)]

pub mod analysis;
pub mod constraints;
pub mod control;
pub mod dance;
pub mod error;
pub mod montecarlo;
pub mod network;
pub mod predict;
pub mod route;
pub mod search;

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
