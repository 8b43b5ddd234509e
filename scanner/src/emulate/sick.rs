//! A SICK LMS-200 speaking its binary telegrams
//! ([`crate::protocol::sick`]), measuring the simulated world with
//! [`SimLms`].
//!
//! It powers on at 9600 Bd in "values on request" mode with 180°/1° and the
//! factory configuration (mm, 8 m). It answers a request whose CRC fails
//! with a raw NAK, a valid one with ACK and its reply: 10h reset (91h, then
//! 90h; back to 9600 Bd), 20h mode (installation mode with the password,
//! continuous output, values on request, the session baud rates — switched
//! after the A0h has gone out at the old rate), 30h 01h one scan, 31h
//! status, 3Ah type, 3Bh variant (180° at 1° or 0.5°; the 100° fields of
//! view and 0.25° are refused, the simulator scans 180°), 74h/77h the
//! configuration block (measuring mode and unit; writing needs installation
//! mode). Anything else gets the 92h "not allowed" reply. In continuous
//! mode it streams a B0h telegram per scan, paced by the mirror (13.32 ms
//! per revolution, 2 for 0.5°) or by the line, whichever is slower.
//! Corruption faults spoil a reply's CRC; NAK faults answer a valid
//! request with NAK.

use std::time::{Duration, Instant};

use super::{Device, FaultState};
use crate::devices::RangeFinder2D;
use crate::protocol::sick::{
    ACK, Decoder, Direction, Event, NAK, PASSWORD, Range, STATUS_OK, Unit, cmd, config, encode_measured, mode,
    mode_baud, reply,
};
use crate::sim::{LmsConfig, LmsRangeMode, LmsResolution, SimLms};

/// The type string of 3Ah and the 90h power-on telegram.
pub const TYPE: &str = "LMS200;301063;V02.10 ";

/// One mirror revolution, seconds (75 Hz).
pub const REVOLUTION_S: f64 = 0.01332;

/// Power-on baud rate.
pub const POWER_ON_BAUD: u32 = 9600;

/// How the emulated scanner outputs values.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Output {
    OnRequest,
    Continuous,
}

/// The emulated scanner.
#[derive(Debug)]
pub struct LmsEmulator {
    lms: SimLms,
    baud: u32,
    decoder: Decoder,
    output: Output,
    installation: bool,
    block: [u8; config::LEN],
    resolution: LmsResolution,
    next_scan: Option<Instant>,
    /// Scans measured (on request and streamed).
    pub scans: usize,
}

impl LmsEmulator {
    /// A scanner measuring with `lms` (its resolution and range mode are
    /// replaced by the device's: 180°/1°, mm, 8 m at power-on; its noise is
    /// kept), at 9600 Bd.
    pub fn new(lms: SimLms) -> Self {
        let mut e = Self {
            lms,
            baud: POWER_ON_BAUD,
            decoder: Decoder::new(Direction::FromHost),
            output: Output::OnRequest,
            installation: false,
            block: config::factory(),
            resolution: LmsResolution::One,
            next_scan: None,
            scans: 0,
        };
        e.apply();
        e
    }

    fn range(&self) -> Range {
        Range::from_config_byte(self.block[config::MEASURING_MODE]).unwrap_or(Range::Bits13)
    }

    fn unit(&self) -> Unit {
        if self.block[config::UNIT] == 0 { Unit::Cm } else { Unit::Mm }
    }

    /// Puts the variant and configuration into the simulated scanner.
    fn apply(&mut self) {
        let mode = match (self.unit(), self.range()) {
            (Unit::Cm, _) => LmsRangeMode::Cm80,
            (Unit::Mm, Range::Bits13) => LmsRangeMode::Mm8,
            (Unit::Mm, Range::Bits14) => LmsRangeMode::Mm16,
            (Unit::Mm, Range::Bits15) => LmsRangeMode::Mm32,
        };
        let sigma_range_m = self.lms.config().sigma_range_m;
        self.lms.set_config(LmsConfig { resolution: self.resolution, mode, sigma_range_m });
    }

