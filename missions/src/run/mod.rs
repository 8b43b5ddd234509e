//! Running a mission: the dance step by step on a backend, journaled and
//! resumable, then the scans fused and the outputs written.
//!
//! - [`runner`]: the dance itself, a short loop of named steps;
//! - [`dispatch`]: every device command replayed or given, retried, journaled;
//! - [`observer`]: the recording, the progress bars and the timings, one
//!   call per event of the dance;
//! - [`backend`]: the simulator or the instruments on serial ports;
//! - [`journal`]: the typed, versioned `journal.jsonl`;
//! - [`directory`]: the run directory's lock and its refusal of symbolic
//!   links;
//! - [`resume`]: a run directory opened for a new run or a resume, and read
//!   back by `fuse`;
//! - [`fuse`]: the scans fused by `[fusion] mode`;
//! - [`outputs`]: the one output stage of `run` and `fuse`;
//! - [`report`]: `report.json`, `fusion.json`, `stations.csv`;
//! - [`adjust`]: the network adjustment of the journal's readings;
//! - [`text`]: what `run` and `fuse` print.

pub mod adjust;
pub mod backend;
pub mod directory;
pub mod dispatch;
pub mod fuse;
pub mod journal;
pub mod observer;
pub mod outputs;
pub mod report;
pub mod resume;
pub mod runner;
pub mod text;
