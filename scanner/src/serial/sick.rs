//! A SICK LMS-2xx over its serial line ([`crate::protocol::sick`]).
//!
//! [`Lms::open`] finds the scanner's current baud rate (the configured one,
//! then 9600, 38400, 500000, 19200: at each it stops any streaming with 20h
//! 25h and asks for the status, 31h), switches the session to the wanted
//! rate (the A0h answer comes at the old rate; the port follows, waits and
//! verifies with 31h), selects the variant (3Bh, 180° at 1° or 0.5°), and
//! writes the configuration block only if the unit or measuring mode differ
//! (74h read; installation mode, 77h write, back to monitoring: the block
//! lives in EEPROM). Then it either polls (30h 01h per slice) or starts
//! continuous output (20h 24h) and takes the first complete B0h telegram
//! that arrives after each request.
//!
//! Every request is answered by ACK and a reply within its deadline, or it
//! is sent again: after a NAK (30 ms later, as the listing asks), a reply
//! whose CRC fails, a 92h "not allowed" or silence. Stray B0h telegrams of
//! a stream are skipped while waiting for another reply. After the last
//! attempt the error is typed: [`ScannerError::Timeout`] (silence) or
//! [`ScannerError::Protocol`] (what was wrong).

use std::time::{Duration, Instant};

use super::Port;
use crate::devices::{RangeFinder2D, Slice};
use crate::error::{Result, ScannerError};
use crate::protocol::ProtocolError;
use crate::protocol::sick::{
    Decoder, Direction, Event, Frame, PASSWORD, Range, Unit, baud_mode, cmd, config, decode_measured, distance, mode,
    request, variant_request,
};

/// Baud rates tried, in order after the configured one, to find the scanner.
pub const CANDIDATE_BAUDS: [u32; 4] = [9600, 38400, 500_000, 19200];

/// Settings of the LMS driver.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LmsSettings {
    /// The session baud rate (9600, 19200, 38400 or 500000). Default 38400.
    pub baud: u32,
    /// Angular resolution in hundredths of a degree over 180°: 100 or 50.
    /// Default 50.
    pub resolution_cdeg: u16,
    /// Measuring mode. Default 15 bits (32 m in mm).
    pub range: Range,
    /// Unit. Default mm.
    pub unit: Unit,
    /// Continuous output (20h 24h) instead of one request per slice.
    /// Default false.
    pub continuous: bool,
    /// Deadline of one request's answer. Default 1 s (the listing's ACK
    /// comes within 60 ms, a 0.5° scan within 60 ms more; at 9600 Bd its
    /// 732 bytes take 0.76 s on the line).
    pub reply_timeout: Duration,
    /// Deadline of a mode change (20h). Default 3 s.
    pub mode_timeout: Duration,
    /// Attempts per request. Default 3.
    pub attempts: usize,
    /// Pause after switching the port's rate before verifying. Default
    /// 250 ms (sicktoolbox).
    pub baud_settle: Duration,
}

impl Default for LmsSettings {
    fn default() -> Self {
        Self {
            baud: 38400,
            resolution_cdeg: 50,
            range: Range::Bits15,
            unit: Unit::Mm,
            continuous: false,
            reply_timeout: Duration::from_secs(1),
            mode_timeout: Duration::from_secs(3),
            attempts: 3,
            baud_settle: Duration::from_millis(250),
        }
    }
}

/// Wait after a NAK before resending (listing: ≥ 30 ms).
const NAK_WAIT: Duration = Duration::from_millis(30);

/// A SICK LMS-2xx.
#[derive(Debug)]
pub struct Lms {
    port: Port,
    settings: LmsSettings,
    decoder: Decoder,
    streaming: bool,
    /// Telegrams dropped (bad CRC, NAK, refused, unexpected) so far.
    pub discarded: usize,
    /// Requests sent again so far.
    pub retries: usize,
}

fn name(code: u8) -> &'static str {
    match code {
        cmd::RESET => "reset (10h)",
        cmd::MODE => "operating mode (20h)",
        cmd::SCAN => "measured values (30h)",
        cmd::STATUS => "status (31h)",
        cmd::TYPE => "type (3Ah)",
        cmd::VARIANT => "variant (3Bh)",
        cmd::READ_CONFIG => "read configuration (74h)",
        cmd::WRITE_CONFIG => "write configuration (77h)",
        _ => "request",
    }
}

