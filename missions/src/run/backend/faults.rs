//! The devices as faults and retries name them, and the faults injected
//! into a simulated team (`--sim-fault`): a device that stops answering or
//! fails every k-th command, a planted blunder in a measurement.

use std::str::FromStr;

use scanner::{ScannerError, TsMeasurement};

/// A device of the team, as named in faults and retry messages.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum DeviceKind {
    /// Any robot's drive.
    Drive,
    /// The parent's total station.
    TotalStation,
    /// The tilt sensor.
    Tilt,
    /// The laser scanner (one whole 3D scan is one command).
    Scanner,
}

impl DeviceKind {
    /// The name used on the command line and in the journal.
    pub fn name(self) -> &'static str {
        match self {
            DeviceKind::Drive => "drive",
            DeviceKind::TotalStation => "total-station",
            DeviceKind::Tilt => "tilt",
            DeviceKind::Scanner => "scanner",
        }
    }
}

/// A fault injected into a simulated device (`--sim-fault`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Fault {
    /// The device.
    pub device: DeviceKind,
    /// When it fails.
    pub rule: FaultRule,
}

/// When an injected fault strikes, counting the device's commands from 1
/// (each retry is a command) — or, for a blunder, the total station's
/// measurements from 1 (children and control alike).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum FaultRule {
    /// Every command after the n-th fails: the device stopped answering.
    After(usize),
    /// Every k-th command fails once (a retry then succeeds).
    Every(usize),
    /// The n-th distance measured is off by this many metres.
    Blunder(usize, f64),
    /// The n-th horizontal angle measured is off by this many radians.
    BlunderAngle(usize, f64),
}

impl FromStr for Fault {
    type Err = String;

    /// `DEVICE:after=N` or `DEVICE:every=K`, DEVICE one of `drive`,
    /// `total-station`, `tilt`, `scanner`; `total-station:blunder=N:D`
    /// (metres) or `total-station:blunder-angle=N:ARCSEC`.
    fn from_str(s: &str) -> Result<Self, String> {
        let expected = "expected DEVICE:after=N or DEVICE:every=K with DEVICE drive, total-station, tilt or scanner, \
                        or total-station:blunder=N:METRES or total-station:blunder-angle=N:ARCSEC";
        let (device, rule) = s.split_once(':').ok_or_else(|| format!("fault \"{s}\": {expected}"))?;
        let device = [DeviceKind::Drive, DeviceKind::TotalStation, DeviceKind::Tilt, DeviceKind::Scanner]
            .into_iter()
            .find(|d| d.name() == device)
            .ok_or_else(|| format!("fault \"{s}\": unknown device \"{device}\"; {expected}"))?;
        let (kind, n) = rule.split_once('=').ok_or_else(|| format!("fault \"{s}\": {expected}"))?;
        if let Some(blunder) = ["blunder", "blunder-angle"].into_iter().find(|b| *b == kind) {
            if device != DeviceKind::TotalStation {
                return Err(format!("fault \"{s}\": blunders are the total station's; {expected}"));
            }
            let (n, d) = n.split_once(':').ok_or_else(|| format!("fault \"{s}\": {expected}"))?;
            let n: usize = n
                .parse()
                .ok()
                .filter(|n| *n >= 1)
                .ok_or_else(|| format!("fault \"{s}\": \"{n}\" is not a measurement number ≥ 1; {expected}"))?;
            let d: f64 = d
                .parse()
                .ok()
                .filter(|d: &f64| d.is_finite() && d.abs() < 1e6)
                .ok_or_else(|| format!("fault \"{s}\": \"{d}\" is not a finite size below 1e6; {expected}"))?;
            let rule = if blunder == "blunder" {
                FaultRule::Blunder(n, d)
            } else {
                FaultRule::BlunderAngle(n, d * cps::RAD_PER_ARCSEC)
            };
            return Ok(Fault { device, rule });
        }
        let n: usize = n.parse().map_err(|_| format!("fault \"{s}\": \"{n}\" is not a whole number; {expected}"))?;
        let rule = match (kind, n) {
            ("after", n) => FaultRule::After(n),
            ("every", k) if k >= 2 => FaultRule::Every(k),
            ("every", _) => return Err(format!("fault \"{s}\": every=K needs K ≥ 2 (K = 1 is after=0)")),
            _ => return Err(format!("fault \"{s}\": unknown rule \"{kind}\"; {expected}")),
        };
        Ok(Fault { device, rule })
    }
}

/// The injected faults of a team with the counts they strike by.
#[derive(Debug, Clone, Default)]
pub struct Faults {
    rules: Vec<Fault>,
    /// Commands so far, per [`DeviceKind`].
    commands: [usize; 4],
    /// The total station's measurements so far (blunders count them).
    pub measurements: usize,
}

impl Faults {
    /// `rules`, nothing counted yet.
    pub fn new(rules: Vec<Fault>) -> Self {
        Self { rules, commands: [0; 4], measurements: 0 }
    }

    /// Counts a command to `device` (called `name`) and fails it when an
    /// injected fault says so.
    pub fn command(&mut self, device: DeviceKind, name: &str) -> scanner::Result<()> {
        let n = &mut self.commands[device as usize];
        *n += 1;
        let strikes = self.rules.iter().any(|f| {
            f.device == device
                && match f.rule {
                    FaultRule::After(k) => *n > k,
                    FaultRule::Every(k) => n.is_multiple_of(k),
                    FaultRule::Blunder(..) | FaultRule::BlunderAngle(..) => false,
                }
        });
        if strikes {
            return Err(ScannerError::Device {
                device: name.to_string(),
                message: format!("no answer to command {n} (injected fault)"),
            });
        }
        Ok(())
    }

    /// Counts a measurement `m` of the total station; a planted blunder
    /// strikes it.
    pub fn measured(&mut self, m: &mut TsMeasurement) {
        self.measurements += 1;
        for f in &self.rules {
            match f.rule {
                FaultRule::Blunder(n, d) if n == self.measurements => m.slope_raw_m += d,
                FaultRule::BlunderAngle(n, a) if n == self.measurements => {
                    m.hz_rad = (m.hz_rad + a).rem_euclid(std::f64::consts::TAU);
                }
                _ => {}
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn faults_parse_and_reject_nonsense() {
        assert_eq!(
            "total-station:after=12".parse::<Fault>(),
            Ok(Fault { device: DeviceKind::TotalStation, rule: FaultRule::After(12) })
        );
        assert_eq!(
            "scanner:every=2".parse::<Fault>(),
            Ok(Fault { device: DeviceKind::Scanner, rule: FaultRule::Every(2) })
        );
        for bad in ["laser:after=1", "tilt", "tilt:every=1", "drive:after=x", "drive:sometimes=3"] {
            let e = bad.parse::<Fault>().expect_err(bad);
            assert!(e.contains(bad), "{e}");
        }
    }
}
