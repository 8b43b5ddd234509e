//! Pipe fitting on a simulated scan of the `sewer` scene: the radius, the
//! axis, the brick and the dent.

use cps::ParentPose;
use cps::geom::{SEWER_BRICK_CENTER, SEWER_BRICK_SIZE_M, SEWER_RADIUS_M, builtin};
use fusion::direct::transform;
use fusion::pipe::{AnomalyKind, Pipe, PipeConfig, anomalies, fit_pipe};
use nalgebra::{Isometry3, Point3, Translation3, UnitQuaternion, Vector3};
use scanner::sim::{LmsConfig, LmsRangeMode, LmsResolution, SimHead, SimLms, SimWorld};
use scanner::{HeadKind, scan_3d};

/// Rotating-table scans from the robot on the invert at x = 9 m and 11 m,
/// in the world frame (the true poses: direct fusion).
fn sewer_scans() -> Vec<Point3<f32>> {
    let mut points = sewer_scan(9.0, 3);
    points.extend(sewer_scan(11.0, 4));
    points
}

fn sewer_scan(x: f64, seed: u64) -> Vec<Point3<f32>> {
    let world = SimWorld::new(builtin("sewer").expect("sewer"), ParentPose::new(x, 0.0, 0.15, 0.0), vec![]);
    let truth = world.truth();
    let body_from_head = Isometry3::from_parts(Translation3::new(0.0, 0.0, 0.3), UnitQuaternion::identity());
    let config = LmsConfig { resolution: LmsResolution::Half, mode: LmsRangeMode::Mm8, sigma_range_m: 0.005 };
    let mut lms = SimLms::new(world.clone(), config, HeadKind::RotatingTable, body_from_head, seed);
    let mut head = SimHead::new(world, HeadKind::RotatingTable);
    let scan = scan_3d(&mut head, &mut lms, 360, &body_from_head, &mut |_, _| {}).expect("scan");
    transform(&scan.points, &truth.tilt.world_from_body(&truth.parent))
}

#[test]
fn sewer_pipe_radius_axis_brick_and_dent() {
    let points = sewer_scans();
    // The default tube: 10 % too small, its axis 3 cm off and tilted by 1°.
    let initial = Pipe {
        a: Point3::new(0.0, 0.03, 0.47),
        b: Point3::new(20.0, 0.03 + 20.0 * 1f64.to_radians().tan(), 0.47),
        radius_m: 0.45,
    };
    let fit = fit_pipe(&points, &initial, &PipeConfig::default()).expect("fit");
    assert!(fit.converged, "{} iterations", fit.iterations);
    let pipe = fit.pipe;
    assert!((pipe.radius_m - SEWER_RADIUS_M).abs() < 0.002, "radius {}", pipe.radius_m);
    let angle = pipe.direction().angle(&Vector3::x()).min(pipe.direction().angle(&-Vector3::x()));
    assert!(angle.to_degrees() < 0.2, "axis off by {}°", angle.to_degrees());
    // The axis passes (y, z) = (0, r) within 2 mm along the scanned stretch.
    for x in [6.0, 10.0, 14.0] {
        let s = (x - pipe.a.x) / pipe.direction().x;
        let p = pipe.a + s * pipe.direction();
        assert!((p.y.powi(2) + (p.z - SEWER_RADIUS_M).powi(2)).sqrt() < 0.002, "axis at x = {x}: {p}");
    }
    // Deviations beyond 2 cm, linked within 5 cm, at least 20 points.
    let found = anomalies(&points, &pipe, 0.02, 0.05, 20).expect("anomalies");
    let near = |c: &Point3<f64>, x: f64| (c.x - x).abs() < 0.3;
    let brick = found.iter().find(|a| near(&a.centroid, SEWER_BRICK_CENTER[0])).expect("the brick is found");
    assert_eq!(brick.kind, AnomalyKind::Intrusion);
    let [bx, by, bz] = SEWER_BRICK_CENTER;
    let [bl, bw, bh] = SEWER_BRICK_SIZE_M;
    // Its points lie on the brick (box grown by 2 cm for noise and the threshold).
    let (lo, hi) = brick.bounds;
    assert!(lo.x > bx - bl / 2.0 - 0.02 && hi.x < bx + bl / 2.0 + 0.02, "x {lo} {hi}");
    assert!(lo.y > by - bw / 2.0 - 0.02 && hi.y < by + bw / 2.0 + 0.02, "y {lo} {hi}");
    assert!(hi.z < bz + bh / 2.0 + 0.02, "z {hi}");
    assert!(brick.max_deviation_m > 0.05, "the brick stands 7 cm: {}", brick.max_deviation_m);
    let dent = found.iter().find(|a| near(&a.centroid, 12.0)).expect("the dent is found");
    assert_eq!(dent.kind, AnomalyKind::Intrusion);
    assert!(dent.centroid.z > 0.9, "the dent is in the crown: {}", dent.centroid);
    assert!((dent.max_deviation_m - 0.04).abs() < 0.01, "dent depth {}", dent.max_deviation_m);
    assert_eq!(found.len(), 2, "nothing else deviates: {found:?}");
}
