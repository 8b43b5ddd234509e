//! `mission.rrd` read back with Rerun's own decoder: every entity the
//! README promises is there, with one row per event that logs it.

use tests::{cps_survey, example, rrd_rows};

#[test]
fn the_hall_recording_holds_every_entity() {
    let dir = tempfile::tempdir().expect("tempdir");
    let out = dir.path().join("hall");
    let run = cps_survey([
        "run".into(),
        example("hall.toml").into_os_string(),
        "--out".into(),
        out.clone().into(),
        "--quiet".into(),
    ]);
    assert_eq!(run.code, 0, "{}", run.stderr);
    let rows = rrd_rows(&out.join("mission.rrd")).expect("the recording decodes");
    let get =
        |path: &str| rows.get(path).copied().unwrap_or_else(|| panic!("{path} missing; entities: {:?}", rows.keys()));

    // 7 cycles, 2 children, 8 stations (0–7), a scan at each.
    let (cycles, children, stations) = (7, 2, 8);
    // The team is logged after each child's placement, after each fix and at the start.
    let team_rows = cycles * (children + 1) + 1;
    for static_path in ["/world", "/world/scene", "/world/robots/parent/body", "/world/truth/left/body"] {
        assert_eq!(get(static_path), (1, true), "{static_path}");
    }
    for robot in ["parent", "left", "right"] {
        assert_eq!(get(&format!("/world/robots/{robot}")), (team_rows, false), "{robot}");
        assert_eq!(get(&format!("/world/truth/{robot}")), (team_rows, false), "{robot}");
        assert_eq!(get(&format!("/world/uncertainty/{robot}/achieved_95pct")).0, team_rows);
        // No prediction is logged at the start.
        assert_eq!(get(&format!("/world/uncertainty/{robot}/predicted_95pct")).0, team_rows - 1);
    }
    assert_eq!(get("/world/sight_lines/placement").0, cycles * children);
    assert_eq!(get("/world/sight_lines/fix").0, cycles);
    assert_eq!(get("/world/trajectories/parent/estimate").0, stations);
    assert_eq!(get("/world/trajectories/parent/truth").0, stations);
    for k in 0..stations {
        assert_eq!(get(&format!("/world/scans/direct/scan{k:03}")), (1, false));
    }
    for series in ["sigma_xy_m", "predicted_sigma_xy_m", "sigma_heading_rad", "error_xy_m"] {
        assert_eq!(get(&format!("/metrics/{series}")).0, stations, "{series}");
    }
    assert_eq!(get("/metrics/fix_sigma0_squared").0, cycles);
    assert!(get("/log").0 >= 2, "start and end at least");
}

#[test]
fn rerun_false_writes_no_recording() {
    let text = std::fs::read_to_string(example("hall.toml")).expect("hall.toml");
    let mission = tests::temp_mission(&text.replace("formats = [\"ply\"]", "formats = [\"ply\"]\nrerun = false"));
    let dir = tempfile::tempdir().expect("tempdir");
    let run = cps_survey([
        "run".into(),
        mission.path.clone().into_os_string(),
        "--out".into(),
        dir.path().into(),
        "--quiet".into(),
    ]);
    assert_eq!(run.code, 0, "{}", run.stderr);
    assert!(!dir.path().join("mission.rrd").exists());
    assert!(dir.path().join("report.json").exists());
}
