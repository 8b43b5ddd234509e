//! A simulated 3D scan of the `hall` from a known, tilted pose with a lever
//! arm lies on the scene's surfaces once transformed to the world.

use cps::ParentPose;
use cps::geom::builtin;
use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};
use scanner::sim::{LmsConfig, LmsRangeMode, LmsResolution, SimHead, SimLms, SimWorld};
use scanner::{HeadKind, Scan, Tilt, scan_3d};

const SIGMA_M: f64 = 0.005;

fn scan(kind: HeadKind, slices: usize, resolution: LmsResolution, seed: u64) -> (Scan, Isometry3<f64>) {
    let world = SimWorld::new(builtin("hall").expect("hall"), ParentPose::new(14.0, 4.0, 1.4, 0.4), vec![]);
    let mut truth = world.truth();
    truth.tilt = Tilt { roll_rad: 0.6f64.to_radians(), pitch_rad: -0.4f64.to_radians() };
    world.set_truth(truth.clone());
    let body_from_head = Isometry3::from_parts(
        Translation3::new(0.12, -0.05, 0.35),
        UnitQuaternion::from_axis_angle(&Vector3::z_axis(), 0.02),
    );
    let config = LmsConfig { resolution, mode: LmsRangeMode::Mm32, sigma_range_m: SIGMA_M };
    let mut lms = SimLms::new(world.clone(), config, kind, body_from_head, seed);
    let mut head = SimHead::new(world, kind);
    let mut calls = 0;
    let scan = scan_3d(&mut head, &mut lms, slices, &body_from_head, &mut |_, _| calls += 1).expect("scan");
    assert_eq!(calls, slices);
    (scan, truth.tilt.world_from_body(&truth.parent))
}

fn median_distance(scan: &Scan, world_from_body: &Isometry3<f64>) -> f64 {
    let hall = builtin("hall").expect("hall");
    let mut d: Vec<f64> = scan.points.iter().map(|p| hall.distance(&(world_from_body * p.cast::<f64>())).0).collect();
    d.sort_by(f64::total_cmp);
    d[d.len() / 2]
}

#[test]
fn rotating_table_scan_lies_on_the_hall() {
    let (scan, world_from_body) = scan(HeadKind::RotatingTable, 720, LmsResolution::Half, 5);
    // 720 slices × 361 beams; every beam in a closed hall returns.
    assert_eq!(scan.len(), 720 * 361);
    let median = median_distance(&scan, &world_from_body);
    assert!(median <= SIGMA_M, "median |distance| {median} m > σ = {SIGMA_M} m");
    // The noise is real (a Gaussian's median |e| is 0.674σ along the beam,
    // less across an oblique surface).
    assert!(median > 0.2 * SIGMA_M, "median {median}");
    // Ranges and indices are consistent with the points (lever arm aside).
    let k = 1000;
    assert_eq!(scan.beam[k] as usize, k % 361);
    assert_eq!(scan.slice[k] as usize, k / 361);
}

#[test]
fn pitching_mount_scan_lies_on_the_hall() {
    let (scan, world_from_body) = scan(HeadKind::PitchingMount, 128, LmsResolution::One, 9);
    assert!(scan.len() > 128 * 181 * 9 / 10, "{} points", scan.len());
    assert!(median_distance(&scan, &world_from_body) <= SIGMA_M);
}

#[test]
fn same_seed_same_scan() {
    let a = scan(HeadKind::RotatingTable, 90, LmsResolution::One, 3).0;
    let b = scan(HeadKind::RotatingTable, 90, LmsResolution::One, 3).0;
    let c = scan(HeadKind::RotatingTable, 90, LmsResolution::One, 4).0;
    assert_eq!(a, b);
    assert_ne!(a, c);
}

/// Reduced points shrink a full scan by about an order of magnitude and
/// stay on the surfaces.
#[test]
fn reduced_points_of_a_hall_scan() {
    let (scan, world_from_body) = scan(HeadKind::RotatingTable, 720, LmsResolution::Half, 5);
    let reduced = scanner::reduced_points(&scan.points, 0.2).expect("reduce");
    let ratio = scan.len() as f64 / reduced.len() as f64;
    assert!(ratio > 8.0, "reduction ×{ratio:.1}");
    let cloud = Scan { points: reduced, ..Scan::default() };
    // Means of points on a plane stay on it; at edges they cut corners by < cell/2.
    assert!(median_distance(&cloud, &world_from_body) <= SIGMA_M);
}

/// A drive and a total station restored from a checkpoint (noise position,
/// believed and true pose, world truth) continue exactly as the originals:
/// the next move and the next measurement are bit-identical.
#[test]
fn restored_devices_continue_the_same_noise() {
    use cps::{Instrument, Reading};
    use nalgebra::Point3;
    use scanner::sim::{NoiseStream, OdometryError, Robot, SimDrive, SimTotalStation};
    use scanner::{Drive, PlanarPose, Target, TotalStation};

    let make = || {
        let world = SimWorld::new(
            builtin("hall").expect("hall"),
            ParentPose::new(4.0, 4.0, 1.4, 0.0),
            vec![Point3::new(8.0, 2.0, 0.5)],
        );
        let start = PlanarPose { x_m: 8.0, y_m: 2.0, heading_rad: 0.0 };
        let drive = SimDrive::new(world.clone(), Robot::Child(0), start, OdometryError::default(), 3).expect("drive");
        let ts = SimTotalStation::new(world.clone(), Instrument::default(), 3);
        (world, drive, ts)
    };
    let target = Target {
        prism: scanner::Prism::Child(0),
        predicted: Reading { slope_m: 4.0, azimuth_rad: 0.0, elevation_rad: 0.0 },
    };
    let (world, mut drive, mut ts) = make();
    for k in 0..3 {
        drive.move_to(&PlanarPose { x_m: 9.0 + k as f64, y_m: 2.5, heading_rad: 0.1 }).expect("move");
        ts.measure(&target).expect("measure");
    }
    let (truth, believed, true_pose) = (world.truth(), drive.believed_pose(), drive.true_pose());
    let (drive_words, ts_words) = (drive.noise_position(), ts.noise_position());
    assert!(drive_words > 0 && ts_words > 0);
    let goal = PlanarPose { x_m: 13.0, y_m: 3.0, heading_rad: 0.2 };
    drive.move_to(&goal).expect("move");
    let expected = (world.truth(), ts.measure(&target).expect("measure"));

    let (world2, mut drive2, mut ts2) = make();
    world2.set_truth(truth);
    drive2.restore(believed, true_pose);
    drive2.set_noise_position(drive_words);
    ts2.set_noise_position(ts_words);
    drive2.move_to(&goal).expect("move");
    assert_eq!((world2.truth(), ts2.measure(&target).expect("measure")), expected);
}
