//! The total-station noise model (DESIGN §5 "Instrument model").

use nalgebra::Matrix3;

use crate::error::{CpsError, Result, ensure_finite};
use crate::observation::Reading;

/// Radians per arc-second.
pub const RAD_PER_ARCSEC: f64 = std::f64::consts::PI / (180.0 * 3600.0);

/// How the constant and the distance-proportional parts of the distance
/// error combine.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum DistanceErrorModel {
    /// σ_r = √(a² + (b·r)²): independent parts (the default).
    #[default]
    Quadrature,
    /// σ_r = a + b·r: the manufacturer's worst-case sum.
    Linear,
}

/// Noise and limits of the parent's total station. SI units throughout.
///
/// The variance of one pointing's reading (r, φ, ψ) is
/// `diag(σ_r², σ_φ², σ_ψ²)` with
/// - σ_r = a ⊕ b·r (see [`DistanceErrorModel`]), a = `sigma_distance_m`,
///   b = `sigma_distance_ppm`·1e-6;
/// - σ_φ² = σ_hz² + (c_i² + c_t²)/h², h the horizontal distance, c_i and c_t the
///   centring errors of instrument and target;
/// - σ_ψ² = σ_v².
#[derive(Debug, Clone, PartialEq)]
pub struct Instrument {
    /// Constant part of the distance error, metres (1σ).
    pub sigma_distance_m: f64,
    /// Distance-proportional part of the distance error, parts per million.
    pub sigma_distance_ppm: f64,
    /// How the two distance parts combine.
    pub distance_model: DistanceErrorModel,
    /// Horizontal-direction error, radians (1σ).
    pub sigma_hz_rad: f64,
    /// Vertical-angle error, radians (1σ).
    pub sigma_v_rad: f64,
    /// Centring error of the instrument over its station, metres (1σ).
    pub centring_instrument_m: f64,
    /// Centring error of the prism over its point, metres (1σ).
    pub centring_target_m: f64,
    /// Prism constant, metres: added to every raw slope distance
    /// ([`Instrument::corrected_slope_m`]).
    pub prism_constant_m: f64,
    /// Shortest measurable slope distance, metres.
    pub min_range_m: f64,
    /// Longest measurable slope distance, metres (may be `f64::INFINITY`).
    pub max_range_m: f64,
}

impl Default for Instrument {
    /// The seed's TOPCON AP-L1: 3 mm + 2 ppm, 5″, range 4–400 m, no centring error.
    fn default() -> Self {
        Self {
            sigma_distance_m: 0.003,
            sigma_distance_ppm: 2.0,
            distance_model: DistanceErrorModel::Quadrature,
            sigma_hz_rad: 5.0 * RAD_PER_ARCSEC,
            sigma_v_rad: 5.0 * RAD_PER_ARCSEC,
            centring_instrument_m: 0.0,
            centring_target_m: 0.0,
            prism_constant_m: 0.0,
            min_range_m: 4.0,
            max_range_m: 400.0,
        }
    }
}

impl Instrument {
    /// Checks every field: finite (but `max_range_m` may be +∞), non-negative,
    /// at least one non-zero angle error and distance error, and
    /// `min_range_m < max_range_m`.
    pub fn validate(&self) -> Result<()> {
        let fields = [
            ("sigma_distance_m", self.sigma_distance_m),
            ("sigma_distance_ppm", self.sigma_distance_ppm),
            ("sigma_hz_rad", self.sigma_hz_rad),
            ("sigma_v_rad", self.sigma_v_rad),
            ("centring_instrument_m", self.centring_instrument_m),
            ("centring_target_m", self.centring_target_m),
            ("min_range_m", self.min_range_m),
        ];
        for (name, value) in fields {
            ensure_finite(|| name.to_string(), value)?;
            if value < 0.0 {
                return Err(CpsError::OutOfRange { what: name.to_string(), value, expected: "≥ 0".into() });
            }
        }
        ensure_finite(|| "prism_constant_m".into(), self.prism_constant_m)?;
        if self.max_range_m.is_nan() || self.max_range_m <= self.min_range_m {
            return Err(CpsError::OutOfRange {
                what: "max_range_m".into(),
                value: self.max_range_m,
                expected: format!("> min_range_m = {}", self.min_range_m),
            });
        }
        for (name, value) in [
            ("sigma_distance_m (with sigma_distance_ppm)", self.sigma_distance_m + self.sigma_distance_ppm),
            ("sigma_hz_rad", self.sigma_hz_rad),
            ("sigma_v_rad", self.sigma_v_rad),
        ] {
            if value <= 0.0 {
                return Err(CpsError::OutOfRange {
                    what: name.to_string(),
                    value,
                    expected: "> 0 (a perfect instrument makes every weight infinite)".into(),
                });
            }
        }
        Ok(())
    }

    /// 1σ distance error at slope distance `slope_m`.
    pub fn sigma_distance_at(&self, slope_m: f64) -> f64 {
        let a = self.sigma_distance_m;
        let b = self.sigma_distance_ppm * 1e-6 * slope_m;
        match self.distance_model {
            DistanceErrorModel::Quadrature => a.hypot(b),
            DistanceErrorModel::Linear => a + b,
        }
    }

