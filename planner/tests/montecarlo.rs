//! The prediction against Monte Carlo of the real non-linear procedure.

mod common;

use cps::{Instrument, RAD_PER_ARCSEC};
use nalgebra::{Matrix2, Matrix4, Vector3};
use planner::montecarlo::monte_carlo;

fn instrument() -> Instrument {
    Instrument {
        sigma_distance_m: 0.003,
        sigma_distance_ppm: 2.0,
        sigma_hz_rad: 5.0 * RAD_PER_ARCSEC,
        sigma_v_rad: 5.0 * RAD_PER_ARCSEC,
        min_range_m: 1.0,
        max_range_m: 400.0,
        ..Instrument::default()
    }
}

/// Checks the final station of `trials` executions against the prediction.
///
/// Bound: with e ~ N(0, P) and n independent trials, the estimator
/// s = (1/n)Σ(e_x² + e_y²) has mean tr(P_xy) and variance 2·tr(P_xy²)/n, so
/// |s/tr(P_xy) − 1| < 3·√(2·tr(P_xy²)/n)/tr(P_xy) holds with 99.7 %
/// (≤ 3·√(2/n) = 13.4 % for n = 1000). The mean NEES of a 4-D Gaussian error
/// is χ²_{4n}/n: |NEES − 4| < 3·√(8/n). The same for the heading variance:
/// |s_θ/P_θθ − 1| < 3·√(2/n).
fn check(formation: &[Vector3<f64>], start: Matrix4<f64>, trials: usize, seed: u64) {
    check_dance(&common::straight_dance(10, 10.0, formation), start, trials, seed);
}

fn check_dance(dance: &planner::Dance, start: Matrix4<f64>, trials: usize, seed: u64) {
    let stats = monte_carlo(dance, &instrument(), &start, trials, seed).expect("runs").filter;
    let last = stats.last().expect("cycles");
    let p_xy = Matrix2::from_fn(|i, j| last.predicted[(i, j)]);
    let n = trials as f64;
    let bound_xy = 3.0 * (2.0 * (p_xy * p_xy).trace() / n).sqrt() / p_xy.trace();
    let ratio = last.ratio_xy();
    assert!((ratio - 1.0).abs() < bound_xy, "σxy² ratio {ratio:.4}, bound ±{bound_xy:.4}");
    let ratio_heading = last.empirical[(3, 3)] / last.predicted[(3, 3)];
    let bound_heading = 3.0 * (2.0 / n).sqrt();
    assert!((ratio_heading - 1.0).abs() < bound_heading, "σθ² ratio {ratio_heading:.4}");
    let bound_nees = 3.0 * (8.0 / n).sqrt();
    assert!((last.nees_mean - 4.0).abs() < bound_nees, "NEES {:.4} ± {bound_nees:.4}", last.nees_mean);
}

#[test]
fn wide_symmetric_formation_matches_monte_carlo() {
    check(&common::symmetric(5.0, 10.0), Matrix4::zeros(), 1000, 1);
}

#[test]
fn compact_asymmetric_formation_matches_monte_carlo() {
    let formation = vec![Vector3::new(3.0, 2.5, 0.3), Vector3::new(6.0, -3.0, -0.2)];
    check(&formation, Matrix4::zeros(), 1000, 2);
}

#[test]
fn three_children_with_an_uncertain_start_match_monte_carlo() {
    let formation = vec![Vector3::new(5.0, 8.0, 0.0), Vector3::new(5.0, -8.0, 0.0), Vector3::new(15.0, 0.0, 0.5)];
    let start = Matrix4::from_diagonal(&nalgebra::Vector4::new(1e-4, 2e-4, 1e-4, (20.0 * RAD_PER_ARCSEC).powi(2)));
    check(&formation, start, 1000, 3);
}

#[test]
fn parent_hops_match_monte_carlo() {
    // Children placed 10 m ahead every third station; the parent fixes
    // itself three times from the same children (their errors are shared
    // by the three fixes: the cross-covariances must be carried).
    let formation = common::symmetric(10.0, 8.0);
    let dance = common::straight_schedule(12, 5.0, &formation, planner::Strategy::ParentHops { hops: 3 });
    assert_eq!(dance.cycles.iter().filter(|c| !c.moved.is_empty()).count(), 4);
    check_dance(&dance, Matrix4::zeros(), 1000, 4);
}

