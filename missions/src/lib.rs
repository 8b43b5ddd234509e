//! Mission files, their validation and the `cps-survey` command line.
//!
//! A mission file (TOML) is read with spans kept ([`reader`]) and validated
//! into a typed, unit-converted [`Mission`]; every problem becomes a
//! [`Diagnostic`] with file:line:column. The CLI ([`cli`]) dispatches the
//! subcommands; [`predict`] renders covariance predictions; [`runner`] runs
//! a mission on the simulator ([`backend`]) with a [`journal`] and a Rerun
//! [`recording`].
#![warn(missing_docs)]

pub mod backend;
pub mod cli;
pub mod diagnostics;
pub mod emulate;
pub mod fuse;
pub mod journal;
pub mod mission;
pub mod montecarlo;
pub mod pipe;
pub mod plan;
pub mod plot;
pub mod predict;
pub mod reader;
pub mod recording;
pub mod register;
pub mod runner;

pub use diagnostics::{Diagnostic, Diagnostics};
pub use mission::{Mission, MissionError};
