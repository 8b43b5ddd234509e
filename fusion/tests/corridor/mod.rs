//! The multi-view scenario of seed 000 Fig. 5 on the simulated `corridor`
//! scene: the parent drives 1.8 m at a time along the 40 m corridor with a
//! poor odometry and takes a rotating-table scan at each of 20 stops.
//! Shared by the multi-view test and the `corridor_multiview` example.
#![allow(dead_code)] // each user needs part of it

use cps::ParentPose;
use cps::geom::builtin;
use nalgebra::{Isometry3, Point3, Translation3, UnitQuaternion};
use scanner::sim::{LmsConfig, LmsRangeMode, LmsResolution, OdometryError, Robot, SimDrive, SimHead, SimLms, SimWorld};
use scanner::{Drive, HeadKind, PlanarPose, scan_3d};

/// Scans in the body frame, the odometry's pose of each (planar, at the
/// body's height) and the true pose (with the terrain's roll and pitch).
pub struct Corridor {
    pub scans: Vec<Vec<Point3<f32>>>,
    pub odometry: Vec<Isometry3<f64>>,
    pub truth: Vec<Isometry3<f64>>,
}

/// Where the scanner stands in the body frame the scans are in: the
/// head's mount, 0.4 m above the body's origin.
pub const SCANNER_IN_BODY: Point3<f64> = Point3::new(0.0, 0.0, 0.4);

/// The multi-view defaults with `strategy`, the scanner where the rig
/// has it.
pub fn multiview_config(strategy: fusion::multiview::Strategy) -> fusion::multiview::MultiviewConfig {
    let defaults = fusion::multiview::MultiviewConfig::default();
    let icp = fusion::icp::IcpConfig { source_viewpoint: SCANNER_IN_BODY, ..defaults.icp };
    fusion::multiview::MultiviewConfig { strategy, icp, ..defaults }
}

/// 3 % scale error, 0.5 mrad/m heading drift, 1 mrad/√m heading noise,
/// 0.2° terrain tilt: over a metre of dead-reckoning error after 34 m,
/// mostly along the corridor (the true path must stay inside it).
pub fn odometry_error() -> OdometryError {
    OdometryError {
        scale_error: 0.03,
        sigma_distance_m_per_sqrt_m: 0.01,
        heading_drift_rad_per_m: 5e-4,
        sigma_heading_rad_per_sqrt_m: 1e-3,
        terrain_tilt_sigma_rad: 0.2f64.to_radians(),
    }
}

/// `n` stops 1.8 m apart along the corridor from x = 1 m; 1° LMS in 8 m
/// mode with 5 mm noise, `slices` table steps per scan.
pub fn corridor(n: usize, slices: usize, seed: u64) -> Corridor {
    drive_and_scan("corridor", 0.0, n, LmsRangeMode::Mm8, slices, seed)
}

/// The same drive along y = 4 m in the 40 × 12 m `hall` (pillars, crates,
/// shelf, machine, tank) with the 32 m mode: well-conditioned scans.
pub fn hall(n: usize, slices: usize, seed: u64) -> Corridor {
    drive_and_scan("hall", 4.0, n, LmsRangeMode::Mm32, slices, seed)
}

fn drive_and_scan(scene: &str, y: f64, n: usize, mode: LmsRangeMode, slices: usize, seed: u64) -> Corridor {
    let z = 0.5;
    let world = SimWorld::new(builtin(scene).expect("scene"), ParentPose::new(1.0, y, z, 0.0), vec![]);
    let start = PlanarPose { x_m: 1.0, y_m: y, heading_rad: 0.0 };
    let mut drive = SimDrive::new(world.clone(), Robot::Parent, start, odometry_error(), seed).expect("drive");
    let body_from_head = Isometry3::from_parts(Translation3::from(SCANNER_IN_BODY.coords), UnitQuaternion::identity());
    let config = LmsConfig { resolution: LmsResolution::One, mode, sigma_range_m: 0.005 };
    let mut lms = SimLms::new(world.clone(), config, HeadKind::RotatingTable, body_from_head, seed);
    let mut head = SimHead::new(world.clone(), HeadKind::RotatingTable);
    let mut out = Corridor { scans: Vec::new(), odometry: Vec::new(), truth: Vec::new() };
    let mut believed = start;
    for k in 0..n {
        if k > 0 {
            believed = PlanarPose { x_m: 1.0 + 1.8 * k as f64, y_m: y, heading_rad: 0.0 };
            drive.move_to(&believed).expect("drive");
        }
        let scan = scan_3d(&mut head, &mut lms, slices, &body_from_head, &mut |_, _| {}).expect("scan");
        let truth = world.truth();
        out.scans.push(scan.points);
        out.truth.push(truth.tilt.world_from_body(&truth.parent));
        out.odometry.push(Isometry3::from_parts(
            Translation3::new(believed.x_m, believed.y_m, z),
            UnitQuaternion::from_euler_angles(0.0, 0.0, believed.heading_rad),
        ));
    }
    out
}

/// Position and heading error of `estimate` against `truth`, per scan:
/// (metres, degrees).
pub fn errors(estimate: &[Isometry3<f64>], truth: &[Isometry3<f64>]) -> Vec<(f64, f64)> {
    estimate
        .iter()
        .zip(truth)
        .map(|(e, t)| {
            ((e.translation.vector - t.translation.vector).norm(), e.rotation.angle_to(&t.rotation).to_degrees())
        })
        .collect()
}
