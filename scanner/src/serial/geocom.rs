//! A Leica total station over GeoCOM ([`crate::protocol::geocom`]).
//!
//! A measurement of child j: `AUT_MakePositioning` to the predicted Hz/V,
//! `AUT_FineAdjust` (ATR onto the prism; with no prism in the window, again
//! in one three times as wide, up to [`ATR_WIDENINGS`] times),
//! `TMC_DoMeasure` (distance), then
//! `TMC_GetSimpleMea` for Hz, V and the slope distance. Each RPC has its
//! own deadline; a missed deadline, a corrupted or malformed reply, or a
//! transient return code (busy, COM timeout, checksum) is retried with a
//! fresh transaction id, and a late reply to an earlier transaction is
//! skipped. Instrument errors (no prism, angles only) are returned typed
//! ([`ScannerError::Instrument`]) for the mission's retry policy.

use std::f64::consts::{FRAC_PI_2, TAU};
use std::time::{Duration, Instant};

use super::Port;
use crate::devices::{Target, TotalStation, TsMeasurement, TsStatus};
use crate::error::{Result, ScannerError};
use crate::protocol::geocom::{Param, Reply, ReturnCode, format_request, parse_reply, rpc};
use crate::protocol::{Line, LineSplitter, ProtocolError};

/// Longest reply line accepted, bytes.
pub const MAX_REPLY: usize = 1024;

/// Settings of the GeoCOM driver.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GeoComConfig {
    /// Deadline of one RPC attempt. Default 5 s (an EDM measurement takes
    /// 1–3 s).
    pub reply_timeout: Duration,
    /// Attempts per RPC. Default 3.
    pub attempts: usize,
    /// Send (and expect) the CRC-16/ARC field. Default true.
    pub checksum: bool,
    /// ATR search window, half-width in Hz and V, radians. Default 1°;
    /// without a prism in it the search is repeated [`ATR_WIDENINGS`] times,
    /// each time three times as wide.
    pub atr_window_rad: f64,
    /// How long the instrument may wait for the distance, ms. Default 3000.
    pub measure_wait_ms: u32,
}

impl Default for GeoComConfig {
    fn default() -> Self {
        Self {
            reply_timeout: Duration::from_secs(5),
            attempts: 3,
            checksum: true,
            atr_window_rad: 1f64.to_radians(),
            measure_wait_ms: 3000,
        }
    }
}

/// How often `AUT_FineAdjust` is repeated with a window three times as
/// wide when it finds no prism.
pub const ATR_WIDENINGS: usize = 3;

/// A total station speaking GeoCOM.
#[derive(Debug)]
pub struct GeoCom {
    port: Port,
    config: GeoComConfig,
    transaction: u16,
    lines: LineSplitter,
    /// Replies dropped as corrupt, malformed or late (for diagnostics).
    pub discarded: usize,
}

/// The RPC's name for messages.
fn rpc_name(n: u16) -> String {
    let name = match n {
        rpc::NULL_PROC => "COM_NullProc",
        rpc::MAKE_POSITIONING => "AUT_MakePositioning",
        rpc::FINE_ADJUST => "AUT_FineAdjust",
        rpc::DO_MEASURE => "TMC_DoMeasure",
        rpc::GET_SIMPLE_MEA => "TMC_GetSimpleMea",
        rpc::SET_MEAS_PRG => "BAP_SetMeasPrg",
        rpc::SET_TARGET_TYPE => "BAP_SetTargetType",
        _ => "RPC",
    };
    format!("{name} ({n})")
}

impl GeoCom {
    /// A driver on `port`; [`GeoCom::connect`] checks the link.
    pub fn new(port: Port, config: GeoComConfig) -> Self {
        Self { port, config, transaction: 0, lines: LineSplitter::new(MAX_REPLY, false), discarded: 0 }
    }

    /// Opens `path` at `baud`, clears the instrument's input (a lone LF),
    /// checks the link (`COM_NullProc`) and selects a reflector target with
    /// the standard single measurement program.
    pub fn open(path: &str, baud: u32, config: GeoComConfig) -> Result<Self> {
        let mut d = Self::new(Port::open("total station", path, baud)?, config);
        d.connect()?;
        Ok(d)
    }

    /// The link check and set-up of [`GeoCom::open`].
    pub fn connect(&mut self) -> Result<()> {
        self.port.write(b"\n")?;
        self.call(rpc::NULL_PROC, &[])?;
        self.call(rpc::SET_TARGET_TYPE, &[Param::Int(0)])?;
        self.call(rpc::SET_MEAS_PRG, &[Param::Int(0)])?;
        Ok(())
    }

    fn next_transaction(&mut self) -> u16 {
        self.transaction = (self.transaction + 1) % 32768;
        self.transaction
    }

