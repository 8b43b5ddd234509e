//! The dance scheduled: the stations and the formation become cycles
//! (leapfrog, parent hops, a robot alone), with the control points and
//! the stations that sight them.

use nalgebra::{Point3, Rotation3, Vector3};

use cps::Instrument;

use crate::control::ControlPoint;
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
    /// The children that move to their position and are measured from the
    /// standing parent at the start of this cycle, in order (all of them in
    /// leapfrog; in parent hops, all at a placement, none in between).
    pub moved: Vec<usize>,
}

/// A complete schedule of a leapfrog dance along a route.
#[derive(Debug, Clone, PartialEq)]
pub struct Dance {
    /// Parent stations; station 0 is the start.
    pub stations: Vec<Station>,
    /// One cycle per station after the first.
    pub cycles: Vec<DanceCycle>,
    /// The control points the parent may sight ([`crate::control`]).
    pub control: Vec<ControlPoint>,
    /// Per station, the control points sighted there (indices into
    /// `control`; empty everywhere without control). Two or more at
    /// station 0 give the start pose by resection.
    pub sightings: Vec<Vec<usize>>,
}

/// Formation offsets (forward, left, up) of each child in the parent frame,
/// metres.
pub type Formation = [Vector3<f64>];

/// Strategy names as written in mission files.
pub const STRATEGIES: [&str; 2] = ["leapfrog", "parent-hops"];

/// How the team advances.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Strategy {
    /// Children move every cycle, then the parent (the seed's dance).
    Leapfrog,
    /// Children are placed every `hops` cycles; the parent makes `hops`
    /// moves and fixes from the same standing children.
    ParentHops {
        /// Parent moves (and fixes) per placement of the children, ≥ 1
        /// (1 is leapfrog).
        hops: usize,
    },
}

impl Strategy {
    /// Parent moves per placement of the children.
    pub fn hops(&self) -> usize {
        match self {
            Strategy::Leapfrog => 1,
            Strategy::ParentHops { hops } => *hops,
        }
    }

    /// The name used in mission files (`leapfrog`, `parent-hops`).
    pub fn name(&self) -> &'static str {
        match self {
            Strategy::Leapfrog => "leapfrog",
            Strategy::ParentHops { .. } => "parent-hops",
        }
    }
}

impl std::fmt::Display for Strategy {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Strategy::Leapfrog => f.write_str("leapfrog"),
            Strategy::ParentHops { hops } => write!(f, "parent-hops ×{hops}"),
        }
    }
}

/// Builds the leapfrog schedule for `stations` with `formation_m` (one offset
/// per child, at least two).
pub fn leapfrog(stations: Vec<Station>, formation_m: &Formation) -> Result<Dance, PlanError> {
    schedule(stations, formation_m, Strategy::Leapfrog)
}

/// Builds the schedule of `strategy` for `stations` with `formation_m` (one
/// offset per child, at least two): the children are placed around station
/// k (`station_k + R(heading_k)·offset`) for every k that is a multiple of
/// the strategy's hops.
pub fn schedule(stations: Vec<Station>, formation_m: &Formation, strategy: Strategy) -> Result<Dance, PlanError> {
    if formation_m.len() < 2 {
        return Err(PlanError::TooFewChildren { got: formation_m.len() });
    }
    let hops = strategy.hops();
    if hops == 0 {
        return Err(PlanError::BadHops { value: hops });
    }
    let mut children = Vec::new();
    let cycles = (1..stations.len())
        .map(|to| {
            let from = to - 1;
            let moved = if from.is_multiple_of(hops) {
                let s = &stations[from];
                let rot = Rotation3::from_axis_angle(&Vector3::z_axis(), s.heading_rad);
                children = formation_m.iter().map(|o| s.position + rot * o).collect();
                (0..formation_m.len()).collect()
            } else {
                Vec::new()
            };
            DanceCycle { cycle: to, from, to, children: children.clone(), moved }
        })
        .collect();
    let sightings = vec![Vec::new(); stations.len()];
    Ok(Dance { stations, cycles, control: Vec::new(), sightings })
}

/// The schedule of a robot alone (no children, no total station): it
/// drives from station to station; every cycle has no children.
pub fn solo(stations: Vec<Station>) -> Dance {
    let cycles = (1..stations.len())
        .map(|to| DanceCycle { cycle: to, from: to - 1, to, children: Vec::new(), moved: Vec::new() })
        .collect();
    let sightings = vec![Vec::new(); stations.len()];
    Dance { stations, cycles, control: Vec::new(), sightings }
}

/// A formation generated from a few parameters, for any number of children
/// (offsets forward, left, up in the parent frame at the placing station).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum FormationKind {
    /// Pairs to either side: pair k at (forward, ±lateral·(k+1)); an odd
    /// last child stands straight ahead at (forward, 0).
    Symmetric {
        /// Forward offset, metres (negative: behind).
        forward_m: f64,
        /// Lateral offset of the first pair, metres (> 0).
        lateral_m: f64,
    },
    /// On an arc of `radius_m` around the parent, spread evenly over
    /// `spread_deg` centred on the heading (`spread_deg` = 0 with one child).
    Fan {
        /// Distance from the parent, metres.
        radius_m: f64,
        /// Angle from the first to the last child, degrees (0 < spread < 360).
        spread_deg: f64,
    },
    /// In a line along the heading: child j at (ahead + j·spacing, 0);
    /// negative `ahead_m` and `spacing_m` put the line behind.
    Line {
        /// Forward offset of the first child, metres.
        ahead_m: f64,
        /// Distance between consecutive children along the line, metres.
        spacing_m: f64,
    },
}