impl Lms {
    /// A driver on an open `port` (nothing sent yet; see [`Lms::connect`]).
    pub fn new(port: Port, settings: LmsSettings) -> Self {
        Self {
            port,
            settings,
            decoder: Decoder::new(Direction::FromDevice),
            streaming: false,
            discarded: 0,
            retries: 0,
        }
    }

    /// Opens `path`, finds the scanner and configures it ([`Lms::connect`]).
    pub fn open(path: &str, settings: LmsSettings) -> Result<Self> {
        let mut lms = Self::new(Port::open("LMS-2xx", path, settings.baud)?, settings);
        lms.connect()?;
        Ok(lms)
    }

    /// The settings.
    pub fn settings(&self) -> &LmsSettings {
        &self.settings
    }

    /// Finds the scanner's rate, switches to the wanted one, sets variant
    /// and configuration, and starts continuous output if asked.
    pub fn connect(&mut self) -> Result<()> {
        let s = self.settings;
        if baud_mode(s.baud).is_none() {
            return Err(ScannerError::OutOfRange {
                device: self.port.device().into(),
                what: "baud rate".into(),
                value: f64::from(s.baud),
                expected: "9600, 19200, 38400 or 500000".into(),
            });
        }
        if ![50, 100].contains(&s.resolution_cdeg) {
            return Err(ScannerError::OutOfRange {
                device: self.port.device().into(),
                what: "resolution (1/100 °)".into(),
                value: f64::from(s.resolution_cdeg),
                expected: "100 (1°) or 50 (0.5°) over 180°".into(),
            });
        }
        let found = self.find_baud()?;
        if found != s.baud {
            self.switch_baud(s.baud)?;
        }
        let v = self.transact(&variant_request(180, s.resolution_cdeg), cmd::VARIANT, s.reply_timeout)?;
        if v.data().first() != Some(&1) {
            return Err(self.refused(cmd::VARIANT, format!("180° at {} 1/100 ° not accepted", s.resolution_cdeg)));
        }
        self.configure()?;
        if s.continuous {
            self.set_mode(mode::CONTINUOUS)?;
            self.streaming = true;
        }
        Ok(())
    }

    fn refused(&self, request: u8, reason: String) -> ScannerError {
        ScannerError::Protocol { device: self.port.device().into(), source: ProtocolError::Refused { request, reason } }
    }

    /// The first candidate rate at which the scanner answers 31h.
    fn find_baud(&mut self) -> Result<u32> {
        let mut rates = vec![self.settings.baud];
        rates.extend(CANDIDATE_BAUDS.iter().filter(|b| **b != self.settings.baud));
        let timeout = self.settings.reply_timeout;
        let started = Instant::now();
        for &baud in &rates {
            self.port.set_baud(baud)?;
            self.flush()?;
            // Stop a stream, then ask for the status; one try each.
            let _ = self.transact_with(&request(cmd::MODE, &[mode::ON_REQUEST]), cmd::MODE, 1, timeout);
            if self.transact_with(&request(cmd::STATUS, &[]), cmd::STATUS, 1, timeout).is_ok() {
                return Ok(baud);
            }
        }
        Err(ScannerError::Timeout {
            device: self.port.device().into(),
            waiting_for: format!("a status reply at any of {rates:?} Bd"),
            waited_s: started.elapsed().as_secs_f64(),
            attempts: rates.len(),
        })
    }

    /// Switches the session to `baud` and verifies it with 31h.
    pub fn switch_baud(&mut self, baud: u32) -> Result<()> {
        let sub = baud_mode(baud).ok_or_else(|| self.refused(cmd::MODE, format!("no session rate {baud} Bd")))?;
        self.set_mode(sub)?;
        self.port.set_baud(baud)?;
        std::thread::sleep(self.settings.baud_settle);
        self.flush()?;
        self.transact(&request(cmd::STATUS, &[]), cmd::STATUS, self.settings.reply_timeout)?;
        Ok(())
    }

    /// A 20h mode change that must be answered A0h 00h.
    fn set_mode(&mut self, data: u8) -> Result<()> {
        self.set_mode_with(&[data])
    }

