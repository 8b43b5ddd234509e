//! Mission files, their validation and the `cps-survey` command line.
//!
//! A mission file (TOML) is read with spans kept ([`reader`]) and validated
//! into a typed, unit-converted [`Mission`]; every problem becomes a
//! [`Diagnostic`] with file:line:column. The CLI ([`cli`]) dispatches the
//! subcommands; [`predict`] renders covariance predictions; [`runner`] runs
//! a mission on the simulator.
#![warn(missing_docs)]

pub mod cli;
pub mod diagnostics;
pub mod mission;
pub mod predict;
pub mod reader;
pub mod register;
pub mod runner;

pub use diagnostics::{Diagnostic, Diagnostics};
pub use mission::{Mission, MissionError};
