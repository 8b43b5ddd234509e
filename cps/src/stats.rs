//! Summaries a surveyor reads — error ellipses and drift — and the
//! distributions geodetic testing needs: the standard normal and χ²
//! distributions with their quantiles, Baarda's critical value and the
//! non-centrality λ0 of the reliability analysis.

use nalgebra::{Matrix2, Matrix4};

/// √χ²₂(0.95): scales a 1σ ellipse to the 95 % confidence region of a 2-D
/// Gaussian position.
pub const CHI2_2D_95_SQRT: f64 = 2.447_746_830_680_816;

/// √χ²₃(0.95): scales a 1σ ellipsoid to the 95 % confidence region of a 3-D
/// Gaussian position.
pub const CHI2_3D_95_SQRT: f64 = 2.795_483_482_915_108;

/// Baarda's critical value of the w-test at the conventional α0 = 0.1 %
/// (two-sided): z₁₋α0/2 = 3.2905.
pub const W_CRITICAL: f64 = 3.290_526_731_491_926;

/// The conventional significance level of one w-test (data snooping), α0.
pub const ALPHA0: f64 = 0.001;

/// The conventional power of one w-test, β0.
pub const BETA0: f64 = 0.80;

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

/// ln Γ(x) for x > 0 (Lanczos, g = 7, 9 terms: relative error < 1e-15).
fn ln_gamma(x: f64) -> f64 {
    const G: [f64; 9] = [
        0.999_999_999_999_809_9,
        676.520_368_121_885_1,
        -1_259.139_216_722_402_8,
        771.323_428_777_653_1,
        -176.615_029_162_140_6,
        12.507_343_278_686_905,
        -0.138_571_095_265_720_12,
        9.984_369_578_019_572e-6,
        1.505_632_735_149_311_6e-7,
    ];
    if x < 0.5 {
        // Reflection: Γ(x)Γ(1 − x) = π / sin(πx).
        let pi = std::f64::consts::PI;
        return (pi / (pi * x).sin()).ln() - ln_gamma(1.0 - x);
    }
    let x = x - 1.0;
    let t = x + 7.5;
    let sum = G[1..].iter().enumerate().fold(G[0], |s, (i, g)| s + g / (x + i as f64 + 1.0));
    0.5 * (2.0 * std::f64::consts::PI).ln() + (x + 0.5) * t.ln() - t + sum.ln()
}

/// The regularised incomplete gamma functions (P(a, x), Q(a, x) = 1 − P)
/// for a > 0, x ≥ 0: the series where it converges fast (x < a + 1), the
/// continued fraction (modified Lentz) elsewhere, so that neither is
/// computed as a difference from 1.
fn gamma_pq(a: f64, x: f64) -> (f64, f64) {
    if x <= 0.0 {
        return (0.0, 1.0);
    }
    let ln_front = a * x.ln() - x - ln_gamma(a);
    if x < a + 1.0 {
        let (mut term, mut sum, mut n) = (1.0 / a, 1.0 / a, a);
        for _ in 0..100_000 {
            n += 1.0;
            term *= x / n;
            sum += term;
            if term.abs() < sum.abs() * 1e-17 {
                break;
            }
        }
        let p = (ln_front.exp() * sum).min(1.0);
        (p, 1.0 - p)
    } else {
        let tiny = 1e-300;
        let mut b = x + 1.0 - a;
        let mut c = 1.0 / tiny;
        let mut d = 1.0 / b;
        let mut h = d;
        for i in 1..100_000 {
            let an = -(i as f64) * (i as f64 - a);
            b += 2.0;
            d = an * d + b;
            if d.abs() < tiny {
                d = tiny;
            }
            c = b + an / c;
            if c.abs() < tiny {
                c = tiny;
            }
            d = 1.0 / d;
            let delta = d * c;
            h *= delta;
            if (delta - 1.0).abs() < 1e-16 {
                break;
            }
        }
        let q = (ln_front.exp() * h).min(1.0);
        (1.0 - q, q)
    }
}

/// Φ(x): the standard normal distribution function.
pub fn normal_cdf(x: f64) -> f64 {
    // Φ(x) = ½·erfc(−x/√2), erfc(t) = Q(½, t²) for t ≥ 0.
    let t = x / std::f64::consts::SQRT_2;
    let (p, q) = gamma_pq(0.5, t * t);
    if x >= 0.0 { 0.5 + 0.5 * p } else { 0.5 * q }
}

/// Φ⁻¹(p): the standard normal quantile, 0 < p < 1 (Acklam's rational
/// approximation refined by two Newton steps on [`normal_cdf`]; NaN outside
/// (0, 1)).
pub fn normal_quantile(p: f64) -> f64 {
    if !(p > 0.0 && p < 1.0) {
        return f64::NAN;
    }
    const A: [f64; 6] = [
        -3.969_683_028_665_376e1,
        2.209_460_984_245_205e2,
        -2.759_285_104_469_687e2,
        1.383_577_518_672_69e2,
        -3.066_479_806_614_716e1,
        2.506_628_277_459_239,
    ];
    const B: [f64; 5] = [
        -5.447_609_879_822_406e1,
        1.615_858_368_580_409e2,
        -1.556_989_798_598_866e2,
        6.680_131_188_771_972e1,
        -1.328_068_155_288_572e1,
    ];
    const C: [f64; 6] = [
        -7.784_894_002_430_293e-3,
        -3.223_964_580_411_365e-1,
        -2.400_758_277_161_838,
        -2.549_732_539_343_734,
        4.374_664_141_464_968,
        2.938_163_982_698_783,
    ];
    const D: [f64; 4] =
        [7.784_695_709_041_462e-3, 3.224_671_290_700_398e-1, 2.445_134_137_142_996, 3.754_408_661_907_416];
    let tail = |q: f64| {
        (((((C[0] * q + C[1]) * q + C[2]) * q + C[3]) * q + C[4]) * q + C[5])
            / ((((D[0] * q + D[1]) * q + D[2]) * q + D[3]) * q + 1.0)
    };
    let mut x = if p < 0.02425 {
        tail((-2.0 * p.ln()).sqrt())
    } else if p > 1.0 - 0.02425 {
        -tail((-2.0 * (1.0 - p).ln()).sqrt())
    } else {
        let q = p - 0.5;
        let r = q * q;
        (((((A[0] * r + A[1]) * r + A[2]) * r + A[3]) * r + A[4]) * r + A[5]) * q
            / (((((B[0] * r + B[1]) * r + B[2]) * r + B[3]) * r + B[4]) * r + 1.0)
    };
    for _ in 0..2 {
        let density = (-0.5 * x * x).exp() / (2.0 * std::f64::consts::PI).sqrt();
        if density > 0.0 {
            x -= (normal_cdf(x) - p) / density;
        }
    }
    x
}

