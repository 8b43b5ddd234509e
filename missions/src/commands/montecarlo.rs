//! `cps-survey montecarlo`: seeded simulated executions of a mission's
//! positioning (no scanning) against the prediction — per station the
//! empirical and predicted horizontal variance, their ratio and the mean
//! NEES with its 95 % χ² interval.

use std::io::Write;
use std::path::PathBuf;

use anyhow::Result;

use super::Outcome;
use crate::mission::Mission;
use crate::planning::Planned;
use crate::planning::montecarlo::simulate;

/// `montecarlo`'s arguments.
#[derive(Debug, Clone, clap::Args)]
pub struct MontecarloArgs {
    /// The mission file (TOML).
    pub mission: PathBuf,
    /// Number of seeded trials (2 to 100,000).
    #[arg(long, default_value_t = 1000)]
    pub trials: usize,
    /// Print one JSON object instead of the table.
    #[arg(long)]
    pub json: bool,
}

/// Runs `montecarlo`: exit 1 when the final NEES is outside its interval.
pub fn run(args: &MontecarloArgs, out: &mut dyn Write) -> Result<Outcome> {
    let mission = Mission::load(&args.mission)?;
    let planned = Planned::new(&mission)?;
    let mc = simulate(&mission, &planned, args.trials)?;
    if args.json {
        crate::view::json::montecarlo(out, &mission, &mc)?;
    } else {
        crate::view::tables::montecarlo(out, &mission, &mc)?;
    }
    Ok(Outcome::passed(mc.consistent()))
}