    /// One B0h telegram of a fresh scan.
    fn measure(&mut self, faults: &mut FaultState) -> Vec<u8> {
        self.scans += 1;
        let words = match self.lms.scan() {
            Ok(slice) => slice.values,
            Err(_) => vec![self.range().mask(); self.resolution.values()],
        };
        let mut t = encode_measured(&words, self.unit(), STATUS_OK);
        if faults.corrupt_now() {
            spoil(&mut t);
        }
        t
    }

    /// The time between streamed scans at the current rate.
    fn scan_period(&self) -> Duration {
        let revolutions = if self.resolution == LmsResolution::Half { 2.0 } else { 1.0 };
        let bytes = (2 * self.resolution.values() + 10) as f64;
        let line = 10.0 * bytes / f64::from(self.baud.max(1));
        Duration::from_secs_f64((revolutions * REVOLUTION_S).max(line))
    }

    /// The reply to a valid request, and whether the baud rate changes
    /// after it has been sent.
    fn answer(&mut self, code: u8, data: &[u8], faults: &mut FaultState) -> (Vec<u8>, Option<u32>) {
        let ok = |data: &[u8]| reply(code | 0x80, data, STATUS_OK);
        let not_allowed = || reply(cmd::NOT_ALLOWED, &[], STATUS_OK);
        match (code, data) {
            (cmd::RESET, []) => {
                self.output = Output::OnRequest;
                self.installation = false;
                let mut out = reply(0x91, &[], STATUS_OK);
                out.extend(reply(0x90, TYPE.as_bytes(), STATUS_OK));
                (out, Some(POWER_ON_BAUD))
            }
            (cmd::MODE, [mode::INSTALLATION, password @ ..]) => {
                let right = password == PASSWORD;
                self.installation = right;
                (ok(&[u8::from(!right)]), None)
            }
            (cmd::MODE, [mode::CONTINUOUS]) => {
                self.output = Output::Continuous;
                self.installation = false;
                self.next_scan = None;
                (ok(&[0]), None)
            }
            (cmd::MODE, [mode::ON_REQUEST]) => {
                self.output = Output::OnRequest;
                self.installation = false;
                (ok(&[0]), None)
            }
            (cmd::MODE, [sub]) => match mode_baud(*sub) {
                Some(baud) => (ok(&[0]), Some(baud)),
                None => (not_allowed(), None),
            },
            (cmd::SCAN, [0x01]) => (self.measure(faults), None),
            (cmd::STATUS, []) => {
                let mut status = vec![0_u8; 152];
                status[..7].copy_from_slice(b"V02.10 ");
                status[7] = if self.installation { 0x00 } else { mode::ON_REQUEST };
                (ok(&status), None)
            }
            (cmd::TYPE, []) => (ok(TYPE.as_bytes()), None),
            (cmd::VARIANT, [a0, a1, r0, r1]) => {
                let (angle, res) = (u16::from_le_bytes([*a0, *a1]), u16::from_le_bytes([*r0, *r1]));
                let chosen = match (angle, res) {
                    (180, 100) => Some(LmsResolution::One),
                    (180, 50) => Some(LmsResolution::Half),
                    _ => None,
                };
                if let Some(r) = chosen {
                    self.resolution = r;
                    self.apply();
                }
                let active: u16 = if self.resolution == LmsResolution::Half { 50 } else { 100 };
                let mut d = vec![u8::from(chosen.is_some())];
                d.extend(180_u16.to_le_bytes());
                d.extend(active.to_le_bytes());
                (ok(&d), None)
            }
            (cmd::READ_CONFIG, []) => (ok(&self.block), None),
            (cmd::WRITE_CONFIG, block) if block.len() == config::LEN => {
                let valid = Range::from_config_byte(block[config::MEASURING_MODE]).is_some()
                    && block[config::UNIT] <= 1
                    && !(block[config::UNIT] == 0 && block[config::MEASURING_MODE] != 0);
                if !self.installation {
                    return (not_allowed(), None);
                }
                if valid {
                    self.block.copy_from_slice(block);
                    self.apply();
                }
                let mut d = vec![u8::from(valid)];
                d.extend(self.block);
                (ok(&d), None)
            }
            _ => (not_allowed(), None),
        }
    }
}

/// Flips the CRC's low byte.
fn spoil(telegram: &mut [u8]) {
    if let Some(b) = telegram.len().checked_sub(2).and_then(|i| telegram.get_mut(i)) {
        *b ^= 0xFF;
    }
}

