//! Are `cps-survey match`'s covariances honest on real scans? (issue 38)
//!
//! The reference is exact on real data, as in the NEES bench
//! (`fusion/benches/covariance_nees.py`): a real scan's points dealt at
//! random into four disjoint shares (each keeps its own noise), each
//! written in a frame of its own under a known random transform, the
//! starts off by about 0.1 m and 2°. `match` (the defaults: graph mode,
//! the automatic schedule) registers them; every trial's parts but the
//! first (the frame) are judged together against their reported joint
//! covariance (`--joint-covariance`): χ² with 6 degrees of freedom per
//! part when the covariance is honest, and over the trials χ² with 6 per
//! part in all.
//!
//! What is claimed, and so asserted, is the bench's: within 1.22× of
//! honest — the sum within the χ² interval of a covariance up to 1.22×
//! too wide or too narrow (per part [4.03, 8.76] on 36 parts: an honest
//! covariance made 1.6× too wide or narrow fails). Not honest exactly:
//! over seven draws of twelve trials each (seeds 1–14) the hall scan's
//! shares were 4.94–7.60 per part (5.83 on average, one draw beyond the
//! interval of an honest covariance), the room's 4.72–5.68 (5.23: 0.87×,
//! pessimistic, three draws below it), as the bench has them (5.85 and
//! 5.39 over eight seeds of eight trials).
//! The calibration on the scans' halves and quarters scaled these parts'
//! covariances by 1.2–3.1 (the hall scan's: 1.5 typically) and 0.7–2.4
//! (the room's).

use std::f64::consts::PI;
use std::ffi::OsString;
use std::path::Path;

use fusion::se3::left_difference;
use nalgebra::{DMatrix, DVector, Isometry3, Point3, Translation3, Unit, UnitQuaternion, Vector3};
use planner::montecarlo::nees_interval;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde_json::Value;
use tests::cps_survey;

use super::match_set::{data, pose, write_parts};

/// A random pose as the bench draws it: turned up to `turn_deg` about z
/// (the scans' up) after a tilt up to `tilt_deg` about a random axis,
/// moved up to `move_m` along each axis.
fn random_pose(rng: &mut ChaCha8Rng, turn_deg: f64, tilt_deg: f64, move_m: f64) -> Isometry3<f64> {
    let axis = Vector3::from_fn(|_, _| rng.random_range(-1.0..1.0));
    let tilt =
        UnitQuaternion::from_axis_angle(&Unit::new_normalize(axis), rng.random_range(-tilt_deg..tilt_deg) * PI / 180.0);
    let turn = UnitQuaternion::from_axis_angle(&Vector3::z_axis(), rng.random_range(-turn_deg..turn_deg) * PI / 180.0);
    let shift = Translation3::from(Vector3::from_fn(|_, _| rng.random_range(-move_m..move_m)));
    Isometry3::from_parts(shift, turn * tilt)
}

/// How far from honest the covariances are claimed to be, at most: a
/// factor on their scale (README, docs/match.md).
const WITHIN: f64 = 1.22;

/// `trials` trials of `points` dealt into four shares (seeded by `seed`),
/// each registered by `match` at the defaults in `dir`: the trials' joint
/// NEES summed and the parts judged, each trial's exit 0 with no scan
/// named.
fn joint_nees(label: &str, points: &[Point3<f32>], trials: usize, seed: u64, dir: &Path) -> (f64, usize) {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let (mut total, mut parts) = (0.0, 0);
    for trial in 0..trials {
        let owner: Vec<usize> = points.iter().map(|_| rng.random_range(0..4)).collect();
        let truths: Vec<Isometry3<f64>> = (0..4)
            .map(|k| if k == 0 { Isometry3::identity() } else { random_pose(&mut rng, 45.0, 2.0, 0.5) })
            .collect();
        let starts: Vec<Isometry3<f64>> = truths
            .iter()
            .enumerate()
            .map(|(k, t)| if k == 0 { *t } else { random_pose(&mut rng, 2.0, 2.0, 0.1 / 3f64.sqrt()) * t })
            .collect();
        let at = dir.join(format!("{label}-{trial}"));
        std::fs::create_dir_all(&at).expect("dir");
        let mut args: Vec<OsString> = vec!["match".into()];
        args.extend(write_parts(&at, points, |i, k| owner[i] == k, &truths, &starts));
        args.extend(["--joint-covariance".into(), "--json".into()]);
        args.extend(["--out".into(), at.join("out").into_os_string()]);
        let run = cps_survey(args);
        assert_eq!(run.code, 0, "{label} trial {trial}: {}", run.stderr);
        let v: Value = serde_json::from_str(&run.stdout).expect("JSON report");
        assert_eq!(v["untrusted"], serde_json::json!([]), "{label} trial {trial}");
        let rows: Vec<Vec<f64>> = serde_json::from_value(v["joint_covariance"].clone()).expect("joint covariance");
        // Scans 1–3 (scan 0 is the frame: its rows are zero).
        let c = DMatrix::from_fn(18, 18, |r, s| rows[6 + r][6 + s]);
        // ξ as the bench takes it (left, world axes; v the translation of
        // estimate·truth⁻¹).
        let xi: Vec<_> =
            (1..4).map(|k| left_difference(&pose(&v["scans"][k]["world_from_scan"]), &truths[k])).collect();
        let e = DVector::from_fn(18, |r, _| xi[r / 6][r % 6]);
        let solved = c.cholesky().expect("a positive definite joint covariance").solve(&e);
        total += e.dot(&solved);
        parts += 3;
    }
    (total, parts)
}

/// Random shares of the 3DTK hall scan and of the PCL room scan, twelve
/// trials each (the first two seeds): the joint NEES per part within
/// [`WITHIN`] of honest (measured 5.91 and 5.43; 6 when honest).
#[test]
fn the_covariances_of_a_real_scans_parts_are_honest() {
    let dir = tempfile::tempdir().expect("temp dir");
    let hall: Vec<Point3<f32>> = scanner::io::read(Path::new(&data("3dtk_dat/scan001.3d")))
        .expect("3DTK scan")
        .points
        .into_iter()
        .filter(|p| (0.5..32.5).contains(&p.coords.norm()))
        .collect();
    let room = scanner::io::read(Path::new(&data("pcl_room_scans/room_scan1.pcd"))).expect("room scan").points;
    for (label, points, seed) in [("hall", &hall, 1), ("room", &room, 2)] {
        let (total, parts) = joint_nees(label, points, 12, seed, dir.path());
        let (lo, hi) = nees_interval(6, parts);
        let (lo, hi) = (lo / WITHIN, hi * WITHIN);
        let per_part = total / parts as f64;
        assert!((lo..=hi).contains(&per_part), "{label}: joint NEES per part {per_part:.2} outside [{lo:.2}, {hi:.2}]");
    }
}
