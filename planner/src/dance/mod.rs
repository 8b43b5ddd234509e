//! Dance schedules.
//!
//! - **Leapfrog** (seed 003 Fig. 1): at station k each child moves to
//!   `station_k + R(heading_k)·formation_m[j]` and is measured from the
//!   standing parent; then the parent moves to station k+1 and fixes itself
//!   from all children.
//! - **Parent hops** (seed 003 §3.2): the children are placed as in leapfrog
//!   at stations 0, h, 2h, …; in between, the parent makes h moves and fixes
//!   itself after each from the same standing children.
//!
//! A [`Dance`] is a list of [`DanceCycle`]s (one parent move and fix each);
//! [`Dance::steps`] spells it out as the list of actions the runner executes.
//!
//! `schedule`: the dance scheduled from the stations and the
//! formation (its cycles, control sightings, range checks); `steps`: the
//! actions the runner executes; `execution`: the dance run through a team
//! state on given readings (prediction, Monte Carlo).

mod execution;
mod schedule;
mod steps;

pub use execution::{Sighted, nominal_reading, run_dance};
pub use schedule::{Dance, DanceCycle, Formation, FormationKind, STRATEGIES, Strategy, leapfrog, schedule, solo};
pub use steps::{Action, Robot, Step};
