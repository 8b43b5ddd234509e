//! `cps-survey predict` and `validate` end to end.

use serde_json::Value;
use tests::Edit;
use tests::{cps_survey, example, temp_mission};

fn json(run: &tests::Run) -> Value {
    serde_json::from_str(&run.stdout).expect("predict --json prints one JSON object")
}

#[test]
fn paper_1km_predicts_100_cycles_near_the_model_floor() {
    let run = cps_survey(["predict".into(), example("paper-1km.toml").into_os_string(), "--json".into()]);
    assert_eq!(run.code, 0, "{}", run.stderr);
    let v = json(&run);
    let cycles = v["cycles"].as_array().expect("cycles");
    assert_eq!(cycles.len(), 100);
    assert_eq!(cycles[0]["cycle"], 1);
    assert_eq!(cycles[0]["distance_m"], 10.0);
    let last = &cycles[99];
    assert_eq!(last["parent"]["x_m"], 1000.0);
    let cov = last["covariance"].as_array().expect("4×4");
    assert_eq!(cov.len(), 4);
    let c = |i: usize, j: usize| cov[i][j].as_f64().expect("number");
    for i in 0..4 {
        for j in 0..4 {
            assert_eq!(c(i, j), c(j, i), "symmetric");
        }
    }
    let sxy2 = v["final"]["sigma_xy2_m2"].as_f64().expect("final");
    assert!((sxy2 - (c(0, 0) + c(1, 1))).abs() < 1e-15);
    // The floor of the model for 3 mm / 5″ is ≈ 0.0204 m²; (10, ±50) m is within 5 % of it.
    assert!((0.0204..0.0215).contains(&sxy2), "σx²+σy² = {sxy2}");
    assert!(v["final"]["accepted"].as_bool().expect("bool"));
    let e = &last["ellipse_95_m"];
    assert!(e["semi_major_m"].as_f64().expect("a") >= e["semi_minor_m"].as_f64().expect("b"));
}

#[test]
fn predict_reports_every_robot_and_every_scan_station() {
    // hall: 21 leapfrog cycles, two children placed every cycle, a scan at
    // every station (22), the start resected on control (a fix of cycle 0).
    let run = cps_survey(["predict".into(), example("hall.toml").into_os_string(), "--json".into()]);
    assert_eq!(run.code, 0, "{}", run.stderr);
    let v = json(&run);
    let cycles = v["cycles"].as_array().expect("cycles");
    let steps = v["steps"].as_array().expect("steps");
    let scans = v["scans"].as_array().expect("scans");
    let of = |a: &str| steps.iter().filter(|s| s["action"] == a).count();
    assert_eq!((of("placement"), of("fix"), scans.len()), (42, 22, 22));
    let start = steps.iter().find(|s| s["action"] == "fix" && s["cycle"] == 0).expect("the resection");
    for (k, scan) in scans.iter().enumerate() {
        assert_eq!(scan["station"], k);
        let cov = &scan["covariance"];
        if k == 0 {
            // The start's pose comes from its resection on W1 and W2.
            assert_eq!(cov, &start["covariance"]);
            assert!(scan["sigma_xy_m"].as_f64().is_some_and(|s| s > 0.0 && s < 1e-3), "{scan}");
        } else {
            // A scan station inherits the fix of the cycle that reached it.
            assert_eq!(cov, &cycles[k - 1]["covariance"], "station {k}");
        }
    }
    // Each child's covariance after its placement is the cycle's child row;
    // it is 3×3 and the parent's 4×4.
    for s in steps.iter().filter(|s| s["cycle"] != 0) {
        let size = s["covariance"].as_array().map(Vec::len);
        let cycle = &cycles[s["cycle"].as_u64().expect("cycle") as usize - 1];
        if s["robot"] == "parent" {
            assert_eq!(size, Some(4));
            assert_eq!(s["covariance"], cycle["covariance"]);
        } else {
            assert_eq!(size, Some(3));
            let child = cycle["children"].as_array().and_then(|c| c.iter().find(|c| c["name"] == s["robot"]));
            assert_eq!(Some(&s["covariance"]), child.map(|c| &c["covariance"]));
        }
    }
    // Children drift with the parent that places them.
    let sigma = |c: &Value| c["children"][0]["sigma_xy_m"].as_f64().expect("σ");
    assert!(sigma(&cycles[6]) > 5.0 * sigma(&cycles[0]));
    let table = cps_survey(["predict".into(), example("hall.toml").into_os_string()]);
    assert!(table.stdout.contains("children after placement") && table.stdout.contains("scan stations:"));
}

#[test]
fn the_table_has_one_row_per_cycle_and_a_summary() {
    let run = cps_survey(["predict".into(), example("indoor-compact.toml").into_os_string()]);
    assert_eq!(run.code, 0, "{}", run.stderr);
    let is_row = |l: &str| {
        let cols: Vec<&str> = l.split_whitespace().collect();
        cols.len() == 10 && cols.iter().all(|c| c.parse::<f64>().is_ok())
    };
    let (filter, adjusted) = run.stdout.split_once("adjusted network").expect("the pre-analysis");
    assert_eq!(filter.lines().filter(|l| is_row(l)).count(), 12, "{}", run.stdout);
    // The adjusted network: every station, the start's too.
    assert_eq!(adjusted.lines().filter(|l| is_row(l)).count(), 13, "{}", run.stdout);
    assert!(run.stdout.contains("σx² + σy²"));
    assert!(run.stdout.contains("acceptance     PASS"));
}

#[test]
fn failing_acceptance_exits_1() {
    let text = std::fs::read_to_string(example("paper-1km.toml")).expect("read");
    let strict = temp_mission(&text.edit("max_final_sigma_xy_m = 0.25", "max_final_sigma_xy_m = 0.01"));
    let run = cps_survey(["predict".into(), strict.path.clone().into_os_string()]);
    assert_eq!(run.code, 1);
    assert!(run.stdout.contains("FAIL"));
}

#[test]
fn every_example_validates() {
    for entry in std::fs::read_dir(tests::workspace().join("missions/examples")).expect("dir") {
        let path = entry.expect("entry").path();
        if path.extension().is_some_and(|e| e == "toml") {
            let run = cps_survey(["validate".into(), path.clone().into_os_string()]);
            // hall-plan.toml is the planner's example of a plan that breaks a
            // constraint: validate refuses it (tests/tests/plan.rs).
            let expected = if path.ends_with("hall-plan.toml") { 2 } else { 0 };
            assert_eq!(run.code, expected, "{}: {}", path.display(), run.stderr);
        }
    }
}

#[test]
fn a_missing_file_is_exit_2_naming_it() {
    let run = cps_survey(["predict", "/nonexistent/mission.toml"]);
    assert_eq!(run.code, 2);
    assert!(run.stderr.contains("/nonexistent/mission.toml"), "{}", run.stderr);
}
