//! Journal version 3 keeps one chain link per fix where version 2 kept
//! every fix's cross-covariances with all earlier scan stations (issue 35:
//! O(n²) bytes). A version 2 run (`tests/fixtures/journal-v2`, written at
//! commit 9e8cf00: four hall stations fused by CPS+ICP, whose joint prior
//! needs those cross-covariances) still re-fuses and resumes to the report
//! it was written with; the same mission run anew fuses to the same poses
//! from the chain; and a journal's bytes per station no longer grow with
//! the route.

use serde_json::Value;
use tests::Edit;
use tests::cps_survey;

use super::journal_v1::{copy_of, fixture_named, json, resumes_to};

fn fixture() -> std::path::PathBuf {
    fixture_named("journal-v2")
}

fn events(run: &std::path::Path) -> Vec<Value> {
    let text = std::fs::read_to_string(run.join("journal.jsonl")).expect("journal");
    text.lines().map(|l| serde_json::from_str(l).expect("a JSON line")).collect()
}

/// Each scan's `world_from_body` and covariance in a report's or a fusion
/// document's `scans`.
fn fused(scans: &Value) -> Vec<Vec<f64>> {
    let numbers = |v: &Value| -> Vec<f64> {
        v.as_array()
            .expect("rows")
            .iter()
            .flat_map(|r| r.as_array().expect("row").iter())
            .filter_map(Value::as_f64)
            .collect()
    };
    let scans = scans.as_array().expect("scans");
    scans
        .iter()
        .map(|s| numbers(&s["world_from_body"]).into_iter().chain(numbers(&s["covariance"])).collect())
        .collect()
}

fn largest_difference(a: &[Vec<f64>], b: &[Vec<f64>]) -> f64 {
    assert_eq!(a.len(), b.len());
    a.iter().zip(b).flat_map(|(x, y)| x.iter().zip(y).map(|(p, q)| (p - q).abs())).fold(0.0, f64::max)
}

#[test]
fn a_version_2_run_re_fuses_with_its_cross_covariances() {
    let (_tmp, run) = copy_of(&fixture());
    let report = json(&run.join("report.json"));
    assert_eq!(report["fusion"]["mode"], "cps-icp");
    assert!(report["fusion"]["matches"].as_u64().expect("matches") >= 2, "the prior meets ICP links");
    let fused_again = cps_survey(["fuse".into(), run.clone().into_os_string(), "--mode".into(), "cps-icp".into()]);
    assert_eq!(fused_again.code, 0, "{}", fused_again.stderr);
    let fusion = json(&run.join("fusion/cps-icp/fusion.json"));
    let d = largest_difference(&fused(&fusion["scans"]), &fused(&report["fusion"]["scans"]));
    assert!(d < 1e-12, "re-fused poses and covariances differ by {d:e}");
}

#[test]
fn a_version_2_run_resumes_in_version_2() {
    let expected = json(&fixture().join("report.json"));
    let lines: Vec<String> =
        std::fs::read_to_string(fixture().join("journal.jsonl")).expect("journal").lines().map(String::from).collect();
    assert!(lines.iter().all(|l| l.contains("\"v\":2")), "the fixture is version 2");
    let second_scan =
        lines.iter().enumerate().filter(|(_, l)| l.contains("\"event\":\"scan\"")).nth(1).expect("scan").0;
    let (_tmp, run) = copy_of(&fixture());
    resumes_to(&run, &(lines[..=second_scan].join("\n") + "\n"), &expected);
    let events = events(&run);
    assert!(events.iter().all(|e| e["v"] == 2), "the journal goes on in version 2");
    let fixes: Vec<&Value> = events.iter().filter(|e| e["event"] == "fix").collect();
    let last = fixes.last().expect("a fix");
    assert_eq!(last["data"]["scan_cross_covariances"].as_array().map(Vec::len), Some(3), "{last}");
    assert!(last["data"].get("chain").is_none());
}

#[test]
fn a_new_run_fuses_from_the_chain_as_version_2_did_from_every_cross_covariance() {
    let dir = tempfile::tempdir().expect("tempdir");
    let run = dir.path().join("run");
    let done = tests::run_mission(&fixture().join("mission.toml"), &run);
    assert_eq!(done.code, 0, "{}", done.stderr);
    let events = events(&run);
    assert!(events.iter().all(|e| e["v"] == 3));
    let fixes: Vec<&Value> = events.iter().filter(|e| e["event"] == "fix").collect();
    assert!(fixes.iter().all(|f| f["data"].get("scan_cross_covariances").is_none() && f["data"]["chain"].is_object()));
    let (new, old) = (json(&run.join("report.json")), json(&fixture().join("report.json")));
    assert_eq!(new["fusion"]["matches"], old["fusion"]["matches"]);
    let d = largest_difference(&fused(&new["fusion"]["scans"]), &fused(&old["fusion"]["scans"]));
    assert!(d < 1e-12, "the chain's joint prior fuses to other poses: {d:e}");
}

/// Stretches paper-1km to `stations` stride lengths, with the scans small.
fn stretched(stations: usize) -> String {
    let text = std::fs::read_to_string(tests::example("paper-1km.toml")).expect("paper-1km");
    text.edit("[1000.0, 0.0, 0.0]", &format!("[{}.0, 0.0, 0.0]", 10 * stations))
        .edit("max_final_sigma_xy_m = 0.25", "max_final_sigma_xy_m = 1000000.0")
        + "\n[scan]\nslices = 2\n\n[output]\nrerun = false\n"
}

#[test]
fn a_journal_grows_linearly_with_the_route() {
    let per_station = |stations: usize| {
        let mission = tests::temp_mission(&stretched(stations));
        let run = mission.path.with_file_name("run");
        let done = tests::run_mission(&mission.path, &run);
        assert_eq!(done.code, 0, "{}", done.stderr);
        std::fs::metadata(run.join("journal.jsonl")).expect("journal").len() as f64 / stations as f64
    };
    let (short, long) = (per_station(20), per_station(160));
    // Version 2 wrote 12.6 and 38.7 KB per station here (a fix's
    // cross-covariances with every earlier scan station).
    assert!(long < 1.1 * short, "{long:.0} bytes per station over 160 stations, {short:.0} over 20");
    assert!(long < 25_000.0, "{long:.0} bytes per station");
}
