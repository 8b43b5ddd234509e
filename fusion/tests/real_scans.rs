//! ICP on the real scans in `data/` (shipped with the repository) against their reference
//! transforms.

use std::path::PathBuf;

use fusion::icp::{IcpConfig, Method, Stage, align_coarse_to_fine};
use nalgebra::{Isometry3, Point3, Translation3, UnitQuaternion, Vector3};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;
use scanner::io::{from_3dtk_axes, read, read_3dtk_pose, read_matrix4};

fn data(rel: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../data").join(rel)
}

fn iso_from_file(rel: &str) -> Isometry3<f64> {
    let m = read_matrix4(&data(rel)).expect("matrix");
    let r = nalgebra::Rotation3::from_matrix(&m.fixed_view::<3, 3>(0, 0).into_owned());
    Isometry3::from_parts(nalgebra::Translation3::from(m.fixed_view::<3, 1>(0, 3).into_owned()), r.into())
}

/// (rotation error in degrees, translation error in metres).
fn error(estimate: &Isometry3<f64>, reference: &Isometry3<f64>) -> (f64, f64) {
    let d = reference.inverse() * estimate;
    (d.rotation.angle().to_degrees(), d.translation.vector.norm())
}

/// The references' own recipe (voxel / max correspondence, metres).
const SCHEDULE: [Stage; 4] = [
    Stage { voxel_m: 0.5, max_correspondence_m: 2.0 },
    Stage { voxel_m: 0.25, max_correspondence_m: 1.0 },
    Stage { voxel_m: 0.1, max_correspondence_m: 0.5 },
    Stage { voxel_m: 0.05, max_correspondence_m: 0.2 },
];

fn threedtk(k: usize) -> Vec<Point3<f32>> {
    let c = read(&data(&format!("3dtk_dat/scan{k:03}.3d"))).expect("scan");
    c.points.into_iter().filter(|p| (0.5..32.5).contains(&p.coords.norm())).collect()
}

/// The odometry's scan_a_from_scan_b of the 3DTK data.
fn threedtk_odometry(a: usize, b: usize) -> Isometry3<f64> {
    let pose = |k: usize| read_3dtk_pose(&data(&format!("3dtk_dat/scan{k:03}.pose"))).expect("pose");
    pose(a).inverse() * pose(b)
}

/// The reference scan_a_from_scan_b of the 3DTK data, in our axes.
fn threedtk_reference(a: usize, b: usize) -> Isometry3<f64> {
    from_3dtk_axes(&read_matrix4(&data(&format!("3dtk_dat/reference_T_scan{a:03}_scan{b:03}.txt"))).expect("m"))
}

#[test]
fn threedtk_pairs_from_odometry() {
    for (a, b) in [(0, 1), (1, 2)] {
        let (odometry, reference) = (threedtk_odometry(a, b), threedtk_reference(a, b));
        for method in [Method::PointToPlane, Method::PointToPoint] {
            let cfg = IcpConfig { method, ..IcpConfig::default() };
            let r = align_coarse_to_fine(&threedtk(b), &threedtk(a), &odometry, &SCHEDULE, &cfg).expect("icp");
            let (deg, m) = error(&r.target_from_source, &reference);
            // Point-to-plane meets the bar; point-to-point must at least
            // improve on the odometry (0.69°).
            match method {
                Method::PointToPlane => assert!(deg < 0.3 && m < 0.02, "{a}←{b}: {deg}° {m} m"),
                Method::PointToPoint => assert!(deg < 0.5 && m < 0.02, "{a}←{b} point-to-point: {deg}° {m} m"),
            }
            // Point-to-point crawls along flat floors and may use the whole cap.
            if method == Method::PointToPlane {
                assert!(r.converged, "{a}←{b} did not converge in {} iterations", r.iterations);
            }
        }
    }
}

/// `start` moved by 0.5 m and turned by 5° about random axes (left side).
fn perturbed(start: &Isometry3<f64>, rng: &mut ChaCha8Rng) -> Isometry3<f64> {
    let mut unit = || {
        let v: Vector3<f64> = Vector3::from_fn(|_, _| rng.sample(StandardNormal));
        v.normalize()
    };
    let (d, axis) = (unit() * 0.5, unit());
    Isometry3::from_parts(Translation3::from(d), UnitQuaternion::from_scaled_axis(axis * 5f64.to_radians())) * start
}

/// Point-to-plane with the coarse-to-fine schedule lands within 0.3° and
/// 2 cm of the reference from the odometry and from ten perturbed guesses,
/// on every pair that has an odometry guess.
#[test]
fn perturbed_guesses_land_on_the_reference() {
    let pairs = [
        ("3dtk 0←1", threedtk(1), threedtk(0), threedtk_odometry(0, 1), threedtk_reference(0, 1)),
        ("3dtk 1←2", threedtk(2), threedtk(1), threedtk_odometry(1, 2), threedtk_reference(1, 2)),
        (
            "room",
            read(&data("pcl_room_scans/room_scan2.pcd")).expect("scan2").points,
            read(&data("pcl_room_scans/room_scan1.pcd")).expect("scan1").points,
            iso_from_file("pcl_room_scans/odometry_T_scan1_scan2.txt"),
            iso_from_file("pcl_room_scans/reference_T_scan1_scan2.txt"),
        ),
    ];
    let mut rng = ChaCha8Rng::seed_from_u64(2026);
    for (name, source, target, odometry, reference) in pairs {
        let mut starts = vec![odometry];
        starts.extend((0..10).map(|_| perturbed(&odometry, &mut rng)));
        for (k, start) in starts.iter().enumerate() {
            let (deg0, m0) = error(start, &reference);
            let r = align_coarse_to_fine(&source, &target, start, &SCHEDULE, &IcpConfig::default()).expect("icp");
            let (deg, m) = error(&r.target_from_source, &reference);
            assert!(deg < 0.3 && m < 0.02, "{name}, start {k} ({deg0:.2}°, {m0:.2} m off): {deg}° {m} m");
        }
    }
}

#[test]
fn room_scans_from_odometry() {
    let target = read(&data("pcl_room_scans/room_scan1.pcd")).expect("scan1").points;
    let source = read(&data("pcl_room_scans/room_scan2.pcd")).expect("scan2").points;
    let odometry = iso_from_file("pcl_room_scans/odometry_T_scan1_scan2.txt");
    let reference = iso_from_file("pcl_room_scans/reference_T_scan1_scan2.txt");
    let r = align_coarse_to_fine(&source, &target, &odometry, &SCHEDULE, &IcpConfig::default()).expect("icp");
    let (deg, m) = error(&r.target_from_source, &reference);
    assert!(deg < 0.3 && m < 0.02, "{deg}° {m} m");
}

#[test]
fn small_gicp_pair_from_identity() {
    let target = read(&data("small_gicp_pair/target.ply")).expect("t").points;
    let source = read(&data("small_gicp_pair/source.ply")).expect("s").points;
    let reference = iso_from_file("small_gicp_pair/T_target_source.txt");
    let r =
        align_coarse_to_fine(&source, &target, &Isometry3::identity(), &SCHEDULE, &IcpConfig::default()).expect("icp");
    let (deg, m) = error(&r.target_from_source, &reference);
    assert!(deg < 0.3 && m < 0.05, "{deg}° {m} m");
}
