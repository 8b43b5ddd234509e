//! The network a batch adjustment estimates: stations (x, y, z, θ) and
//! points (x, y, z), each free, weighted by an a-priori covariance or held
//! fixed coordinate by coordinate, and the readings between them; the
//! unknowns' layout and the observation groups the adjustment linearises.

use nalgebra::{DMatrix, DVector, Matrix3, Matrix4, Point3};

use crate::error::{CpsError, Result};
use crate::observation::{ParentPose, Reading, observe_with_jacobians, wrap_angle};

/// A parent station of the network.
#[derive(Debug, Clone, PartialEq)]
pub struct Station {
    /// Its approximate pose — and, with a prior, the prior's mean.
    pub pose: ParentPose,
    /// `None`: free. `Some(Σ)`: weighted by Σ (x, y, z, θ), a coordinate
    /// of zero variance held fixed.
    pub prior: Option<Matrix4<f64>>,
}

/// A point of the network: a child placement or a control point.
#[derive(Debug, Clone, PartialEq)]
pub struct Point {
    /// Its approximate position — and, with a prior, the prior's mean.
    pub position: Point3<f64>,
    /// `None`: free. `Some(Σ)`: weighted by Σ (x, y, z), a coordinate of
    /// zero variance held fixed.
    pub prior: Option<Matrix3<f64>>,
}

/// One pointing: station → point, its reading and the reading's covariance
/// (r, φ, ψ; m and rad).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NetworkReading {
    /// Index into [`Network::stations`].
    pub station: usize,
    /// Index into [`Network::points`].
    pub point: usize,
    /// The reading (prism constant applied), CPS convention.
    pub reading: Reading,
    /// Its covariance, order (r, φ, ψ).
    pub covariance: Matrix3<f64>,
}

/// A CPS network: stations, points and every reading between them.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Network {
    /// The parent's stations, route order (station 0 is the start).
    pub stations: Vec<Station>,
    /// Child placements and control points.
    pub points: Vec<Point>,
    /// Every pointing.
    pub readings: Vec<NetworkReading>,
}

/// What an unknown of the adjustment is (eight bytes: a 100,000-cycle
/// network has a million).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Unknown {
    /// Coordinate `coordinate` (0 x, 1 y, 2 z, 3 θ) of station `station`.
    Station {
        /// The station.
        station: u32,
        /// The coordinate.
        coordinate: u8,
    },
    /// Coordinate `coordinate` (0 x, 1 y, 2 z) of point `point`.
    Point {
        /// The point.
        point: u32,
        /// The coordinate.
        coordinate: u8,
    },
}

impl std::fmt::Display for Unknown {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        const STATION: [&str; 4] = ["x", "y", "z", "heading"];
        match *self {
            Unknown::Station { station, coordinate } => {
                write!(f, "{} of station {station}", STATION[usize::from(coordinate)])
            }
            Unknown::Point { point, coordinate } => {
                write!(f, "{} of point {point}", ["x", "y", "z"][usize::from(coordinate)])
            }
        }
    }
}

/// Where each free coordinate's column is.
#[derive(Debug, Clone, PartialEq)]
pub struct Layout {
    /// Per station, the column of each coordinate (`None`: held fixed).
    pub stations: Vec<[Option<usize>; 4]>,
    /// Per point, likewise.
    pub points: Vec<[Option<usize>; 3]>,
    /// Column → unknown.
    pub unknowns: Vec<Unknown>,
}

/// Whether coordinate `k` of a prior is held fixed (zero variance).
fn fixed<const D: usize>(prior: &Option<nalgebra::SMatrix<f64, D, D>>, k: usize) -> bool {
    prior.as_ref().is_some_and(|p| p[(k, k)] <= 0.0)
}

impl Layout {
    /// Columns for every coordinate that is not held fixed, station by
    /// station, then point by point.
    pub fn new(network: &Network) -> Self {
        let mut unknowns = Vec::with_capacity(4 * network.stations.len() + 3 * network.points.len());
        let mut next = |u: Unknown| {
            unknowns.push(u);
            Some(unknowns.len() - 1)
        };
        let stations = network
            .stations
            .iter()
            .enumerate()
            .map(|(s, st)| {
                std::array::from_fn(|c| {
                    (!fixed(&st.prior, c))
                        .then_some(())
                        .and_then(|()| next(Unknown::Station { station: s as u32, coordinate: c as u8 }))
                })
            })
            .collect();
        let points = network
            .points
            .iter()
            .enumerate()
            .map(|(p, pt)| {
                std::array::from_fn(|c| {
                    (!fixed(&pt.prior, c))
                        .then_some(())
                        .and_then(|()| next(Unknown::Point { point: p as u32, coordinate: c as u8 }))
                })
            })
            .collect();
        Self { stations, points, unknowns }
    }

