//! Emulators: the real instruments' protocols spoken on pseudo-terminals,
//! answering from the simulated world, so that the serial drivers (and
//! independent clients such as `geocompy` or `pynmea2`) can be run against
//! them. [`Emulator::spawn`] starts one on its own thread; its
//! [`Emulator::path`] is the port to open. Faults can be injected while it
//! runs ([`Faults`]).
//!
//! The emulator holds the pty's slave end open itself, so a driver can
//! close and reopen the port; it learns the driver's baud rate from the
//! pty (the line settings are shared) and ignores input while the rates
//! differ, like a real device.

pub mod geocom;
pub mod nmea;
pub mod robot;
pub mod sick;

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use serialport::{SerialPort, TTYPort};

use crate::error::{Result, ScannerError};

/// Faults an emulator injects into its output (counts are per emulator).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Faults {
    /// Drop every n-th byte written.
    pub drop_every: Option<usize>,
    /// Write every n-th byte twice.
    pub duplicate_every: Option<usize>,
    /// Corrupt the checksum (or CRC) of every n-th message.
    pub corrupt_every: Option<usize>,
    /// Answer every n-th request with a NAK (SICK) or a COM checksum error
    /// (GeoCOM) instead of processing it.
    pub nak_every: Option<usize>,
    /// Wait this long before each answer.
    pub delay: Duration,
    /// Stop answering after this many messages.
    pub stop_after: Option<usize>,
    /// Run the line at this baud rate instead of the configured one (so a
    /// driver at the configured rate is not understood).
    pub baud: Option<u32>,
}

/// What a device model does with input and time.
pub trait Device: Send {
    /// The device's name for messages.
    fn name(&self) -> &str;
    /// Its line's baud rate.
    fn baud(&self) -> u32;
    /// Takes received bytes; returns the messages to send in answer. The
    /// device asks `faults` for each message ([`FaultState::corrupt_now`],
    /// which also counts it) and each request ([`FaultState::nak_now`]).
    fn input(&mut self, bytes: &[u8], faults: &mut FaultState) -> Vec<Vec<u8>>;
    /// Unsolicited output due by `now` (a streaming sensor).
    fn tick(&mut self, _now: Instant, _faults: &mut FaultState) -> Vec<Vec<u8>> {
        Vec::new()
    }
}

/// The faults and the counters that schedule them.
#[derive(Debug, Default)]
pub struct FaultState {
    /// The faults asked for.
    pub faults: Faults,
    /// Messages sent so far.
    pub messages: usize,
    /// Requests received so far.
    pub requests: usize,
    /// Bytes written so far.
    pub bytes: usize,
}

impl FaultState {
    /// Counts a request; true when it is to be answered with a NAK.
    pub fn nak_now(&mut self) -> bool {
        self.requests += 1;
        self.faults.nak_every.is_some_and(|k| k > 0 && self.requests.is_multiple_of(k))
    }

    /// Counts a message; true when its checksum is to be corrupted.
    pub fn corrupt_now(&mut self) -> bool {
        self.messages += 1;
        self.faults.corrupt_every.is_some_and(|k| k > 0 && self.messages.is_multiple_of(k))
    }

    /// True once the device is to stop answering: the message just counted
    /// is beyond `stop_after`.
    pub fn stopped(&self) -> bool {
        self.faults.stop_after.is_some_and(|n| self.messages > n)
    }

    /// The bytes as they go on the wire, with dropped and duplicated ones.
    fn on_wire(&mut self, message: &[u8]) -> Vec<u8> {
        let mut out = Vec::with_capacity(message.len() + 4);
        for &b in message {
            self.bytes += 1;
            let k = self.bytes;
            if self.faults.drop_every.is_some_and(|d| d > 0 && k.is_multiple_of(d)) {
                continue;
            }
            out.push(b);
            if self.faults.duplicate_every.is_some_and(|d| d > 0 && k.is_multiple_of(d)) {
                out.push(b);
            }
        }
        out
    }
}

/// Spoils an NMEA-framed line's checksum (`…*hh`, CR LF optional): flips
/// its last hex digit between 0 and 1.
pub(crate) fn spoil_nmea_checksum(line: &mut String) {
    let Some(star) = line.rfind('*') else { return };
    if let Some(&digit) = line.as_bytes().get(star + 2) {
        line.replace_range(star + 2..star + 3, if digit == b'0' { "1" } else { "0" });
    }
}

