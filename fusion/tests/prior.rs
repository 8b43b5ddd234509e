//! CPS-prior ICP in a corridor, where the scans cannot see motion along the
//! corridor: the prior fills that direction, the scans the others, and the
//! fused covariance matches Monte Carlo.

mod common;

use common::left_error;
use fusion::FusionError;
use fusion::icp::{IcpConfig, Prior, Target, align, align_with_prior};
use nalgebra::{Isometry3, Matrix6, Point3, Translation3, UnitQuaternion, Vector3, Vector6};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal, StandardNormal};

/// Walls at y = ±1, floor z = 0, ceiling z = 3, x in `xs`, as separate
/// patches 0.4 m apart (so no PCA neighbourhood straddles an edge, whose
/// L-shaped neighbourhoods would give spurious normals along x); noise σ
/// along the normals.
fn corridor(n: usize, xs: std::ops::Range<f64>, sigma: f64, rng: &mut ChaCha8Rng) -> Vec<Point3<f64>> {
    let noise = Normal::new(0.0, sigma).expect("σ");
    (0..n)
        .map(|i| {
            let x = rng.random_range(xs.clone());
            let e = noise.sample(rng);
            match i % 4 {
                0 => Point3::new(x, -1.0 + e, rng.random_range(0.4..2.6)),
                1 => Point3::new(x, 1.0 + e, rng.random_range(0.4..2.6)),
                2 => Point3::new(x, rng.random_range(-0.6..0.6), e),
                _ => Point3::new(x, rng.random_range(-0.6..0.6), 3.0 + e),
            }
        })
        .collect()
}

fn exp(xi: &Vector6<f64>) -> Isometry3<f64> {
    Isometry3::from_parts(
        Translation3::new(xi[3], xi[4], xi[5]),
        UnitQuaternion::from_scaled_axis(Vector3::new(xi[0], xi[1], xi[2])),
    )
}

#[test]
fn prior_fills_the_direction_the_corridor_cannot_see() {
    let mut rng = ChaCha8Rng::seed_from_u64(5);
    let target_pts: Vec<Point3<f32>> = corridor(40_000, 0.0..20.0, 0.0, &mut rng).iter().map(|p| p.cast()).collect();
    let target = Target::new(&target_pts, 10).expect("target");
    let truth =
        Isometry3::from_parts(Translation3::new(6.0, 0.02, 0.01), UnitQuaternion::from_euler_angles(0.0, 0.0, 0.0));
    // The prior: 1° and 5 cm per axis.
    let sd = Vector6::new(1f64.to_radians(), 1f64.to_radians(), 1f64.to_radians(), 0.05, 0.05, 0.05);
    let prior_cov = Matrix6::from_diagonal(&sd.component_mul(&sd));
    let information = prior_cov.try_inverse().expect("invertible");
    let config = IcpConfig { max_correspondence_m: 0.3, max_iterations: 30, ..IcpConfig::default() };

    // ICP alone cannot place the scan along the corridor.
    let source: Vec<Point3<f32>> =
        corridor(3_000, 2.0..8.0, 0.005, &mut rng).iter().map(|p| (truth.inverse() * p).cast()).collect();
    match align(&source, &target, &truth, &config) {
        Err(FusionError::Degenerate { .. }) => {}
        Ok(r) => {
            let along = r.covariance().map_or(f64::INFINITY, |c| c[(3, 3)]);
            assert!(along > 1.0, "ICP alone claims σ_x = {} m along the corridor", along.sqrt());
        }
        Err(e) => panic!("unexpected error {e}"),
    }

    let trials = 300;
    let (mut nees, mut errors, mut predicted) = (0.0, Vec::new(), Matrix6::zeros());
    for _ in 0..trials {
        let source: Vec<Point3<f32>> =
            corridor(3_000, 2.0..8.0, 0.005, &mut rng).iter().map(|p| (truth.inverse() * p).cast()).collect();
        let xi = Vector6::from_fn(|k, _| sd[k] * rng.sample::<f64, _>(StandardNormal));
        let prior = Prior { target_from_source: exp(&xi) * truth, information };
        let r = align_with_prior(&source, &target, &prior.target_from_source, &prior, &config).expect("fused");
        let cov = r.covariance().expect("the fused information is regular");
        let e = left_error(&r.target_from_source, &truth);
        nees += (e.transpose() * r.information * e)[(0, 0)];
        predicted += cov;
        errors.push(e);
    }
    let n = f64::from(trials);
    predicted /= n;
    let nees_mean = nees / n;
    // Consistent: mean NEES 6 (sampling sd 0.2 at 300 trials), ±15 %.
    assert!((5.1..6.9).contains(&nees_mean), "mean NEES {nees_mean}");
    let empirical_var = |k: usize| errors.iter().map(|e| e[k] * e[k]).sum::<f64>() / n;
    // Along the corridor the fused estimate keeps the prior's 5 cm…
    assert!((predicted[(3, 3)].sqrt() - 0.05).abs() < 0.002, "predicted σ_x {}", predicted[(3, 3)].sqrt());
    let sx = empirical_var(3).sqrt();
    assert!((0.04..0.06).contains(&sx), "empirical σ_x {sx}");
    // …across it the scans win by far over the prior's 5 cm, and the
    // predicted σ matches the spread (±20 %; sampling sd ≈ 4 % at 300 trials).
    for k in [4, 5] {
        let (p, e) = (predicted[(k, k)].sqrt(), empirical_var(k).sqrt());
        assert!(p < 0.002 && (e / p - 1.0).abs() < 0.2, "σ[{k}]: predicted {p}, empirical {e}");
    }
}

#[test]
fn prior_needs_point_to_plane_and_a_valid_information() {
    let mut rng = ChaCha8Rng::seed_from_u64(1);
    let pts: Vec<Point3<f32>> = corridor(2_000, 0.0..5.0, 0.0, &mut rng).iter().map(|p| p.cast()).collect();
    let target = Target::new(&pts, 10).expect("target");
    let id = Isometry3::identity();
    let good = Prior { target_from_source: id, information: Matrix6::identity() };
    let p2p = IcpConfig { method: fusion::icp::Method::PointToPoint, ..IcpConfig::default() };
    assert!(align_with_prior(&pts, &target, &id, &good, &p2p).is_err());
    let mut bad = good;
    bad.information[(0, 0)] = -1.0;
    let e = align_with_prior(&pts, &target, &id, &bad, &IcpConfig::default()).expect_err("negative");
    assert!(e.to_string().contains("positive semi-definite"), "{e}");
    bad.information[(0, 0)] = f64::NAN;
    assert!(align_with_prior(&pts, &target, &id, &bad, &IcpConfig::default()).is_err());
}
