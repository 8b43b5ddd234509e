//! One total-station pointing from the parent to a child prism (DESIGN §5).
//!
//! With d = c − p_xyz: r = |d|, φ = atan2(d_y, d_x) − θ (wrapped to (−π, π]),
//! ψ = atan2(d_z, √(d_x² + d_y²)).

use nalgebra::{Matrix3, Matrix3x4, Point3, Vector3};

use crate::error::{CpsError, Result, ensure_finite};

/// Wraps an angle to (−π, π].
pub fn wrap_angle(a: f64) -> f64 {
    let two_pi = std::f64::consts::TAU;
    let w = a - two_pi * (a / two_pi).round();
    if w <= -std::f64::consts::PI { w + two_pi } else { w }
}

/// The parent robot's pose: position of the total station's centre in the
/// world frame (m) and heading θ (rad, counter-clockwise from world +x).
/// Roll and pitch come from the tilt sensor and are not estimated.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ParentPose {
    /// Position in the world frame, metres.
    pub position: Point3<f64>,
    /// Heading θ, radians, counter-clockwise from world +x.
    pub heading_rad: f64,
}

impl ParentPose {
    /// A pose from x, y, z (m) and heading (rad).
    pub fn new(x: f64, y: f64, z: f64, heading_rad: f64) -> Self {
        Self { position: Point3::new(x, y, z), heading_rad }
    }

    /// The state vector (x, y, z, θ).
    pub fn to_vector(&self) -> nalgebra::Vector4<f64> {
        nalgebra::Vector4::new(self.position.x, self.position.y, self.position.z, self.heading_rad)
    }

    /// The pose from a state vector (x, y, z, θ); θ is wrapped.
    pub fn from_vector(v: &nalgebra::Vector4<f64>) -> Self {
        Self::new(v[0], v[1], v[2], wrap_angle(v[3]))
    }
}

/// One pointing's reading in the CPS model's convention: slope distance
/// (corrected for the prism constant), azimuth φ counter-clockwise from the
/// parent's heading, elevation ψ above the horizon. Metres and radians.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Reading {
    /// Slope distance r, metres.
    pub slope_m: f64,
    /// Azimuth φ, radians, counter-clockwise from the parent's heading.
    pub azimuth_rad: f64,
    /// Elevation ψ, radians, positive up.
    pub elevation_rad: f64,
}

impl Reading {
    /// The reading as a vector (r, φ, ψ).
    pub fn to_vector(&self) -> Vector3<f64> {
        Vector3::new(self.slope_m, self.azimuth_rad, self.elevation_rad)
    }

    /// Observed − computed, (r, φ, ψ), the azimuth wrapped to (−π, π]: the
    /// misclosure of every fix, adjustment and field test.
    pub fn minus(&self, computed: &Reading) -> [f64; 3] {
        [
            self.slope_m - computed.slope_m,
            wrap_angle(self.azimuth_rad - computed.azimuth_rad),
            self.elevation_rad - computed.elevation_rad,
        ]
    }

    /// Checks the reading is finite with a positive slope distance and an
    /// elevation strictly between −90° and 90° (`child` names it in errors).
    pub fn validate(&self, child: usize) -> Result<()> {
        ensure_finite(|| format!("slope distance to child {child}"), self.slope_m)?;
        ensure_finite(|| format!("azimuth to child {child}"), self.azimuth_rad)?;
        ensure_finite(|| format!("elevation to child {child}"), self.elevation_rad)?;
        if self.slope_m <= 0.0 {
            return Err(CpsError::OutOfRange {
                what: format!("slope distance to child {child}"),
                value: self.slope_m,
                expected: "> 0 m".into(),
            });
        }
        if self.elevation_rad.abs() >= std::f64::consts::FRAC_PI_2 - 1e-9 {
            return Err(CpsError::OutOfRange {
                what: format!("elevation to child {child}"),
                value: self.elevation_rad,
                expected: "strictly between −π/2 and π/2 (a vertical sight line has no azimuth)".into(),
            });
        }
        Ok(())
    }
}

/// Horizontal separations below this make the azimuth undefined.
pub const MIN_HORIZONTAL_M: f64 = 1e-6;

/// The noise-free reading from `parent` to the prism at `child`.
/// Fails when the two are horizontally coincident (azimuth undefined).
pub fn observe(parent: &ParentPose, child: &Point3<f64>) -> Result<Reading> {
    let d = child - parent.position;
    let h2 = d.x * d.x + d.y * d.y;
    let h = h2.sqrt();
    if h < MIN_HORIZONTAL_M {
        return Err(CpsError::CoincidentPoints { what: "parent and child (horizontally)".into(), separation_m: h });
    }
    Ok(Reading {
        slope_m: (h2 + d.z * d.z).sqrt(),
        azimuth_rad: wrap_angle(d.y.atan2(d.x) - parent.heading_rad),
        elevation_rad: d.z.atan2(h),
    })
}

/// Jacobians of one pointing: ∂(r, φ, ψ)/∂(x, y, z, θ) of the parent and
/// ∂(r, φ, ψ)/∂(x, y, z) of the child, at the given geometry.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ObservationJacobians {
    /// ∂(r, φ, ψ)/∂(x0, y0, z0, θ0).
    pub wrt_parent: Matrix3x4<f64>,
    /// ∂(r, φ, ψ)/∂(xc, yc, zc).
    pub wrt_child: Matrix3<f64>,
}

/// Analytic Jacobians of [`observe`]. Fails where `observe` fails.
pub fn observation_jacobians(parent: &ParentPose, child: &Point3<f64>) -> Result<ObservationJacobians> {
    observe_with_jacobians(parent, child).map(|(_, j)| j)
}

