//! A dance as one network for the batch adjustment ([`cps::batch`]): its
//! stations, one point per child placement (a child that moves is a new
//! point) and one per control point, and every reading in the order the
//! dance takes them ([`reading_order`]) — the planned network (nominal
//! readings: the pre-analysis) or an executed one (a journal's readings, a
//! Monte Carlo trial's).

use cps::batch::{AdjustOptions, Adjustment, Network, NetworkReading, Point, Station};
use cps::{Instrument, ParentPose, Reading};
use nalgebra::Matrix4;

use crate::control::sighting_instrument;
use crate::dance::Dance;

/// What a point of the network is.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PointId {
    /// Child `child` placed in cycle `cycle` (1-based).
    Placement {
        /// The child (team order).
        child: usize,
        /// The cycle that placed it.
        cycle: usize,
    },
    /// Control point `k` of [`Dance::control`].
    Control(usize),
}

/// What one reading of the dance is of.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Taken {
    /// Child `child` placed in `cycle`, from the standing parent at `station`.
    Placement {
        /// The cycle.
        cycle: usize,
        /// The child.
        child: usize,
        /// The standing parent's station.
        station: usize,
    },
    /// Child `child` from the parent moved to `station` for its fix.
    Fix {
        /// The cycle.
        cycle: usize,
        /// The child.
        child: usize,
        /// The station.
        station: usize,
    },
    /// Control point `control` from `station` (cycle 0: the start).
    Control {
        /// The cycle.
        cycle: usize,
        /// The control point.
        control: usize,
        /// The station.
        station: usize,
    },
}

impl Taken {
    /// The station the reading is taken from.
    pub fn station(&self) -> usize {
        match *self {
            Taken::Placement { station, .. } | Taken::Fix { station, .. } | Taken::Control { station, .. } => station,
        }
    }
}

/// Every reading of `dance` in the order it takes them: the control points
/// sighted from the start; then per cycle the moved children's placements,
/// every child from the new station, the control points sighted there.
pub fn reading_order(dance: &Dance) -> Vec<Taken> {
    let mut out: Vec<Taken> =
        dance.sighted_at(0).iter().map(|&control| Taken::Control { cycle: 0, control, station: 0 }).collect();
    for c in &dance.cycles {
        out.extend(c.moved.iter().map(|&child| Taken::Placement { cycle: c.cycle, child, station: c.from }));
        out.extend((0..c.children.len()).map(|child| Taken::Fix { cycle: c.cycle, child, station: c.to }));
        out.extend(dance.sighted_at(c.to).iter().map(|&control| Taken::Control {
            cycle: c.cycle,
            control,
            station: c.to,
        }));
    }
    out
}

/// A dance's network and what each of its points is.
#[derive(Debug, Clone, PartialEq)]
pub struct DanceNetwork {
    /// The network.
    pub network: Network,
    /// `points[k]` is network point k.
    pub points: Vec<PointId>,
    /// `taken[k]` is what network reading k is.
    pub taken: Vec<Taken>,
}

/// The network of `dance` from `readings` taken in [`reading_order`] (a
/// prefix of it for a run that stopped early: the stations reached by then
/// and the readings among them), with `stations` the approximate poses of
/// the stations reached (their filter estimates) and the start's prior
/// `start_covariance` (unless the start is resected on control).
pub fn build(
    dance: &Dance,
    instrument: &Instrument,
    start_covariance: &Matrix4<f64>,
    stations: &[ParentPose],
    readings: &[Reading],
) -> cps::Result<DanceNetwork> {
    let order = reading_order(dance);
    let n_stations = stations.len().min(dance.stations.len());
    let sighting = sighting_instrument(instrument);
    let mut network = Network {
        stations: stations[..n_stations].iter().map(|p| Station { pose: *p, prior: None }).collect(),
        points: Vec::new(),
        readings: Vec::new(),
    };
    if let (false, Some(s)) = (dance.resects_start(), network.stations.first_mut()) {
        s.prior = Some(*start_covariance);
    }
    let mut points = Vec::new();
    let mut control: Vec<Option<usize>> = vec![None; dance.control.len()];
    let mut current: Vec<Option<usize>> = vec![None; dance.n_children()];
    let mut taken = Vec::new();
    for (t, reading) in order.iter().zip(readings) {
        if t.station() >= n_stations {
            continue;
        }
        let (point, covariance) = match *t {
            Taken::Placement { cycle, child, station } => {
                let placed = cps::place(&network.stations[station].pose, reading, child)?;
                network.points.push(Point { position: placed.position, prior: None });
                points.push(PointId::Placement { child, cycle });
                current[child] = Some(network.points.len() - 1);
                (network.points.len() - 1, instrument.reading_covariance(reading))
            }
            Taken::Fix { child, .. } => {
                let Some(p) = current.get(child).copied().flatten() else { continue };
                (p, instrument.reading_covariance(reading))
            }
            Taken::Control { control: k, .. } => {
                let p = match control[k] {
                    Some(p) => p,
                    None => {
                        let c = &dance.control[k];
                        network
                            .points
                            .push(Point { position: c.position, prior: Some(c.prism_covariance(instrument)) });
                        points.push(PointId::Control(k));
                        control[k] = Some(network.points.len() - 1);
                        network.points.len() - 1
                    }
                };
                (p, sighting.reading_covariance(reading))
            }
        };
        network.readings.push(NetworkReading { station: t.station(), point, reading: *reading, covariance });
        taken.push(*t);
    }
    Ok(DanceNetwork { network, points, taken })
}

/// The planned network: nominal stations and readings — what the batch
/// adjustment predicts before anyone drives.
pub fn planned(dance: &Dance, instrument: &Instrument, start_covariance: &Matrix4<f64>) -> cps::Result<DanceNetwork> {
    let read = crate::dance::nominal_reading(dance);
    let readings = reading_order(dance)
        .iter()
        .map(|t| {
            let from = dance.station_pose(t.station());
            match *t {
                Taken::Placement { cycle, child, .. } | Taken::Fix { cycle, child, .. } => {
                    let at = dance
                        .child_at(cycle, child)
                        .ok_or(cps::CpsError::UnknownChild { child, team: dance.n_children() })?;
                    read(&from, crate::Sighted::Child(&at))
                }
                Taken::Control { control, .. } => read(&from, crate::Sighted::Control(control)),
            }
        })
        .collect::<cps::Result<Vec<_>>>()?;
    let stations: Vec<ParentPose> = (0..dance.stations.len()).map(|k| dance.station_pose(k)).collect();
    build(dance, instrument, start_covariance, &stations, &readings)
}

/// The pre-analysis: the planned network ([`planned`]) adjusted — every
/// station's covariance and every planned reading's redundancy number and
/// MDB with the default test settings (no snooping: nothing to remove).
pub fn pre_analysis(
    dance: &Dance,
    instrument: &Instrument,
    start_covariance: &Matrix4<f64>,
) -> cps::Result<(DanceNetwork, Adjustment)> {
    let net = planned(dance, instrument, start_covariance)?;
    let options = AdjustOptions { snooping: false, ..AdjustOptions::default() };
    let adjustment = cps::batch::adjust(&net.network, &options)?;
    Ok((net, adjustment))
}

/// The adjusted station with the largest √(σx² + σy²): (index, metres).
pub fn worst_station(adjustment: &Adjustment) -> Option<(usize, f64)> {
    (0..adjustment.stations.len())
        .map(|k| (k, cps::sigma_xy2(&adjustment.station_covariance(k)).sqrt()))
        .max_by(|a, b| a.1.total_cmp(&b.1))
}
