//! The dead-reckoning prediction of a robot alone (`planner::predict_odometry`)
//! against Monte Carlo runs of the simulator's drive: an L-shaped route of
//! 2 m moves with random distance and heading errors only.

use cps::ParentPose;
use nalgebra::{Matrix2, Point3, Vector2};
use scanner::sim::{OdometryError, Robot, SimDrive, SimWorld};
use scanner::{Drive, PlanarPose};

#[test]
fn dead_reckoning_covariance_matches_monte_carlo() {
    let route = [Point3::new(0.0, 0.0, 0.5), Point3::new(20.0, 0.0, 0.5), Point3::new(20.0, 10.0, 0.5)];
    let stations = planner::stations(&route, 2.0).expect("stations");
    let dance = planner::solo(stations);
    let noise = planner::OdometryNoise { sigma_distance_m_per_sqrt_m: 0.01, sigma_heading_rad_per_sqrt_m: 0.002 };
    let prediction = planner::predict_odometry(&dance, &noise, &nalgebra::Matrix4::zeros());
    let predicted = prediction.last().expect("cycles").covariance;
    let error = OdometryError {
        scale_error: 0.0,
        sigma_distance_m_per_sqrt_m: noise.sigma_distance_m_per_sqrt_m,
        heading_drift_rad_per_m: 0.0,
        sigma_heading_rad_per_sqrt_m: noise.sigma_heading_rad_per_sqrt_m,
        terrain_tilt_sigma_rad: 0.0,
    };
    let scene = cps::geom::builtin("hall").expect("scene");
    let trials = 2000;
    let (mut sum, mut sum_sq, mut heading_sq) = (Vector2::zeros(), Matrix2::zeros(), 0.0);
    for seed in 0..trials {
        let start = dance.station_pose(0);
        let world = SimWorld::new(scene.clone(), start, vec![]);
        let mut drive =
            SimDrive::new(world.clone(), Robot::Parent, PlanarPose::from(&start), error, seed).expect("drive");
        for k in 1..dance.stations.len() {
            drive.move_to(&PlanarPose::from(&dance.station_pose(k))).expect("move");
        }
        let truth: ParentPose = world.truth().parent;
        let end = dance.station_pose(dance.stations.len() - 1);
        let e = truth.position.xy() - end.position.xy();
        sum += e;
        sum_sq += e * e.transpose();
        heading_sq += cps::wrap_angle(truth.heading_rad - end.heading_rad).powi(2);
    }
    let n = trials as f64;
    let mean = sum / n;
    let empirical = (sum_sq - n * mean * mean.transpose()) / (n - 1.0);
    let p = predicted.fixed_view::<2, 2>(0, 0);
    // σx² + σy² within 3·√(2·tr(P²)/n)/tr(P) (≈ 9 % for n = 2000).
    let tr = p.trace();
    let bound = 3.0 * (2.0 * (p * p).trace() / n).sqrt() / tr;
    let ratio = empirical.trace() / tr;
    assert!((ratio - 1.0).abs() < bound, "σxy² ratio {ratio} (bound ±{bound}); predicted {p}, empirical {empirical}");
    // The heading variance, within 3·√(2/n).
    let h = heading_sq / n / predicted[(3, 3)];
    assert!((h - 1.0).abs() < 3.0 * (2.0 / n).sqrt(), "heading variance ratio {h}");
    // No systematic error: the mean is within 4 standard errors of zero.
    assert!(mean.norm() < 4.0 * (tr / n).sqrt(), "mean error {mean}");
    // And the test can fail: a prediction with half the heading noise is far off.
    let half = planner::OdometryNoise { sigma_heading_rad_per_sqrt_m: 0.001, ..noise };
    let wrong = planner::predict_odometry(&dance, &half, &nalgebra::Matrix4::zeros());
    let wrong_tr = wrong.last().expect("cycles").covariance.fixed_view::<2, 2>(0, 0).trace();
    assert!((empirical.trace() / wrong_tr - 1.0).abs() > bound, "the check separates a wrong prediction");
}
