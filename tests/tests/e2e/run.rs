//! `cps-survey run` end to end on the simulator: the hall example's outputs
//! exist, parse and agree with each other, the errors are consistent with the
//! reported covariance, the fused cloud lies on the scene, and a finished run
//! is never overwritten.

use serde_json::Value;
use tests::Edit;
use tests::{example, temp_mission};

#[test]
fn hall_runs_end_to_end() {
    let dir = tempfile::tempdir().expect("tempdir");
    let out = dir.path().join("hall");
    let run = tests::run_mission(&example("hall.toml"), &out);
    assert_eq!(run.code, 0, "{}\n{}", run.stdout, run.stderr);
    assert!(run.stdout.contains("acceptance: passed"), "{}", run.stdout);

    // report.json: every station with its pose, covariances, truth and error.
    let report: Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("report.json")).expect("report")).expect("JSON");
    assert_eq!(report["mission"], "hall");
    assert_eq!(report["seed"], 1);
    assert_eq!(report["schema_version"], 1);
    assert_eq!(report["tool_version"], env!("CARGO_PKG_VERSION"));
    assert_eq!(report["adjustment"]["tool_version"], env!("CARGO_PKG_VERSION"));
    // `drift_percent` (deprecated) is the true error's, as `error_drift_percent`.
    let last = &report["final"];
    assert_eq!(last["drift_percent"], last["error_drift_percent"]);
    let (e, d) = (last["error_xy_m"].as_f64().expect("error"), last["distance_m"].as_f64().expect("distance"));
    assert!((last["error_drift_percent"].as_f64().expect("drift") - 100.0 * e / d).abs() < 1e-9);
    let stations = report["stations"].as_array().expect("stations");
    assert_eq!(stations.len(), 22);
    for (k, s) in stations.iter().enumerate() {
        assert_eq!(s["index"], k);
        let cov: Vec<Vec<f64>> = serde_json::from_value(s["covariance"].clone()).expect("4×4");
        let pred: Vec<Vec<f64>> = serde_json::from_value(s["predicted_covariance"].clone()).expect("4×4");
        let sigma_xy = (cov[0][0] + cov[1][1]).sqrt();
        let (x, y) = (s["pose"]["x_m"].as_f64().expect("x"), s["pose"]["y_m"].as_f64().expect("y"));
        let (tx, ty) = (s["truth"]["x_m"].as_f64().expect("x"), s["truth"]["y_m"].as_f64().expect("y"));
        let e = s["error_m"].as_f64().expect("error");
        assert!(((x - tx).hypot(y - ty) - e).abs() < 1e-9, "station {k}: error_m is the horizontal error");
        // The estimate's covariance (the start's from its resection on W1
        // and W2) is the prediction's within 5 % (same geometry, readings a
        // few mm off), and the error is within 3.5 σ.
        let pred_xy = (pred[0][0] + pred[1][1]).sqrt();
        assert!((sigma_xy / pred_xy - 1.0).abs() < 0.05, "station {k}: σ {sigma_xy} vs predicted {pred_xy}");
        assert!(e < 3.5 * sigma_xy, "station {k}: error {e} m vs σxy {sigma_xy} m");
        assert_eq!(s["scan"], format!("scans/scan{k:03}.3d"));
    }
    let last = stations.last().expect("last");
    assert_eq!(report["final"]["error_xy_m"], last["error_m"]);
    let distance = report["final"]["distance_m"].as_f64().expect("distance");
    assert!((distance - 75.6).abs() < 0.5, "the route is 75.6 m: {distance}");

    // stations.csv: a header with units and one row per station matching the report.
    let csv = std::fs::read_to_string(out.join("stations.csv")).expect("csv");
    let mut lines = csv.lines();
    let header: Vec<&str> = lines.next().expect("header").split(',').collect();
    assert!(header.iter().skip(1).all(|h| h.ends_with("_m") || h.ends_with("_rad")), "{header:?}");
    let rows: Vec<Vec<f64>> = lines.map(|l| l.split(',').map(|v| v.parse().expect("a number")).collect()).collect();
    assert_eq!(rows.len(), 22);
    let col = |name: &str| header.iter().position(|h| *h == name).expect("column");
    for (row, s) in rows.iter().zip(stations) {
        // (serde_json parses floats to within an ulp or two.)
        assert!((row[col("x_m")] - s["pose"]["x_m"].as_f64().expect("x")).abs() < 1e-9);
        assert!((row[col("error_xy_m")] - s["error_m"].as_f64().expect("e")).abs() < 1e-12);
    }

    // The journal: one JSON object per line with the schema version, every
    // reading in order, each scan file written before it is referenced.
    let journal = std::fs::read_to_string(out.join("journal.jsonl")).expect("journal");
    let events: Vec<Value> = journal.lines().map(|l| serde_json::from_str(l).expect("a JSON line")).collect();
    assert!(events.iter().all(|e| e["v"] == 3), "journal schema version 3");
    assert_eq!(events[0]["event"], "start");
    assert_eq!(events.last().expect("end")["event"], "end");
    let count = |kind: &str| events.iter().filter(|e| e["event"] == kind).count();
    assert_eq!(count("measure"), 21 * 2 * 2 + 6, "two children, placement and fix, 21 cycles; 6 of control");
    assert_eq!(count("fix"), 22, "the start's resection and 21 cycles");
    assert_eq!(count("scan"), 22);
    for e in events.iter().filter(|e| e["event"] == "scan") {
        let file = out.join(e["data"]["file"].as_str().expect("file"));
        let cloud = scanner::io::read(&file).expect("the scan file reads");
        assert_eq!(cloud.len() as u64, e["data"]["points"].as_u64().expect("points"));
        assert!(file.with_extension("pose").exists());
    }

    // The fused cloud lies on the hall's surfaces.
    let cloud = scanner::io::read(&out.join("cloud.ply")).expect("cloud.ply");
    assert!(cloud.len() > 200_000, "{} points", cloud.len());
    let scene = cps::geom::builtin("hall").expect("hall");
    let on = missions::run::runner::on_surface_fraction(&scene, &cloud.points, 0.05);
    assert!(on > 0.99, "{:.2} % of the points within 5 cm of a surface", 100.0 * on);

    // A finished run is never overwritten, and says it is finished.
    let again = tests::run_mission(&example("hall.toml"), &out);
    assert_eq!(again.code, 2);
    assert!(again.stderr.contains("holds a finished run"), "{}", again.stderr);
    let mut resume = vec!["run".into(), example("hall.toml").into_os_string(), "--out".into()];
    resume.extend([out.clone().into_os_string(), "--resume".into(), "--quiet".into()]);
    let resumed = tests::cps_survey(resume);
    assert_eq!(resumed.code, 2);
    assert!(resumed.stderr.contains("is finished"), "{}", resumed.stderr);
}

