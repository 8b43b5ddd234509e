//! The example missions and the fusion modes end to end: corridor-icp (a
//! robot alone, simultaneous matching), building (outdoors, CPS), the hall
//! with CPS+ICP against CPS alone and ICP alone (`fuse RUN_DIR --mode`),
//! scan-station lists, the pitching head and a scene file.

use serde_json::Value;
use tests::{cps_survey, example, temp_mission};

fn json_file(path: &std::path::Path) -> Value {
    serde_json::from_str(&std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{}: {e}", path.display())))
        .expect("JSON")
}

fn f(v: &Value) -> f64 {
    v.as_f64().unwrap_or_else(|| panic!("expected a number, found {v}"))
}

/// The fraction of a PLY cloud's points within `tolerance_m` of a scene.
fn on_scene(scene: &str, cloud: &std::path::Path, tolerance_m: f64) -> f64 {
    let scene = cps::geom::builtin(scene).expect("scene");
    let cloud = scanner::io::read(cloud).expect("cloud");
    missions::runner::on_surface_fraction(&scene, &cloud.points, tolerance_m)
}

/// The hall with every fusion mode: in this small, structured hall ICP
/// alone is several times better than CPS alone, and CPS+ICP lands with
/// ICP (the CPS priors, taken as independent per station although the
/// CPS errors of neighbouring stations are correlated, pull it a little
/// towards the CPS); the fused cloud lies on the scene.
#[test]
fn hall_fusion_modes_compare() {
    let text = std::fs::read_to_string(example("hall.toml")).expect("hall.toml");
    let mission = temp_mission(&text.replace("[output]", "[fusion]\nmode = \"cps-icp\"\n\n[output]"));
    let dir = tempfile::tempdir().expect("tempdir");
    let run = tests::run_mission(&mission.path, dir.path());
    assert_eq!(run.code, 0, "{}\n{}", run.stdout, run.stderr);
    assert!(run.stdout.contains("fusion cps-icp:"), "{}", run.stdout);
    let report = json_file(&dir.path().join("report.json"));
    let fusion = &report["fusion"];
    assert_eq!(fusion["mode"], "cps-icp");
    let scans = fusion["scans"].as_array().expect("scans");
    assert_eq!(scans.len(), 8);
    assert!(scans.iter().skip(1).all(|s| f(&s["rmse_m"]) < 0.02), "every scan matched: {fusion}");
    let cps_icp = f(&fusion["rms_error_xy_m"]);
    let direct = f(&fusion["direct_rms_error_xy_m"]);

    // `fuse` re-fuses the same run in the other modes.
    let mut rms = std::collections::BTreeMap::new();
    for mode in ["direct", "icp", "cps-icp"] {
        let out = cps_survey([
            "fuse".into(),
            dir.path().as_os_str().to_owned(),
            "--mode".into(),
            mode.into(),
            "--json".into(),
        ]);
        assert_eq!(out.code, 0, "{mode}: {}", out.stderr);
        let j: Value = serde_json::from_str(&out.stdout).expect("fuse --json");
        assert_eq!(j, json_file(&dir.path().join(format!("fusion/{mode}/fusion.json"))));
        assert!(dir.path().join(format!("fusion/{mode}/cloud.ply")).exists());
        rms.insert(mode, f(&j["rms_error_xy_m"]));
    }
    assert!((rms["cps-icp"] - cps_icp).abs() < 1e-12, "fuse reproduces the run's fusion");
    assert!((rms["direct"] - direct).abs() < 1e-12);
    assert!(rms["icp"] < 0.5 * rms["direct"], "{rms:?}");
    assert!(rms["cps-icp"] < 0.5 * rms["direct"] && rms["cps-icp"] < 1.5 * rms["icp"], "{rms:?}");
    let on = on_scene("hall", &dir.path().join("cloud.ply"), 0.05);
    assert!(on > 0.97, "{:.1} % of the fused cloud within 5 cm of the hall", 100.0 * on);

    // The recording holds the refined scans next to the direct ones, and
    // the ICP RMSE of the 7 matched scans as one column.
    let rows = tests::rrd_rows(&dir.path().join("mission.rrd")).expect("the recording decodes");
    for k in 0..8 {
        for kind in ["direct", "icp"] {
            let path = format!("/world/scans/{kind}/scan{k:03}");
            assert_eq!(rows.get(&path).map(|r| r.0), Some(1), "{path}: {:?}", rows.keys());
        }
    }
    assert_eq!(rows.get("/metrics/icp_rmse_m").map(|r| r.0), Some(7), "{:?}", rows.keys());

    // `fuse` on something that is not a run is an error naming it.
    let bad = cps_survey(["fuse".into(), mission.path.parent().expect("dir").join("nope").into_os_string()]);
    assert_eq!(bad.code, 2);
    assert!(bad.stderr.contains("is not a run directory"), "{}", bad.stderr);
}

/// corridor-icp at half the table resolution: the odometry alone drifts by
/// decimetres, simultaneous matching brings every scan within centimetres
/// of the truth, and the mission passes its acceptance on the matched poses.
#[test]
fn corridor_icp_example() {
    let text = std::fs::read_to_string(example("corridor-icp.toml")).expect("corridor-icp.toml");
    let mission = temp_mission(&text.replace("slices = 180", "slices = 120"));
    let dir = tempfile::tempdir().expect("tempdir");
    let run = tests::run_mission(&mission.path, dir.path());
    assert_eq!(run.code, 0, "{}\n{}", run.stdout, run.stderr);
    let report = json_file(&dir.path().join("report.json"));
    let stations = report["stations"].as_array().expect("stations");
    assert_eq!(stations.len(), 20);
    let odometry_final = f(&stations[19]["error_m"]);
    assert!(odometry_final > 0.3, "the odometry alone drifts: {odometry_final} m");
    // The odometry's covariance is the dead-reckoning prediction.
    assert_eq!(stations[19]["covariance"], stations[19]["predicted_covariance"]);
    let fusion = &report["fusion"];
    assert_eq!(fusion["mode"], "icp");
    let worst = fusion["scans"].as_array().expect("scans").iter().map(|s| f(&s["error_xy_m"])).fold(0.0, f64::max);
    assert!(worst < 0.05, "ICP puts every scan within 5 cm: worst {worst} m");
    assert!(f(&fusion["rms_error_xy_m"]) < 0.1 * f(&fusion["direct_rms_error_xy_m"]), "{fusion}");
    let on = on_scene("corridor", &dir.path().join("cloud.ply"), 0.05);
    assert!(on > 0.95, "{:.1} % of the cloud within 5 cm of the corridor", 100.0 * on);
}

/// building at a quarter of the table resolution: 13 stations around the
/// building, each station's error within 3.5 σ of its covariance, the
/// loop's last stations back over the first.
#[test]
fn building_example() {
    let text = std::fs::read_to_string(example("building.toml")).expect("building.toml");
    let mission = temp_mission(&text.replace("slices = 180", "slices = 45"));
    let dir = tempfile::tempdir().expect("tempdir");
    let run = tests::run_mission(&mission.path, dir.path());
    assert_eq!(run.code, 0, "{}\n{}", run.stdout, run.stderr);
    let report = json_file(&dir.path().join("report.json"));
    let stations = report["stations"].as_array().expect("stations");
    assert_eq!(stations.len(), 13);
    for s in stations.iter().skip(1) {
        let cov: Vec<Vec<f64>> = serde_json::from_value(s["covariance"].clone()).expect("4×4");
        let sigma = (cov[0][0] + cov[1][1]).sqrt();
        assert!(f(&s["error_m"]) < 3.5 * sigma, "station {}: {} m vs σ {sigma} m", s["index"], s["error_m"]);
    }
    assert!((f(&report["final"]["distance_m"]) - 240.0).abs() < 1.0);
    let on = on_scene("building", &dir.path().join("cloud.ply"), 0.05);
    assert!(on > 0.97, "{:.1} % of the cloud within 5 cm of the building", 100.0 * on);
}

/// `[scan] stations`, the pitching head and a scene file: scans only where
/// listed, a pitching-mount scan that lies on the scene file's surfaces,
/// and the scene file kept in the run directory for `fuse`.
#[test]
fn scan_stations_pitching_head_and_scene_file() {
    let dir = tempfile::tempdir().expect("tempdir");
    std::fs::write(
        dir.path().join("lab.toml"),
        "name = \"lab\"\nbase = \"hall\"\n[[box]]\nname = \"cabinet\"\ncenter_m = [12, 1, 1]\nsize_m = [1, 1, 2]\n",
    )
    .expect("scene file");
    let text = std::fs::read_to_string(example("hall.toml")).expect("hall.toml");
    let text = text
        .replace("scene = \"hall\"", "scene_file = \"lab.toml\"")
        .replace("every_n_stations = 1", "stations = [0, 3, 7]\nhead = \"pitching\"")
        .replace("slices = 180", "slices = 32");
    let mission = dir.path().join("m.toml");
    std::fs::write(&mission, text).expect("mission");
    let out = dir.path().join("run");
    let run = tests::run_mission(&mission, &out);
    assert_eq!(run.code, 0, "{}\n{}", run.stdout, run.stderr);
    let report = json_file(&out.join("report.json"));
    let scanned: Vec<u64> = report["stations"]
        .as_array()
        .expect("stations")
        .iter()
        .filter(|s| !s["scan"].is_null())
        .map(|s| s["index"].as_u64().expect("index"))
        .collect();
    assert_eq!(scanned, [0, 3, 7]);
    assert_eq!(report["scene"], "lab.toml");
    assert!(out.join("scene.toml").exists());
    let lab = cps::geom::parse_scene_toml(&std::fs::read_to_string(dir.path().join("lab.toml")).expect("lab"))
        .expect("lab scene");
    let cloud = scanner::io::read(&out.join("cloud.ply")).expect("cloud");
    let on = missions::runner::on_surface_fraction(&lab, &cloud.points, 0.05);
    assert!(on > 0.97, "{:.1} % on the lab scene", 100.0 * on);
    // The cabinet is in the scans: points lie on its faces.
    let cabinet =
        cloud.points.iter().filter(|p| (p.x - 12.0).abs() < 0.52 && (p.y - 1.0).abs() < 0.52 && p.z > 0.1).count();
    assert!(cabinet > 10, "{cabinet} points on the cabinet");
    let fuse = cps_survey(["fuse".into(), out.clone().into_os_string(), "--mode".into(), "direct".into()]);
    assert_eq!(fuse.code, 0, "{}", fuse.stderr);
    // Resuming with a changed scene file is refused.
    std::fs::write(dir.path().join("lab.toml"), "name = \"lab\"\nbase = \"hall\"\n").expect("scene file");
    let resumed = cps_survey([
        "run".into(),
        mission.into_os_string(),
        "--out".into(),
        out.into_os_string(),
        "--resume".into(),
        "--quiet".into(),
    ]);
    assert_eq!(resumed.code, 2);
    assert!(resumed.stderr.contains("scene file changed"), "{}", resumed.stderr);
}

/// A broken scene file is reported at the mission's `scene_file` with the
/// scene file's own line and column.
#[test]
fn a_broken_scene_file_names_both_files() {
    let dir = tempfile::tempdir().expect("tempdir");
    std::fs::write(
        dir.path().join("bad.toml"),
        "name = \"bad\"\n[[box]]\nname = \"b\"\ncenter_m = [1, 2]\nsize_m = [1, 1, 1]\n",
    )
    .expect("scene file");
    let text = std::fs::read_to_string(example("hall.toml")).expect("hall.toml");
    let mission = dir.path().join("m.toml");
    std::fs::write(&mission, text.replace("scene = \"hall\"", "scene_file = \"bad.toml\"")).expect("mission");
    let run = cps_survey(["validate".into(), mission.clone().into_os_string()]);
    assert_eq!(run.code, 2);
    let line = text.lines().position(|l| l.starts_with("scene = ")).expect("scene line") + 1;
    assert!(run.stderr.contains(&format!("m.toml:{line}:14: backend.scene_file: scene file")), "{}", run.stderr);
    assert!(run.stderr.contains("line 4"), "{}", run.stderr);
}

/// A robot alone cannot use cps-icp, and montecarlo says why it has nothing
/// to simulate.
#[test]
fn a_robot_alone_refuses_what_needs_the_cps() {
    let text = std::fs::read_to_string(example("corridor-icp.toml")).expect("corridor-icp.toml");
    let mission = temp_mission(&text.replace("mode = \"icp\"", "mode = \"cps-icp\""));
    let run = cps_survey(["validate".into(), mission.path.clone().into_os_string()]);
    assert_eq!(run.code, 2);
    assert!(run.stderr.contains("fusion.mode: cps-icp needs CPS poses"), "{}", run.stderr);
    let mc = cps_survey([
        "montecarlo".into(),
        example("corridor-icp.toml").into_os_string(),
        "--trials".into(),
        "10".into(),
    ]);
    assert_eq!(mc.code, 2);
    assert!(mc.stderr.contains("has no children"), "{}", mc.stderr);
}
