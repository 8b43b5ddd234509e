//! The recording's colours and the 95 % ellipsoid it draws.

use cps::CHI2_3D_95_SQRT;
use nalgebra::{Matrix3, SymmetricEigen, UnitQuaternion};

pub(super) fn green() -> rerun::Color {
    rerun::Color::from_rgb(40, 170, 70)
}

pub(super) fn red() -> rerun::Color {
    rerun::Color::from_rgb(220, 40, 40)
}

/// The 95 % ellipsoid of a 3×3 position covariance: half sizes along the
/// eigenvectors and the rotation to them.
pub fn ellipsoid_95(cov: &Matrix3<f64>) -> ([f32; 3], rerun::Quaternion) {
    let eig = SymmetricEigen::new(*cov);
    let mut v = eig.eigenvectors;
    if v.determinant() < 0.0 {
        v.column_mut(2).neg_mut();
    }
    let q = UnitQuaternion::from_matrix(&v).coords;
    let h = eig.eigenvalues.map(|l| (CHI2_3D_95_SQRT * l.max(0.0).sqrt()) as f32);
    ([h.x, h.y, h.z], rerun::Quaternion::from_xyzw([q.x as f32, q.y as f32, q.z as f32, q.w as f32]))
}

/// Colour of a fix sight line by Baarda's |w|: green below 2, amber up to
/// the critical value, red above; grey when nothing checks the observation.
pub fn w_colour(w: Option<f64>) -> rerun::Color {
    match w.map(f64::abs) {
        None => rerun::Color::from_rgb(150, 150, 150),
        Some(w) if w < 2.0 => rerun::Color::from_rgb(40, 200, 80),
        Some(w) if w <= cps::W_CRITICAL => rerun::Color::from_rgb(240, 170, 30),
        Some(_) => rerun::Color::from_rgb(230, 40, 40),
    }
}

/// Colour of a deviation from a fitted surface: grey within `threshold_m`,
/// then towards full blue (inside) or red (outside) at twice it.
pub(super) fn deviation_colour(deviation_m: f64, threshold_m: f64) -> rerun::Color {
    let t = (deviation_m.abs() / threshold_m.max(1e-9) - 1.0).clamp(0.0, 1.0);
    if deviation_m.abs() <= threshold_m {
        return rerun::Color::from_rgb(190, 190, 190);
    }
    let mix = |from: f64, to: f64| (from + (to - from) * (0.5 + 0.5 * t)) as u8;
    if deviation_m < 0.0 {
        rerun::Color::from_rgb(mix(190.0, 30.0), mix(190.0, 80.0), mix(190.0, 240.0))
    } else {
        rerun::Color::from_rgb(mix(190.0, 235.0), mix(190.0, 40.0), mix(190.0, 40.0))
    }
}

/// Colour by height within `[lo, hi]` (blue → green → red).
pub(super) fn height_colour(z: f32, lo: f32, hi: f32) -> rerun::Color {
    let t = ((z - lo) / (hi - lo).max(1e-3)).clamp(0.0, 1.0);
    let (r, g, b) = if t < 0.5 { (0.0, 2.0 * t, 1.0 - 2.0 * t) } else { (2.0 * t - 1.0, 2.0 - 2.0 * t, 0.0) };
    rerun::Color::from_rgb((40.0 + 215.0 * r) as u8, (40.0 + 215.0 * g) as u8, (40.0 + 215.0 * b) as u8)
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Vector3;

    /// The 95 % ellipsoid's axes are √(χ²₃ · eigenvalue) along the
    /// eigenvectors: a covariance rotated by 30° about z gives back the
    /// rotation and the half sizes.
    #[test]
    fn ellipsoid_axes_follow_the_covariance() {
        let r = nalgebra::Rotation3::from_axis_angle(&Vector3::z_axis(), 30f64.to_radians());
        let d = Matrix3::from_diagonal(&Vector3::new(4e-4, 1e-4, 9e-6));
        let cov = r.matrix() * d * r.matrix().transpose();
        let (half, q) = ellipsoid_95(&cov);
        let q =
            UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(q.0[3], q.0[0], q.0[1], q.0[2]).cast::<f64>());
        let mut expected = [0.02, 0.01, 0.003].map(|s| s * CHI2_3D_95_SQRT);
        expected.sort_by(f64::total_cmp);
        let mut got = half.map(f64::from);
        got.sort_by(f64::total_cmp);
        for (g, e) in got.iter().zip(expected) {
            assert!((g - e).abs() < 1e-6, "{got:?} vs {expected:?}");
        }
        // Each axis of the rotated frame, scaled by its half size, lies on the
        // ellipsoid xᵀ Σ⁻¹ x = χ².
        let inv = cov.try_inverse().expect("invertible");
        for (k, h) in half.iter().enumerate() {
            let x = q * (Vector3::ith(k, 1.0) * f64::from(*h));
            let m = (x.transpose() * inv * x)[(0, 0)];
            assert!((m - CHI2_3D_95_SQRT.powi(2)).abs() < 1e-4 * m, "axis {k}: {m}");
        }
        assert_eq!(w_colour(None), rerun::Color::from_rgb(150, 150, 150));
        assert_ne!(w_colour(Some(-4.0)), w_colour(Some(1.0)));
    }
}
