//! What the journal holds: its versions, the typed events and their
//! records, and the steps a replay hands back.

use anyhow::{Result, bail};
use scanner::{TsMeasurement, TsStatus};
use serde::{Deserialize, Serialize};

use crate::documents::records::{Matrix4Rows, Pose, nested};

/// The schema version this build writes.
pub const VERSION: u32 = 3;

/// Versions this build reads.
pub const READS: [u32; 3] = [1, 2, 3];

/// One line of the journal: the version and the event.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub(super) struct Line {
    #[serde(flatten)]
    pub(super) event: Event,
    pub(super) v: u32,
}

/// A journal event, tagged by `"event"`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "event", rename_all = "snake_case")]
pub enum Event {
    /// The run starts: what it is.
    Start(Start),
    /// A robot drove (`data`: the distance its odometry reports).
    Drive(Recorded<DriveKey, Driven>),
    /// A total-station measurement, in the instrument's convention.
    Measure(Recorded<MeasureKey, Measured>),
    /// A tilt reading at a scan station.
    Tilt(Recorded<StationKey, Tilted>),
    /// A 3D scan, written to its file before this event names it.
    Scan(Recorded<StationKey, Scanned>),
    /// A parent fix (or, for a robot alone, the odometry's pose) — derived.
    Fix(Derived<FixKey, FixRecord>),
    /// The run ended — derived.
    End(Derived<EndKey, EndRecord>),
    /// A device command failed and is tried again.
    Retry(Retry),
    /// A device failed beyond its retries: the run stopped.
    Stop(Stop),
    /// A resumed run continues live from here.
    Resume,
}

/// `start`: the run's identity, checked when it is resumed.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Start {
    /// `[mission] name`.
    pub mission: String,
    /// The simulator's seed.
    pub seed: u64,
    /// The scene's name (or the scene file as written).
    pub scene: String,
    /// Parent stations planned.
    pub stations: usize,
    /// The children's names, team order.
    pub children: Vec<String>,
}

/// A device step as journaled: its key (what was commanded), its reading
/// and the team's state after it (the simulator's whole state, or on serial
/// ports the parent's odometry).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Recorded<K, D> {
    /// What was commanded.
    #[serde(flatten)]
    pub key: K,
    /// What the device answered.
    pub data: D,
    /// The team's state after the step.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sim: Option<Checkpoint>,
    /// When the step was done, UNIX seconds (UTC), on real instruments
    /// (version 3; the simulator's steps take the mission clock).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub unix_time_s: Option<f64>,
}

/// A result the run derives, as journaled.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Derived<K, D> {
    /// Which result.
    #[serde(flatten)]
    pub key: K,
    /// The result.
    pub data: D,
}

/// `drive`: which robot, in which cycle, to where.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct DriveKey {
    /// Dance cycle, 1-based.
    pub cycle: usize,
    /// `parent` or the child's name.
    pub robot: String,
    /// The goal: x, y (m) and heading (rad).
    pub target: [f64; 3],
}

/// What a measurement is for.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Phase {
    /// The standing parent places a child.
    Placement,
    /// The parent, moved, measures a standing child for its fix.
    Fix,
    /// The parent sights a control point (version 2).
    Control,
}

/// `measure`: which prism, in which cycle, for what.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct MeasureKey {
    /// Dance cycle, 1-based (0: at the start).
    pub cycle: usize,
    /// Placement, fix or control.
    pub phase: Phase,
    /// The child's index, team order (placement and fix).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub child: Option<usize>,
    /// The control point's name (control).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub control: Option<String>,
    /// 0 for the first measurement of this prism for this purpose; 1, 2, …
    /// for each time a fix's field test had it measured again (issue 34,
    /// S7). The later attempt supersedes the earlier, which stays here.
    #[serde(default, skip_serializing_if = "is_first")]
    pub attempt: u32,
}

/// Serde's test for a first attempt (not written, as journals before
/// attempts were).
fn is_first(attempt: &u32) -> bool {
    *attempt == 0
}

/// `tilt`, `scan`: at which station.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct StationKey {
    /// Parent station, 0 = the start.
    pub station: usize,
}

/// `fix`: which cycle, which station.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct FixKey {
    /// Dance cycle, 1-based.
    pub cycle: usize,
    /// The station the parent fixed itself at.
    pub station: usize,
}

/// `end` has no key.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct EndKey {}

/// A drive's report.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Driven {
    /// Distance the odometry reports, metres.
    pub distance_m: f64,
}

