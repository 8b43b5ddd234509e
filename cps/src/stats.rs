//! Summaries a surveyor reads: error ellipses and drift.

use nalgebra::{Matrix2, Matrix4};

/// √χ²₂(0.95): scales a 1σ ellipse to the 95 % confidence region of a 2-D
/// Gaussian position.
pub const CHI2_2D_95_SQRT: f64 = 2.447_746_830_680_816;

/// A horizontal error ellipse.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ErrorEllipse {
    /// Semi-major axis, metres.
    pub semi_major_m: f64,
    /// Semi-minor axis, metres.
    pub semi_minor_m: f64,
    /// Direction of the major axis, radians counter-clockwise from world +x,
    /// in (−π/2, π/2].
    pub orientation_rad: f64,
}

impl ErrorEllipse {
    /// The 1σ ellipse of a 2×2 (x, y) covariance.
    pub fn from_covariance(cov: &Matrix2<f64>) -> Self {
        let (a, b, c) = (cov[(0, 0)], 0.5 * (cov[(0, 1)] + cov[(1, 0)]), cov[(1, 1)]);
        let mean = 0.5 * (a + c);
        let radius = (0.25 * (a - c).powi(2) + b * b).sqrt();
        let (l1, l2) = (mean + radius, (mean - radius).max(0.0));
        let mut orientation = 0.5 * (2.0 * b).atan2(a - c);
        if orientation <= -std::f64::consts::FRAC_PI_2 {
            orientation += std::f64::consts::PI; // atan2(−0, −x) = −π
        }
        Self { semi_major_m: l1.sqrt(), semi_minor_m: l2.sqrt(), orientation_rad: orientation }
    }

    /// The ellipse scaled by `k` (e.g. [`CHI2_2D_95_SQRT`]).
    pub fn scaled(&self, k: f64) -> Self {
        Self { semi_major_m: k * self.semi_major_m, semi_minor_m: k * self.semi_minor_m, ..*self }
    }
}

/// Horizontal variance σx² + σy² of a pose covariance (m²).
pub fn sigma_xy2(cov: &Matrix4<f64>) -> f64 {
    cov[(0, 0)] + cov[(1, 1)]
}

/// Horizontal drift: √(σx² + σy²) as a percentage of `distance_m`.
pub fn drift_percent(cov: &Matrix4<f64>, distance_m: f64) -> f64 {
    if distance_m > 0.0 { 100.0 * sigma_xy2(cov).sqrt() / distance_m } else { 0.0 }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ellipse_of_rotated_covariance() {
        // Axes 3 and 1 rotated by 30°.
        let t = 30f64.to_radians();
        let r = nalgebra::Rotation2::new(t).into_inner();
        let cov = r * Matrix2::new(9.0, 0.0, 0.0, 1.0) * r.transpose();
        let e = ErrorEllipse::from_covariance(&cov);
        assert!((e.semi_major_m - 3.0).abs() < 1e-12);
        assert!((e.semi_minor_m - 1.0).abs() < 1e-12);
        assert!((e.orientation_rad - t).abs() < 1e-12);
        let along_y = ErrorEllipse::from_covariance(&Matrix2::new(1.0, -0.0, -0.0, 4.0));
        assert_eq!(along_y.orientation_rad, std::f64::consts::FRAC_PI_2);
        assert!((e.scaled(CHI2_2D_95_SQRT).semi_major_m - 3.0 * 5.991_464_547_107_979f64.sqrt()).abs() < 1e-12);
    }
}
