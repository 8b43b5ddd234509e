//! The χ² distribution's 99.9 % points and a χ² in a covariance that may
//! be singular: the one table every test of a pose's move against its σ
//! uses (the priors' gate, a held direction's move, a pair's departure in
//! its poses' relative σ).

use nalgebra::{Matrix6, Vector6};

/// The 99.9 % point of χ² with `dof` degrees of freedom (1–6; clamped).
pub const fn chi2_999(dof: usize) -> f64 {
    const LIMITS: [f64; 6] = [10.828, 13.816, 16.266, 18.467, 20.515, 22.458];
    let k = if dof < 1 {
        1
    } else if dof > 6 {
        6
    } else {
        dof
    };
    LIMITS[k - 1]
}

/// eᵀ·C⁺·e and the rank of `c` (eigenvalues above 10⁻¹² of the largest).
/// A departure along a direction `c` does not span — beyond 10⁻⁹ (radians
/// or metres) — is infinitely unlikely: χ² is then infinite (with a zero
/// `c`, any nonzero `e`).
pub fn within(c: &Matrix6<f64>, e: &Vector6<f64>) -> (f64, usize) {
    let eigen = nalgebra::SymmetricEigen::new(0.5 * (c + c.transpose()));
    let largest = eigen.eigenvalues.max();
    let (mut chi2, mut rank, mut null) = (0.0, 0, 0.0);
    for k in 0..6 {
        let l = eigen.eigenvalues[k];
        let along = eigen.eigenvectors.column(k).dot(e);
        if l > 1e-12 * largest && l > 0.0 {
            chi2 += along.powi(2) / l;
            rank += 1;
        } else {
            null += along.powi(2);
        }
    }
    if null.sqrt() > 1e-9 {
        chi2 = f64::INFINITY;
    }
    (chi2, rank)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The table against the distribution: P(χ²ₖ > limit) = 10⁻³, by the
    /// closed forms for 2, 4 and 6 degrees of freedom (e^(−x/2) times the
    /// first k/2 terms of its series).
    #[test]
    fn the_limits_leave_a_thousandth_beyond() {
        for k in [2usize, 4, 6] {
            let x = chi2_999(k) / 2.0;
            let (mut term, mut sum) = (1.0, 0.0);
            for j in 0..k / 2 {
                if j > 0 {
                    term *= x / j as f64;
                }
                sum += term;
            }
            let tail = (-x).exp() * sum;
            assert!((tail - 1e-3).abs() < 2e-6, "χ²{k}: tail {tail}");
        }
        assert_eq!(chi2_999(0), chi2_999(1));
        assert_eq!(chi2_999(9), chi2_999(6));
    }

    /// In a covariance of rank 3 a departure within its span is weighed by
    /// its pseudo-inverse; one outside it, or any against a zero
    /// covariance, is infinitely unlikely.
    #[test]
    fn a_departure_the_covariance_does_not_span_is_infinitely_unlikely() {
        let c = Matrix6::from_diagonal(&Vector6::new(4.0, 1.0, 0.25, 0.0, 0.0, 0.0));
        let (chi2, rank) = within(&c, &Vector6::new(2.0, 1.0, 0.5, 0.0, 0.0, 0.0));
        assert_eq!(rank, 3);
        assert!((chi2 - 3.0).abs() < 1e-12, "{chi2}");
        assert_eq!(within(&c, &Vector6::new(0.0, 0.0, 0.0, 1e-3, 0.0, 0.0)).0, f64::INFINITY);
        assert_eq!(within(&Matrix6::zeros(), &Vector6::zeros()), (0.0, 0));
        assert_eq!(within(&Matrix6::zeros(), &Vector6::new(1e-3, 0.0, 0.0, 0.0, 0.0, 0.0)).0, f64::INFINITY);
    }
}
