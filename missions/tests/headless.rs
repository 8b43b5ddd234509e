//! The headless build (`--no-default-features`, no `recording`): a run
//! writes every output but `mission.rrd` and says so; what asks for a
//! recording explicitly is refused before anything is computed.
#![cfg(not(feature = "recording"))]

mod common;

use std::process::Command;

fn cps_survey(args: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_cps-survey")).args(args).output().expect("the binary runs")
}

#[test]
fn a_headless_run_writes_everything_but_the_recording() {
    let dir = tempfile::tempdir().expect("tmp");
    let mission = common::short_hall(dir.path(), false);
    let out = dir.path().join("run");
    let run = cps_survey(&["run", mission.to_str().expect("utf-8"), "--out", out.to_str().expect("utf-8"), "--quiet"]);
    assert_eq!(run.status.code(), Some(0), "{}", String::from_utf8_lossy(&run.stderr));
    let stdout = String::from_utf8_lossy(&run.stdout);
    assert!(stdout.contains("built without the `recording` feature"), "{stdout}");
    for file in ["report.json", "stations.csv", "journal.jsonl", "cloud.ply"] {
        assert!(out.join(file).exists(), "{file}");
    }
    assert!(!out.join("mission.rrd").exists());

    let rrd = dir.path().join("plan.rrd");
    for args in [
        vec!["predict", mission.to_str().expect("utf-8"), "--rrd", rrd.to_str().expect("utf-8")],
        vec!["run", mission.to_str().expect("utf-8"), "--out", "elsewhere", "--spawn"],
    ] {
        let refused = cps_survey(&args);
        assert_eq!(refused.status.code(), Some(2));
        assert!(String::from_utf8_lossy(&refused.stderr).contains("without the `recording` feature"));
        assert!(refused.stdout.is_empty(), "nothing printed before the refusal");
    }
    assert!(!std::path::Path::new("elsewhere").exists());
}
