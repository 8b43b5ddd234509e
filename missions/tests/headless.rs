//! The headless build (`--no-default-features`, no `recording`): a run
//! writes every output but `mission.rrd` and says so; what asks for a
//! recording explicitly is refused before anything is computed.
#![cfg(not(feature = "recording"))]

use std::process::Command;

fn cps_survey(args: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_cps-survey")).args(args).output().expect("the binary runs")
}

#[test]
fn a_headless_run_writes_everything_but_the_recording() {
    let dir = tempfile::tempdir().expect("tmp");
    let hall = std::fs::read_to_string(format!("{}/examples/hall.toml", env!("CARGO_MANIFEST_DIR"))).expect("hall");
    let mission = dir.path().join("m.toml");
    let text = hall
        .replace(
            "[[1.5, 4.2, 1.5], [37.5, 4.2, 1.5], [37.5, 7.8, 1.5], [1.5, 7.8, 1.5]]",
            "[[1.5, 4.2, 1.5], [8.7, 4.2, 1.5]]",
        )
        .replace("control_at = [0, 10, 21]", "")
        .replace("slices = 180", "slices = 8");
    // Without its control (the control points are the file's last tables):
    // the short route sights only the west wall's.
    let text = text.split("[[control]]").next().expect("the text before the control points").to_string();
    assert!(!text.contains("control_at"), "hall.toml's control_at changed: update this test");
    std::fs::write(&mission, text).expect("mission");
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
