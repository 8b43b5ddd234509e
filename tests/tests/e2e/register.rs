//! `cps-survey register` end to end on the real scans in `data/`.

use serde_json::Value;
use tests::{cps_survey, workspace};

fn data(rel: &str) -> std::ffi::OsString {
    workspace().join("data").join(rel).into_os_string()
}

#[test]
fn register_json_has_the_documented_fields_and_lands_on_the_reference() {
    let run = cps_survey([
        "register".into(),
        data("pcl_room_scans/room_scan2.pcd"),
        data("pcl_room_scans/room_scan1.pcd"),
        "--init-file".into(),
        data("pcl_room_scans/odometry_T_scan1_scan2.txt"),
        "--schedule".into(),
        "0.5/2,0.25/1,0.1/0.5,0.05/0.2".into(),
        "--json".into(),
    ]);
    assert_eq!(run.code, 0, "{}", run.stderr);
    let v: Value = serde_json::from_str(&run.stdout).expect("one JSON object");
    for key in ["converged", "iterations", "inliers", "rmse_m", "seconds", "covariance"] {
        assert!(v.get(key).is_some(), "{key} missing: {v}");
    }
    let m: Vec<Vec<f64>> = serde_json::from_value(v["target_from_source"].clone()).expect("4×4");
    let text = std::fs::read_to_string(workspace().join("data/pcl_room_scans/reference_T_scan1_scan2.txt"))
        .expect("reference");
    let reference: Vec<f64> = text.split_whitespace().filter_map(|t| t.parse().ok()).collect();
    assert_eq!(reference.len(), 16);
    for i in 0..3 {
        assert!((m[i][3] - reference[4 * i + 3]).abs() < 0.02, "translation row {i}: {m:?}");
        for j in 0..3 {
            assert!((m[i][j] - reference[4 * i + j]).abs() < 0.005, "rotation ({i},{j}): {m:?}");
        }
    }
    assert_eq!(m[3], vec![0.0, 0.0, 0.0, 1.0]);
    assert!(v["converged"].as_bool().expect("bool"));
    assert!(v["rmse_m"].as_f64().expect("rmse") < 0.05);
}

#[test]
fn register_text_report_and_init_option() {
    let run = cps_survey([
        "register".into(),
        data("small_gicp_pair/source.ply"),
        data("small_gicp_pair/target.ply"),
        "--init".into(),
        "0 0 0 0 0 0".into(),
        "--method".into(),
        "point-to-point".into(),
    ]);
    assert_eq!(run.code, 0, "{}", run.stderr);
    assert!(run.stdout.contains("target_from_source") && run.stdout.contains("RMSE"), "{}", run.stdout);
}

#[test]
fn register_bad_input_names_the_problem() {
    let cases: [(&[&str], &str); 5] = [
        (&["register", "/nonexistent/a.ply", "/nonexistent/b.ply"], "/nonexistent/a.ply"),
        (&["register", "a.ply", "b.ply", "--init", "1 2 3"], "expected six"),
        (&["register", "a.ply", "b.ply", "--schedule", "0.1-0.5"], "VOXEL/MAXDIST"),
        (&["register", "a.ply", "b.ply", "--min-range", "5", "--max-range", "1"], "--min-range"),
        (&["register", "a.unknown", "b.ply"], "a.unknown"),
    ];
    for (args, needle) in cases {
        let run = cps_survey(args.iter().copied());
        assert_eq!(run.code, 2, "{args:?}");
        assert!(run.stderr.contains(needle), "{args:?}: {}", run.stderr);
    }
    // A 4×4 that is not a rigid transform.
    let dir = tempfile::tempdir().expect("dir");
    let bad = dir.path().join("scaled.txt");
    std::fs::write(&bad, "2 0 0 0\n0 2 0 0\n0 0 2 0\n0 0 0 1\n").expect("write");
    let run = cps_survey([
        "register".into(),
        data("small_gicp_pair/source.ply"),
        data("small_gicp_pair/target.ply"),
        "--init-file".into(),
        bad.into_os_string(),
    ]);
    assert_eq!(run.code, 2);
    assert!(run.stderr.contains("not a rotation"), "{}", run.stderr);
}