/// [`observe`] and [`observation_jacobians`] in one pass.
pub fn observe_with_jacobians(parent: &ParentPose, child: &Point3<f64>) -> Result<(Reading, ObservationJacobians)> {
    let d = child - parent.position;
    let h2 = d.x * d.x + d.y * d.y;
    let h = h2.sqrt();
    if h < MIN_HORIZONTAL_M {
        return Err(CpsError::CoincidentPoints { what: "parent and child (horizontally)".into(), separation_m: h });
    }
    let r2 = h2 + d.z * d.z;
    let r = r2.sqrt();
    #[rustfmt::skip]
    let wrt_child = Matrix3::new(
        d.x / r,                  d.y / r,                  d.z / r,
        -d.y / h2,                d.x / h2,                 0.0,
        -d.x * d.z / (r2 * h),    -d.y * d.z / (r2 * h),    h / r2,
    );
    let mut wrt_parent = Matrix3x4::zeros();
    wrt_parent.fixed_view_mut::<3, 3>(0, 0).copy_from(&(-wrt_child));
    wrt_parent[(1, 3)] = -1.0;
    let reading = Reading {
        slope_m: r,
        azimuth_rad: wrap_angle(d.y.atan2(d.x) - parent.heading_rad),
        elevation_rad: d.z.atan2(h),
    };
    Ok((reading, ObservationJacobians { wrt_parent, wrt_child }))
}

/// A random pose with |x|, |y| < `xy_m`, |z| < `z_m` and any heading (tests only).
#[cfg(test)]
pub(crate) fn random_pose(rng: &mut impl rand::Rng, xy_m: f64, z_m: f64) -> ParentPose {
    ParentPose::new(
        rng.random_range(-xy_m..xy_m),
        rng.random_range(-xy_m..xy_m),
        rng.random_range(-z_m..z_m),
        rng.random_range(-3.1..3.1),
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    fn random_geometry(rng: &mut ChaCha8Rng) -> (ParentPose, Point3<f64>) {
        let parent = random_pose(rng, 100.0, 5.0);
        let dist = rng.random_range(2.0..300.0);
        let az = rng.random_range(-3.1..3.1f64);
        let el = rng.random_range(-0.6..0.6f64);
        let child = parent.position + dist * Vector3::new(el.cos() * az.cos(), el.cos() * az.sin(), el.sin());
        (parent, child)
    }

    fn reading_diff(a: &Reading, b: &Reading) -> Vector3<f64> {
        Vector3::new(
            a.slope_m - b.slope_m,
            wrap_angle(a.azimuth_rad - b.azimuth_rad),
            a.elevation_rad - b.elevation_rad,
        )
    }

    #[test]
    fn jacobians_match_central_differences_on_100_geometries() {
        let mut rng = ChaCha8Rng::seed_from_u64(7);
        for _ in 0..100 {
            let (parent, child) = random_geometry(&mut rng);
            let j = observation_jacobians(&parent, &child).expect("regular geometry");
            let eps = 1e-6;
            for k in 0..4 {
                let mut plus = parent.to_vector();
                let mut minus = plus;
                plus[k] += eps;
                minus[k] -= eps;
                let rp = observe(&ParentPose::from_vector(&plus), &child).expect("obs");
                let rm = observe(&ParentPose::from_vector(&minus), &child).expect("obs");
                let fd = reading_diff(&rp, &rm) / (2.0 * eps);
                let an = j.wrt_parent.column(k);
                let (joint, _) = observe_with_jacobians(&parent, &child).expect("obs");
                assert_eq!(joint, observe(&parent, &child).expect("obs"));
                assert!((fd - an).norm() <= 1e-6 * (1.0 + an.norm()), "parent col {k}: fd {fd} an {an}");
            }
            for k in 0..3 {
                let mut plus = child;
                let mut minus = child;
                plus[k] += eps;
                minus[k] -= eps;
                let rp = observe(&parent, &plus).expect("obs");
                let rm = observe(&parent, &minus).expect("obs");
                let fd = reading_diff(&rp, &rm) / (2.0 * eps);
                let an = j.wrt_child.column(k);
                assert!((fd - an).norm() <= 1e-6 * (1.0 + an.norm()), "child col {k}: fd {fd} an {an}");
            }
        }
    }

    #[test]
    fn observe_follows_the_conventions() {
        // Parent heading +y (90°); child at +x of the parent: azimuth −90° (clockwise).
        let parent = ParentPose::new(1.0, 2.0, 0.5, std::f64::consts::FRAC_PI_2);
        let r = observe(&parent, &Point3::new(11.0, 2.0, 0.5 + 10.0)).expect("obs");
        assert!((r.slope_m - 200f64.sqrt()).abs() < 1e-12);
        assert!((r.azimuth_rad + std::f64::consts::FRAC_PI_2).abs() < 1e-12);
        assert!((r.elevation_rad - std::f64::consts::FRAC_PI_4).abs() < 1e-12);
    }

    #[test]
    fn vertical_sight_line_is_an_error_not_nan() {
        let parent = ParentPose::new(0.0, 0.0, 0.0, 0.0);
        assert!(matches!(observe(&parent, &Point3::new(0.0, 0.0, 5.0)), Err(CpsError::CoincidentPoints { .. })));
        assert!(observation_jacobians(&parent, &Point3::new(0.0, 0.0, 5.0)).is_err());
    }

    #[test]
    fn wrap_angle_range() {
        for a in [-7.0, -std::f64::consts::PI, 0.0, 3.0, std::f64::consts::PI, 9.5] {
            let w = wrap_angle(a);
            assert!(w > -std::f64::consts::PI && w <= std::f64::consts::PI, "{a} -> {w}");
            assert!(((a - w) / std::f64::consts::TAU - ((a - w) / std::f64::consts::TAU).round()).abs() < 1e-12);
        }
    }
}
