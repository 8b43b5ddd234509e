//! `cps-survey run MISSION`: the mission end to end on the simulator or on
//! serial ports — see [`crate::run::runner`].

use std::io::Write;
use std::path::PathBuf;

use anyhow::{Context, Result};

use super::Outcome;
use crate::mission::Mission;
use crate::planning::Planned;
use crate::run::backend::Fault;
use crate::run::runner::RunOptions;
use crate::view::recording::Viewer;

/// `run`'s arguments.
#[derive(Debug, Clone, clap::Args)]
pub struct RunArgs {
    /// The mission file (TOML).
    pub mission: PathBuf,
    /// The run directory (default `runs/<mission name>/`).
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// The simulator's seed, overriding the mission's `[backend] seed`.
    #[arg(long, value_name = "N")]
    pub seed: Option<u64>,
    /// No progress bars.
    #[arg(long)]
    pub quiet: bool,
    /// Continue the interrupted run in the --out directory from its journal.
    #[arg(long)]
    pub resume: bool,
    /// Also stream the recording to a newly started Rerun viewer (bound to
    /// 127.0.0.1).
    #[arg(long, conflicts_with = "connect")]
    pub spawn: bool,
    /// Also stream the recording to a running Rerun viewer.
    #[arg(long, value_name = "URL", num_args = 0..=1,
          default_missing_value = "rerun+http://127.0.0.1:9876/proxy")]
    pub connect: Option<String>,
    /// Log every ICP iteration of the fusion (modes icp and cps-icp) to the
    /// recording, on its own timeline `icp_iteration`.
    #[arg(long)]
    pub log_icp_iterations: bool,
    /// Inject a fault into a simulated device: DEVICE:after=N (stops
    /// answering after N commands) or DEVICE:every=K (every K-th command
    /// fails), DEVICE drive, total-station, tilt or scanner; or a blunder:
    /// total-station:blunder=N:METRES adds METRES to the N-th distance
    /// measured, total-station:blunder-angle=N:ARCSEC to the N-th
    /// horizontal angle (counting from 1, children and control alike).
    /// Repeatable.
    #[arg(long, value_name = "FAULT")]
    pub sim_fault: Vec<Fault>,
    /// Abort the process after writing N journal events (crash test).
    #[arg(long, value_name = "N", hide = true)]
    pub abort_after_events: Option<usize>,
}

/// Runs `run`: exit 1 when `[acceptance]` fails, 2 when a device fails
/// beyond its retries (the message says how to resume).
pub fn run(args: &RunArgs, out: &mut dyn Write) -> Result<Outcome> {
    if args.spawn || args.connect.is_some() || args.log_icp_iterations {
        crate::view::recording::available()?;
    }
    let mut mission = Mission::load(&args.mission)?;
    let dir = args.out.clone().unwrap_or_else(|| PathBuf::from("runs").join(&mission.name));
    match (args.seed, args.resume) {
        (Some(seed), _) => mission.backend.seed = seed,
        // A resumed run goes on with the seed it started with.
        (None, true) => {
            let journal = dir.join("journal.jsonl");
            if journal.exists() {
                mission.backend.seed = crate::journal::read(&journal)?.start(&journal)?.seed;
            }
        }
        (None, false) => {}
    }
    let planned = Planned::new(&mission)?;
    let viewer = match (args.spawn, &args.connect) {
        (true, _) => Viewer::Spawn,
        (false, Some(url)) => Viewer::Connect(url.clone()),
        (false, None) => Viewer::None,
    };
    let options = RunOptions {
        quiet: args.quiet,
        resume: args.resume,
        faults: args.sim_fault.clone(),
        abort_after_events: args.abort_after_events,
        viewer,
        log_icp_iterations: args.log_icp_iterations,
    };
    let mut summary = crate::run::runner::run(&mission, &planned, &dir, &options)?;
    if mission.output.ros2_bag {
        // From the finished journal and scans, as `export` writes it.
        let run = crate::products::load::load(&summary.dir)?;
        crate::ros2::export::write(&run, &summary.dir, &summary.dir.join("rosbag2")).context(
            "writing rosbag2/ ([output] ros2_bag); `cps-survey export RUN_DIR --ros2-bag DIR` writes it again",
        )?;
        summary.files.push("rosbag2/".into());
    }
    crate::run::text::run_summary(out, &mission, &summary)?;
    Ok(Outcome::passed(summary.accepted))
}