    /// The number of unknowns.
    pub fn len(&self) -> usize {
        self.unknowns.len()
    }

    /// True without unknowns.
    pub fn is_empty(&self) -> bool {
        self.unknowns.is_empty()
    }
}

/// What an observation group is: a reading's (r, φ, ψ), or a prior's
/// weighted coordinates.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Source {
    /// Reading `index` of [`Network::readings`].
    Reading(usize),
    /// The prior of station `index`.
    StationPrior(usize),
    /// The prior of point `index`.
    PointPrior(usize),
}

/// Observations that share one covariance block: a reading's three
/// components, or a prior's weighted coordinates. Scalars that data
/// snooping removed are left out. Eight bytes beside its source: the
/// covariance is the network's ([`Group::covariance`]), not a copy (a
/// 100,000-cycle network's groups took 81 MB with one).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Group {
    /// Where it comes from.
    pub source: Source,
    /// The scalars of the block (0 r / x, 1 φ / y, 2 ψ / z, 3 θ), `len` of
    /// them.
    components: [u8; 4],
    len: u8,
    /// Bit i: the scalar at position i is in the adjustment (clear:
    /// removed by data snooping).
    active: u8,
}

impl Group {
    /// A group of `components` (each < 4), all active.
    fn new(source: Source, components: &[usize]) -> Self {
        let mut c = [0u8; 4];
        for (slot, &k) in c.iter_mut().zip(components) {
            *slot = k as u8;
        }
        let len = components.len().min(4) as u8;
        Self { source, components: c, len, active: (1u8 << len) - 1 }
    }

    /// How many scalars it has.
    pub fn len(&self) -> usize {
        usize::from(self.len)
    }

    /// True when it has none (never, as built).
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// The scalar at position `pos` (0 r / x, 1 φ / y, 2 ψ / z, 3 θ).
    pub fn component(&self, pos: usize) -> usize {
        usize::from(self.components[pos])
    }

    /// The position of scalar `component`, if the group has it.
    pub fn position(&self, component: usize) -> Option<usize> {
        (0..self.len()).find(|&p| self.component(p) == component)
    }

    /// Whether the scalar at `pos` is in the adjustment.
    pub fn is_active(&self, pos: usize) -> bool {
        self.active & (1 << pos) != 0
    }

    /// Puts the scalar at `pos` in or out of the adjustment.
    pub fn set_active(&mut self, pos: usize, active: bool) {
        if active {
            self.active |= 1 << pos;
        } else {
            self.active &= !(1 << pos);
        }
    }

    /// The positions of the scalars in the adjustment, in order.
    pub fn active_positions(&self) -> impl Iterator<Item = usize> + '_ {
        (0..self.len()).filter(|&p| self.is_active(p))
    }

    /// The covariance of the scalars at positions `a` and `b`, from the
    /// network's reading or prior.
    pub fn covariance(&self, network: &Network, a: usize, b: usize) -> f64 {
        let (i, j) = (self.component(a), self.component(b));
        match self.source {
            Source::Reading(k) => network.readings[k].covariance[(i, j)],
            Source::StationPrior(k) => network.stations[k].prior.map_or(0.0, |p| p[(i, j)]),
            Source::PointPrior(k) => network.points[k].prior.map_or(0.0, |p| p[(i, j)]),
        }
    }
}

/// One group linearised at the current estimate: misclosure l − f(x)
/// (azimuth wrapped) and Jacobian over `columns`, of its active scalars,
/// with the Cholesky factor of their covariance.
#[derive(Debug, Clone)]
pub struct Linearised {
    /// The active scalars' positions in the group.
    pub active: Vec<usize>,
    /// Misclosure observed − computed.
    pub misclosure: DVector<f64>,
    /// The unknowns' columns this group involves.
    pub columns: Vec<usize>,
    /// ∂f/∂x over `columns` (active rows).
    pub jacobian: DMatrix<f64>,
    /// Covariance of the active scalars.
    pub covariance: DMatrix<f64>,
}

