//! Multi-view matching on simulated drives: the strategies' mechanics in the
//! well-conditioned `hall`, the seed's Fig. 5 scenario in the `corridor`
//! (numbers in docs/fusion.md), and bad input.

mod corridor;

use fusion::FusionError;
use fusion::multiview::{MultiviewConfig, Strategy, register_views};
use nalgebra::{Isometry3, Point3, Translation3, UnitQuaternion};

fn mean(e: &[(f64, f64)]) -> f64 {
    e.iter().map(|x| x.0).sum::<f64>() / e.len() as f64
}

fn config(strategy: Strategy) -> MultiviewConfig {
    corridor::multiview_config(strategy)
}

/// In the hall every strategy removes the dead-reckoning error to a few
/// centimetres, and simultaneous matching re-matches earlier scans against
/// later ones until its queues empty.
#[test]
fn hall_every_strategy_recovers_the_drive() {
    let h = corridor::hall(8, 120, 11);
    let odometry = corridor::errors(&h.odometry, &h.truth);
    assert!(odometry[7].0 > 0.3, "the odometry must be poor for the test to mean anything: {odometry:?}");
    for strategy in [Strategy::Pairwise, Strategy::Incremental, Strategy::Simultaneous] {
        let mut calls = Vec::new();
        // Millimetre thresholds here, so the re-queueing is exercised.
        let cfg = MultiviewConfig { moved_translation_m: 1e-3, moved_rotation_rad: 1e-4, ..config(strategy) };
        let r = register_views(&h.scans, &h.odometry, &cfg, &mut |d, t| calls.push((d, t))).expect("views");
        assert_eq!(calls, (1..=8).map(|d| (d, 8)).collect::<Vec<_>>(), "progress");
        assert_eq!(r.world_from_scan[0], h.odometry[0], "{strategy:?}: the master scan is fixed");
        assert!(r.last_match[0].is_none() && r.last_match[1..].iter().all(Option::is_some));
        let e = corridor::errors(&r.world_from_scan, &h.truth);
        for (k, (pos, hdg)) in e.iter().enumerate() {
            assert!(*pos < 0.03 && *hdg < 0.15, "{strategy:?}: scan {k} off by {pos} m, {hdg}°");
        }
        match strategy {
            Strategy::Pairwise | Strategy::Incremental => assert_eq!(r.matches, 7),
            Strategy::Simultaneous => {
                assert!(r.settled, "the queues empty");
                assert!(r.matches > 7, "scans were re-matched: {}", r.matches);
                // Some earlier scan was re-matched against later ones.
                let back = r.partners.iter().enumerate().any(|(k, p)| p.iter().any(|&j| j > k));
                assert!(back, "partners {:?}", r.partners);
            }
        }
        if strategy == Strategy::Incremental {
            assert_eq!(r.partners[7], (0..7).collect::<Vec<_>>(), "the metascan is every earlier scan");
        }
    }
}

/// With `trace`, every ICP run is kept iteration by iteration: one trace
/// per match, in order, each ending where that run put its scan, the last
/// run of each scan ending at its final pose — and the result is the same
/// as without tracing.
#[test]
fn traces_follow_every_icp_run() {
    let h = corridor::hall(5, 120, 3);
    let plain = config(Strategy::Simultaneous);
    let traced = MultiviewConfig { icp: fusion::icp::IcpConfig { trace: true, ..plain.icp }, ..plain };
    let a = register_views(&h.scans, &h.odometry, &plain, &mut |_, _| {}).expect("views");
    let b = register_views(&h.scans, &h.odometry, &traced, &mut |_, _| {}).expect("views");
    assert!(a.traces.is_empty());
    assert_eq!(a.world_from_scan, b.world_from_scan);
    assert_eq!(b.traces.len(), b.matches);
    for k in 1..5 {
        let last = b.traces.iter().rev().find(|t| t.scan == k).expect("scan k was matched");
        assert_eq!(last.world_from_scan.last(), Some(&b.world_from_scan[k]));
        let result = b.last_match[k].as_ref().expect("matched");
        assert_eq!(last.world_from_scan.len(), result.iterations);
        assert_eq!(result.trace, last.world_from_scan);
        assert_eq!(last.partners, b.partners[k]);
    }
    // The first iteration moves the scan away from where it started.
    let first = &b.traces[0];
    assert_eq!(first.scan, 1);
    assert_ne!(first.world_from_scan[0], h.odometry[1]);
}

