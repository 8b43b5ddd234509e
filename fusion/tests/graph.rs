//! The pose graph against Monte Carlo: noisy priors and noisy relative
//! measurements of known poses; the adjusted poses' errors must match the
//! covariance the adjustment reports (mean NEES ≈ 6 per pose) and χ² its
//! redundancy.

mod common;

use common::left_error;
use fusion::graph::{Edge, optimize};
use fusion::icp::Prior;
use nalgebra::{Isometry3, Matrix6, Translation3, UnitQuaternion, Vector3, Vector6};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;

fn exp(xi: &Vector6<f64>) -> Isometry3<f64> {
    Isometry3::from_parts(
        Translation3::new(xi[3], xi[4], xi[5]),
        UnitQuaternion::from_scaled_axis(Vector3::new(xi[0], xi[1], xi[2])),
    )
}

/// A sample of N(0, diag(sd²)) rotated by `basis` (so the covariance is
/// full): returns the sample and the covariance.
fn noise(sd: &Vector6<f64>, basis: &Matrix6<f64>, rng: &mut ChaCha8Rng) -> Vector6<f64> {
    basis * Vector6::from_fn(|k, _| sd[k] * rng.sample::<f64, _>(StandardNormal))
}

#[test]
fn graph_covariance_matches_monte_carlo() {
    let mut rng = ChaCha8Rng::seed_from_u64(11);
    let n = 6;
    let truth: Vec<Isometry3<f64>> = (0..n)
        .map(|i| {
            Isometry3::from_parts(
                Translation3::new(4.0 * i as f64, 0.3 * (i as f64).sin(), 0.1 * i as f64),
                UnitQuaternion::from_euler_angles(0.01 * i as f64, -0.02, 0.3 * i as f64),
            )
        })
        .collect();
    // A full-rank rotation of the noise axes (orthonormal via QR).
    let basis = Matrix6::from_fn(|r, c| ((r * 7 + c * 3) % 11) as f64 - 5.0 + if r == c { 9.0 } else { 0.0 }).qr().q();
    let prior_sd = Vector6::new(2e-3, 2e-3, 5e-3, 0.01, 0.01, 0.005);
    let edge_sd = Vector6::new(5e-4, 5e-4, 1e-3, 0.002, 0.003, 0.001);
    let info = |sd: &Vector6<f64>| basis * Matrix6::from_diagonal(&sd.map(|s| 1.0 / (s * s))) * basis.transpose();
    let (prior_info, edge_info) = (info(&prior_sd), info(&edge_sd));

    let trials = 400;
    let mut nees = vec![0.0; n];
    let mut chi2 = 0.0;
    let mut redundancy = 0;
    for _ in 0..trials {
        // Priors on every other scan; edges between neighbours and one long one.
        let priors: Vec<Option<Prior>> = (0..n)
            .map(|i| {
                i.is_multiple_of(2).then(|| Prior {
                    target_from_source: exp(&noise(&prior_sd, &basis, &mut rng)) * truth[i],
                    information: prior_info,
                })
            })
            .collect();
        let mut pairs: Vec<(usize, usize)> = (1..n).map(|i| (i - 1, i)).collect();
        pairs.push((0, n - 1));
        let edges: Vec<Edge> = pairs
            .iter()
            .map(|&(t, s)| Edge {
                target: t,
                source: s,
                target_from_source: exp(&noise(&edge_sd, &basis, &mut rng)) * (truth[t].inverse() * truth[s]),
                information: edge_info,
            })
            .collect();
        // Start from a rough guess: the truth moved by 5 cm and 1°.
        let init: Vec<Isometry3<f64>> =
            truth.iter().map(|t| exp(&Vector6::new(0.0, 0.0, 0.017, 0.05, -0.05, 0.0)) * t).collect();
        let r = optimize(&init, &priors, &edges, 20).expect("solvable");
        assert!(r.iterations < 20, "Gauss–Newton converges");
        for i in 0..n {
            let e = left_error(&truth[i], &r.world_from_scan[i]);
            let info = r.covariance[i].try_inverse().expect("regular");
            nees[i] += (e.transpose() * info * e)[(0, 0)] / trials as f64;
        }
        chi2 += r.chi2 / trials as f64;
        redundancy = r.redundancy;
    }
    // χ²₆ has variance 12: the mean of 400 is 6 ± 3·√(12/400) = 6 ± 0.52.
    for (i, v) in nees.iter().enumerate() {
        assert!((v - 6.0).abs() < 3.0 * (12.0 / trials as f64).sqrt(), "pose {i}: mean NEES {v}");
    }
    let dof = redundancy as f64;
    assert_eq!(redundancy, 6 * (3 + n) - 6 * n);
    assert!((chi2 - dof).abs() < 3.0 * (2.0 * dof / trials as f64).sqrt(), "mean χ² {chi2} vs {dof}");
}

