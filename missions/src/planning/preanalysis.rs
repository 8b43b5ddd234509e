//! The pre-analysis of a plan: its network — the planned stations, child
//! placements, control points and nominal readings — adjusted as the run's
//! will be ([`planner::network::pre_analysis`]), before anyone drives. It
//! gives every station's adjusted covariance (what `[acceptance]
//! max_station_sigma_xy_m` is checked against) and every planned reading's
//! redundancy number and MDB: which observations nothing will check.

use cps::batch::Source;
use cps::{Instrument, ParentPose};
use nalgebra::Matrix4;
use planner::Dance;
use planner::network::PointId;

use crate::mission::Mission;

pub use planner::analysis::UNCHECKED_REDUNDANCY;

/// The three scalars of a reading, as the reports name them.
pub const KINDS: [&str; 3] = ["slope_distance", "azimuth", "elevation"];

/// A planned station after the adjustment.
#[derive(Debug, Clone, PartialEq)]
pub struct PlannedStation {
    /// Station index.
    pub index: usize,
    /// Its planned pose.
    pub pose: ParentPose,
    /// Its adjusted covariance (x, y, z, θ).
    pub covariance: Matrix4<f64>,
}

impl PlannedStation {
    /// √(σx² + σy²), metres.
    pub fn sigma_xy_m(&self) -> f64 {
        cps::sigma_xy2(&self.covariance).sqrt()
    }
}

/// A planned observation's reliability.
#[derive(Debug, Clone, PartialEq)]
pub struct PlannedObservation {
    /// The station it is measured from.
    pub station: usize,
    /// What it is measured to: a control point's name or `child@cycle`.
    pub target: String,
    /// One of [`KINDS`].
    pub kind: &'static str,
    /// Its a-priori σ, m or rad.
    pub sigma: f64,
    /// Its redundancy number.
    pub redundancy: f64,
    /// Its minimal detectable bias, m or rad (none when unchecked).
    pub mdb: Option<f64>,
    /// How far an undetected error of MDB moves its station, metres.
    pub station_shift_m: Option<f64>,
}

/// The adjusted plan.
#[derive(Debug, Clone, PartialEq)]
pub struct PreAnalysis {
    /// Every station.
    pub stations: Vec<PlannedStation>,
    /// Every reading's three scalars, in the order the dance takes them.
    pub observations: Vec<PlannedObservation>,
    /// Observations minus unknowns.
    pub redundancy: usize,
}

impl PreAnalysis {
    /// The plan of `dance` adjusted with `instrument` and the start's
    /// `start_covariance`.
    pub fn of(
        mission: &Mission,
        dance: &Dance,
        instrument: &Instrument,
        start_covariance: &Matrix4<f64>,
    ) -> cps::Result<Self> {
        let (net, a) = planner::network::pre_analysis(dance, instrument, start_covariance)?;
        let stations = (0..a.stations.len())
            .map(|k| PlannedStation { index: k, pose: a.stations[k], covariance: a.station_covariance(k) })
            .collect();
        let observations = a
            .observations
            .iter()
            .filter_map(|o| {
                let Source::Reading(k) = o.source else { return None };
                let r = net.network.readings.get(k)?;
                Some(PlannedObservation {
                    station: r.station,
                    target: point_name(mission, dance, net.points.get(r.point)?),
                    kind: KINDS.get(o.component)?,
                    sigma: o.sigma,
                    redundancy: o.redundancy,
                    mdb: o.mdb,
                    station_shift_m: o.station_shift_m,
                })
            })
            .collect();
        Ok(Self { stations, observations, redundancy: a.redundancy })
    }

    /// The station with the largest adjusted √(σx² + σy²).
    pub fn worst(&self) -> Option<&PlannedStation> {
        self.stations.iter().max_by(|a, b| a.sigma_xy_m().total_cmp(&b.sigma_xy_m()))
    }

    /// The observations nothing checks (redundancy below
    /// [`UNCHECKED_REDUNDANCY`]).
    pub fn unchecked(&self) -> impl Iterator<Item = &PlannedObservation> {
        self.observations.iter().filter(|o| o.redundancy < UNCHECKED_REDUNDANCY)
    }

    /// Of the observations others check, the one whose undetected MDB
    /// would move its station most.
    pub fn worst_mdb(&self) -> Option<&PlannedObservation> {
        self.observations
            .iter()
            .filter(|o| o.redundancy >= UNCHECKED_REDUNDANCY && o.station_shift_m.is_some())
            .max_by(|a, b| a.station_shift_m.unwrap_or(0.0).total_cmp(&b.station_shift_m.unwrap_or(0.0)))
    }
}

/// What a network point is called in the reports: a control point's name,
/// or `child@cycle` for a child's placement.
pub fn point_name(mission: &Mission, dance: &Dance, id: &PointId) -> String {
    match *id {
        PointId::Placement { child, cycle } => {
            format!("{}@{cycle}", mission.children.get(child).map_or("?", String::as_str))
        }
        PointId::Control(k) => dance.control.get(k).map_or_else(|| format!("control {k}"), |c| c.name.clone()),
    }
}
