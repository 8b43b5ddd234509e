//! `cps-survey validate MISSION`: every problem of a mission file with
//! file:line:column, and its plan's constraints (as `plan` checks them).

use std::io::Write;
use std::path::PathBuf;

use anyhow::Result;

use super::Outcome;
use crate::mission::Mission;
use crate::planning::Planned;

/// `validate`'s arguments.
#[derive(Debug, Clone, clap::Args)]
pub struct ValidateArgs {
    /// The mission file (TOML).
    pub mission: PathBuf,
}

/// Runs `validate`.
pub fn run(args: &ValidateArgs, out: &mut dyn Write) -> Result<Outcome> {
    let mission = Mission::load(&args.mission)?;
    let planned = Planned::new(&mission)?;
    crate::planning::constraints::refuse_violations(&mission, &planned)?;
    writeln!(
        out,
        "{}: ok (mission \"{}\", {} children, {} stations)",
        args.mission.display(),
        mission.name,
        mission.children.len(),
        planned.stations()
    )?;
    Ok(Outcome::Success)
}
