//! Control points: reflectors at given coordinates that the parent sights
//! from its stations, tying the dance to a datum, and the stations asked to
//! sight them ([`ControlAt`]). Which station sees which control point is the
//! planner's decision (the `sighting` module).
//!
//! **Centring.** A control prism is set up over its monument once for the
//! whole survey: its centring error (the instrument's `centring_target_m`,
//! horizontal) is one offset shared by every sighting of it. It is
//! therefore carried in the prism's position — covariance = the given
//! coordinates' + c_t² in x and y ([`ControlPoint::prism_covariance`]) —
//! and left out of each sighting's reading ([`sighting_instrument`]); the
//! readings of one control point are correlated through it.

use nalgebra::{Matrix3, Point3};

use cps::Instrument;

/// A control point.
#[derive(Debug, Clone, PartialEq)]
pub struct ControlPoint {
    /// Its name.
    pub name: String,
    /// Its given coordinates, world frame, metres.
    pub position: Point3<f64>,
    /// Their covariance (x, y, z), m²; a zero variance holds the coordinate
    /// fixed.
    pub covariance: Matrix3<f64>,
}

impl ControlPoint {
    /// The covariance of its prism's position: the given coordinates' and
    /// the prism's centring (horizontal, common to every sighting).
    pub fn prism_covariance(&self, instrument: &Instrument) -> Matrix3<f64> {
        let c2 = instrument.centring_target_m.powi(2);
        self.covariance + Matrix3::from_diagonal(&nalgebra::Vector3::new(c2, c2, 0.0))
    }
}

/// The noise model of a sighting of a control prism: the instrument's,
/// without the prism's centring (carried in the prism's position).
pub fn sighting_instrument(instrument: &Instrument) -> Instrument {
    instrument.without_target_centring()
}

/// The stations where the parent also sights every control point within
/// the instrument's range and in line of sight (`[plan] control_at`).
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub enum ControlAt {
    /// Every station (`"every"`, the default).
    #[default]
    Every,
    /// The first and the last (`"start-end"`).
    StartEnd,
    /// These stations (`[0, 5, 11]`).
    Stations(Vec<usize>),
}

impl ControlAt {
    /// Whether station `k` of `n` sights control.
    pub fn includes(&self, k: usize, n: usize) -> bool {
        match self {
            ControlAt::Every => true,
            ControlAt::StartEnd => k == 0 || k + 1 == n,
            ControlAt::Stations(list) => list.contains(&k),
        }
    }

    /// The first station index it names that a plan of `n` stations does
    /// not have.
    pub fn missing(&self, n: usize) -> Option<usize> {
        match self {
            ControlAt::Stations(list) => list.iter().find(|k| **k >= n).copied(),
            _ => None,
        }
    }
}

impl std::fmt::Display for ControlAt {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            ControlAt::Every => write!(f, "\"every\""),
            ControlAt::StartEnd => write!(f, "\"start-end\""),
            ControlAt::Stations(list) => {
                let list: Vec<String> = list.iter().map(usize::to_string).collect();
                write!(f, "[{}]", list.join(", "))
            }
        }
    }
}
