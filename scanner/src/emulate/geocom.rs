//! A Leica total station speaking GeoCOM, measuring the simulated world.
//!
//! It keeps a pointing (Hz, V). `AUT_MakePositioning` sets it;
//! `AUT_FineAdjust` locks the ATR onto the one prism within the search
//! window around it (8710 when there is none, 8711 when there are several;
//! before any positioning the instrument is taken to be aimed at child 0,
//! as an operator would); `TMC_DoMeasure` measures the locked prism with
//! the simulated instrument's noise (line of sight and range included);
//! `TMC_GetSimpleMea`, `TMC_GetAngle1` and `BAP_MeasDistanceAngle` report
//! it. The connection RPCs geocompy sends (0, 108, 5003, 5004, 110, 5034)
//! are answered like a TS30. Replies carry a CRC when the request did.

use std::f64::consts::{FRAC_PI_2, TAU};

use cps::{Instrument, observe, wrap_angle};

use super::{Device, FaultState};
use nalgebra::Point3;

use crate::devices::{Prism, Target, TotalStation, TsMeasurement};
use crate::protocol::geocom::{ReturnCode, format_reply, parse_request, rpc};
use crate::protocol::{Line, LineSplitter};
use crate::sim::{SimTotalStation, SimWorld};

/// The emulated instrument.
#[derive(Debug)]
pub struct GeoComEmulator {
    world: SimWorld,
    station: SimTotalStation,
    instrument: Instrument,
    baud: u32,
    lines: LineSplitter,
    pointing: Option<(f64, f64)>,
    locked: Option<usize>,
    measured: Option<Result<TsMeasurement, ReturnCode>>,
}

impl GeoComEmulator {
    /// An instrument on the parent of `world` with `instrument`'s noise and
    /// limits, noise stream `seed`, at `baud`.
    pub fn new(world: SimWorld, instrument: Instrument, seed: u64, baud: u32) -> Self {
        let station = SimTotalStation::new(world.clone(), instrument.clone(), seed);
        Self {
            world,
            station,
            instrument,
            baud,
            lines: LineSplitter::new(1024, false),
            pointing: None,
            locked: None,
            measured: None,
        }
    }

    /// Prism `j` of the world: the children's, then the control prisms'.
    fn prism(truth: &crate::sim::Truth, j: usize) -> Option<(Prism, Point3<f64>)> {
        let n = truth.children.len();
        match truth.children.get(j) {
            Some(p) => Some((Prism::Child(j), *p)),
            None => truth.control.get(j - n).map(|p| (Prism::Control(j - n), *p)),
        }
    }

    /// Hz (clockwise) and V (zenith) from the instrument to prism `j`.
    fn direction(&self, j: usize) -> Option<(f64, f64)> {
        let truth = self.world.truth();
        let r = observe(&truth.parent, &Self::prism(&truth, j)?.1).ok()?;
        Some(((-r.azimuth_rad).rem_euclid(TAU), FRAC_PI_2 - r.elevation_rad))
    }

    fn fine_adjust(&mut self, window_hz: f64, window_v: f64) -> ReturnCode {
        let n = {
            let truth = self.world.truth();
            truth.children.len() + truth.control.len()
        };
        let Some((hz, v)) = self.pointing.or_else(|| self.direction(0)) else { return ReturnCode::NoTarget };
        let inside: Vec<usize> = (0..n)
            .filter(|&j| {
                self.direction(j).is_some_and(|(h, vv)| {
                    wrap_angle(h - hz).abs() <= window_hz.abs() && (vv - v).abs() <= window_v.abs()
                })
            })
            .collect();
        match inside[..] {
            [j] => {
                self.locked = Some(j);
                self.pointing = self.direction(j);
                ReturnCode::Ok
            }
            [] => ReturnCode::NoTarget,
            _ => ReturnCode::MultipleTargets,
        }
    }

    fn measure(&mut self) -> Result<TsMeasurement, ReturnCode> {
        let j = self.locked.ok_or(ReturnCode::NoTarget)?;
        let truth = self.world.truth();
        let (prism, at) = Self::prism(&truth, j).ok_or(ReturnCode::NoTarget)?;
        let exact = observe(&truth.parent, &at).map_err(|_| ReturnCode::NoTarget)?;
        match self.station.measure(&Target { prism, predicted: exact }) {
            Ok(m) => Ok(m),
            // Out of range or blocked: the ATR may still see the prism's
            // direction, but the EDM gets no distance.
            Err(_) => Err(ReturnCode::DistanceError),
        }
    }

    fn angles(&self) -> (f64, f64) {
        match &self.measured {
            Some(Ok(m)) => (m.hz_rad, m.v_rad),
            _ => self.pointing.unwrap_or((0.0, FRAC_PI_2)),
        }
    }