/// A running emulator.
#[derive(Debug)]
pub struct Emulator {
    path: String,
    name: String,
    faults: Arc<Mutex<FaultState>>,
    stop: Arc<AtomicBool>,
    thread: Option<std::thread::JoinHandle<Result<()>>>,
    _slave: TTYPort,
}

fn lock(f: &Mutex<FaultState>) -> std::sync::MutexGuard<'_, FaultState> {
    f.lock().unwrap_or_else(std::sync::PoisonError::into_inner)
}

impl Emulator {
    /// Starts `device` on a new pseudo-terminal.
    pub fn spawn(device: impl Device + 'static) -> Result<Self> {
        let name = device.name().to_string();
        let err = |what: &str, e: serialport::Error| ScannerError::Device {
            device: format!("{name} emulator"),
            message: format!("{what}: {e}"),
        };
        let (mut master, mut slave) = TTYPort::pair().map_err(|e| err("creating a pseudo-terminal", e))?;
        let path = slave.name().ok_or_else(|| ScannerError::Device {
            device: format!("{name} emulator"),
            message: "the pseudo-terminal has no path".into(),
        })?;
        slave.set_baud_rate(device.baud()).map_err(|e| err("setting the baud rate", e))?;
        master.set_timeout(Duration::from_millis(5)).map_err(|e| err("setting the timeout", e))?;
        let faults = Arc::new(Mutex::new(FaultState::default()));
        let stop = Arc::new(AtomicBool::new(false));
        let (f, s) = (faults.clone(), stop.clone());
        let thread = std::thread::Builder::new()
            .name(format!("emulator {name}"))
            .spawn(move || serve(device, master, &f, &s))
            .map_err(|e| ScannerError::Device { device: format!("{name} emulator"), message: e.to_string() })?;
        Ok(Self { path, name, faults, stop, thread: Some(thread), _slave: slave })
    }

    /// The port a driver opens.
    pub fn path(&self) -> &str {
        &self.path
    }

    /// The device's name.
    pub fn name(&self) -> &str {
        &self.name
    }

    /// Replaces the injected faults (counters keep running).
    pub fn set_faults(&self, faults: Faults) {
        lock(&self.faults).faults = faults;
    }

    /// Messages sent so far.
    pub fn messages(&self) -> usize {
        lock(&self.faults).messages
    }

    /// Stops the emulator and reports an error its thread ended with.
    pub fn stop(mut self) -> Result<()> {
        self.stop.store(true, Ordering::Relaxed);
        match self.thread.take().map(std::thread::JoinHandle::join) {
            Some(Ok(r)) => r,
            Some(Err(_)) => Err(ScannerError::Device {
                device: format!("{} emulator", self.name),
                message: "the emulator thread panicked".into(),
            }),
            None => Ok(()),
        }
    }
}

impl Drop for Emulator {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

fn serve(mut device: impl Device, mut master: TTYPort, faults: &Mutex<FaultState>, stop: &AtomicBool) -> Result<()> {
    use std::io::{Read, Write};
    let mut buf = [0_u8; 4096];
    while !stop.load(Ordering::Relaxed) {
        let received = match master.read(&mut buf) {
            Ok(n) => &buf[..n],
            Err(e) if matches!(e.kind(), std::io::ErrorKind::TimedOut | std::io::ErrorKind::Interrupted) => &[],
            // Nobody holds the port open right now (our slave fd keeps the
            // pty alive): wait and look again.
            Err(_) => {
                std::thread::sleep(Duration::from_millis(5));
                &[]
            }
        };
        let mut state = lock(faults);
        let line_baud = state.faults.baud.unwrap_or(device.baud());
        // The driver's settings are visible on the pty.
        let driver_baud = master.baud_rate().unwrap_or(line_baud);
        let mut out = Vec::new();
        if !received.is_empty() && driver_baud == line_baud {
            out.extend(device.input(received, &mut state));
        }
        if driver_baud == line_baud {
            out.extend(device.tick(Instant::now(), &mut state));
        }
        let delay = state.faults.delay;
        let mut wire = Vec::new();
        for m in out {
            if state.stopped() {
                break;
            }
            wire.push(state.on_wire(&m));
        }
        drop(state);
        for w in wire {
            if !delay.is_zero() {
                std::thread::sleep(delay);
            }
            // A stalled reader must not block the emulator: a full pty
            // drops the message, like a real device's output.
            if master.write_all(&w).is_err() {
                continue;
            }
        }
    }
    Ok(())
}
