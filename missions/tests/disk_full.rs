//! A full disk (a file-size limit, `ulimit -f`, stands in for it: writes
//! past it fail with EFBIG) is a file-system error naming the file — never
//! a device fault, never retried, never a hang — and `--resume` finishes
//! the run once there is room.
#![cfg(feature = "recording")]

mod common;

use std::path::Path;
use std::process::Command;

/// `run` under a file-size limit of `blocks` (512 or 1024 bytes each,
/// as the shell counts them); (exit code, stderr).
fn run_limited(blocks: u32, mission: &Path, out: &Path) -> (Option<i32>, String) {
    let script = format!("ulimit -f {blocks}; trap '' XFSZ; exec \"$0\" run \"$1\" --out \"$2\" --quiet");
    let output = Command::new("sh")
        .args(["-c", &script, env!("CARGO_BIN_EXE_cps-survey")])
        .args([mission, out])
        .output()
        .expect("sh runs");
    (output.status.code(), String::from_utf8_lossy(&output.stderr).into_owned())
}

fn resume(mission: &Path, out: &Path) -> Option<i32> {
    let mission = mission.to_str().expect("utf-8");
    let out = out.to_str().expect("utf-8");
    Command::new(env!("CARGO_BIN_EXE_cps-survey"))
        .args(["run", mission, "--out", out, "--quiet", "--resume"])
        .output()
        .expect("the binary runs")
        .status
        .code()
}

#[test]
fn a_scan_file_that_cannot_be_written_is_named_and_not_retried() {
    let dir = tempfile::tempdir().expect("tempdir");
    let mission = common::short_hall(dir.path(), false);
    let out = dir.path().join("run");
    // 60 blocks: 30 or 60 KB; a scan file is ~85 KB, the journal ~1 KB then.
    let (code, stderr) = run_limited(60, &mission, &out);
    assert_eq!(code, Some(2), "{stderr}");
    assert!(
        stderr.contains("scans/scan000.3d") && stderr.contains("A file-system error, not a scanner fault"),
        "{stderr}"
    );
    let journal = std::fs::read_to_string(out.join("journal.jsonl")).expect("journal");
    assert!(!journal.contains("\"retry\""), "not retried as a device fault: {journal}");
    assert_eq!(resume(&mission, &out), Some(0));
    assert!(out.join("report.json").exists());
}

#[test]
fn a_recording_that_cannot_be_written_is_named_and_the_reports_are_kept() {
    let dir = tempfile::tempdir().expect("tempdir");
    let mission = common::short_hall(dir.path(), false);
    let out = dir.path().join("run");
    // 200 blocks: 100 or 200 KB; the scans, the cloud and the reports fit,
    // the recording (~290 KB) does not.
    let (code, stderr) = run_limited(200, &mission, &out);
    assert_eq!(code, Some(2), "{stderr}");
    assert!(stderr.contains("mission.rrd") && stderr.contains("is the disk full?"), "{stderr}");
    for file in ["report.json", "stations.csv", "cloud.ply"] {
        assert!(out.join(file).exists(), "{file} kept");
    }
    assert_eq!(resume(&mission, &out), Some(0));
    let journal = std::fs::read_to_string(out.join("journal.jsonl")).expect("journal");
    assert!(journal.lines().last().is_some_and(|l| l.starts_with("{\"event\":\"end\"")), "the journal ends");
    assert!(std::fs::metadata(out.join("mission.rrd")).expect("rrd").len() > 200 * 1024, "the recording rewritten");
}

/// A LAS cloud that cannot be written (the disk fills while it grows) is a
/// named error, exit 2 — not a panic in the `las` crate's writer as it is
/// dropped (exit 101, or 134 on a full tmpfs) — and no half-written cloud
/// is left under its name. (LAZ and COPC: `scanner/tests/disk_full.rs`.)
#[test]
fn a_las_cloud_that_cannot_be_written_is_named_not_a_panic() {
    let dir = tempfile::tempdir().expect("tempdir");
    let mission = common::short_hall(dir.path(), false);
    // Five scans: each scan file (~86 KB) fits in 170 blocks (85 or 170
    // KB), the LAS cloud (~220 KB) does not; no recording.
    let text = std::fs::read_to_string(&mission)
        .expect("mission")
        .replace("[[1.5, 4.2, 1.5], [8.7, 4.2, 1.5]]", "[[1.5, 4.2, 1.5], [15.9, 4.2, 1.5]]")
        .replace("formats = [\"ply\"]", "formats = [\"las\"]\nrerun = false");
    assert!(text.contains("formats = [\"las\"]") && text.contains("[15.9, 4.2"), "the helper's mission changed");
    std::fs::write(&mission, text).expect("mission");
    let out = dir.path().join("run");
    let (code, stderr) = run_limited(170, &mission, &out);
    assert_eq!(code, Some(2), "{stderr}");
    assert!(!stderr.contains("panicked"), "{stderr}");
    assert!(stderr.contains("cloud.las"), "the cloud file named: {stderr}");
    assert!(!out.join("cloud.las").exists(), "no half-written cloud.las");
}

