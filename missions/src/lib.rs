//! Mission files, the runner and the `cps-survey` command line.
//!
//! The rooms, in the order data flows through them:
//! - [`mission`]: a mission file (TOML, spans kept) → a validated,
//!   unit-converted [`Mission`]; every problem is a [`Diagnostic`] with
//!   file:line:column;
//! - [`planning`]: the mission → its plan ([`planning::Planned`]: scene,
//!   dance, steps, prediction), built once per command; its constraints,
//!   its analysis and search, and the optimized mission file;
//! - [`run`]: running a mission ([`run::runner`]) on the simulator or serial
//!   ports ([`run::backend`]), every command journaled so a killed run
//!   resumes ([`run::resume`]);
//! - [`journal`]: the typed, versioned `journal.jsonl` and the run
//!   directory's guards;
//! - [`products`]: what a run directory's readings make, at the end of a
//!   run and again by `fuse`, `adjust`, `export` — the run read back, the
//!   fusion of the scans, the run's output stage, the network adjustment,
//!   the reports;
//! - [`inspection`]: the `[pipe]` inspection of a fused cloud;
//! - [`output`]: the one output stage of every merged cloud (its origin,
//!   its files, each scan's part);
//! - [`scans`]: a user's own scans outside a mission (files, 3DTK
//!   directories, multi-scan E57) with their start poses, for `register`
//!   and `match`;
//! - [`documents`]: every JSON document the CLI writes, typed and
//!   versioned, with the records they share (imports nothing of the
//!   crate);
//! - [`view`]: what the user sees — terminal tables, JSON documents, plots
//!   and the Rerun recording (never imports `run`);
//! - [`commands`]: one file per subcommand, [`cli`] the command line.
#![warn(missing_docs)]

pub mod cli;
pub mod commands;
pub mod documents;
pub mod inspection;
pub mod journal;
pub mod mission;
pub mod output;
pub mod planning;
pub mod products;
pub mod ros2;
pub mod run;
pub mod scans;
pub mod view;

pub use mission::diagnostics::{Diagnostic, Diagnostics};
pub use mission::{Mission, MissionError};
