//! A two-axis tilt sensor streaming NMEA XDR lines
//! ([`crate::protocol::nmea`]) from the simulated tilt sensor, at a fixed
//! rate. Corruption faults spoil a line's checksum; "stop answering" stops
//! the stream (the driver then reports stale data).

use std::time::{Duration, Instant};

use super::{Device, FaultState};
use crate::devices::TiltSensor;
use crate::protocol::nmea::format_tilt;
use crate::sim::SimTilt;

/// The emulated sensor.
#[derive(Debug)]
pub struct NmeaTiltEmulator {
    sensor: SimTilt,
    baud: u32,
    period: Duration,
    next: Option<Instant>,
}

impl NmeaTiltEmulator {
    /// A sensor reading `sensor` every `1 / rate_hz` seconds at `baud`.
    pub fn new(sensor: SimTilt, rate_hz: f64, baud: u32) -> Self {
        let period = Duration::from_secs_f64(1.0 / rate_hz.clamp(0.1, 1000.0));
        Self { sensor, baud, period, next: None }
    }
}

impl Device for NmeaTiltEmulator {
    fn name(&self) -> &str {
        "NMEA tilt sensor"
    }

    fn baud(&self) -> u32 {
        self.baud
    }

    /// The sensor only streams; input is ignored.
    fn input(&mut self, _bytes: &[u8], _faults: &mut FaultState) -> Vec<Vec<u8>> {
        Vec::new()
    }

    fn tick(&mut self, now: Instant, faults: &mut FaultState) -> Vec<Vec<u8>> {
        let due = *self.next.get_or_insert(now);
        if now < due {
            return Vec::new();
        }
        self.next = Some(due.max(now - self.period) + self.period);
        let Ok(tilt) = self.sensor.read() else { return Vec::new() };
        let mut line = format_tilt("II", &tilt);
        if faults.corrupt_now() {
            super::spoil_nmea_checksum(&mut line);
        }
        vec![line.into_bytes()]
    }
}