impl Network {
    /// Checks indices, finiteness and the covariances; every problem is an
    /// error naming the reading, station or point.
    pub fn validate(&self) -> Result<()> {
        let finite = |what: String, v: f64| crate::error::ensure_finite(|| what.clone(), v);
        for (k, s) in self.stations.iter().enumerate() {
            for v in s.pose.to_vector().iter() {
                finite(format!("pose of station {k}"), *v)?;
            }
            if let Some(p) = &s.prior {
                check_prior(&format!("prior of station {k}"), p.as_slice(), 4)?;
            }
        }
        for (k, p) in self.points.iter().enumerate() {
            for v in p.position.iter() {
                finite(format!("position of point {k}"), *v)?;
            }
            if let Some(c) = &p.prior {
                check_prior(&format!("prior of point {k}"), c.as_slice(), 3)?;
            }
        }
        for (k, r) in self.readings.iter().enumerate() {
            if r.station >= self.stations.len() || r.point >= self.points.len() {
                return Err(CpsError::OutOfRange {
                    what: format!("reading {k}: station {} / point {}", r.station, r.point),
                    value: k as f64,
                    expected: format!("< {} stations / {} points", self.stations.len(), self.points.len()),
                });
            }
            for (name, v) in [("slope", r.reading.slope_m), ("azimuth", r.reading.azimuth_rad)] {
                finite(format!("{name} of reading {k}"), v)?;
            }
            finite(format!("elevation of reading {k}"), r.reading.elevation_rad)?;
            if r.covariance.cholesky().is_none() || r.covariance.iter().any(|v| !v.is_finite()) {
                return Err(CpsError::NotPositiveDefinite { what: format!("covariance of reading {k}") });
            }
        }
        Ok(())
    }

    /// [`Network::groups`] with the scalars `left_out` (source, component)
    /// inactive — e.g. those data snooping removed; one that is not in the
    /// network is ignored.
    pub fn groups_without(&self, left_out: &[(Source, usize)]) -> Vec<Group> {
        let mut groups = self.groups();
        for (source, component) in left_out {
            if let Some(g) = groups.iter_mut().find(|g| g.source == *source)
                && let Some(pos) = g.position(*component)
            {
                g.set_active(pos, false);
            }
        }
        groups
    }

    /// Every observation group: the readings', then the weighted priors'.
    pub fn groups(&self) -> Vec<Group> {
        let mut out = Vec::with_capacity(self.readings.len() + 1);
        for k in 0..self.readings.len() {
            out.push(Group::new(Source::Reading(k), &[0, 1, 2]));
        }
        for (k, s) in self.stations.iter().enumerate() {
            if let Some(p) = &s.prior {
                let c: Vec<usize> = (0..4).filter(|&i| p[(i, i)] > 0.0).collect();
                if !c.is_empty() {
                    out.push(Group::new(Source::StationPrior(k), &c));
                }
            }
        }
        for (k, pt) in self.points.iter().enumerate() {
            if let Some(p) = &pt.prior {
                let c: Vec<usize> = (0..3).filter(|&i| p[(i, i)] > 0.0).collect();
                if !c.is_empty() {
                    out.push(Group::new(Source::PointPrior(k), &c));
                }
            }
        }
        out
    }

    /// The unknowns' columns `group` involves, in the order
    /// [`Network::linearise`] gives them (its `columns`), into `out`
    /// (cleared first): what the normal matrix's pattern needs, without
    /// linearising.
    pub fn columns_into(&self, group: &Group, layout: &Layout, out: &mut Vec<usize>) {
        out.clear();
        match group.source {
            Source::Reading(k) => {
                let nr = &self.readings[k];
                out.extend(layout.stations[nr.station].iter().flatten());
                out.extend(layout.points[nr.point].iter().flatten());
            }
            Source::StationPrior(k) => out
                .extend(group.active_positions().map(|a| layout.stations[k][group.component(a)].unwrap_or(usize::MAX))),
            Source::PointPrior(k) => {
                out.extend(group.active_positions().map(|a| layout.points[k][group.component(a)].unwrap_or(usize::MAX)))
            }
        }
    }

