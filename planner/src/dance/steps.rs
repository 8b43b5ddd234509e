//! The dance spelled out as the actions the runner executes.

use nalgebra::Point3;

use super::schedule::Dance;
use crate::error::Phase;

/// A robot of the team.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Robot {
    /// The parent (total station, scanner).
    Parent,
    /// Child `j` (a prism), team order.
    Child(usize),
}

/// One action of a schedule.
#[derive(Debug, Clone, PartialEq)]
pub enum Action {
    /// A child drives in a straight line from `from` to `to` (prism
    /// positions; at its first placement a child starts where it is placed).
    MoveChild {
        /// Child index.
        child: usize,
        /// Start of the move.
        from: Point3<f64>,
        /// End of the move.
        to: Point3<f64>,
    },
    /// The parent, standing at `station`, measures a child.
    Measure {
        /// Child index.
        child: usize,
        /// The parent's station.
        station: usize,
        /// Placement of a child that has moved, or the parent's fix.
        phase: Phase,
    },
    /// The parent, standing at `station`, sights control point `control`.
    Sight {
        /// Index into [`Dance::control`].
        control: usize,
        /// The parent's station.
        station: usize,
    },
    /// The parent drives from station `from` to station `to`.
    MoveParent {
        /// Station left.
        from: usize,
        /// Station reached.
        to: usize,
    },
    /// The parent fixes its pose at `station` from the children and the
    /// control points sighted there (at station 0: a resection).
    Fix {
        /// The station.
        station: usize,
    },
    /// The parent takes a 3D scan at `station`.
    Scan {
        /// The station.
        station: usize,
    },
}

/// One step of a schedule: its index in [`Dance::steps`], the dance cycle it
/// belongs to (0 before the first) and what happens.
#[derive(Debug, Clone, PartialEq)]
pub struct Step {
    /// Position in the schedule, 0-based.
    pub index: usize,
    /// Dance cycle, 1-based (0: the start, before the first cycle).
    pub cycle: usize,
    /// What happens.
    pub action: Action,
}

impl Dance {
    /// The schedule as the runner executes it: at station 0 the sightings of
    /// control (and the resection when two or more are seen), a scan if
    /// due; then per cycle each moved child's move and placement
    /// measurement, the parent's move, its measurement of every child and
    /// of the control points it sees there, its fix, and a scan if one is
    /// due at the new station (`scan_at(station)`).
    pub fn steps(&self, scan_at: impl Fn(usize) -> bool) -> Vec<Step> {
        let mut out = Vec::new();
        let mut push = |cycle, action| {
            let index = out.len();
            out.push(Step { index, cycle, action });
        };
        for &control in self.sighted_at(0) {
            push(0, Action::Sight { control, station: 0 });
        }
        if self.resects_start() {
            push(0, Action::Fix { station: 0 });
        }
        if scan_at(0) {
            push(0, Action::Scan { station: 0 });
        }
        let mut at: Vec<Option<Point3<f64>>> = vec![None; self.n_children()];
        for c in &self.cycles {
            for &j in &c.moved {
                let to = c.children[j];
                let from = at[j].unwrap_or(to);
                at[j] = Some(to);
                push(c.cycle, Action::MoveChild { child: j, from, to });
                push(c.cycle, Action::Measure { child: j, station: c.from, phase: Phase::Placement });
            }
            push(c.cycle, Action::MoveParent { from: c.from, to: c.to });
            for j in 0..c.children.len() {
                push(c.cycle, Action::Measure { child: j, station: c.to, phase: Phase::Fix });
            }
            for &control in self.sighted_at(c.to) {
                push(c.cycle, Action::Sight { control, station: c.to });
            }
            if !c.children.is_empty() {
                push(c.cycle, Action::Fix { station: c.to });
            }
            if scan_at(c.to) {
                push(c.cycle, Action::Scan { station: c.to });
            }
        }
        out
    }
}