/// P(χ²_dof ≤ x): the χ² distribution function with `dof` degrees of freedom.
pub fn chi2_cdf(x: f64, dof: f64) -> f64 {
    gamma_pq(0.5 * dof, 0.5 * x).0
}

/// The p-quantile of the χ² distribution with `dof` > 0 degrees of freedom,
/// 0 < p < 1: the Wilson–Hilferty start, then Newton steps on [`chi2_cdf`]
/// safeguarded by bisection (relative accuracy ~1e-12; NaN for bad input).
pub fn chi2_quantile(p: f64, dof: f64) -> f64 {
    if !(p > 0.0 && p < 1.0 && dof > 0.0 && dof.is_finite()) {
        return f64::NAN;
    }
    let z = normal_quantile(p);
    let h = 2.0 / (9.0 * dof);
    let mut x = (dof * (1.0 - h + z * h.sqrt()).powi(3)).max(1e-3 * dof.min(1.0));
    let (mut lo, mut hi) = (0.0, f64::INFINITY);
    for _ in 0..200 {
        let f = chi2_cdf(x, dof) - p;
        if f < 0.0 {
            lo = x;
        } else {
            hi = x;
        }
        let k = 0.5 * dof;
        let ln_pdf = (k - 1.0) * x.ln() - 0.5 * x - k * std::f64::consts::LN_2 - ln_gamma(k);
        let mut next = x - f / ln_pdf.exp();
        if !(next > lo && next < hi && next.is_finite()) {
            next = if hi.is_finite() { 0.5 * (lo + hi) } else { 2.0 * x.max(1e-3) };
        }
        if (next - x).abs() <= 1e-13 * x.max(1e-300) {
            return next;
        }
        x = next;
    }
    x
}

/// Baarda's non-centrality λ0 of a one-dimensional test at significance
/// `alpha0` (two-sided) with power `beta0`: λ0 = (z₁₋α0/2 + z_β0)²
/// (≈ 17.07 for α0 = 0.001, β0 = 0.80). The minimal detectable bias of an
/// observation with standard deviation σ and redundancy number r is
/// σ·√(λ0 / r).
pub fn noncentrality(alpha0: f64, beta0: f64) -> f64 {
    (normal_quantile(1.0 - alpha0 / 2.0) + normal_quantile(beta0)).powi(2)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Quantiles against published tables (R's qnorm / qchisq).
    #[test]
    fn quantiles_match_the_tables() {
        let close = |a: f64, b: f64, tol: f64| assert!((a - b).abs() <= tol * b.abs(), "{a} vs {b}");
        close(normal_quantile(0.9995), 3.290_526_731_491_926, 1e-12);
        close(normal_quantile(0.8), 0.841_621_233_572_914_3, 1e-12);
        close(normal_quantile(0.025), -1.959_963_984_540_054, 1e-12);
        close(normal_quantile(1e-10), -6.361_340_902_404_056, 1e-10);
        close(normal_cdf(1.959_963_984_540_054), 0.975, 1e-14);
        close(normal_cdf(-8.0), 6.220_960_574_271_74e-16, 1e-10);
        close(chi2_quantile(0.95, 2.0), 5.991_464_547_107_979, 1e-12);
        close(chi2_quantile(0.95, 3.0), 7.814_727_903_251_179, 1e-12);
        close(chi2_quantile(0.025, 10.0), 3.246_972_780_236_841, 1e-11);
        close(chi2_quantile(0.975, 10.0), 20.483_177_350_807_39, 1e-12);
        close(chi2_quantile(0.025, 1.0), 9.820_691_171_752_555e-4, 1e-9);
        close(chi2_quantile(0.975, 1000.0), 1_089.530_912_774_913_5, 1e-11);
        close(chi2_quantile(0.025, 12_000.0), 11_698.262_408_215_567, 1e-11);
        close(chi2_cdf(5.991_464_547_107_979, 2.0), 0.95, 1e-13);
        close(noncentrality(ALPHA0, BETA0), 17.074_646_805_189_502, 1e-9);
        close(W_CRITICAL, normal_quantile(1.0 - ALPHA0 / 2.0), 1e-12);
        close(CHI2_2D_95_SQRT, chi2_quantile(0.95, 2.0).sqrt(), 1e-12);
        close(CHI2_3D_95_SQRT, chi2_quantile(0.95, 3.0).sqrt(), 1e-12);
        assert!(chi2_quantile(1.5, 3.0).is_nan() && normal_quantile(0.0).is_nan());
    }

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
