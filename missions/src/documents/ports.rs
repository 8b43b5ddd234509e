//! `emulate --json`: the emulated instruments' ports.

use serde::Serialize;

use super::Document;

/// `emulate --json`: the ports.
#[derive(Debug, Serialize, schemars::JsonSchema)]
pub struct PortsJson {
    /// `[mission] name`.
    pub mission: String,
    /// The simulated world's seed.
    pub seed: u64,
    /// Every instrument served.
    pub instruments: Vec<InstrumentJson>,
    /// The `[backend.serial]` table with these ports (TOML).
    pub backend_serial: String,
}

/// One served instrument.
#[derive(Debug, Serialize, schemars::JsonSchema)]
pub struct InstrumentJson {
    /// `total-station`, `tilt`, `scanner`, `head`, `parent` or a child's name.
    pub role: String,
    /// The pseudo-terminal.
    pub path: String,
    /// Its baud rate.
    pub baud: u32,
    /// The protocol spoken.
    pub protocol: &'static str,
}

impl Document for PortsJson {
    const NAME: &'static str = "emulate";
    const VERSION: u32 = 1;
}