/// Seed 000 Fig. 5's scenario: 20 scans down the corridor with an 8 m
/// scanner and a poor odometry (1.09 m off at the end on this seed). Every
/// strategy brings every scan within centimetres (about 20× better than
/// dead reckoning on average) and keeps headings within 0.3°, and
/// incremental matching's error grows along the corridor. Which strategy
/// ends best varies with the seed at this level (see docs/fusion.md), so that
/// is reported, not asserted.
#[test]
fn corridor_twenty_scans() {
    let c = corridor::corridor(20, 180, 7);
    let odometry = corridor::errors(&c.odometry, &c.truth);
    assert!(odometry[19].0 > 1.0, "the odometry must be poor for the test to mean anything: {odometry:?}");
    for strategy in [Strategy::Pairwise, Strategy::Incremental, Strategy::Simultaneous] {
        let r = register_views(&c.scans, &c.odometry, &config(strategy), &mut |_, _| {}).expect("views");
        let e = corridor::errors(&r.world_from_scan, &c.truth);
        assert!(mean(&e) < 0.1 * mean(&odometry), "{strategy:?}: mean {} vs odometry {}", mean(&e), mean(&odometry));
        assert!(e.iter().all(|x| x.0 < 0.1 && x.1 < 0.3), "{strategy:?}: within 0.1 m and 0.3°: {e:?}");
        if strategy == Strategy::Incremental {
            assert!(e[19].0 > 1.5 * e[4].0, "incremental drifts: scan 5 {} m, scan 20 {} m", e[4].0, e[19].0);
        }
        if strategy == Strategy::Simultaneous {
            assert!(r.settled);
        }
    }
}

#[test]
fn bad_input_is_named() {
    let h = corridor::hall(2, 60, 3);
    let cfg = MultiviewConfig::default();
    let e = register_views(&h.scans, &h.odometry[..1], &cfg, &mut |_, _| {}).expect_err("count");
    assert!(e.to_string().contains("one per scan (2)"), "{e}");
    let e = register_views::<Vec<Point3<f32>>>(&[], &[], &cfg, &mut |_, _| {}).expect_err("empty");
    assert!(e.to_string().contains("number of scans"), "{e}");
    let mut nan = h.odometry.clone();
    nan[1].translation.x = f64::NAN;
    let e = register_views(&h.scans, &nan, &cfg, &mut |_, _| {}).expect_err("NaN");
    assert!(e.to_string().contains("pose guess of scan 1"), "{e}");
    let e = register_views(&h.scans, &h.odometry, &MultiviewConfig { source_voxel_m: 0.0, ..cfg }, &mut |_, _| {})
        .expect_err("voxel");
    assert!(e.to_string().contains("source voxel"), "{e}");
    // Scan 1's guess 30 m away: no overlap, named.
    let mut far = h.odometry.clone();
    far[1] = Isometry3::from_parts(Translation3::new(0.0, 30.0, 0.0), UnitQuaternion::identity()) * far[1];
    for strategy in [Strategy::Pairwise, Strategy::Incremental, Strategy::Simultaneous] {
        match register_views(&h.scans, &far, &config(strategy), &mut |_, _| {}) {
            Err(FusionError::NoOverlap { scan: 1, pairs, needed: 251, .. }) => assert!(pairs < 251),
            other => panic!("{strategy:?}: expected NoOverlap for scan 1, got {other:?}"),
        }
    }
    // A scan too small for a target is named.
    let tiny = vec![h.scans[0].clone(), vec![Point3::new(1.0f32, 2.0, 3.0)]];
    let e = register_views(&tiny, &h.odometry, &cfg, &mut |_, _| {}).expect_err("tiny");
    assert!(matches!(e, FusionError::InScan { scan: 1, .. }), "{e}");
    assert!(e.to_string().starts_with("scan 1: "), "{e}");
}