/// `adjust` on a full disk keeps the complete `adjustment.txt` it had
/// (issue 34, F1: it was replaced by a truncated one).
#[test]
fn adjust_on_a_full_disk_keeps_the_last_listing_whole() {
    let dir = tempfile::tempdir().expect("tempdir");
    let mission = common::short_hall(dir.path(), false);
    let out = dir.path().join("run");
    let run = Command::new(env!("CARGO_BIN_EXE_cps-survey"))
        .args([mission.as_os_str(), out.as_os_str()].iter().enumerate().flat_map(|(k, a)| {
            let flag: &std::ffi::OsStr = if k == 0 { "run".as_ref() } else { "--out".as_ref() };
            [flag.to_os_string(), a.to_os_string()]
        }))
        .arg("--quiet")
        .output()
        .expect("runs");
    assert!(run.status.success(), "{}", String::from_utf8_lossy(&run.stderr));
    let listing = out.join("adjustment.txt");
    let before = std::fs::read(&listing).expect("listing");
    assert!(before.len() > 2048, "a listing of {} bytes", before.len());
    // 2 blocks (1 or 2 KB): less than the listing.
    let script = "ulimit -f 2; trap '' XFSZ; exec \"$0\" adjust \"$1\" --alpha 0.2";
    let output =
        Command::new("sh").args(["-c", script, env!("CARGO_BIN_EXE_cps-survey")]).arg(&out).output().expect("sh runs");
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert_eq!(output.status.code(), Some(2), "{stderr}");
    assert!(stderr.contains("adjustment.txt"), "{stderr}");
    assert_eq!(std::fs::read(&listing).expect("listing"), before, "the last listing, whole");
    assert!(!out.join("adjustment.txt.partial").exists(), "no partial file left");
}

/// `match` whose recording (1,625 KB) cannot be written whole under a
/// file-size limit its LAZ cloud (787 KB) fits in — 1,560 blocks: 799 KB
/// of 512 bytes (dash) or 1,597 KB of 1,024 (bash) (issue 34, F3: a
/// truncated match.rrd was left): exit 2 naming match.rrd, no match.rrd
/// and no `.partial`, what was written kept.
#[test]
fn a_match_recording_that_cannot_be_written_leaves_no_truncated_file() {
    let dir = tempfile::tempdir().expect("tempdir");
    let data = Path::new(env!("CARGO_MANIFEST_DIR")).join("../data/pcl_room_scans");
    let odometry = std::fs::read_to_string(data.join("odometry_T_scan1_scan2.txt")).expect("odometry");
    let rows: Vec<String> = odometry
        .lines()
        .filter(|l| !l.trim().is_empty())
        .map(|l| format!("[{}]", l.split_whitespace().collect::<Vec<_>>().join(",")))
        .collect();
    let init = dir.path().join("init.json");
    std::fs::write(&init, format!("[{{\"file\": \"room_scan2.pcd\", \"world_from_scan\": [{}]}}]", rows.join(",")))
        .expect("init");
    let out = dir.path().join("full");
    let script = "ulimit -f 1560; trap '' XFSZ; exec \"$0\" \"$@\"";
    let output = Command::new("sh")
        .args(["-c", script, env!("CARGO_BIN_EXE_cps-survey"), "match"])
        .args([data.join("room_scan1.pcd"), data.join("room_scan2.pcd")])
        .arg("--init-poses")
        .arg(&init)
        .args(["--formats", "laz", "--out"])
        .arg(&out)
        .output()
        .expect("sh runs");
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert_eq!(output.status.code(), Some(2), "{stderr}");
    assert!(stderr.contains("match.rrd"), "{stderr}");
    assert!(!out.join("match.rrd").exists() && !out.join("match.rrd.partial").exists(), "no truncated recording");
    assert!(out.join("cloud.laz").is_file() && out.join("poses.json").is_file(), "what was written is kept");
}
