//! `mission.rrd` read back with Rerun's own decoder: every entity the
//! docs/recording.md promises is there, with one row per event that logs it.

use tests::Edit;
use tests::{cps_survey, example, rrd_rows};

#[test]
fn the_hall_recording_holds_every_entity() {
    let dir = tempfile::tempdir().expect("tempdir");
    let out = dir.path().join("hall");
    let run = tests::run_mission(&example("hall.toml"), &out);
    assert_eq!(run.code, 0, "{}", run.stderr);
    let rows = rrd_rows(&out.join("mission.rrd")).expect("the recording decodes");
    let get =
        |path: &str| rows.get(path).copied().unwrap_or_else(|| panic!("{path} missing; entities: {:?}", rows.keys()));

    // 21 cycles, 2 children, 22 stations (0–21), a scan at each.
    let (cycles, children, stations) = (21, 2, 22);
    // The team is logged after each child's placement, after each fix and at the start.
    let team_rows = cycles * (children + 1) + 1;
    for static_path in ["/world", "/world/scene", "/world/robots/parent/body", "/world/truth/ahead/body"] {
        assert_eq!(get(static_path), (1, true), "{static_path}");
    }
    for robot in ["parent", "ahead", "behind"] {
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
    // Every fix, the start's resection on W1 and W2 too.
    assert_eq!(get("/metrics/fix_sigma0_squared").0, cycles + 1);
    assert_eq!(get("/world/sight_lines/control").0, 1);
    // The network adjustment at the end: the control points, every reading
    // coloured by |w|, the misclosures at E1 and E2.
    assert_eq!(get("/world/control").0, 1);
    assert_eq!(get("/world/adjustment/observations").0, 1);
    assert!(rows.keys().any(|k| k.starts_with("/world/adjustment/misclosures_x")), "{:?}", rows.keys());
    // Control sighted at the start, the east end and back at the start.
    assert_eq!(get("/world/plan/control_sight_lines").0, 6);
    assert!(get("/log").0 >= 2, "start and end at least");
    // The plan as it was driven, on its own timeline.
    assert_eq!(get("/world/plan/route"), (1, true));
    assert_eq!(get("/world/plan/sight_lines").0, 2 * cycles * children);
    assert_eq!(get("/world/plan/moves").0, cycles * (children + 1));
    assert!(!rows.contains_key("/world/plan/violations"), "hall.toml keeps every constraint");
}

#[test]
fn plan_rrd_holds_the_plan_its_violation_and_the_optimized_plan() {
    let dir = tempfile::tempdir().expect("tempdir");
    let rrd = dir.path().join("plan.rrd");
    let run = cps_survey([
        "plan".into(),
        example("hall-plan.toml").into_os_string(),
        "--optimize".into(),
        "--rrd".into(),
        rrd.clone().into(),
    ]);
    assert!(run.code <= 1, "{}", run.stderr);
    assert!(run.stdout.contains("recorded the plan in"), "{}", run.stdout);
    let rows = rrd_rows(&rrd).expect("the recording decodes");
    let get = |path: &str| rows.get(path).copied().unwrap_or_else(|| panic!("{path} missing: {:?}", rows.keys()));
    // As written: 7 leapfrog cycles with 2 children, 8 stations.
    let (cycles, children) = (7, 2);
    for path in ["/world", "/world/scene", "/world/plan/route", "/world/plan/stations"] {
        assert_eq!(get(path), (1, true), "{path}");
    }
    // Each child moves and is measured every cycle, the parent moves, fixes
    // from both children; one estimate per placement and per fix.
    assert_eq!(get("/world/plan/moves").0, cycles * (children + 1));
    assert_eq!(get("/world/plan/sight_lines").0, 2 * cycles * children);
    assert_eq!(get("/world/plan/robots/parent").0, cycles + 1);
    assert_eq!(get("/world/plan/robots/left").0, cycles);
    let ellipsoids: Vec<&String> = rows.keys().filter(|p| p.starts_with("/world/plan/uncertainty/")).collect();
    assert_eq!(ellipsoids.len(), children + 1, "{ellipsoids:?}");
    assert!(ellipsoids.iter().all(|p| p.contains("/predicted_95pct_x")), "the scale is in the name");
    assert!(ellipsoids.iter().all(|p| get(p).0 == cycles));
    assert_eq!(get("/plan/metrics/predicted_sigma_xy_m").0, cycles);
    // The one violation (step 12: the right child through the crates).
    assert_eq!(get("/world/plan/violations").0, 1);
    assert_eq!(get("/plan/log").0, 1);
    // The optimized plan beside it, without violations; no empty series.
    assert_eq!(get("/world/plan_optimized/route"), (1, true));
    assert!(!rows.contains_key("/world/plan_optimized/violations"));
    assert!(!rows.contains_key("/metrics/sigma_xy_m"), "no run, no run metrics");
}

#[test]
fn rerun_false_writes_no_recording() {
    let text = std::fs::read_to_string(example("hall.toml")).expect("hall.toml");
    let mission = tests::temp_mission(&text.edit("formats = [\"ply\"]", "formats = [\"ply\"]\nrerun = false"));
    let dir = tempfile::tempdir().expect("tempdir");
    let run = tests::run_mission(&mission.path, dir.path());
    assert_eq!(run.code, 0, "{}", run.stderr);
    assert!(!dir.path().join("mission.rrd").exists());
    assert!(dir.path().join("report.json").exists());
}

#[test]
fn log_icp_iterations_puts_every_iteration_on_its_own_timeline() {
    let text = std::fs::read_to_string(example("hall.toml")).expect("hall.toml");
    let text = text.edit("[output]", "[fusion]\nmode = \"icp\"\n\n[output]");
    let mission = tests::temp_mission(&text);
    let dir = tempfile::tempdir().expect("tempdir");
    let run = cps_survey([
        "run".into(),
        mission.path.clone().into_os_string(),
        "--out".into(),
        dir.path().into(),
        "--quiet".into(),
        "--log-icp-iterations".into(),
    ]);
    assert_eq!(run.code, 0, "{}\n{}", run.stdout, run.stderr);
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.path().join("report.json")).expect("report")).expect("json");
    let matches = report["fusion"]["matches"].as_u64().expect("matches") as usize;
    assert!(matches >= 42, "coarse and fine pass over 21 scans at least: {matches}");
    let rows = rrd_rows(&dir.path().join("mission.rrd")).expect("the recording decodes");
    // Scan 0 holds the frame; every other scan moves, its points shown once.
    let transforms: usize = (1..22).map(|k| rows[&format!("/world/scans/icp_iterations/scan{k:03}")].0).sum();
    for k in 1..22 {
        assert_eq!(rows[&format!("/world/scans/icp_iterations/scan{k:03}/points")], (1, false));
    }
    assert!(!rows.contains_key("/world/scans/icp_iterations/scan000"));
    // One transform per iteration; a shift per iteration after each run's first.
    assert!(transforms > matches, "{transforms} iterations in {matches} runs");
    assert_eq!(rows["/metrics/icp_iteration_shift_m"].0, transforms - matches);
    // Without the flag, none of it.
    let plain = tempfile::tempdir().expect("tempdir");
    assert_eq!(tests::run_mission(&mission.path, plain.path()).code, 0);
    let rows = rrd_rows(&plain.path().join("mission.rrd")).expect("decodes");
    assert!(!rows.keys().any(|p| p.contains("icp_iteration")), "{:?}", rows.keys());
}