    fn set_mode_with(&mut self, data: &[u8]) -> Result<()> {
        let a = self.transact(&request(cmd::MODE, data), cmd::MODE, self.settings.mode_timeout)?;
        if a.data() != [0] {
            return Err(self.refused(cmd::MODE, format!("mode {:#04x} answered {:02x?}", data[0], a.data())));
        }
        Ok(())
    }

    /// Writes unit and measuring mode into the configuration block if they
    /// differ (EEPROM: only when needed).
    fn configure(&mut self) -> Result<()> {
        let s = self.settings;
        let timeout = s.mode_timeout;
        let block = self.transact(&request(cmd::READ_CONFIG, &[]), cmd::READ_CONFIG, timeout)?.data().to_vec();
        if block.len() != config::LEN {
            return Err(ScannerError::Protocol {
                device: self.port.device().into(),
                source: ProtocolError::Malformed {
                    what: "F4h configuration",
                    reason: format!("{} bytes; expected {}", block.len(), config::LEN),
                    excerpt: crate::protocol::hex_excerpt(&block, 12),
                },
            });
        }
        let unit = u8::from(s.unit == Unit::Mm);
        let range = s.range.config_byte();
        if block[config::UNIT] == unit && block[config::MEASURING_MODE] == range {
            return Ok(());
        }
        let mut wanted = block;
        wanted[config::UNIT] = unit;
        wanted[config::MEASURING_MODE] = range;
        self.set_mode_with(&[&[mode::INSTALLATION][..], PASSWORD].concat())?;
        let w = self.transact(&request(cmd::WRITE_CONFIG, &wanted), cmd::WRITE_CONFIG, timeout)?;
        let stored = w.data().get(1..).unwrap_or(&[]);
        let accepted = w.data().first() == Some(&1) && stored == wanted.as_slice();
        self.set_mode(mode::ON_REQUEST)?;
        if !accepted {
            return Err(self.refused(cmd::WRITE_CONFIG, format!("unit {unit:#04x}, mode {range:#04x} not stored")));
        }
        Ok(())
    }

    /// Drops everything received so far.
    fn flush(&mut self) -> Result<()> {
        self.port.clear_input()?;
        self.decoder.clear();
        Ok(())
    }

    /// Sends `telegram` and waits for the reply with `code` + 80h.
    pub fn transact(&mut self, telegram: &[u8], code: u8, timeout: Duration) -> Result<Frame> {
        self.transact_with(telegram, code, self.settings.attempts, timeout)
    }

    fn transact_with(&mut self, telegram: &[u8], code: u8, attempts: usize, timeout: Duration) -> Result<Frame> {
        let started = Instant::now();
        let mut last: Option<ProtocolError> = None;
        let attempts = attempts.max(1);
        for attempt in 0..attempts {
            if attempt > 0 {
                self.retries += 1;
                // The rest of a damaged reply is garbage that could hold
                // bytes looking like ACK or NAK.
                self.flush()?;
            }
            self.port.write(telegram)?;
            match self.await_reply(code, timeout)? {
                Ok(frame) => return Ok(frame),
                Err(Some(e)) => {
                    self.discarded += 1;
                    if matches!(e, ProtocolError::Refused { .. }) {
                        std::thread::sleep(NAK_WAIT);
                    }
                    last = Some(e);
                }
                Err(None) => {}
            }
        }
        Err(match last {
            Some(source) => ScannerError::Protocol { device: self.port.device().into(), source },
            None => ScannerError::Timeout {
                device: self.port.device().into(),
                waiting_for: name(code).into(),
                waited_s: started.elapsed().as_secs_f64(),
                attempts,
            },
        })
    }

    /// The reply to `code`, or why this attempt failed (`None`: silence).
    fn await_reply(
        &mut self,
        code: u8,
        timeout: Duration,
    ) -> Result<std::result::Result<Frame, Option<ProtocolError>>> {
        let deadline = Instant::now() + timeout;
        loop {
            while let Some(event) = self.decoder.next_event() {
                match event {
                    Event::Ack => {}
                    Event::Nak => {
                        return Ok(Err(Some(ProtocolError::Refused { request: code, reason: "NAK".into() })));
                    }
                    Event::Corrupt(e) => return Ok(Err(Some(e))),
                    Event::Frame(f) if f.code() == code | 0x80 => return Ok(Ok(f)),
                    // 10h is answered 91h (and 90h later).
                    Event::Frame(f) if code == cmd::RESET && f.code() == 0x91 => return Ok(Ok(f)),
                    Event::Frame(f) if f.code() == cmd::NOT_ALLOWED => {
                        return Ok(Err(Some(ProtocolError::Refused {
                            request: code,
                            reason: "not allowed in the scanner's state (92h)".into(),
                        })));
                    }
                    // A streamed scan or a late answer: not ours.
                    Event::Frame(_) => self.discarded += 1,
                }
            }
            let bytes = self.port.read_before(deadline)?;
            if bytes.is_empty() {
                return Ok(Err(None));
            }
            self.decoder.push(&bytes);
        }
    }