impl Device for LmsEmulator {
    fn name(&self) -> &str {
        "SICK LMS-200"
    }

    fn baud(&self) -> u32 {
        self.baud
    }

    fn input(&mut self, bytes: &[u8], faults: &mut FaultState) -> Vec<Vec<u8>> {
        self.decoder.push(bytes);
        let mut out = Vec::new();
        while let Some(event) = self.decoder.next_event() {
            match event {
                Event::Corrupt(_) => out.push(vec![NAK]),
                Event::Frame(f) if f.address == 0 => {
                    if faults.nak_now() {
                        out.push(vec![NAK]);
                        continue;
                    }
                    let (mut telegram, baud) = self.answer(f.code(), f.data(), faults);
                    if f.code() != cmd::SCAN && faults.corrupt_now() {
                        spoil(&mut telegram);
                    }
                    let mut message = vec![ACK];
                    message.append(&mut telegram);
                    out.push(message);
                    if let Some(b) = baud {
                        self.baud = b;
                        // Whatever followed at the old rate is lost.
                        self.decoder.clear();
                        self.next_scan = None;
                    }
                }
                // Another device's address: silence.
                Event::Frame(_) | Event::Ack | Event::Nak => {}
            }
        }
        out
    }

    fn tick(&mut self, now: Instant, faults: &mut FaultState) -> Vec<Vec<u8>> {
        if self.output != Output::Continuous {
            return Vec::new();
        }
        let due = *self.next_scan.get_or_insert(now + self.scan_period());
        if now < due {
            return Vec::new();
        }
        self.next_scan = Some(due.max(now - self.scan_period()) + self.scan_period());
        vec![self.measure(faults)]
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::protocol::sick::{Frame, crc16, decode_measured, encode, request, variant_request};

    fn emulator() -> LmsEmulator {
        use cps::ParentPose;
        use nalgebra::Isometry3;
        let world = crate::sim::SimWorld::new(
            cps::geom::builtin("hall").expect("hall"),
            ParentPose::new(12.0, 4.0, 1.0, 0.0),
            vec![],
        );
        let config = LmsConfig { sigma_range_m: 0.0, ..LmsConfig::default() };
        LmsEmulator::new(SimLms::new(world, config, crate::HeadKind::PitchingMount, Isometry3::identity(), 1))
    }

    /// Sends `bytes`, returns the events of the answer.
    fn exchange(e: &mut LmsEmulator, bytes: &[u8]) -> Vec<Event> {
        let mut faults = FaultState::default();
        let mut d = Decoder::new(Direction::FromDevice);
        for m in e.input(bytes, &mut faults) {
            d.push(&m);
        }
        std::iter::from_fn(|| d.next_event()).collect()
    }

    fn frame(events: &[Event]) -> &Frame {
        match events {
            [Event::Ack, Event::Frame(f)] => f,
            other => panic!("ACK and a telegram expected: {other:?}"),
        }
    }

    /// The exchanges of device_protocols.md §1.9, byte for byte.
    #[test]
    fn answers_like_the_listing() {
        let mut e = emulator();
        let mut faults = FaultState::default();
        let out = e.input(&request(cmd::MODE, &[mode::ON_REQUEST]), &mut faults);
        assert_eq!(out, [[&[ACK][..], &[0x02, 0x80, 0x03, 0x00, 0xA0, 0x00, 0x10, 0x16, 0x0A]].concat()]);
        let out = e.input(&variant_request(180, 100), &mut faults);
        assert_eq!(
            out,
            [[&[ACK][..], &[0x02, 0x80, 0x07, 0x00, 0xBB, 0x01, 0xB4, 0x00, 0x64, 0x00, 0x10, 0x5B, 0x30]].concat()]
        );
        // §1.9's NAK case.
        assert_eq!(e.input(&[0x02, 0x00, 0x02, 0x00, 0x20, 0x24, 0x34, 0x09], &mut faults), [vec![NAK]]);
        // Not our address: silence.
        assert!(e.input(&encode(0x05, &[cmd::STATUS]), &mut faults).is_empty());
    }

    #[test]
    fn scans_follow_variant_and_configuration() {
        let mut e = emulator();
        let m = decode_measured(frame(&exchange(&mut e, &request(cmd::SCAN, &[1]))), false).expect("B0h");
        // Power-on: 1°, mm, 8 m: the end wall 28 m ahead is out of range.
        assert_eq!((m.words.len(), m.unit), (181, Unit::Mm));
        assert_eq!((m.words[0], m.words[90]), (4000, 0x1FF7));
        // 0.5° and the 32 m mode in mm (installation mode first).
        assert_eq!(frame(&exchange(&mut e, &variant_request(180, 50))).data()[0], 1);
        let mut block = frame(&exchange(&mut e, &request(cmd::READ_CONFIG, &[]))).data().to_vec();
        block[config::MEASURING_MODE] = Range::Bits15.config_byte();
        let refused = exchange(&mut e, &request(cmd::WRITE_CONFIG, &block));
        assert_eq!(frame(&refused).code(), cmd::NOT_ALLOWED, "not in installation mode");
        let pw = [&[mode::INSTALLATION][..], PASSWORD].concat();
        assert_eq!(frame(&exchange(&mut e, &request(cmd::MODE, &pw))).data(), [0]);
        let written = exchange(&mut e, &request(cmd::WRITE_CONFIG, &block));
        assert_eq!(frame(&written).data(), [&[1][..], &block].concat());
        let m = decode_measured(frame(&exchange(&mut e, &request(cmd::SCAN, &[1]))), false).expect("B0h");
        assert_eq!((m.words.len(), m.words[180]), (361, 28000));
        // A wrong password is refused (A0h 01h).
        assert_eq!(frame(&exchange(&mut e, &request(cmd::MODE, &[0, b'x', b'x']))).data(), [1]);
        // cm with the 32 m mode is not a valid block.
        block[config::UNIT] = 0;
        assert_eq!(frame(&exchange(&mut e, &request(cmd::MODE, &pw))).data(), [0]);
        assert_eq!(frame(&exchange(&mut e, &request(cmd::WRITE_CONFIG, &block))).data()[0], 0);
    }

    #[test]
    fn baud_changes_after_the_answer_and_reset_returns_to_9600() {
        let mut e = emulator();
        assert_eq!(e.baud(), 9600);
        let a = exchange(&mut e, &request(cmd::MODE, &[mode::BAUD_500000]));
        assert_eq!(frame(&a).data(), [0]);
        assert_eq!(e.baud(), 500_000);
        let mut faults = FaultState::default();
        let out = e.input(&request(cmd::RESET, &[]), &mut faults).concat();
        let mut d = Decoder::new(Direction::FromDevice);
        d.push(&out);
        let events: Vec<_> = std::iter::from_fn(|| d.next_event()).collect();
        assert!(matches!(&events[..], [Event::Ack, Event::Frame(a), Event::Frame(b)]
            if a.code() == 0x91 && b.code() == 0x90 && b.data() == TYPE.as_bytes()));
        assert_eq!(e.baud(), 9600);
        // The listing's 91h telegram (CRC 79 30).
        assert_eq!(crc16(&[0x02, 0x80, 0x02, 0x00, 0x91, 0x10]), 0x3079);
    }

    #[test]
    fn streams_at_the_mirror_or_line_rate() {
        let mut e = emulator();
        let mut faults = FaultState::default();
        e.input(&request(cmd::MODE, &[mode::CONTINUOUS]), &mut faults);
        let t0 = Instant::now();
        assert!(e.tick(t0, &mut faults).is_empty(), "the first scan needs a period");
        // 372 bytes at 9600 Bd: 0.3875 s per scan.
        assert!((e.scan_period().as_secs_f64() - 0.3875).abs() < 1e-9);
        let out = e.tick(t0 + Duration::from_millis(400), &mut faults);
        assert_eq!(out.len(), 1);
        e.baud = 500_000;
        assert!((e.scan_period().as_secs_f64() - REVOLUTION_S).abs() < 1e-9);
        e.input(&request(cmd::MODE, &[mode::ON_REQUEST]), &mut faults);
        assert!(e.tick(t0 + Duration::from_secs(5), &mut faults).is_empty());
    }
}