#[test]
fn acceptance_failure_exits_1_with_outputs_written() {
    let text = std::fs::read_to_string(example("hall.toml")).expect("hall.toml");
    let strict = text
        .edit("max_final_sigma_xy_m = 0.05", "max_final_sigma_xy_m = 0.0001")
        .edit("every_n_stations = 1", "every_n_stations = 0");
    let mission = temp_mission(&strict);
    let dir = tempfile::tempdir().expect("tempdir");
    let run = tests::run_mission(&mission.path, dir.path());
    assert_eq!(run.code, 1, "{}", run.stderr);
    assert!(run.stdout.contains("acceptance: FAILED"));
    let report: Value =
        serde_json::from_str(&std::fs::read_to_string(dir.path().join("report.json")).expect("report")).expect("JSON");
    assert_eq!(report["accepted"], false);
    assert!(report["stations"].as_array().expect("stations").iter().all(|s| s["scan"].is_null()), "no scans");
}

/// `[backend]` odometry settings reach the simulated drives, which navigate
/// by their CPS estimate: with every error zero the parent truly stands at
/// the planned stations up to the CPS's own error (millimetres), and a 2 %
/// scale error overshoots each 3.6 m stride by 7.2 cm — it does not pile
/// up over the hall's first 25 m leg, since every drive starts from the
/// last fix.
#[test]
fn odometry_settings_drive_the_simulator() {
    let text = std::fs::read_to_string(example("hall.toml")).expect("hall.toml");
    let truth_x = |extra: &str| -> Vec<f64> {
        let mission = temp_mission(
            &tests::hall_first_leg(&text)
                .edit("every_n_stations = 1", "every_n_stations = 0")
                .edit("seed = 1", &format!("seed = 1\n{extra}")),
        );
        let dir = tempfile::tempdir().expect("tempdir");
        let run = tests::run_mission(&mission.path, dir.path());
        assert_eq!(run.code, 0, "{}", run.stderr);
        let report: Value =
            serde_json::from_str(&std::fs::read_to_string(dir.path().join("report.json")).expect("report"))
                .expect("JSON");
        report["stations"]
            .as_array()
            .expect("stations")
            .iter()
            .map(|s| s["truth"]["x_m"].as_f64().expect("x"))
            .collect()
    };
    let perfect = "odometry_scale_error_percent = 0\nodometry_sigma_distance_mm_per_sqrt_m = 0\n\
                   odometry_heading_drift_mrad_per_m = 0\nodometry_sigma_heading_mrad_per_sqrt_m = 0\nterrain_tilt_sigma_deg = 0";
    let stations = truth_x(perfect);
    assert_eq!(stations.len(), 8);
    for (k, x) in stations.iter().enumerate() {
        assert!((x - (1.5 + 3.6 * k as f64)).abs() < 0.01, "station {k}: {x}");
    }
    let long = perfect.edit("odometry_scale_error_percent = 0", "odometry_scale_error_percent = 2");
    for (k, x) in truth_x(&long).iter().enumerate().skip(1) {
        assert!((x - (1.5 + 3.6 * k as f64 + 0.02 * 3.6)).abs() < 0.01, "station {k}: {x}");
    }
}