    /// Linearises `group` at the estimate (`stations`, `points`).
    pub fn linearise(
        &self,
        group: &Group,
        layout: &Layout,
        stations: &[ParentPose],
        points: &[Point3<f64>],
    ) -> Result<Linearised> {
        let active: Vec<usize> = group.active_positions().collect();
        let covariance =
            DMatrix::from_fn(active.len(), active.len(), |i, j| group.covariance(self, active[i], active[j]));
        let columns;
        let (misclosure, jacobian) = match group.source {
            Source::Reading(k) => {
                let nr = &self.readings[k];
                let (computed, j) = observe_with_jacobians(&stations[nr.station], &points[nr.point])?;
                let full = nr.reading.minus(&computed);
                let mut cols: Vec<(usize, Vec<f64>)> = Vec::new();
                for (c, col) in layout.stations[nr.station].iter().enumerate() {
                    if let Some(col) = col {
                        cols.push((*col, active.iter().map(|&a| j.wrt_parent[(group.component(a), c)]).collect()));
                    }
                }
                for (c, col) in layout.points[nr.point].iter().enumerate() {
                    if let Some(col) = col {
                        cols.push((*col, active.iter().map(|&a| j.wrt_child[(group.component(a), c)]).collect()));
                    }
                }
                columns = cols.iter().map(|(c, _)| *c).collect();
                let jac = DMatrix::from_fn(active.len(), cols.len(), |i, c| cols[c].1[i]);
                (DVector::from_iterator(active.len(), active.iter().map(|&a| full[group.component(a)])), jac)
            }
            Source::StationPrior(k) => {
                let s = &self.stations[k];
                let mut d = s.pose.to_vector() - stations[k].to_vector();
                d[3] = wrap_angle(d[3]);
                let comps: Vec<usize> = active.iter().map(|&a| group.component(a)).collect();
                columns = comps.iter().map(|&c| layout.stations[k][c].unwrap_or(usize::MAX)).collect();
                (
                    DVector::from_iterator(comps.len(), comps.iter().map(|&c| d[c])),
                    DMatrix::identity(comps.len(), comps.len()),
                )
            }
            Source::PointPrior(k) => {
                let d = self.points[k].position - points[k];
                let comps: Vec<usize> = active.iter().map(|&a| group.component(a)).collect();
                columns = comps.iter().map(|&c| layout.points[k][c].unwrap_or(usize::MAX)).collect();
                (
                    DVector::from_iterator(comps.len(), comps.iter().map(|&c| d[c])),
                    DMatrix::identity(comps.len(), comps.len()),
                )
            }
        };
        Ok(Linearised { active, misclosure, columns, jacobian, covariance })
    }
}

/// A prior covariance must be finite, symmetric and positive definite on
/// its non-fixed coordinates, with no correlation to a fixed one.
fn check_prior(what: &str, m: &[f64], d: usize) -> Result<()> {
    let at = |i: usize, j: usize| m[i + d * j];
    if let Some(bad) = m.iter().find(|v| !v.is_finite()) {
        return Err(CpsError::NonFinite { what: what.into(), value: *bad });
    }
    let free: Vec<usize> = (0..d).filter(|&i| at(i, i) > 0.0).collect();
    for i in 0..d {
        if at(i, i) < 0.0 {
            return Err(CpsError::OutOfRange {
                what: format!("{what}: variance {i}"),
                value: at(i, i),
                expected: "≥ 0".into(),
            });
        }
        for j in 0..d {
            let fixed_pair = !free.contains(&i) || !free.contains(&j);
            if (at(i, j) - at(j, i)).abs() > 1e-12 * at(i, i).abs().max(at(j, j).abs()).max(1e-300)
                || (fixed_pair && i != j && at(i, j) != 0.0)
            {
                return Err(CpsError::NotPositiveDefinite {
                    what: format!("{what} (asymmetric, or correlated with a fixed coordinate)"),
                });
            }
        }
    }
    let sub = DMatrix::from_fn(free.len(), free.len(), |i, j| at(free[i], free[j]));
    if !free.is_empty() && sub.cholesky().is_none() {
        return Err(CpsError::NotPositiveDefinite { what: what.into() });
    }
    Ok(())
}
