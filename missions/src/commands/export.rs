//! `cps-survey export RUN_DIR --ros2-bag DIR`: a finished or interrupted
//! run, from its journal and scans, as a rosbag2 of standard ROS 2
//! messages ([`crate::ros2::export`]).

use std::io::Write;
use std::path::PathBuf;

use anyhow::Result;

use super::Outcome;

/// `export`'s arguments.
#[derive(Debug, Clone, clap::Args)]
pub struct ExportArgs {
    /// The run directory (holds mission.toml, journal.jsonl and scans/).
    pub run_dir: PathBuf,
    /// Write the run as a rosbag2 directory (metadata.yaml and one .mcap of
    /// standard messages) into DIR, which must not exist.
    #[arg(long = "ros2-bag", value_name = "DIR")]
    pub ros2_bag: PathBuf,
}

/// Runs `export`.
pub fn run(args: &ExportArgs, out: &mut dyn Write) -> Result<Outcome> {
    let dir = &args.run_dir;
    let _lock = crate::journal::directory::guard(dir, &format!("export {}", dir.display()))?;
    let run = crate::products::load::load(dir)?;
    let bag = crate::ros2::export::write(&run, dir, &args.ros2_bag)?;
    writeln!(out, "rosbag2 written to {}:", bag.dir.display())?;
    for (topic, count) in &bag.topics {
        writeln!(out, "  {topic:<24} {count:>6} message(s)")?;
    }
    Ok(Outcome::Success)
}