#[test]
fn an_inconsistent_prediction_would_fail_the_check() {
    // Guard against a test that cannot fail: the same Monte Carlo compared
    // with a prediction that is off by 30 % is outside the bound.
    let dance = common::straight_dance(10, 10.0, &common::symmetric(5.0, 10.0));
    let stats = monte_carlo(&dance, &instrument(), &Matrix4::zeros(), 1000, 1).expect("runs").filter;
    let last = stats.last().expect("cycles");
    let p_xy = Matrix2::from_fn(|i, j| last.predicted[(i, j)]);
    let bound = 3.0 * (2.0 * (p_xy * p_xy).trace() / 1000.0).sqrt() / p_xy.trace();
    let wrong = cps::sigma_xy2(&last.empirical) / (1.3 * cps::sigma_xy2(&last.predicted));
    assert!((wrong - 1.0).abs() > bound);
}

#[test]
fn every_robots_step_estimate_matches_monte_carlo() {
    // The per-step child and scan-station covariances against the spread of
    // the real procedure's child positions and parent poses. Parent hops
    // place the children at cycles 1, 4, 7 and 10; the last placement
    // carries three fixes' worth of parent error into the children.
    use rand::SeedableRng;
    let formation = common::symmetric(10.0, 8.0);
    let dance = common::straight_schedule(12, 5.0, &formation, planner::Strategy::ParentHops { hops: 3 });
    let instrument = instrument();
    let start = Matrix4::zeros();
    let prediction = planner::predict(&dance, &instrument, &start).expect("predicts");
    let steps = dance.steps(|k| k % 2 == 0);
    let estimates = planner::step_estimates(&dance, &prediction, &steps);
    // One estimate per placement, per fix and per scan.
    let placements = dance.cycles.iter().map(|c| c.moved.len()).sum::<usize>();
    let scans = (0..dance.stations.len()).filter(|k| k % 2 == 0).count();
    assert_eq!(estimates.len(), placements + dance.cycles.len() + scans);
    // Scan-station covariance equals the fix's at the same station.
    for e in estimates.iter().filter(|e| e.scan && e.cycle > 0) {
        let fix = estimates.iter().find(|f| !f.scan && f.robot == planner::Robot::Parent && f.cycle == e.cycle);
        assert_eq!(fix.map(|f| &f.covariance), Some(&e.covariance));
    }
    let last_child =
        |j| estimates.iter().rev().find(|e| e.robot == planner::Robot::Child(j)).expect("child placed").clone();
    let (c0, c1) = (last_child(0), last_child(1));
    assert_eq!(c0.cycle, 10);
    // Monte Carlo: the children's estimated positions at the end of cycle
    // 10 (placed in it, untouched by its fix) minus the truth.
    let trials = 1000;
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(21);
    let mut sums = [0.0_f64; 2];
    for _ in 0..trials {
        let mut team = cps::TeamState::new(dance.station_pose(0), start, 2).expect("team");
        let read = |from: &cps::ParentPose, to: planner::Sighted<'_>| match to {
            planner::Sighted::Child(to) => planner::montecarlo::noisy_reading(from, to, &instrument, &mut rng),
            planner::Sighted::Control(_) => unreachable!("no control in this dance"),
        };
        let mut errors = [0.0_f64; 2];
        planner::run_dance(&dance, &mut team, &instrument, false, read, |c, team, _| {
            if let Some(c) = c.filter(|c| c.cycle == 10) {
                for (j, e) in errors.iter_mut().enumerate() {
                    let d = team.child(j).expect("placed") - c.children[j];
                    *e = d.x * d.x + d.y * d.y;
                }
            }
        })
        .expect("runs");
        for j in 0..2 {
            sums[j] += errors[j];
        }
    }
    // Bound as in `check`: |s/tr(P) − 1| < 3·√(2·tr(P²)/n)/tr(P).
    for (j, c) in [c0, c1].iter().enumerate() {
        let p = Matrix2::from_fn(|r, s| c.covariance[(r, s)]);
        let bound = 3.0 * (2.0 * (p * p).trace() / trials as f64).sqrt() / p.trace();
        let ratio = sums[j] / trials as f64 / p.trace();
        assert!((ratio - 1.0).abs() < bound, "child {j}: ratio {ratio:.4}, bound ±{bound:.4}");
    }
}
