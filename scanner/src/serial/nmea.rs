//! A tilt sensor streaming NMEA XDR lines ([`crate::protocol::nmea`]).
//!
//! A reading is the first valid sentence that arrives after it is asked
//! for (input buffered before is dropped, and the partial line after the
//! drop with it), so it is never older than the request. Lines with a bad
//! checksum or grammar are counted and skipped; when no valid sentence
//! arrives within `stale_periods` periods (plus one for the line dropped
//! after the flush) the reading fails with [`ScannerError::Stale`].

use std::time::{Duration, Instant};

use super::Port;
use crate::devices::{Tilt, TiltSensor};
use crate::error::{Result, ScannerError};
use crate::protocol::nmea::{MAX_LINE, parse_xdr};
use crate::protocol::{Line, LineSplitter};

/// A streaming XDR tilt sensor.
#[derive(Debug)]
pub struct NmeaTilt {
    port: Port,
    period: Duration,
    stale_periods: f64,
    lines: LineSplitter,
    /// Sentences skipped as corrupt or malformed.
    pub rejected: usize,
}

impl NmeaTilt {
    /// A driver for a sensor that sends a sentence every `period`; a reading
    /// fails after `stale_periods` periods without a valid one (the
    /// specification's default is 3).
    pub fn new(port: Port, period: Duration, stale_periods: f64) -> Self {
        Self { port, period, stale_periods, lines: LineSplitter::new(MAX_LINE, true), rejected: 0 }
    }

    /// Opens `path` at `baud`.
    pub fn open(path: &str, baud: u32, period: Duration) -> Result<Self> {
        Ok(Self::new(Port::open("tilt sensor", path, baud)?, period, 3.0))
    }
}

impl TiltSensor for NmeaTilt {
    fn name(&self) -> &str {
        self.port.device()
    }

    fn read(&mut self) -> Result<Tilt> {
        self.port.clear_input()?;
        self.lines.restart();
        let started = Instant::now();
        let deadline = started + self.period.mul_f64(self.stale_periods.max(1.0) + 1.0);
        loop {
            let bytes = self.port.read_before(deadline)?;
            if bytes.is_empty() {
                return Err(ScannerError::Stale {
                    device: self.port.device().into(),
                    age_s: started.elapsed().as_secs_f64(),
                    period_s: self.period.as_secs_f64(),
                });
            }
            for line in self.lines.push(&bytes) {
                match line {
                    Line::Text(text) => match parse_xdr(&text) {
                        Ok(t) => return Ok(t.tilt()),
                        Err(_) => self.rejected += 1,
                    },
                    Line::Dropped(_) => self.rejected += 1,
                }
            }
        }
    }
}
