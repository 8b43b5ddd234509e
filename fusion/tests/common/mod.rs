//! Helpers shared by the fusion integration tests, written independently of
//! the library's own convention code.

use nalgebra::{Isometry3, Vector6};

/// ξ = (ω, v) with `a = exp(ξ) · b` to first order (left perturbation,
/// in `b`'s target frame).
pub fn left_error(a: &Isometry3<f64>, b: &Isometry3<f64>) -> Vector6<f64> {
    let d = a * b.inverse();
    let w = d.rotation.scaled_axis();
    Vector6::new(w.x, w.y, w.z, d.translation.x, d.translation.y, d.translation.z)
}
