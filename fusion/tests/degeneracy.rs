//! Degeneracy-aware ICP on a straight, featureless corridor (two walls, a
//! floor and a ceiling along x): the matches see y, z and every rotation
//! but not the corridor's axis. Plain point-to-plane refuses the singular
//! normal equations; with `degeneracy_ratio` the axis is reported as
//! unobservable and held where the start put it, while the rest is
//! recovered.

use fusion::icp::{IcpConfig, Target, align};
use nalgebra::{Isometry3, Point3, Translation3, UnitQuaternion, Vector3};

/// The corridor's surfaces sampled on a 5 cm grid, x from 0 to 20 m.
fn corridor() -> Vec<Point3<f32>> {
    let mut points = Vec::new();
    for i in 0..400 {
        let x = i as f32 * 0.05;
        for k in 0..50 {
            let z = k as f32 * 0.05;
            points.push(Point3::new(x, -1.5, z));
            points.push(Point3::new(x, 1.5, z));
        }
        for k in 0..60 {
            let y = -1.5 + k as f32 * 0.05;
            points.push(Point3::new(x, y, 0.0));
            points.push(Point3::new(x, y, 2.5));
        }
    }
    points
}

#[test]
fn the_corridor_axis_is_unobservable_and_held_while_the_rest_is_recovered() {
    let target_points = corridor();
    let target = Target::new(&target_points, 10).expect("normals");
    // The truth moves the source 0.06 m across, 0.04 m up and 0.8° in yaw;
    // the start knows none of it and is 0.25 m off along the axis.
    let truth = Isometry3::from_parts(
        Translation3::new(0.0, 0.06, 0.04),
        UnitQuaternion::from_euler_angles(0.0, 0.0, 0.8f64.to_radians()),
    );
    // 1 mm of (deterministic) noise on every source coordinate, as a
    // scanner gives.
    let mut state = 12_345u64;
    let mut noise = || {
        state = state.wrapping_mul(6_364_136_223_846_793_005).wrapping_add(1_442_695_040_888_963_407);
        ((state >> 11) as f64 / (1u64 << 53) as f64 - 0.5) * 0.002
    };
    let source: Vec<Point3<f32>> = target_points
        .iter()
        .filter(|p| (2.0..18.0).contains(&p.x))
        .map(|p| (truth.inverse() * p.cast::<f64>() + Vector3::new(noise(), noise(), noise())).cast::<f32>())
        .collect();
    let start = Isometry3::translation(0.25, 0.0, 0.0);
    let plain = IcpConfig { max_correspondence_m: 0.3, ..IcpConfig::default() };
    // (Analysed about the source's centroid, a rotation weighs less than
    // about the corridor's end: the axis's numerical noise, 1e-4 of the
    // largest eigenvalue there, asks for 1e-3.)
    let aware = IcpConfig { degeneracy_ratio: Some(1e-3), ..plain };
    let r = align(&source, &target, &start, &aware).expect("converges");
    assert!(r.converged);
    assert_eq!(r.unobservable.len(), 1, "{:?}", r.unobservable);
    let d = r.unobservable[0];
    assert!(d[3].abs() > 0.999, "the unobservable direction is translation along x: {d}");
    let t = r.target_from_source.translation.vector;
    // Along the axis: held where the start put it (0.25 m), not slid.
    assert!((t.x - (0.25 + truth.translation.x)).abs() < 0.01, "x {}", t.x);
    // Across and up, and the rotation: recovered.
    let want = truth.translation.vector;
    assert!((Vector3::new(0.0, t.y, t.z) - Vector3::new(0.0, want.y, want.z)).norm() < 1e-3, "{t}");
    let angle = (r.target_from_source.rotation.inverse() * truth.rotation).angle();
    assert!(angle < 0.02f64.to_radians(), "{}°", angle.to_degrees());
}

#[test]
fn a_closed_room_has_no_unobservable_direction_and_the_same_answer() {
    // The corridor closed by end walls at x = 0 and x = 20.
    let mut target_points = corridor();
    for k in 0..50 {
        for j in 0..60 {
            let (y, z) = (-1.5 + j as f32 * 0.05, k as f32 * 0.05);
            target_points.push(Point3::new(0.0, y, z));
            target_points.push(Point3::new(20.0, y, z));
        }
    }
    let target = Target::new(&target_points, 10).expect("normals");
    let truth = Isometry3::from_parts(
        Translation3::new(0.12, -0.05, 0.03),
        UnitQuaternion::from_euler_angles(0.2f64.to_radians(), 0.0, -0.5f64.to_radians()),
    );
    let source: Vec<Point3<f32>> =
        target_points.iter().map(|p| (truth.inverse() * p.cast::<f64>()).cast::<f32>()).collect();
    let plain = IcpConfig { max_correspondence_m: 0.3, ..IcpConfig::default() };
    let aware = IcpConfig { degeneracy_ratio: Some(1e-3), ..plain };
    let a = align(&source, &target, &Isometry3::identity(), &plain).expect("plain");
    let b = align(&source, &target, &Isometry3::identity(), &aware).expect("aware");
    assert!(b.unobservable.is_empty(), "{:?}", b.unobservable);
    assert!((a.target_from_source.translation.vector - b.target_from_source.translation.vector).norm() < 1e-9);
    assert!((b.target_from_source.translation.vector - truth.translation.vector).norm() < 1e-3);
}
