//! The `cps-survey` command line: the subcommands ([`crate::commands`], one
//! file each with its arguments and its `run`) and the exit code.

use std::io::Write;

use clap::{Parser, Subcommand};

use crate::commands::{self, Outcome};

/// Survey buildings in 3D with a team of robots that position each other:
/// plan a route and predict its accuracy before anyone drives, run the
/// survey on the simulator or on real instruments, fuse the scans, and
/// review it in the Rerun viewer.
#[derive(Debug, Parser)]
#[command(name = "cps-survey", version)]
pub struct Cli {
    /// What to do.
    #[command(subcommand)]
    pub command: Command,
}

/// The subcommands.
#[derive(Debug, Subcommand)]
pub enum Command {
    /// Run a mission — on the simulator, or on real instruments over serial
    /// ports with `[backend] kind = "serial"`: the dance, a scan at every
    /// scan station, the fused cloud, the reports and mission.rrd.
    Run(commands::run::RunArgs),
    /// Predict the pose covariance after every dance cycle of a mission's
    /// plan, and adjust the planned network: every station's covariance,
    /// every planned reading's reliability (exit 1 when the plan misses the
    /// acceptance tolerances).
    Predict(commands::predict::PredictArgs),
    /// Check a mission's plan step by step (ranges, line of sight, tracking,
    /// clearance, slope, scan range), analyse its accuracy, and with
    /// --optimize search formation, stride, strategy and control_at (exit 1
    /// when the plan breaks a constraint or misses the acceptance
    /// tolerances).
    Plan(commands::plan::PlanArgs),
    /// Check a mission file and report every problem with file:line:column.
    Validate(commands::validate::ValidateArgs),
    /// Simulate a mission's positioning N times and compare the spread with
    /// the prediction — the filter's, and with control the adjusted
    /// network's at every station (exit 1 when a NEES is outside its
    /// interval).
    Montecarlo(commands::montecarlo::MontecarloArgs),
    /// Re-fuse a finished (or interrupted) run's scans from its journal into
    /// `RUN_DIR/fusion/<mode>/`, without re-running it.
    Fuse(commands::fuse::FuseArgs),
    /// Adjust a run's whole network from its journal (every station, child
    /// placement and control point from every reading): the global test,
    /// data snooping, reliability, misclosures; writes
    /// RUN_DIR/adjustment.txt (exit 1 when the model fails: the global test
    /// fails and data snooping does not find the cause).
    Adjust(commands::adjust::AdjustArgs),
    /// Export a finished (or interrupted) run from its journal and scans:
    /// --ros2-bag DIR writes it as a rosbag2 (MCAP) of standard ROS 2
    /// messages (tf, poses with covariance, point clouds, paths, markers).
    Export(commands::export::ExportArgs),
    /// Align one scan file to another with ICP.
    Register(commands::register::RegisterArgs),
    /// Register a set of your own scans into one frame (a 3DTK directory,
    /// a multi-scan E57, or scan files): poses, merged cloud, link table,
    /// match.rrd.
    Match(commands::match_set::MatchArgs),
    /// Serve a mission's instruments on pseudo-terminals (total station,
    /// tilt sensor, LMS-2xx, scan head, drives), answering from the
    /// simulated world; prints the [backend.serial] table with the ports and
    /// runs until stopped (Ctrl-C).
    Emulate(commands::emulate::EmulateArgs),
    /// Print the JSON Schema of a JSON document this tool writes (report,
    /// fusion, adjust, predict, plan, montecarlo, register, emulate), list
    /// them, or write them all with --out DIR.
    Schemas(commands::schemas::SchemasArgs),
}

/// The process exit code of a command's result: 0 success, 1 acceptance
/// failed, 2 error.
pub fn exit_code(result: &anyhow::Result<Outcome>) -> u8 {
    match result {
        Ok(Outcome::Success) => 0,
        Ok(Outcome::AcceptanceFailed) => 1,
        Err(_) => 2,
    }
}

/// Runs a parsed command, writing its report to `out`. Errors mean exit 2.
pub fn run(cli: Cli, out: &mut dyn Write) -> anyhow::Result<Outcome> {
    let outcome = match &cli.command {
        Command::Run(args) => commands::run::run(args, out),
        Command::Predict(args) => commands::predict::run(args, out),
        Command::Plan(args) => commands::plan::run(args, out),
        Command::Validate(args) => commands::validate::run(args, out),
        Command::Montecarlo(args) => commands::montecarlo::run(args, out),
        Command::Fuse(args) => commands::fuse::run(args, out),
        Command::Adjust(args) => commands::adjust::run(args, out),
        Command::Export(args) => commands::export::run(args, out),
        Command::Register(args) => commands::register::run(args, out),
        Command::Match(args) => commands::match_set::run(args, out),
        Command::Emulate(args) => commands::emulate::run(args, out),
        Command::Schemas(args) => commands::schemas::run(args, out),
    }?;
    out.flush()?;
    Ok(outcome)
}
