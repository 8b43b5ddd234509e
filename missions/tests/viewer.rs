//! A viewer that is not there (`--connect` to a closed port, `--spawn`
//! where the viewer cannot start) costs a warning, never the run: every
//! output is written, the journal ends, exit 0. A spawned viewer listens on
//! the loopback interface only (a stand-in `rerun` first on the PATH writes
//! down how it was started).
#![cfg(feature = "recording")]

mod common;

use std::path::Path;
use std::process::Command;

/// Runs the binary with `path` as its PATH; (exit code, stdout, stderr).
fn run(mission: &Path, out: &Path, viewer: &[&str], path: &str) -> (Option<i32>, String, String) {
    let output = Command::new(env!("CARGO_BIN_EXE_cps-survey"))
        .args(["run", mission.to_str().expect("utf-8"), "--out", out.to_str().expect("utf-8"), "--quiet"])
        .args(viewer)
        .env("PATH", path)
        .output()
        .expect("the binary runs");
    let text = |b: &[u8]| String::from_utf8_lossy(b).into_owned();
    (output.status.code(), text(&output.stdout), text(&output.stderr))
}

/// The outputs of a finished run, and its journal's last line the `end`.
fn assert_finished(out: &Path) {
    for file in ["report.json", "stations.csv", "mission.rrd", "cloud.ply", "adjustment.txt"] {
        assert!(out.join(file).exists(), "{file} written");
    }
    let journal = std::fs::read_to_string(out.join("journal.jsonl")).expect("journal");
    assert!(journal.lines().last().is_some_and(|l| l.starts_with("{\"event\":\"end\"")), "the journal ends");
}

#[test]
fn a_viewer_that_is_not_there_costs_a_warning_not_the_run() {
    let dir = tempfile::tempdir().expect("tempdir");
    let mission = common::short_hall(dir.path(), true);
    let system_path = std::env::var("PATH").unwrap_or_default();

    // --connect to a port nobody listens on.
    let out = dir.path().join("connect");
    let (code, stdout, stderr) = run(&mission, &out, &["--connect", "rerun+http://127.0.0.1:1/proxy"], &system_path);
    assert_eq!(code, Some(0), "{stderr}");
    assert!(
        stdout.contains("warning: the viewer at rerun+http://127.0.0.1:1/proxy did not take the recording"),
        "{stdout}"
    );
    assert_finished(&out);

    // --spawn where the viewer exits at once (as without a display): a
    // stand-in `rerun` that writes down its arguments and fails.
    assert!(
        std::net::TcpStream::connect(("127.0.0.1", 9876)).is_err(),
        "this test needs port 9876 free (a viewer there would be used instead of spawning one)"
    );
    let bin = dir.path().join("bin");
    std::fs::create_dir(&bin).expect("bin");
    let args = dir.path().join("rerun-args.txt");
    let fake = bin.join("rerun");
    let script = format!("#!/bin/sh\n[ \"$1\" = --version ] && exit 1\necho \"$@\" >> '{}'\nexit 1\n", args.display());
    std::fs::write(&fake, script).expect("the stand-in viewer");
    std::fs::set_permissions(&fake, std::os::unix::fs::PermissionsExt::from_mode(0o755)).expect("chmod");
    let out = dir.path().join("spawn");
    let (code, stdout, stderr) = run(&mission, &out, &["--spawn"], &format!("{}:{system_path}", bin.display()));
    assert_eq!(code, Some(0), "{stderr}");
    assert!(stdout.contains("warning: the viewer at rerun+http://127.0.0.1:9876/proxy"), "{stdout}");
    assert_finished(&out);
    let spawned = std::fs::read_to_string(&args).expect("the stand-in viewer was started");
    assert!(spawned.contains("--bind 127.0.0.1"), "bound to the loopback interface: {spawned}");
}
