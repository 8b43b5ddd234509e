//! Child placement (seed 003 eqs 17–24, physically consistent form).
//!
//! c = p_xyz + r·(cos ψ cos(θ0 + φ), cos ψ sin(θ0 + φ), sin ψ).
//! Linearised, dc = G_p·dp + G_m·d(r, φ, ψ). Unlike eq. (20) as printed, G_p
//! keeps the heading column: a heading error dθ0 moves the child sideways by
//! r·cos ψ·dθ0.

use nalgebra::{Matrix3, Matrix3x4, Point3, Vector3};

use crate::error::Result;
use crate::observation::{ParentPose, Reading};

/// A child's position computed from the parent's pose and one reading, with
/// the Jacobians that carry the covariance.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Placement {
    /// The child's prism position in the world frame, metres.
    pub position: Point3<f64>,
    /// ∂c/∂(x0, y0, z0, θ0).
    pub wrt_parent: Matrix3x4<f64>,
    /// ∂c/∂(r, φ, ψ).
    pub wrt_reading: Matrix3<f64>,
}

/// Places a child from the parent's pose and a validated reading (eqs 17–19).
pub fn place(parent: &ParentPose, reading: &Reading, child: usize) -> Result<Placement> {
    reading.validate(child)?;
    let (r, psi) = (reading.slope_m, reading.elevation_rad);
    let az = parent.heading_rad + reading.azimuth_rad;
    let (sa, ca) = az.sin_cos();
    let (sp, cp) = psi.sin_cos();
    let position = parent.position + r * Vector3::new(cp * ca, cp * sa, sp);
    let mut wrt_parent = Matrix3x4::zeros();
    wrt_parent.fixed_view_mut::<3, 3>(0, 0).copy_from(&Matrix3::identity());
    wrt_parent[(0, 3)] = -r * cp * sa;
    wrt_parent[(1, 3)] = r * cp * ca;
    #[rustfmt::skip]
    let wrt_reading = Matrix3::new(
        cp * ca, -r * cp * sa, -r * sp * ca,
        cp * sa,  r * cp * ca, -r * sp * sa,
        sp,       0.0,          r * cp,
    );
    Ok(Placement { position, wrt_parent, wrt_reading })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::observation::{observe, random_pose};
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    #[test]
    fn placement_inverts_observation() {
        let mut rng = ChaCha8Rng::seed_from_u64(11);
        for _ in 0..50 {
            let parent = random_pose(&mut rng, 50.0, 2.0);
            let child =
                Point3::new(rng.random_range(-50.0..50.0), rng.random_range(-50.0..50.0), rng.random_range(-2.0..2.0));
            let reading = observe(&parent, &child).expect("regular");
            let p = place(&parent, &reading, 0).expect("valid");
            assert!((p.position - child).norm() < 1e-10);
        }
    }

    #[test]
    fn placement_jacobians_match_central_differences() {
        let mut rng = ChaCha8Rng::seed_from_u64(12);
        for _ in 0..60 {
            let parent = random_pose(&mut rng, 50.0, 2.0);
            let reading = Reading {
                slope_m: rng.random_range(1.0..200.0),
                azimuth_rad: rng.random_range(-3.0..3.0),
                elevation_rad: rng.random_range(-0.5..0.5),
            };
            let p = place(&parent, &reading, 0).expect("valid");
            let eps = 1e-6;
            for k in 0..4 {
                let (mut a, mut b) = (parent.to_vector(), parent.to_vector());
                a[k] += eps;
                b[k] -= eps;
                let fd = (place(&ParentPose::from_vector(&a), &reading, 0).expect("v").position
                    - place(&ParentPose::from_vector(&b), &reading, 0).expect("v").position)
                    / (2.0 * eps);
                assert!((fd - p.wrt_parent.column(k)).norm() < 1e-6 * (1.0 + fd.norm()), "parent col {k}");
            }
            for k in 0..3 {
                let (mut a, mut b) = (reading.to_vector(), reading.to_vector());
                a[k] += eps;
                b[k] -= eps;
                let ra = Reading { slope_m: a[0], azimuth_rad: a[1], elevation_rad: a[2] };
                let rb = Reading { slope_m: b[0], azimuth_rad: b[1], elevation_rad: b[2] };
                let fd = (place(&parent, &ra, 0).expect("v").position - place(&parent, &rb, 0).expect("v").position)
                    / (2.0 * eps);
                assert!((fd - p.wrt_reading.column(k)).norm() < 1e-6 * (1.0 + fd.norm()), "reading col {k}");
            }
        }
    }

    #[test]
    fn heading_error_moves_child_sideways_by_r_dtheta() {
        let parent = ParentPose::new(0.0, 0.0, 0.0, 0.0);
        let reading = Reading { slope_m: 100.0, azimuth_rad: 0.0, elevation_rad: 0.0 };
        let p = place(&parent, &reading, 0).expect("valid");
        assert!((p.wrt_parent[(1, 3)] - 100.0).abs() < 1e-12);
    }
}
