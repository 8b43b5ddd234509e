//! The team a mission runs on: one [`Team`] over `scanner`'s device traits
//! ([`team`]), made by a backend — the simulator ([`sim`]) or the real
//! instruments on serial ports ([`serial`]); [`faults`] names the devices
//! and injects faults into a simulated team. Another backend (a replay of a
//! journal, a robot middleware bridge) is one more file that makes a
//! [`Team`] from its devices.

pub mod faults;
pub mod serial;
pub mod sim;
pub mod team;

use anyhow::{Result, bail};
use planner::Dance;

pub use faults::{DeviceKind, Fault, FaultRule};
pub use team::{Team, truth_record};

use crate::mission::Mission;

/// The mission's backend, standing where `dance` starts; `faults` are for
/// the simulator only.
pub fn open(mission: &Mission, dance: &Dance, faults: Vec<Fault>) -> Result<Team> {
    match &mission.backend.serial {
        None => sim::team(mission, dance, faults),
        Some(_) if !faults.is_empty() => {
            bail!("--sim-fault injects faults into the simulator; this mission runs on serial ports")
        }
        Some(ports) => serial::team(mission, dance, ports),
    }
}
