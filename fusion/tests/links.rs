//! The link graph ([`fusion::links`]) on synthetic scans with known truth:
//! a straight, featureless corridor, where every link is blind along the
//! axis — held at the start's increments with the start's σ — and the
//! rest is recovered; and a link that converged into the wrong place,
//! left out.

use fusion::links::{LinkConfig, adjust};
use fusion::multiview::MultiviewConfig;
use nalgebra::{Isometry3, Point3, Translation3, UnitQuaternion, Vector3};

/// A corridor's walls, floor and ceiling along x on a 5 cm grid, x in
/// [x0, x1], with 1 mm of deterministic noise, in the frame `world_from_scan`.
fn corridor(x0: f64, x1: f64, world_from_scan: &Isometry3<f64>, seed: u64) -> Vec<Point3<f32>> {
    let mut state = seed;
    let mut noise = || {
        state = state.wrapping_mul(6_364_136_223_846_793_005).wrapping_add(1_442_695_040_888_963_407);
        ((state >> 11) as f64 / (1u64 << 53) as f64 - 0.5) * 0.002
    };
    let mut points = Vec::new();
    let mut x = x0;
    while x <= x1 {
        for k in 0..50 {
            let z = k as f64 * 0.05;
            points.push(Vector3::new(x, -1.5, z));
            points.push(Vector3::new(x, 1.5, z));
        }
        for k in 0..60 {
            let y = -1.5 + k as f64 * 0.05;
            points.push(Vector3::new(x, y, 0.0));
            points.push(Vector3::new(x, y, 2.5));
        }
        x += 0.05;
    }
    let scan_from_world = world_from_scan.inverse();
    points
        .into_iter()
        .map(|p| (scan_from_world * Point3::from(p) + Vector3::new(noise(), noise(), noise())).cast::<f32>())
        .collect()
}

fn config() -> LinkConfig {
    let c = LinkConfig::default();
    LinkConfig {
        multiview: MultiviewConfig {
            source_voxel_m: 0.1,
            target_voxel_m: 0.1,
            icp: fusion::icp::IcpConfig { max_correspondence_m: 0.3, reject_back_faces: false, ..c.multiview.icp },
            ..c.multiview
        },
        ..c
    }
}

#[test]
fn a_corridor_is_blind_along_its_axis_and_held_there_by_the_start() {
    let truth: Vec<Isometry3<f64>> = (0..3)
        .map(|k| {
            let k = k as f64;
            Isometry3::from_parts(
                Translation3::new(2.0 * k, 0.04 * k, 0.5 + 0.01 * k),
                UnitQuaternion::from_euler_angles(0.0, 0.0, (0.5 * k).to_radians()),
            )
        })
        .collect();
    let scans: Vec<Vec<Point3<f32>>> = truth
        .iter()
        .enumerate()
        .map(|(k, t)| corridor(2.0 * k as f64 - 6.0, 2.0 * k as f64 + 6.0, t, k as u64 + 1))
        .collect();
    // The start: 0.15 m per step too far along the axis, and 3 cm / 0.3°
    // off across.
    let starts: Vec<Isometry3<f64>> = truth
        .iter()
        .enumerate()
        .map(|(k, t)| {
            let k = k as f64;
            Isometry3::from_parts(
                Translation3::new(0.15 * k, -0.03 * k, 0.0),
                UnitQuaternion::from_euler_angles(0.0, 0.0, (0.3 * k).to_radians()),
            ) * t
        })
        .collect();
    let c = config();
    let g = adjust(&scans, &starts, &starts, &c, &mut |_, _| ()).expect("adjusts");
    assert_eq!(g.links.len(), 3);
    assert!(
        g.links.iter().all(|l| l.rejected.is_none()),
        "{:?}",
        g.links.iter().map(|l| &l.rejected).collect::<Vec<_>>()
    );
    // Scan 0 holds the frame: nothing of it is blind (issue 38).
    assert!(g.unobservable[0].is_empty(), "{:?}", g.unobservable[0]);
    for k in 0..3 {
        // The axis is every other scan's blind direction …
        if k > 0 {
            let d = &g.unobservable[k];
            assert_eq!(d.len(), 1, "scan {k}: {d:?}");
            assert!(d[0][3].abs() > 0.99, "scan {k}: {}", d[0]);
        }
        // … so along it each scan stays where the start put it (relative
        // to scan 0), while across it and in rotation the truth comes back.
        let (p, s, t) = (g.world_from_scan[k], starts[k], truth[k]);
        let along = (p.translation.vector - starts[0].translation.vector).x
            - (s.translation.vector - starts[0].translation.vector).x;
        // (The truth is 0.15 m per step away: a match that saw the axis
        // would have moved the scan there. What does move it is the links'
        // last couplings of the axis with their turns, which weigh about as
        // much as the start's 0.1 m step: 1 cm for scan 2 matched one way,
        // 3.3 cm matched both ways, from links that differ by 0.2 mm and
        // 0.004° — well within the σ along the axis the graph reports,
        // 0.1–0.14 m.)
        assert!(along.abs() < 0.05, "scan {k}: moved {along} m along the axis");
        let across = (p.translation.vector - t.translation.vector).yz().norm();
        assert!(across < 0.002, "scan {k}: {across} m off across");
        assert!(p.rotation.angle_to(&t.rotation) < 0.02f64.to_radians(), "scan {k}");
    }
    // σ along the axis is the start's (0.1 m a step from scan 0; the
    // couplings left between the links pull it somewhat below), across it
    // the matches' (millimetres).
    for k in 1..3 {
        let sigma_x = g.covariance[k][(3, 3)].sqrt();
        let want = c.step_sigma_m * (k as f64).sqrt();
        assert!((0.5 * want..1.2 * want).contains(&sigma_x), "scan {k}: σx {sigma_x} m, the start's {want} m");
        assert!(g.covariance[k][(4, 4)].sqrt() < 0.002, "across the axis the matches hold it");
    }
    assert_eq!(g.covariance[0], nalgebra::Matrix6::zeros());
}
