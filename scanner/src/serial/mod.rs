//! Drivers for the real instruments over serial ports, behind the same
//! traits as the simulated devices: [`geocom::GeoCom`] (a Leica total
//! station, [`crate::TotalStation`]) and [`nmea::NmeaTilt`] (an XDR tilt
//! sensor, [`crate::TiltSensor`]).
//!
//! Every read has a deadline: a [`Port`] read returns what arrived before
//! the deadline (serial reads are partial and time out instead of
//! returning nothing), and each driver turns a missed deadline into
//! retries and at last a typed [`ScannerError`]. No driver relies on the
//! DTR/RTS modem lines (ptys and many adapters do not have them).

pub mod geocom;
pub mod nmea;
pub mod robot;
pub mod sick;

use std::io::{Read, Write};
use std::time::{Duration, Instant};

use serialport::SerialPort;

use crate::error::{Result, ScannerError};

/// The longest single blocking read; deadlines are checked between reads.
pub const POLL: Duration = Duration::from_millis(20);

/// A serial port with deadline reads, named for messages.
pub struct Port {
    port: Box<dyn SerialPort>,
    device: String,
}

impl std::fmt::Debug for Port {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Port").field("device", &self.device).finish_non_exhaustive()
    }
}

impl Port {
    /// Opens `path` at `baud` (8N1, no flow control) for the device `kind`
    /// (e.g. "total station"); the port's name in messages is
    /// `kind on path`.
    pub fn open(kind: &str, path: &str, baud: u32) -> Result<Self> {
        let device = format!("{kind} on {path}");
        let port = serialport::new(path, baud).timeout(POLL).open().map_err(|e| ScannerError::Device {
            device: device.clone(),
            message: format!("cannot open the port at {baud} Bd: {e}"),
        })?;
        Ok(Self { port, device })
    }

    /// Wraps an open port.
    pub fn from_port(device: impl Into<String>, port: Box<dyn SerialPort>) -> Self {
        Self { port, device: device.into() }
    }

    /// The device's name for messages.
    pub fn device(&self) -> &str {
        &self.device
    }

    fn error(&self, what: &str, e: impl std::fmt::Display) -> ScannerError {
        ScannerError::Device { device: self.device.clone(), message: format!("{what}: {e}") }
    }

    /// Writes all of `bytes` and flushes.
    pub fn write(&mut self, bytes: &[u8]) -> Result<()> {
        self.port.write_all(bytes).map_err(|e| self.error("writing", e))?;
        self.port.flush().map_err(|e| self.error("flushing", e))
    }

    /// The bytes that arrive before `deadline`: returns as soon as some
    /// have arrived, or empty at the deadline.
    pub fn read_before(&mut self, deadline: Instant) -> Result<Vec<u8>> {
        let mut buf = [0_u8; 1024];
        loop {
            let now = Instant::now();
            if now >= deadline {
                return Ok(Vec::new());
            }
            self.port.set_timeout((deadline - now).min(POLL)).map_err(|e| self.error("setting the timeout", e))?;
            match self.port.read(&mut buf) {
                Ok(n) if n > 0 => return Ok(buf[..n].to_vec()),
                Ok(_) => {}
                Err(e) if matches!(e.kind(), std::io::ErrorKind::TimedOut | std::io::ErrorKind::Interrupted) => {}
                Err(e) => return Err(self.error("reading", e)),
            }
        }
    }

    /// Switches the port's baud rate.
    pub fn set_baud(&mut self, baud: u32) -> Result<()> {
        self.port.set_baud_rate(baud).map_err(|e| self.error(&format!("setting {baud} Bd"), e))
    }

    /// The port's baud rate.
    pub fn baud(&self) -> Result<u32> {
        self.port.baud_rate().map_err(|e| self.error("reading the baud rate", e))
    }

    /// Drops whatever has been received and not read.
    pub fn clear_input(&mut self) -> Result<()> {
        self.port.clear(serialport::ClearBuffer::Input).map_err(|e| self.error("clearing the input", e))
    }
}
