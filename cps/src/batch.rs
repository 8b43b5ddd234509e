//! Batch network adjustment: every station and every child placement
//! estimated at once from every reading (dense Gauss–Newton, faer QR).
//!
//! Unknowns, in order: the parent stations (x, y, z, θ each; station 0 only
//! when it has a start covariance, otherwise it is held fixed), then the
//! points (x, y, z each; one point per child *placement* — a child that moves
//! is a new point). Each reading is one (station → point) pointing. The
//! whitened Jacobian is factorised by QR; the covariance is R⁻¹R⁻ᵀ.
//!
//! For the chain-shaped dance, the covariance of the **last** station equals
//! the sequential filter's ([`crate::TeamState`]); earlier stations improve
//! (smoothing).

use faer::Mat;
use faer::prelude::*;
use nalgebra::{Cholesky, DMatrix, Matrix4, Point3};

use crate::error::{CpsError, Result};
use crate::instrument::Instrument;
use crate::observation::{ParentPose, Reading, observe_with_jacobians, wrap_angle};

/// One pointing of the network.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NetworkReading {
    /// Index into [`Network::stations`].
    pub station: usize,
    /// Index into [`Network::points`].
    pub point: usize,
    /// The reading.
    pub reading: Reading,
}

/// A CPS network: approximate stations and points, and all readings.
#[derive(Debug, Clone, PartialEq)]
pub struct Network {
    /// Approximate parent poses; station 0 is the start.
    pub stations: Vec<ParentPose>,
    /// Covariance of the start pose (x, y, z, θ); zero holds it fixed.
    pub start_covariance: Matrix4<f64>,
    /// Approximate prism positions, one per child placement.
    pub points: Vec<Point3<f64>>,
    /// Every pointing.
    pub readings: Vec<NetworkReading>,
}

/// The adjusted network.
#[derive(Debug, Clone, PartialEq)]
pub struct Adjustment {
    /// Adjusted stations (station 0 unchanged when held fixed).
    pub stations: Vec<ParentPose>,
    /// Adjusted points.
    pub points: Vec<Point3<f64>>,
    /// Covariance of all unknowns (order in the module docs).
    pub covariance: DMatrix<f64>,
    /// Whether station 0 is an unknown.
    pub start_free: bool,
    /// Gauss–Newton iterations done.
    pub iterations: usize,
    /// Whether the increments fell below 1e-10 m / 1e-12 rad.
    pub converged: bool,
    /// Observations minus unknowns.
    pub redundancy: usize,
    /// vᵀΣ⁻¹v / redundancy (0 without redundancy).
    pub sigma0_squared: f64,
}

impl Adjustment {
    /// Covariance of station `k` (zero for a fixed start).
    pub fn station_covariance(&self, k: usize) -> Matrix4<f64> {
        match self.station_offset(k) {
            Some(o) => self.covariance.fixed_view::<4, 4>(o, o).into_owned(),
            None => Matrix4::zeros(),
        }
    }

    fn station_offset(&self, k: usize) -> Option<usize> {
        if self.start_free { Some(4 * k) } else { k.checked_sub(1).map(|k| 4 * k) }
    }
}