impl FormationKind {
    /// The offsets of `n` children, all at height `up_m` relative to the
    /// parent's instrument.
    pub fn offsets(&self, n: usize, up_m: f64) -> Vec<Vector3<f64>> {
        (0..n)
            .map(|j| match *self {
                FormationKind::Symmetric { forward_m, lateral_m } => {
                    let pair = (j / 2 + 1) as f64;
                    if j + 1 == n && n % 2 == 1 {
                        Vector3::new(forward_m, 0.0, up_m)
                    } else if j % 2 == 0 {
                        Vector3::new(forward_m, lateral_m * pair, up_m)
                    } else {
                        Vector3::new(forward_m, -lateral_m * pair, up_m)
                    }
                }
                FormationKind::Fan { radius_m, spread_deg } => {
                    let a = if n > 1 { spread_deg.to_radians() * (0.5 - j as f64 / (n - 1) as f64) } else { 0.0 };
                    Vector3::new(radius_m * a.cos(), radius_m * a.sin(), up_m)
                }
                FormationKind::Line { ahead_m, spacing_m } => Vector3::new(ahead_m + j as f64 * spacing_m, 0.0, up_m),
            })
            .collect()
    }
}

impl Dance {
    /// The dance with control points and the stations that sight them
    /// (`sightings[station]`, decided by the `sighting` module).
    pub fn with_control(mut self, control: Vec<ControlPoint>, sightings: Vec<Vec<usize>>) -> Self {
        self.control = control;
        self.sightings = sightings;
        self.sightings.resize(self.stations.len(), Vec::new());
        self
    }

    /// Whether the start pose comes from a resection on the control points
    /// sighted from station 0 (two or more).
    pub fn resects_start(&self) -> bool {
        self.sightings.first().is_some_and(|s| s.len() >= 2)
    }

    /// The control points sighted from station `k`.
    pub fn sighted_at(&self, k: usize) -> &[usize] {
        self.sightings.get(k).map_or(&[], Vec::as_slice)
    }

    /// Number of children in the team.
    pub fn n_children(&self) -> usize {
        self.cycles.first().map_or(0, |c| c.children.len())
    }

    /// Nominal parent pose at station `k`.
    pub fn station_pose(&self, k: usize) -> cps::ParentPose {
        let s = &self.stations[k];
        cps::ParentPose { position: s.position, heading_rad: s.heading_rad }
    }

    /// Where child `j` stands during dance cycle `cycle` (1-based), if the
    /// cycle exists.
    pub fn child_at(&self, cycle: usize, j: usize) -> Option<Point3<f64>> {
        self.cycles.get(cycle.checked_sub(1)?)?.children.get(j).copied()
    }

    /// Every sight line that leaves the instrument's range or comes within
    /// [`crate::range::RANGE_MARGIN_M`] of one of its limits, in schedule order.
    pub fn range_violations(&self, instrument: &Instrument) -> Vec<PlanError> {
        let mut out = Vec::new();
        for c in &self.cycles {
            for (phase, station) in [(Phase::Placement, c.from), (Phase::Fix, c.to)] {
                for (child, p) in c.children.iter().enumerate() {
                    if phase == Phase::Placement && !c.moved.contains(&child) {
                        continue;
                    }
                    let range_m = (p - self.stations[station].position).norm();
                    let inside = crate::range::usable(instrument);
                    if instrument.check_range(child, range_m).is_err() || !inside.contains(&range_m) {
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn generated_formations() {
        let s = FormationKind::Symmetric { forward_m: 3.0, lateral_m: 2.0 }.offsets(5, -0.5);
        let xy: Vec<(f64, f64, f64)> = s.iter().map(|o| (o.x, o.y, o.z)).collect();
        assert_eq!(xy, [(3.0, 2.0, -0.5), (3.0, -2.0, -0.5), (3.0, 4.0, -0.5), (3.0, -4.0, -0.5), (3.0, 0.0, -0.5)]);
        let f = FormationKind::Fan { radius_m: 10.0, spread_deg: 90.0 }.offsets(3, 0.0);
        let half = 10.0 * std::f64::consts::FRAC_1_SQRT_2;
        for (o, e) in f.iter().zip([(half, half), (10.0, 0.0), (half, -half)]) {
            assert!((o.x - e.0).abs() < 1e-12 && (o.y - e.1).abs() < 1e-12, "{o:?}");
        }
        let l = FormationKind::Line { ahead_m: -2.0, spacing_m: -3.0 }.offsets(3, 0.0);
        assert_eq!(l.iter().map(|o| o.x).collect::<Vec<_>>(), [-2.0, -5.0, -8.0]);
    }

    #[test]
    fn parent_hops_place_the_children_every_h_stations() {
        let route = [Point3::new(0.0, 0.0, 0.0), Point3::new(35.0, 0.0, 0.0)];
        let formation = FormationKind::Symmetric { forward_m: 6.0, lateral_m: 4.0 }.offsets(2, 0.0);
        let d = schedule(crate::stations(&route, 5.0).expect("route"), &formation, Strategy::ParentHops { hops: 3 })
            .expect("dance");
        let placed: Vec<usize> = d.cycles.iter().filter(|c| !c.moved.is_empty()).map(|c| c.from).collect();
        assert_eq!(placed, [0, 3, 6]);
        // Between placements the children stand still.
        assert_eq!(d.cycles[1].children, d.cycles[0].children);
        assert_eq!(d.cycles[3].children[0], Point3::new(21.0, 4.0, 0.0));
        assert!(matches!(
            schedule(d.stations.clone(), &formation, Strategy::ParentHops { hops: 0 }),
            Err(PlanError::BadHops { value: 0 })
        ));
        assert_eq!(
            leapfrog(d.stations.clone(), &formation)
                .expect("dance")
                .cycles
                .iter()
                .filter(|c| c.moved.len() == 2)
                .count(),
            7
        );
    }
}
