//! Running a mission: the dance step by step on a backend, journaled and
//! resumable; at its end the products ([`crate::products`]).
//!
//! - [`runner`]: the dance itself, a short loop of named steps;
//! - [`dispatch`]: every device command replayed or given, retried, journaled;
//! - [`observer`]: the recording, the progress bars and the timings, one
//!   call per event of the dance;
//! - [`backend`]: the team the mission commands — the simulator or the
//!   instruments on serial ports;
//! - [`resume`]: a run directory opened for a new run or a resume;
//! - [`text`]: what `run` prints.

pub mod backend;
pub mod dispatch;
pub mod observer;
pub mod resume;
pub mod runner;
pub mod text;