/// A scan with nothing in range (paper-1km's stations beyond the default
/// scene) does not stop the CPS+ICP fusion (issue 35's scaling runs: exit
/// 2, "target point count = 0"): it keeps its CPS pose, a link says why,
/// and the others fuse.
#[test]
fn empty_scans_keep_their_cps_pose_in_cps_icp_fusion() {
    let text = std::fs::read_to_string(example("paper-1km.toml"))
        .expect("paper-1km")
        .edit("[1000.0, 0.0, 0.0]", "[120.0, 0.0, 0.0]")
        .edit("max_final_sigma_xy_m = 0.25", "max_final_sigma_xy_m = 1000000.0")
        + "\n[scan]\nslices = 90\n\n[output]\nrerun = false\n";
    let mission = tests::temp_mission(&text);
    let run = mission.path.with_file_name("run");
    let done = tests::run_mission(&mission.path, &run);
    assert_eq!(done.code, 0, "{}", done.stderr);
    let fused = tests::cps_survey(["fuse".into(), run.clone().into_os_string(), "--mode".into(), "cps-icp".into()]);
    assert_eq!(fused.code, 0, "{}", fused.stderr);
    let fusion: Value =
        serde_json::from_str(&std::fs::read_to_string(run.join("fusion/cps-icp/fusion.json")).expect("fusion"))
            .expect("JSON");
    let report: Value =
        serde_json::from_str(&std::fs::read_to_string(run.join("report.json")).expect("report")).expect("JSON");
    let empty: Vec<u64> = fusion["links"]
        .as_array()
        .expect("links")
        .iter()
        .filter(|l| l["reason"].as_str().is_some_and(|r| r.contains("too few to match")))
        .map(|l| l["source"].as_u64().expect("station"))
        .collect();
    assert!(empty.len() >= 3, "{}", fusion["links"]);
    assert!(fusion["matches"].as_u64().expect("matches") > 0, "the others still match");
    for station in empty {
        let (a, b) = (&fusion["scans"][station as usize], &report["fusion"]["scans"][station as usize]);
        assert_eq!(a["world_from_body"], b["world_from_body"], "station {station} keeps its CPS pose");
    }
}

/// A 100 km open traverse (10,000 stations of paper-1km, no scans) runs to
/// its end and its network adjustment converges. Before, the parent's fix
/// stopped converging 53 km out (its weights move with the pose, its steps
/// shrank by a constant factor and reached 10⁻¹⁰ m only after 20
/// iterations) and the run stopped at 86 km with "the reading of c1 is off
/// by -0.005 m …" (exit 2); the adjustment ran all 20 iterations "not
/// converged" (its steps' rounding at 10⁵ m coordinates stayed above
/// 10⁻¹⁰ m), and each of snooping's 18 re-adjustments too (24 s).
#[test]
fn a_100_km_traverse_runs_to_its_end_and_its_adjustment_converges() {
    let text = std::fs::read_to_string(example("paper-1km.toml"))
        .expect("paper-1km")
        .edit("[1000.0, 0.0, 0.0]", "[100000.0, 0.0, 0.0]")
        .edit("max_final_sigma_xy_m = 0.25", "max_final_sigma_xy_m = 1000000.0")
        + "\n[scan]\nevery_n_stations = 0\n\n[output]\nrerun = false\n";
    let mission = tests::temp_mission(&text);
    let run = mission.path.with_file_name("run");
    let done = tests::run_mission(&mission.path, &run);
    assert_eq!(done.code, 0, "{}", done.stderr);
    let report: Value =
        serde_json::from_str(&std::fs::read_to_string(run.join("report.json")).expect("report")).expect("JSON");
    assert_eq!(report["stations"].as_array().expect("stations").len(), 10_001);
    let adjustment = &report["adjustment"];
    assert_eq!(adjustment["converged"], true, "{}", adjustment["iterations"]);
    assert!(adjustment["iterations"].as_u64().expect("iterations") <= 5, "{}", adjustment["iterations"]);
}