    /// Variances (σ_r², σ_φ², σ_ψ²) of one pointing with this reading.
    pub fn reading_variances(&self, reading: &Reading) -> [f64; 3] {
        let sr = self.sigma_distance_at(reading.slope_m);
        let h = reading.slope_m * reading.elevation_rad.cos();
        let centring = self.centring_instrument_m.powi(2) + self.centring_target_m.powi(2);
        let var_phi = self.sigma_hz_rad.powi(2) + if centring > 0.0 { centring / (h * h) } else { 0.0 };
        [sr * sr, var_phi, self.sigma_v_rad.powi(2)]
    }

    /// Covariance of one pointing's reading, order (r, φ, ψ), m and rad.
    pub fn reading_covariance(&self, reading: &Reading) -> Matrix3<f64> {
        let [a, b, c] = self.reading_variances(reading);
        Matrix3::from_diagonal(&nalgebra::Vector3::new(a, b, c))
    }

    /// `exact` with this instrument's noise: `z` holds three standard-normal
    /// draws, scaled by (σ_r, σ_φ, σ_ψ) of [`Instrument::reading_variances`]
    /// (the azimuth is wrapped). Simulators and Monte Carlo share this so
    /// that they draw exactly the noise the prediction assumes.
    pub fn perturbed(&self, exact: &Reading, z: [f64; 3]) -> Reading {
        let [vr, vp, vv] = self.reading_variances(exact);
        Reading {
            slope_m: exact.slope_m + vr.sqrt() * z[0],
            azimuth_rad: crate::observation::wrap_angle(exact.azimuth_rad + vp.sqrt() * z[1]),
            elevation_rad: exact.elevation_rad + vv.sqrt() * z[2],
        }
    }

    /// The noise model of a sighting of a prism set up once for the whole
    /// survey (a control point's): without the prism's centring, which is
    /// one offset shared by every sighting of it and belongs to the prism's
    /// position instead.
    pub fn without_target_centring(&self) -> Instrument {
        Instrument { centring_target_m: 0.0, ..self.clone() }
    }

    /// The raw slope distance corrected by the prism constant.
    pub fn corrected_slope_m(&self, raw_slope_m: f64) -> f64 {
        raw_slope_m + self.prism_constant_m
    }

    /// Checks that a sight line of `slope_m` to `child` is measurable.
    pub fn check_range(&self, child: usize, slope_m: f64) -> Result<()> {
        if slope_m < self.min_range_m || slope_m > self.max_range_m {
            return Err(CpsError::BeyondInstrumentRange {
                child,
                range_m: slope_m,
                min_m: self.min_range_m,
                max_m: self.max_range_m,
            });
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn distance_error_models() {
        let mut i = Instrument { sigma_distance_m: 0.003, sigma_distance_ppm: 2.0, ..Instrument::default() };
        // 3 mm ⊕ 2 ppm of 2 km (4 mm) = 5 mm; linear: 7 mm.
        assert!((i.sigma_distance_at(2000.0) - 0.005).abs() < 1e-15);
        i.distance_model = DistanceErrorModel::Linear;
        assert!((i.sigma_distance_at(2000.0) - 0.007).abs() < 1e-15);
    }

    #[test]
    fn centring_adds_c2_over_h2_to_direction_variance() {
        let i = Instrument { centring_instrument_m: 0.001, centring_target_m: 0.002, ..Instrument::default() };
        let reading = Reading { slope_m: 20.0, azimuth_rad: 0.3, elevation_rad: (0.6f64).asin() };
        let h = 16.0; // 20 · cos(asin 0.6) = 20 · 0.8
        let [_, var_phi, var_psi] = i.reading_variances(&reading);
        let expected = i.sigma_hz_rad.powi(2) + (1e-6 + 4e-6) / (h * h);
        assert!((var_phi - expected).abs() < 1e-22);
        assert_eq!(var_psi, i.sigma_v_rad.powi(2));
    }

    #[test]
    fn validation_names_the_field() {
        let bad = Instrument { sigma_hz_rad: f64::NAN, ..Instrument::default() };
        let err = bad.validate().expect_err("NaN must be rejected");
        assert!(err.to_string().contains("sigma_hz_rad"), "{err}");
        let bad = Instrument { min_range_m: 10.0, max_range_m: 5.0, ..Instrument::default() };
        assert!(bad.validate().expect_err("inverted range").to_string().contains("max_range_m"));
        let zero = Instrument { sigma_v_rad: 0.0, ..Instrument::default() };
        assert!(zero.validate().is_err());
        assert!(Instrument::default().validate().is_ok());
    }

    #[test]
    fn range_check() {
        let i = Instrument::default();
        assert!(i.check_range(0, 3.9).is_err());
        assert!(i.check_range(0, 4.0).is_ok());
        assert!(i.check_range(1, 400.1).is_err());
    }
}