#[test]
fn graph_rejects_a_free_frame_and_bad_edges() {
    let init = vec![Isometry3::identity(); 2];
    let edge =
        Edge { target: 0, source: 1, target_from_source: Isometry3::identity(), information: Matrix6::identity() };
    let err = optimize(&init, &[None, None], &[edge], 10).expect_err("no prior");
    assert!(err.to_string().contains("without any prior"), "{err}");
    let prior = Prior { target_from_source: Isometry3::identity(), information: Matrix6::identity() };
    let bad = Edge { source: 5, ..edge };
    let err = optimize(&init, &[Some(prior), None], &[bad], 10).expect_err("edge out of range");
    assert!(err.to_string().contains("two different scans below 2"), "{err}");
    // Scan 1 has neither a prior nor an edge: singular.
    let err = optimize(&init, &[Some(prior), None], &[], 10).expect_err("unconstrained scan");
    assert!(err.to_string().contains("singular"), "{err}");
}

/// A joint prior whose errors are correlated like a leapfrog chain's (a
/// random walk: pose i's prior error is the sum of i + 1 independent
/// steps) with relative measurements between neighbours: the adjusted
/// poses' errors match the reported covariance (mean NEES ≈ 6), χ² its
/// redundancy — and taking the same priors as independent (their marginals)
/// misjudges the errors, which is why the missions pass the joint one.
#[test]
fn joint_prior_covariance_matches_monte_carlo() {
    use fusion::graph::{JointPrior, optimize_joint};
    let mut rng = ChaCha8Rng::seed_from_u64(5);
    let n = 5;
    let truth: Vec<Isometry3<f64>> = (0..n)
        .map(|i| {
            Isometry3::from_parts(
                Translation3::new(5.0 * i as f64, 0.2 * i as f64, 0.0),
                UnitQuaternion::from_euler_angles(0.0, 0.01, 0.2 * i as f64),
            )
        })
        .collect();
    let basis = Matrix6::from_fn(|r, c| ((r * 5 + c * 2) % 7) as f64 - 3.0 + if r == c { 8.0 } else { 0.0 }).qr().q();
    let step_sd = Vector6::new(1e-3, 1e-3, 3e-3, 0.006, 0.008, 0.003);
    let edge_sd = Vector6::new(2e-3, 2e-3, 2e-3, 0.004, 0.004, 0.004);
    let q = basis * Matrix6::from_diagonal(&step_sd.map(|s| s * s)) * basis.transpose();
    let edge_info = basis * Matrix6::from_diagonal(&edge_sd.map(|s| 1.0 / (s * s))) * basis.transpose();
    // cov(ξᵢ, ξⱼ) = (min(i, j) + 1)·Q.
    let mut joint = faer::Mat::<f64>::zeros(6 * n, 6 * n);
    for i in 0..n {
        for j in 0..n {
            for r in 0..6 {
                for c in 0..6 {
                    joint[(6 * i + r, 6 * j + c)] = (i.min(j) + 1) as f64 * q[(r, c)];
                }
            }
        }
    }
    let trials = 400;
    let (mut nees, mut nees_independent, mut chi2) = (vec![0.0; n], 0.0, 0.0);
    let mut redundancy = 0;
    for trial in 0..trials {
        let mut walk = Vector6::zeros();
        let means: Vec<Isometry3<f64>> = truth
            .iter()
            .map(|t| {
                walk += noise(&step_sd, &basis, &mut rng);
                exp(&walk) * t
            })
            .collect();
        let edges: Vec<Edge> = (1..n)
            .map(|s| Edge {
                target: s - 1,
                source: s,
                target_from_source: exp(&noise(&edge_sd, &basis, &mut rng)) * (truth[s - 1].inverse() * truth[s]),
                information: edge_info,
            })
            .collect();
        let prior = JointPrior::new(means.clone(), joint.clone()).expect("prior");
        let r = optimize_joint(&means, &prior, &edges, 20).expect("solvable");
        for i in 0..n {
            let e = left_error(&truth[i], &r.world_from_scan[i]);
            nees[i] += (e.transpose() * r.covariance[i].try_inverse().expect("regular") * e)[(0, 0)] / trials as f64;
        }
        chi2 += r.chi2 / trials as f64;
        redundancy = r.redundancy;
        // The marginals alone, as independent priors.
        let marginals: Vec<Option<Prior>> = (0..n).map(|i| Some(prior.marginal(i))).collect();
        let ind = optimize(&means, &marginals, &edges, 20).expect("solvable");
        let e = left_error(&truth[n - 1], &ind.world_from_scan[n - 1]);
        nees_independent +=
            (e.transpose() * ind.covariance[n - 1].try_inverse().expect("regular") * e)[(0, 0)] / trials as f64;
        if trial == 0 {
            // A block-diagonal joint prior is the independent priors.
            let block = JointPrior::independent(&marginals.iter().flatten().copied().collect::<Vec<_>>())
                .expect("block diagonal");
            let same = optimize_joint(&means, &block, &edges, 20).expect("solvable");
            for (a, b) in same.world_from_scan.iter().zip(&ind.world_from_scan) {
                assert!(left_error(a, b).amax() < 1e-9);
            }
            assert!((same.chi2 - ind.chi2).abs() < 1e-6 * ind.chi2.max(1.0));
        }
    }
    let bound = 3.0 * (12.0 / trials as f64).sqrt();
    for (i, v) in nees.iter().enumerate() {
        assert!((v - 6.0).abs() < bound, "pose {i}: mean NEES {v}");
    }
    assert_eq!(redundancy, 6 * (n + n - 1) - 6 * n);
    let dof = redundancy as f64;
    assert!((chi2 - dof).abs() < 3.0 * (2.0 * dof / trials as f64).sqrt(), "mean χ² {chi2} vs {dof}");
    assert!((nees_independent - 6.0).abs() > 3.0 * bound, "independent priors: mean NEES {nees_independent}");
}

#[test]
fn joint_prior_rejects_bad_sizes_and_values() {
    use fusion::graph::JointPrior;
    let means = vec![Isometry3::identity(); 2];
    assert!(JointPrior::new(means.clone(), faer::Mat::zeros(6, 6)).is_err(), "6×6 for 2 poses");
    let mut nan = faer::Mat::<f64>::identity(12, 12);
    nan[(3, 4)] = f64::NAN;
    assert!(JointPrior::new(means.clone(), nan).expect_err("NaN").to_string().contains("finite"));
    let mut asym = faer::Mat::<f64>::identity(12, 12);
    asym[(0, 7)] = 0.5;
    assert!(JointPrior::new(means.clone(), asym).expect_err("asymmetric").to_string().contains("symmetric"));
    let ok = JointPrior::new(means, faer::Mat::identity(12, 12)).expect("identity");
    assert_eq!(ok.len(), 2);
    assert_eq!(ok.covariance_block(0, 1), Matrix6::zeros());
}