/// Adjusts the network (at most `max_iterations` Gauss–Newton steps).
pub fn adjust(network: &Network, instrument: &Instrument, max_iterations: usize) -> Result<Adjustment> {
    let start_free = network.start_covariance.amax() > 0.0;
    let n_free_stations = network.stations.len() - usize::from(!start_free);
    let point0 = 4 * n_free_stations;
    let n = point0 + 3 * network.points.len();
    let n_obs = 3 * network.readings.len() + if start_free { 4 } else { 0 };
    if n_obs < n {
        return Err(CpsError::DegenerateGeometry {
            what: format!("{n_obs} observations for {n} unknowns"),
            condition: f64::INFINITY,
        });
    }
    let station_col = |k: usize| if start_free { Some(4 * k) } else { k.checked_sub(1).map(|k| 4 * k) };
    let prior_whitener = if start_free {
        let chol = Cholesky::new(network.start_covariance).ok_or_else(|| CpsError::NotPositiveDefinite {
            what: "start covariance (a batch adjustment needs it positive definite or zero)".into(),
        })?;
        chol.l().try_inverse()
    } else {
        None
    };
    let prior = network
        .stations
        .first()
        .copied()
        .ok_or(CpsError::DegenerateGeometry { what: "network without stations".into(), condition: f64::INFINITY })?;

    let mut stations = network.stations.clone();
    let mut points = network.points.clone();
    let mut iterations = 0;
    loop {
        let mut jac = Mat::<f64>::zeros(n_obs, n);
        let mut rhs = Mat::<f64>::zeros(n_obs, 1);
        let mut row = 0;
        for nr in &network.readings {
            let (p, c) = (&stations[nr.station], &points[nr.point]);
            let (computed, j) = observe_with_jacobians(p, c)?;
            let misclosure = [
                nr.reading.slope_m - computed.slope_m,
                wrap_angle(nr.reading.azimuth_rad - computed.azimuth_rad),
                nr.reading.elevation_rad - computed.elevation_rad,
            ];
            let sigma = instrument.reading_variances(&nr.reading).map(f64::sqrt);
            for k in 0..3 {
                rhs[(row + k, 0)] = misclosure[k] / sigma[k];
                if let Some(o) = station_col(nr.station) {
                    for q in 0..4 {
                        jac[(row + k, o + q)] = j.wrt_parent[(k, q)] / sigma[k];
                    }
                }
                let o = point0 + 3 * nr.point;
                for q in 0..3 {
                    jac[(row + k, o + q)] = j.wrt_child[(k, q)] / sigma[k];
                }
            }
            row += 3;
        }
        if let Some(w) = &prior_whitener {
            let mut d = prior.to_vector() - stations[0].to_vector();
            d[3] = wrap_angle(d[3]);
            let wd = w * d;
            for k in 0..4 {
                rhs[(row + k, 0)] = wd[k];
                for q in 0..4 {
                    jac[(row + k, q)] = w[(k, q)];
                }
            }
        }
        let qr = jac.qr();
        let dx = qr.solve_lstsq(&rhs);
        iterations += 1;
        let mut max_pos: f64 = 0.0;
        let mut max_ang: f64 = 0.0;
        for (k, s) in stations.iter_mut().enumerate() {
            if let Some(o) = station_col(k) {
                let mut v = s.to_vector();
                for q in 0..4 {
                    v[q] += dx[(o + q, 0)];
                }
                max_pos = max_pos.max(dx[(o, 0)].abs()).max(dx[(o + 1, 0)].abs()).max(dx[(o + 2, 0)].abs());
                max_ang = max_ang.max(dx[(o + 3, 0)].abs());
                *s = ParentPose::from_vector(&v);
            }
        }
        for (k, p) in points.iter_mut().enumerate() {
            let o = point0 + 3 * k;
            for q in 0..3 {
                p[q] += dx[(o + q, 0)];
                max_pos = max_pos.max(dx[(o + q, 0)].abs());
            }
        }
        if !(max_pos.is_finite() && max_ang.is_finite()) {
            return Err(CpsError::Diverged { what: "batch adjustment".into(), iterations });
        }
        let converged = max_pos < 1e-10 && max_ang < 1e-12;
        if converged || iterations >= max_iterations {
            // Residual sum of squares after the step, from the linear model.
            let v = &rhs - &jac * &dx;
            let vtv: f64 = (0..n_obs).map(|i| v[(i, 0)].powi(2)).sum();
            let r = qr.thin_R();
            let condition = equilibrated_condition(jac.as_ref(), r);
            if condition.is_nan() || condition > 1e14 {
                return Err(CpsError::DegenerateGeometry {
                    what: "the readings do not determine every station and point".into(),
                    condition,
                });
            }
            let mut r_inv = Mat::<f64>::identity(n, n);
            faer::linalg::triangular_solve::solve_upper_triangular_in_place(r, r_inv.as_mut(), faer::Par::Seq);
            let cov = &r_inv * r_inv.transpose();
            let covariance = DMatrix::from_fn(n, n, |i, j| 0.5 * (cov[(i, j)] + cov[(j, i)]));
            let redundancy = n_obs - n;
            return Ok(Adjustment {
                stations,
                points,
                covariance,
                start_free,
                iterations,
                converged,
                redundancy,
                sigma0_squared: if redundancy > 0 { vtv / redundancy as f64 } else { 0.0 },
            });
        }
    }
}

/// Condition estimate of R after scaling each unknown to a unit column.
fn equilibrated_condition(jac: faer::MatRef<'_, f64>, r: faer::MatRef<'_, f64>) -> f64 {
    let (mut lo, mut hi) = (f64::INFINITY, 0.0f64);
    for k in 0..r.ncols() {
        let norm = jac.col(k).norm_l2();
        let d = if norm > 0.0 { r[(k, k)].abs() / norm } else { 0.0 };
        lo = lo.min(d);
        hi = hi.max(d);
    }
    if lo > 0.0 { hi / lo } else { f64::INFINITY }
}
