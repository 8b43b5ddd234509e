//! The leapfrog dance (seed 003 Fig. 1): at station k each child moves to
//! `station_k + R(heading_k)·formation_m[j]` and is measured from the standing
//! parent; then the parent moves to station k+1 and fixes itself from all
//! children.

use nalgebra::{Point3, Rotation3, Vector3};

use cps::{FixOptions, Instrument, ParentPose, Reading, TeamState};

use crate::error::{Phase, PlanError};
use crate::route::Station;

/// One dance cycle: children placed around station `from`, parent fixed at
/// station `to`.
#[derive(Debug, Clone, PartialEq)]
pub struct DanceCycle {
    /// Cycle number, 1-based.
    pub cycle: usize,
    /// Index of the station the children are measured from.
    pub from: usize,
    /// Index of the station the parent moves to and fixes itself at.
    pub to: usize,
    /// Nominal prism positions of the children during this cycle, team order.
    pub children: Vec<Point3<f64>>,
}

/// A complete schedule of a leapfrog dance along a route.
#[derive(Debug, Clone, PartialEq)]
pub struct Dance {
    /// Parent stations; station 0 is the start.
    pub stations: Vec<Station>,
    /// One cycle per station after the first.
    pub cycles: Vec<DanceCycle>,
}

/// Formation offsets (forward, left, up) of each child in the parent frame,
/// metres.
pub type Formation = [Vector3<f64>];

/// Builds the leapfrog schedule for `stations` with `formation_m` (one offset
/// per child, at least two).
pub fn leapfrog(stations: Vec<Station>, formation_m: &Formation) -> Result<Dance, PlanError> {
    if formation_m.len() < 2 {
        return Err(PlanError::TooFewChildren { got: formation_m.len() });
    }
    let cycles = (1..stations.len())
        .map(|to| {
            let s = &stations[to - 1];
            let rot = Rotation3::from_axis_angle(&Vector3::z_axis(), s.heading_rad);
            DanceCycle {
                cycle: to,
                from: to - 1,
                to,
                children: formation_m.iter().map(|o| s.position + rot * o).collect(),
            }
        })
        .collect();
    Ok(Dance { stations, cycles })
}

/// The schedule of a robot alone (no children, no total station): it
/// drives from station to station; every cycle has no children.
pub fn solo(stations: Vec<Station>) -> Dance {
    let cycles =
        (1..stations.len()).map(|to| DanceCycle { cycle: to, from: to - 1, to, children: Vec::new() }).collect();
    Dance { stations, cycles }
}

impl Dance {
    /// Number of children in the team.
    pub fn n_children(&self) -> usize {
        self.cycles.first().map_or(0, |c| c.children.len())
    }

    /// Nominal parent pose at station `k`.
    pub fn station_pose(&self, k: usize) -> cps::ParentPose {
        let s = &self.stations[k];
        cps::ParentPose { position: s.position, heading_rad: s.heading_rad }
    }

    /// Every sight line that leaves the instrument's range, in schedule order.
    pub fn range_violations(&self, instrument: &Instrument) -> Vec<PlanError> {
        let mut out = Vec::new();
        for c in &self.cycles {
            for (phase, station) in [(Phase::Placement, c.from), (Phase::Fix, c.to)] {
                for (child, p) in c.children.iter().enumerate() {
                    let range_m = (p - self.stations[station].position).norm();
                    if instrument.check_range(child, range_m).is_err() {
                        out.push(PlanError::ChildOutOfRange {
                            cycle: c.cycle,
                            child,
                            phase,
                            range_m,
                            min_m: instrument.min_range_m,
                            max_m: instrument.max_range_m,
                        });
                    }
                }
            }
        }
        out
    }
}

/// Runs `dance` through `team`: in every cycle each child is placed from the
/// reading `read(station, child)` taken at the standing parent's nominal
/// station, then the parent fixes itself at the next station from fresh
/// readings; `after_fix` sees the team after each fix. With
/// `start_at_nominal`, Gauss–Newton starts at the planned station instead of
/// the closed-form start (prediction: the readings are exact).
pub fn run_dance(
    dance: &Dance,
    team: &mut TeamState,
    instrument: &Instrument,
    start_at_nominal: bool,
    mut read: impl FnMut(&ParentPose, &Point3<f64>) -> cps::Result<Reading>,
    mut after_fix: impl FnMut(&DanceCycle, &TeamState),
) -> Result<(), PlanError> {
    let mut readings = Vec::with_capacity(dance.n_children());
    for c in &dance.cycles {
        let model = |source| PlanError::Model { cycle: c.cycle, source };
        let from = dance.station_pose(c.from);
        for (j, child) in c.children.iter().enumerate() {
            let reading = read(&from, child).map_err(model)?;
            team.place_child(j, &reading, instrument).map_err(model)?;
        }
        let to = dance.station_pose(c.to);
        readings.clear();
        for (j, child) in c.children.iter().enumerate() {
            readings.push((j, read(&to, child).map_err(model)?));
        }
        let options = FixOptions { initial: start_at_nominal.then_some(to), ..FixOptions::default() };
        team.fix_parent(&readings, instrument, &options).map_err(model)?;
        after_fix(c, team);
    }
    Ok(())
}