    /// The reply's return code and values for a request.
    fn answer(&mut self, number: u16, params: &[String]) -> (ReturnCode, Vec<String>) {
        let num = |i: usize| params.get(i).and_then(|p| p.trim().parse::<f64>().ok());
        let ok = ReturnCode::Ok;
        let f = |x: f64| format!("{x:.10}");
        match number {
            rpc::NULL_PROC | rpc::SET_TARGET_TYPE | rpc::SET_PRISM_TYPE | rpc::SET_MEAS_PRG | rpc::SET_LOCK_STATUS => {
                (ok, vec![])
            }
            rpc::LOCK_IN => (ok, vec![]),
            rpc::GET_DOUBLE_PRECISION => (ok, vec!["10".into()]),
            rpc::GET_SW_VERSION | rpc::CSV_GET_SW_VERSION => (ok, vec!["5".into(), "50".into(), "0".into()]),
            rpc::GET_INSTRUMENT_NO => (ok, vec!["123456".into()]),
            rpc::GET_INSTRUMENT_NAME => (ok, vec!["\"TS30 cps-survey emulator\"".into()]),
            rpc::MAKE_POSITIONING => match (num(0), num(1)) {
                (Some(hz), Some(v)) if (0.0..=std::f64::consts::PI).contains(&v) => {
                    self.pointing = Some((hz.rem_euclid(TAU), v));
                    self.locked = None;
                    (ok, vec![])
                }
                _ => (ReturnCode::InvalidParameter, vec![]),
            },
            rpc::FINE_ADJUST => match (num(0), num(1)) {
                (Some(wh), Some(wv)) => (self.fine_adjust(wh, wv), vec![]),
                _ => (ReturnCode::InvalidParameter, vec![]),
            },
            rpc::DO_MEASURE => {
                match num(0).map(|p| p as i64) {
                    // STOP and CLEAR forget the distance.
                    Some(0) | Some(3) => self.measured = None,
                    Some(_) => self.measured = Some(self.measure()),
                    None => return (ReturnCode::InvalidParameter, vec![]),
                }
                (ok, vec![])
            }
            rpc::GET_SIMPLE_MEA => {
                let (hz, v) = self.angles();
                match &self.measured {
                    Some(Ok(m)) => (ok, vec![f(m.hz_rad), f(m.v_rad), f(m.slope_raw_m)]),
                    Some(Err(code)) => (*code, vec![f(hz), f(v), f(0.0)]),
                    None => (ReturnCode::AnglesOnly, vec![f(hz), f(v), f(0.0)]),
                }
            }
            rpc::GET_ANGLE1 => {
                let (hz, v) = self.angles();
                let sigma = format!("{:.10}", self.instrument.sigma_hz_rad);
                (ok, vec![f(hz), f(v), sigma, "0".into(), f(0.0), f(0.0), f(0.0), "0".into(), "0".into()])
            }
            rpc::MEAS_DISTANCE_ANGLE => {
                let mode = params.first().cloned().unwrap_or_else(|| "2".into());
                self.measured = Some(self.measure());
                let (hz, v) = self.angles();
                match &self.measured {
                    Some(Ok(m)) => (ok, vec![f(m.hz_rad), f(m.v_rad), f(m.slope_raw_m), mode]),
                    Some(Err(code)) => (*code, vec![f(hz), f(v), f(0.0), mode]),
                    None => (ReturnCode::AnglesOnly, vec![f(hz), f(v), f(0.0), mode]),
                }
            }
            _ => (ReturnCode::NotImplemented, vec![]),
        }
    }
}

impl Device for GeoComEmulator {
    fn name(&self) -> &str {
        "GeoCOM total station"
    }

    fn baud(&self) -> u32 {
        self.baud
    }

    fn input(&mut self, bytes: &[u8], faults: &mut FaultState) -> Vec<Vec<u8>> {
        let mut out = Vec::new();
        for line in self.lines.push(bytes) {
            let Line::Text(text) = line else { continue };
            let text = text.trim();
            if text.is_empty() || text == "c" {
                continue;
            }
            let request = match parse_request(text) {
                Ok(r) => r,
                // A corrupted request: the COM layer's checksum error.
                Err(_) => {
                    faults.corrupt_now();
                    out.push(format_reply(3101, 0, ReturnCode::Ok, &[], false).into_bytes());
                    continue;
                }
            };
            if faults.nak_now() {
                faults.corrupt_now();
                out.push(format_reply(3102, request.transaction, ReturnCode::Ok, &[], request.checksum).into_bytes());
                continue;
            }
            let (rc, values) = self.answer(request.rpc, &request.params);
            let mut reply = format_reply(0, request.transaction, rc, &values, request.checksum);
            if faults.corrupt_now() {
                reply = corrupt(&reply, request.checksum);
            }
            out.push(reply.into_bytes());
        }
        out
    }
}

/// A reply whose CRC no longer matches (checksum mode), or cut short.
fn corrupt(reply: &str, checksum: bool) -> String {
    if checksum
        && let Some((head, body)) = reply.split_once(':')
        && let Some((front, crc)) = head.rsplit_once(',')
    {
        let bad = crc.parse::<u32>().map_or(0, |c| (c + 1) % 65536);
        return format!("{front},{bad}:{body}");
    }
    let mut cut = reply.len() / 2;
    while !reply.is_char_boundary(cut) {
        cut -= 1;
    }
    format!("{}\r\n", &reply[..cut])
}