/// A total-station measurement in the instrument's convention.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Measured {
    /// Slope distance before the prism constant, metres.
    pub slope_raw_m: f64,
    /// Horizontal direction, clockwise, radians.
    pub hz_rad: f64,
    /// Zenith angle, radians.
    pub v_rad: f64,
    /// The instrument flagged the measurement as of reduced accuracy.
    pub reduced_accuracy: bool,
}

impl Measured {
    /// The record of a measurement.
    pub fn new(m: TsMeasurement) -> Self {
        Self {
            slope_raw_m: m.slope_raw_m,
            hz_rad: m.hz_rad,
            v_rad: m.v_rad,
            reduced_accuracy: m.status == TsStatus::ReducedAccuracy,
        }
    }

    /// The measurement in the instrument's terms.
    pub fn measurement(&self) -> TsMeasurement {
        TsMeasurement {
            slope_raw_m: self.slope_raw_m,
            hz_rad: self.hz_rad,
            v_rad: self.v_rad,
            status: if self.reduced_accuracy { TsStatus::ReducedAccuracy } else { TsStatus::Ok },
        }
    }
}

/// A tilt reading.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Tilted {
    /// Roll, radians.
    pub roll_rad: f64,
    /// Pitch, radians.
    pub pitch_rad: f64,
}

/// A scan written to the run directory.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Scanned {
    /// Its file, relative to the run directory.
    pub file: String,
    /// Points in it.
    pub points: usize,
    /// CRC-32 (IEEE) of the file's bytes, 8 hex digits (version 2).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub crc32: Option<String>,
    /// When the scan was taken: UNIX seconds, UTC (version 2).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub unix_time_s: Option<f64>,
}

/// A parent fix: the pose, its covariance and the fix's statistics; for a
/// robot alone the odometry's pose (`source`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FixRecord {
    /// The estimated pose.
    pub pose: Pose,
    /// Its 4×4 covariance (x, y, z, θ).
    pub covariance: Matrix4Rows,
    /// The fix's a-posteriori variance factor.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sigma0_squared: Option<f64>,
    /// The fix's redundancy.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub redundancy: Option<usize>,
    /// cov(this station, each earlier scan station), 4×4 each, in scan
    /// order (versions 1 and 2).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub scan_cross_covariances: Option<Vec<Matrix4Rows>>,
    /// How the team state here depends on the last scan station's
    /// (version 3), from which the scan stations' joint covariance is
    /// rebuilt.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub chain: Option<ChainRecord>,
    /// `odometry` for a robot alone.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub source: Option<String>,
}

/// A fix's link in the chain of scan stations ([`cps::chain::ChainLink`]).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ChainRecord {
    /// cov(X, p): each state's row (parent x, y, z, θ, then each child's
    /// and each control point's x, y, z) against the parent's x, y, z, θ.
    pub parent_columns: Vec<[f64; 4]>,
    /// ∂(parent and children)/∂X at the last scan station, row by row;
    /// absent before the first scan.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub from_last_scan: Option<Vec<Vec<f64>>>,
}

impl ChainRecord {
    /// The team's link now ([`cps::TeamState::set_anchor`]).
    pub fn of(team: &cps::TeamState) -> Self {
        let c = team.covariance();
        let m = c.nrows() - 4 * team.clones();
        Self {
            parent_columns: (0..m).map(|r| [c[(r, 0)], c[(r, 1)], c[(r, 2)], c[(r, 3)]]).collect(),
            from_last_scan: team.from_anchor().map(nested),
        }
    }

    /// The link, checked for its shape: `what` names it in errors.
    pub fn link(&self, what: &str) -> Result<cps::chain::ChainLink> {
        let parent_columns = nalgebra::DMatrix::from_fn(self.parent_columns.len(), 4, |r, c| self.parent_columns[r][c]);
        let from_previous = match &self.from_last_scan {
            None => None,
            Some(rows) => {
                let width = rows.first().map_or(0, Vec::len);
                if let Some(r) = rows.iter().position(|r| r.len() != width) {
                    bail!("{what}: chain.from_last_scan row {r} has {} values, row 0 {width}", rows[r].len());
                }
                Some(nalgebra::DMatrix::from_fn(rows.len(), width, |r, c| rows[r][c]))
            }
        };
        Ok(cps::chain::ChainLink { parent_columns, from_previous })
    }
}

/// The end of a run.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct EndRecord {
    /// Whether the acceptance held.
    pub accepted: bool,
}

/// Which step a `retry` or `stop` was about.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "event", rename_all = "snake_case")]
pub enum StepKey {
    /// A drive.
    Drive(DriveKey),
    /// A measurement.
    Measure(MeasureKey),
    /// A tilt reading.
    Tilt(StationKey),
    /// A scan.
    Scan(StationKey),
}

