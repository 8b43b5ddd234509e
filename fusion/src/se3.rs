//! SE(3) in the convention every part of `fusion` shares: errors are
//! ξ = (ω, v) — rotation first, then translation — with **left**
//! perturbation, `T_true = exp(ξ) · T̂`; and a Gaussian prior on a pose in
//! that convention.

use nalgebra::{Isometry3, Matrix3, Matrix6, Point3, Translation3, UnitQuaternion, Vector3, Vector6};

/// A prior on `target_from_source` — typically the CPS pose of the scan
/// and its covariance — with its 6×6 information in the same convention as
/// [`IcpResult::information`](crate::icp::IcpResult::information) (ξ = (ω, v), left perturbation, target frame).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Prior {
    /// The prior's mean.
    pub target_from_source: Isometry3<f64>,
    /// Its information (inverse covariance), symmetric positive semi-definite.
    pub information: Matrix6<f64>,
}

/// The cross-product matrix: `skew(v) · x = v × x`.
pub fn skew(v: &Vector3<f64>) -> Matrix3<f64> {
    Matrix3::new(0.0, -v.z, v.y, v.z, 0.0, -v.x, -v.y, v.x, 0.0)
}

/// ξ = (ω, v) with `a ≈ exp(ξ) · b` to first order.
pub fn left_difference(a: &Isometry3<f64>, b: &Isometry3<f64>) -> Vector6<f64> {
    let d = a * b.inverse();
    let w = d.rotation.scaled_axis();
    Vector6::new(w.x, w.y, w.z, d.translation.x, d.translation.y, d.translation.z)
}

/// How far `delta` moves points whose centroid is `centroid` and whose
/// RMS distance from it is `radius` (in the frame `delta` acts in): the
/// centroid's displacement plus the turn times the radius — the same
/// wherever the frame's origin is, and at least the points' RMS motion.
pub fn motion(delta: &Isometry3<f64>, centroid: &Point3<f64>, radius: f64) -> f64 {
    (delta * centroid - centroid).norm() + delta.rotation.angle() * radius
}

/// exp of ξ = (ω, v) as an isometry (rotation exp(ω), translation v).
pub fn exp(xi: &Vector6<f64>) -> Isometry3<f64> {
    Isometry3::from_parts(
        Translation3::new(xi[3], xi[4], xi[5]),
        UnitQuaternion::from_scaled_axis(Vector3::new(xi[0], xi[1], xi[2])),
    )
}

/// The adjoint of `t` in the (ω, v) order: exp(Ad·ξ) = t·exp(ξ)·t⁻¹.
pub fn adjoint(t: &Isometry3<f64>) -> Matrix6<f64> {
    let r = *t.rotation.to_rotation_matrix().matrix();
    let mut a = Matrix6::zeros();
    a.fixed_view_mut::<3, 3>(0, 0).copy_from(&r);
    a.fixed_view_mut::<3, 3>(3, 3).copy_from(&r);
    a.fixed_view_mut::<3, 3>(3, 0).copy_from(&(skew(&t.translation.vector) * r));
    a
}
