//! Control points: reflectors at given coordinates that the parent sights
//! from its stations, tying the dance to a datum. Which station sees which
//! control point is the planner's decision — within the instrument's range,
//! in line of sight against the scene — and part of the [`Dance`].
//!
//! **Centring.** A control prism is set up over its monument once for the
//! whole survey: its centring error (the instrument's `centring_target_m`,
//! horizontal) is one offset shared by every sighting of it. It is
//! therefore carried in the prism's position — covariance = the given
//! coordinates' + c_t² in x and y ([`ControlPoint::prism_covariance`]) —
//! and left out of each sighting's reading ([`sighting_instrument`]); the
//! readings of one control point are correlated through it.

use nalgebra::{Matrix3, Point3};

use cps::geom::Scene;
use cps::{Instrument, ParentPose, observe};

use crate::dance::Dance;

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

/// Why a station does not see a control point (for `plan`'s listing).
#[derive(Debug, Clone, PartialEq)]
pub enum Unseen {
    /// Not a station that sights control (`control_at`).
    NotScheduled,
    /// Beyond the instrument's range (the slope distance, metres).
    OutOfRange(f64),
    /// Straight above or below the instrument.
    Vertical,
    /// Something of the scene is in the way (its name, the distance to it).
    Blocked(String, f64),
}

/// Whether the parent at `station` sees the prism at `point`: a regular
/// sight line within the instrument's range and, with a scene, unblocked.
pub fn visibility(
    station: &ParentPose,
    point: &Point3<f64>,
    instrument: &Instrument,
    scene: Option<&Scene>,
) -> Result<f64, Unseen> {
    let reading = observe(station, point).map_err(|_| Unseen::Vertical)?;
    if reading.validate(0).is_err() {
        return Err(Unseen::Vertical);
    }
    // The documented margin inside the range, as for the children's sight
    // lines (issue 34, S9: a point 0.1 mm away with min_range_m = 0 was
    // "seen from station 0 (0.0 m)").
    let margin = crate::dance::RANGE_MARGIN_M;
    if reading.slope_m < instrument.min_range_m + margin || reading.slope_m > instrument.max_range_m - margin {
        return Err(Unseen::OutOfRange(reading.slope_m));
    }
    if let Some(scene) = scene
        && let Some(hit) = scene.obstruction(&station.position, point)
    {
        return Err(Unseen::Blocked(scene.object_name(hit.object).to_string(), hit.distance_m));
    }
    Ok(reading.slope_m)
}

/// For every station of `dance` where `sights_at(station)`, the control
/// points it sees (index into `control`, in order).
pub fn sightings(
    dance: &Dance,
    control: &[ControlPoint],
    sights_at: &dyn Fn(usize) -> bool,
    instrument: &Instrument,
    scene: Option<&Scene>,
) -> Vec<Vec<usize>> {
    (0..dance.stations.len())
        .map(|k| {
            if !sights_at(k) {
                return Vec::new();
            }
            let pose = dance.station_pose(k);
            (0..control.len()).filter(|&c| visibility(&pose, &control[c].position, instrument, scene).is_ok()).collect()
        })
        .collect()
}

/// `dance` with `control` sighted at the stations `at` names, where they
/// are seen; or the control points no station sees (index into `control`).
pub fn attach(
    dance: Dance,
    control: &[ControlPoint],
    at: &ControlAt,
    instrument: &Instrument,
    scene: Option<&Scene>,
) -> Result<Dance, Vec<usize>> {
    if control.is_empty() {
        return Ok(dance);
    }
    let n = dance.stations.len();
    let seen = sightings(&dance, control, &|k| at.includes(k, n), instrument, scene);
    let unseen: Vec<usize> = (0..control.len()).filter(|c| !seen.iter().any(|s| s.contains(c))).collect();
    if !unseen.is_empty() {
        return Err(unseen);
    }
    Ok(dance.with_control(control.to_vec(), seen))
}

/// How many stations sight control in `dance` (each a setup that costs
/// time in the field).
pub fn setups(dance: &Dance) -> usize {
    dance.sightings.iter().filter(|s| !s.is_empty()).count()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_station_sees_what_is_in_range_and_unblocked() {
        let scene = cps::geom::builtin("hall").expect("hall");
        let inst = Instrument { min_range_m: 1.5, max_range_m: 30.0, ..Instrument::default() };
        let station = ParentPose::new(5.0, 4.2, 1.5, 0.0);
        // Along the hall's free strip: seen.
        assert!(visibility(&station, &Point3::new(0.3, 4.2, 1.0), &inst, Some(&scene)).is_ok());
        // Too close, too far, straight up.
        assert!(matches!(visibility(&station, &Point3::new(5.5, 4.2, 1.5), &inst, None), Err(Unseen::OutOfRange(_))));
        assert!(matches!(visibility(&station, &Point3::new(39.0, 4.2, 1.5), &inst, None), Err(Unseen::OutOfRange(_))));
        assert_eq!(visibility(&station, &Point3::new(5.0, 4.2, 5.0), &inst, None), Err(Unseen::Vertical));
        // Within the 5 cm margin of a limit: not planned as seen (S9).
        assert!(matches!(visibility(&station, &Point3::new(6.52, 4.2, 1.5), &inst, None), Err(Unseen::OutOfRange(_))));
        assert!(visibility(&station, &Point3::new(6.56, 4.2, 1.5), &inst, None).is_ok());
        let from_zero = Instrument { min_range_m: 0.0, ..inst };
        let touching = visibility(&station, &Point3::new(5.0, 4.2001, 1.5), &from_zero, None);
        assert!(matches!(touching, Err(Unseen::OutOfRange(_))), "{touching:?}");
        // Through a pillar (the hall's pillars stand at y = 6 m).
        let behind =
            visibility(&ParentPose::new(10.0, 3.0, 1.5, 0.0), &Point3::new(10.0, 9.0, 1.5), &inst, Some(&scene));
        assert!(matches!(behind, Err(Unseen::Blocked(_, _))), "{behind:?}");
    }
}