    /// One RPC with retries: the reply to this transaction with COM_RC 0,
    /// whatever its procedure return code (the caller judges it).
    pub fn call(&mut self, number: u16, params: &[Param]) -> Result<Reply> {
        let started = Instant::now();
        let mut last: Option<ScannerError> = None;
        for _ in 0..self.config.attempts.max(1) {
            let tr = self.next_transaction();
            self.port.write(format_request(number, tr, params, self.config.checksum).as_bytes())?;
            match self.await_reply(tr)? {
                Some(Ok(reply)) if reply.com == ReturnCode::Ok && !reply.rc.transient() => return Ok(reply),
                Some(Ok(reply)) => {
                    let code = if reply.com == ReturnCode::Ok { reply.rc } else { reply.com };
                    last = Some(ScannerError::Instrument {
                        device: self.port.device().into(),
                        request: rpc_name(number),
                        code,
                    });
                }
                Some(Err(e)) => last = Some(ScannerError::Protocol { device: self.port.device().into(), source: e }),
                None => {}
            }
        }
        Err(last.unwrap_or_else(|| ScannerError::Timeout {
            device: self.port.device().into(),
            waiting_for: rpc_name(number),
            waited_s: started.elapsed().as_secs_f64(),
            attempts: self.config.attempts.max(1),
        }))
    }

    /// Waits for the reply to `tr`: `None` at the deadline, the parse error
    /// of a corrupt or malformed line (the attempt is lost), or the reply.
    /// Replies to other transactions (late answers) are skipped.
    fn await_reply(&mut self, tr: u16) -> Result<Option<std::result::Result<Reply, ProtocolError>>> {
        let deadline = Instant::now() + self.config.reply_timeout;
        loop {
            let bytes = self.port.read_before(deadline)?;
            if bytes.is_empty() {
                return Ok(None);
            }
            for line in self.lines.push(&bytes) {
                match line {
                    Line::Dropped(reason) => {
                        self.discarded += 1;
                        return Ok(Some(Err(ProtocolError::Malformed {
                            what: "GeoCOM reply",
                            reason,
                            excerpt: String::new(),
                        })));
                    }
                    Line::Text(text) if text.trim().is_empty() || text.trim() == "?" => {}
                    Line::Text(text) => match parse_reply(&text) {
                        Ok(reply) if reply.transaction == tr => return Ok(Some(Ok(reply))),
                        Ok(_) => self.discarded += 1,
                        Err(e) => {
                            self.discarded += 1;
                            return Ok(Some(Err(e)));
                        }
                    },
                }
            }
        }
    }

    /// Calls and requires a return code whose values are valid.
    fn call_ok(&mut self, number: u16, params: &[Param]) -> Result<Reply> {
        let reply = self.call(number, params)?;
        if reply.rc.values_valid() {
            Ok(reply)
        } else {
            Err(ScannerError::Instrument {
                device: self.port.device().into(),
                request: rpc_name(number),
                code: reply.rc,
            })
        }
    }

    fn protocol(&self, e: ProtocolError) -> ScannerError {
        ScannerError::Protocol { device: self.port.device().into(), source: e }
    }
}

impl TotalStation for GeoCom {
    fn name(&self) -> &str {
        self.port.device()
    }

    fn measure(&mut self, target: &Target) -> Result<TsMeasurement> {
        // The model's azimuth is counter-clockwise, GeoCOM's Hz clockwise;
        // V is the zenith angle.
        let hz = (-target.predicted.azimuth_rad).rem_euclid(TAU);
        let v = FRAC_PI_2 - target.predicted.elevation_rad;
        self.call_ok(
            rpc::MAKE_POSITIONING,
            &[Param::Double(hz), Param::Double(v), Param::Int(0), Param::Int(0), Param::Int(0)],
        )?;
        // The prism is where the estimate puts it only within the
        // estimate's error: no prism in a window → search again in one
        // three times as wide, up to 27 × (a prism twice is an error).
        let mut w = self.config.atr_window_rad;
        for widenings in 0.. {
            match self.call_ok(rpc::FINE_ADJUST, &[Param::Double(w), Param::Double(w), Param::Int(0)]) {
                Err(ScannerError::Instrument { code: ReturnCode::NoTarget, .. }) if widenings < ATR_WIDENINGS => {
                    w *= 3.0;
                }
                other => {
                    other?;
                    break;
                }
            }
        }
        self.call_ok(rpc::DO_MEASURE, &[Param::Int(1), Param::Int(1)])?;
        let wait = i64::from(self.config.measure_wait_ms);
        let reply = self.call_ok(rpc::GET_SIMPLE_MEA, &[Param::Int(wait), Param::Int(1)])?;
        let (hz, v, sd) = (
            reply.double(0).map_err(|e| self.protocol(e))?,
            reply.double(1).map_err(|e| self.protocol(e))?,
            reply.double(2).map_err(|e| self.protocol(e))?,
        );
        if sd <= 0.0 || !(0.0..=std::f64::consts::PI).contains(&v) {
            return Err(self.protocol(ProtocolError::Malformed {
                what: "TMC_GetSimpleMea reply",
                reason: format!("slope distance {sd} m and V {v} rad; expected SD > 0 and 0 ≤ V ≤ π"),
                excerpt: reply.values.join(","),
            }));
        }
        let status = if reply.rc == ReturnCode::Ok { TsStatus::Ok } else { TsStatus::ReducedAccuracy };
        Ok(TsMeasurement { slope_raw_m: sd, hz_rad: hz.rem_euclid(TAU), v_rad: v, status })
    }
}