    /// The first complete B0h telegram of the stream received after the
    /// request (input before it is dropped; a telegram cut by the drop
    /// fails its CRC and is skipped).
    fn next_streamed(&mut self) -> Result<Frame> {
        let s = self.settings;
        self.flush()?;
        let started = Instant::now();
        let deadline = started + s.reply_timeout.mul_f64(s.attempts.max(1) as f64);
        loop {
            while let Some(event) = self.decoder.next_event() {
                match event {
                    Event::Frame(f) if f.code() == cmd::MEASURED => return Ok(f),
                    Event::Frame(_) | Event::Corrupt(_) => self.discarded += 1,
                    Event::Ack | Event::Nak => {}
                }
            }
            let bytes = self.port.read_before(deadline)?;
            if bytes.is_empty() {
                return Err(ScannerError::Timeout {
                    device: self.port.device().into(),
                    waiting_for: "a streamed B0h scan".into(),
                    waited_s: started.elapsed().as_secs_f64(),
                    attempts: 1,
                });
            }
            self.decoder.push(&bytes);
        }
    }

    /// Stops streaming and returns the line to 9600 Bd (so the next start
    /// is quick); best effort.
    pub fn close(&mut self) -> Result<()> {
        if self.streaming {
            self.set_mode(mode::ON_REQUEST)?;
            self.streaming = false;
        }
        if self.settings.baud != 9600 {
            self.set_mode(mode::BAUD_9600)?;
            self.port.set_baud(9600)?;
        }
        Ok(())
    }

    /// A B0h telegram as a slice, checked against the settings.
    fn slice(&self, frame: &Frame) -> Result<Slice> {
        let s = self.settings;
        let protocol = |source| ScannerError::Protocol { device: self.port.device().into(), source };
        let m = decode_measured(frame, false).map_err(protocol)?;
        let n = if s.resolution_cdeg == 50 { 361 } else { 181 };
        if m.words.len() != n || m.unit != s.unit || m.partial.is_some() {
            return Err(protocol(ProtocolError::Unexpected {
                expected: format!("{n} values in {:?}, a complete scan", s.unit),
                received: format!(
                    "{} values in {:?}{}",
                    m.words.len(),
                    m.unit,
                    if m.partial.is_some() { ", partial" } else { "" }
                ),
            }));
        }
        if let Some(problem) = m.status.problem().filter(|_| m.status.severity() >= 3) {
            return Err(ScannerError::Device { device: self.port.device().into(), message: problem });
        }
        let max_valid = s.range.max_valid();
        let values = m.words.iter().map(|w| distance(*w, s.range).unwrap_or(max_valid)).collect();
        Ok(Slice {
            start_rad: 0.0,
            step_rad: (f64::from(s.resolution_cdeg) / 100.0).to_radians(),
            values,
            metres_per_count: s.unit.metres_per_count(),
            max_valid,
        })
    }
}

impl Drop for Lms {
    fn drop(&mut self) {
        if self.streaming {
            // Best effort: a stream left running slows the next start.
            let stop = request(cmd::MODE, &[mode::ON_REQUEST]);
            let _ = self.transact_with(&stop, cmd::MODE, 1, Duration::from_millis(200));
        }
    }
}

impl RangeFinder2D for Lms {
    fn name(&self) -> &str {
        self.port.device()
    }

    fn scan(&mut self) -> Result<Slice> {
        let frame = if self.streaming {
            self.next_streamed()?
        } else {
            self.transact(&request(cmd::SCAN, &[0x01]), cmd::SCAN, self.settings.reply_timeout)?
        };
        self.slice(&frame)
    }
}