/// `retry`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Retry {
    /// `drive`, `total-station`, `tilt` or `scanner`.
    pub device: String,
    /// 1 for the first retry.
    pub attempt: u32,
    /// What failed.
    pub error: String,
    /// The step.
    pub step: StepKey,
}

/// `stop`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Stop {
    /// The device.
    pub device: String,
    /// The last failure.
    pub error: String,
    /// The step.
    pub step: StepKey,
}

/// A robot's state in a checkpoint: its pose as its odometry believes it,
/// its true pose (simulator) and its noise stream's position.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct DriveState {
    /// x, y (m), heading (rad) as the odometry believes.
    pub believed: [f64; 3],
    /// The true x, y, heading (simulator only).
    #[serde(rename = "true", default, skip_serializing_if = "Option::is_none")]
    pub truth: Option<[f64; 3]>,
    /// Position in the drive's noise stream, decimal (simulator only).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub noise: Option<String>,
}

/// The simulated instruments' noise-stream positions, decimal strings (a
/// u128 does not fit every reader's JSON numbers).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct NoiseState {
    /// The total station's (none without children).
    pub total_station: Option<String>,
    /// The tilt sensor's.
    pub tilt: String,
    /// The laser scanner's.
    pub scanner: String,
    /// The total station's measurements so far (version 2).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub measurements: Option<usize>,
}

/// The simulated world's truth.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TruthRecord {
    /// The parent: x, y, z, heading.
    pub parent: [f64; 4],
    /// Its roll and pitch.
    pub tilt: [f64; 2],
    /// Every child's prism, x, y, z.
    pub children: Vec<[f64; 3]>,
    /// The scan head's angle, radians.
    pub head_rad: f64,
}

/// The team's state after a step: on the simulator everything needed to
/// continue bit for bit; on serial ports the parent's odometry
/// (`drives[0].believed`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Checkpoint {
    /// The parent's drive first, then the children's.
    pub drives: Vec<DriveState>,
    /// The instruments' noise streams (simulator only).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub noise: Option<NoiseState>,
    /// The truth (simulator only).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub truth: Option<TruthRecord>,
}

impl Checkpoint {
    /// The parent's odometry.
    pub fn parent_believed(&self) -> Option<scanner::PlanarPose> {
        let b = self.drives.first()?.believed;
        Some(scanner::PlanarPose { x_m: b[0], y_m: b[1], heading_rad: b[2] })
    }
}

impl Event {
    /// The event's name, as in the file.
    pub fn name(&self) -> &'static str {
        match self {
            Event::Start(_) => "start",
            Event::Drive(_) => "drive",
            Event::Measure(_) => "measure",
            Event::Tilt(_) => "tilt",
            Event::Scan(_) => "scan",
            Event::Fix(_) => "fix",
            Event::End(_) => "end",
            Event::Retry(_) => "retry",
            Event::Stop(_) => "stop",
            Event::Resume => "resume",
        }
    }

    /// Whether a replay skips it (it records what happened but is no step).
    pub fn informational(&self) -> bool {
        matches!(self, Event::Retry(_) | Event::Stop(_) | Event::Resume)
    }

    /// Whether both are the same derived step (`fix` of one cycle and
    /// station, or `end`), whatever their data.
    pub fn same_derived_step(&self, other: &Event) -> bool {
        match (self, other) {
            (Event::Fix(a), Event::Fix(b)) => a.key == b.key,
            (Event::End(_), Event::End(_)) => true,
            _ => false,
        }
    }

    /// The event as one JSON line (without the version), for messages.
    pub fn describe(&self) -> String {
        serde_json::to_string(self).unwrap_or_else(|_| self.name().to_string())
    }
}

/// The key of a journaled step and the event that carries it with its data.
pub trait Step: Sized {
    /// What identifies the step.
    type Key: PartialEq + Clone + Serialize;
    /// The event of a recorded step.
    fn event(recorded: Recorded<Self::Key, Self>) -> Event;
    /// The recorded step in `event`, if it is one of this kind.
    fn recorded(event: Event) -> Option<Recorded<Self::Key, Self>>;
}

macro_rules! step {
    ($data:ty, $key:ty, $variant:ident) => {
        impl Step for $data {
            type Key = $key;
            fn event(recorded: Recorded<$key, $data>) -> Event {
                Event::$variant(recorded)
            }
            fn recorded(event: Event) -> Option<Recorded<$key, $data>> {
                match event {
                    Event::$variant(r) => Some(r),
                    _ => None,
                }
            }
        }
    };
}

step!(Driven, DriveKey, Drive);
step!(Measured, MeasureKey, Measure);
step!(Tilted, StationKey, Tilt);
step!(Scanned, StationKey, Scan);
