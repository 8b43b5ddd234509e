//! `cps-survey run --resume`: a run killed at any point (a real SIGKILL, and
//! an abort after each of a sweep of journal events) or stopped by a device
//! that no longer answers continues from its journal and ends with the same
//! `report.json` as an uninterrupted run, wall-clock fields aside.

mod common;

use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};
use std::time::{Duration, Instant};

use serde_json::Value;

fn bin() -> Command {
    Command::new(env!("CARGO_BIN_EXE_cps-survey"))
}

/// The hall example's first leg (8 stations) with a coarser scan (fast) or
/// a finer one (slow enough to kill mid-run), and no pause between retries.
fn mission(dir: &Path, slices: usize, resolution_deg: f64) -> PathBuf {
    let text = common::hall_edited(&[
        (common::HALL_ROUTE, "route_m = [[1.5, 4.2, 1.5], [26.7, 4.2, 1.5]]"),
        ("slices = 180", &format!("slices = {slices}")),
        ("resolution_deg = 1", &format!("resolution_deg = {resolution_deg}")),
        ("seed = 1", "seed = 1\nretry_delay_s = 0"),
        ("control_at = [0, 10, 21]", "control_at = \"start-end\""),
    ]);
    let path = dir.join(format!("hall-{slices}.toml"));
    std::fs::write(&path, text).expect("write mission");
    path
}

fn run(mission: &Path, out: &Path, extra: &[&str]) -> Output {
    bin().arg("run").arg(mission).arg("--out").arg(out).arg("--quiet").args(extra).output().expect("cps-survey runs")
}

/// report.json without its wall-clock fields.
fn report(out: &Path) -> Value {
    let mut r: Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("report.json")).expect("report.json")).expect("JSON");
    r.as_object_mut().expect("object").remove("timings");
    r
}

fn journal(out: &Path) -> Vec<Value> {
    std::fs::read_to_string(out.join("journal.jsonl"))
        .expect("journal")
        .lines()
        .map(|l| serde_json::from_str(l).expect("a JSON line"))
        .collect()
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

#[test]
fn a_run_aborted_after_any_event_resumes_to_the_same_report() {
    let dir = tempfile::tempdir().expect("tempdir");
    let m = mission(dir.path(), 36, 1.0);
    let whole = dir.path().join("whole");
    assert_eq!(run(&m, &whole, &[]).status.code(), Some(0));
    let expected = report(&whole);
    let events = journal(&whole).len();
    assert_eq!(
        events, 81,
        "start, 2 × measure (W1, W2) and the resection's fix, 8 × (tilt, scan), \
         7 × (2 × (drive, measure), drive, 2 × measure, fix), 4 × measure (the end's control), end"
    );

    // The first events, one in each kind of step, the last steps, the end.
    for n in [1, 2, 3, 4, 5, 6, 9, 12, 13, 30, 51, events - 2, events - 1, events] {
        let out = dir.path().join(format!("abort{n}"));
        let crashed = run(&m, &out, &["--abort-after-events", &n.to_string()]);
        assert!(!crashed.status.success(), "aborted after {n} events");
        assert_eq!(journal(&out).len(), n, "the journal holds exactly the events written before the crash");
        let resumed = run(&m, &out, &["--resume"]);
        // A run killed after its end is finished: resuming it says so
        // (exit 2) and touches nothing.
        let finished = n == events;
        assert_eq!(resumed.status.code(), Some(if finished { 2 } else { 0 }), "after {n}: {}", stderr(&resumed));
        assert!(!finished || stderr(&resumed).contains("is finished"), "{}", stderr(&resumed));
        assert_eq!(report(&out), expected, "resumed after {n} events");
        let kinds: Vec<Value> = journal(&out).iter().map(|e| e["event"].clone()).collect();
        assert_eq!(kinds.iter().filter(|k| *k == "resume").count(), usize::from(!finished));
        assert_eq!(kinds.iter().rev().find(|k| *k != "resume"), Some(&Value::from("end")));
        assert_eq!(kinds.iter().filter(|k| *k == "end").count(), 1);
    }
}

#[test]
fn a_run_killed_with_sigkill_resumes_to_the_same_report() {
    let dir = tempfile::tempdir().expect("tempdir");
    // 0.5° and 360 slices: each scan takes long enough to be killed in.
    let m = mission(dir.path(), 360, 0.5);
    let whole = dir.path().join("whole");
    assert_eq!(run(&m, &whole, &[]).status.code(), Some(0));

    let out = dir.path().join("killed");
    let mut child = bin()
        .arg("run")
        .arg(&m)
        .arg("--out")
        .arg(&out)
        .arg("--quiet")
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .expect("spawn");
    let started = Instant::now();
    let lines = || std::fs::read_to_string(out.join("journal.jsonl")).map_or(0, |t| t.lines().count());
    while lines() < 20 {
        assert!(started.elapsed() < Duration::from_secs(60), "the run never wrote 20 events");
        std::thread::sleep(Duration::from_millis(2));
    }
    child.kill().expect("SIGKILL");
    child.wait().expect("reaped");
    let before = journal(&out);
    assert!(before.last().is_none_or(|e| e["event"] != "end"), "killed before the end ({} events)", before.len());

    let resumed = run(&m, &out, &["--resume"]);
    assert_eq!(resumed.status.code(), Some(0), "{}", stderr(&resumed));
    assert_eq!(report(&out), report(&whole));
    // Every event recorded before the kill is still there, in order.
    let after = journal(&out);
    assert_eq!(&after[..before.len()], &before[..]);
}

#[test]
fn a_device_that_stops_answering_stops_cleanly_and_resumes() {
    let dir = tempfile::tempdir().expect("tempdir");
    let m = mission(dir.path(), 36, 1.0);
    let whole = dir.path().join("whole");
    assert_eq!(run(&m, &whole, &[]).status.code(), Some(0));

    // The total station answers 9 commands, then nothing: 2 retries, exit 2.
    let out = dir.path().join("stopped");
    let stopped = run(&m, &out, &["--sim-fault", "total-station:after=9"]);
    assert_eq!(stopped.status.code(), Some(2));
    let message = stderr(&stopped);
    assert!(message.contains("total-station failed 3 time(s)"), "{message}");
    assert!(message.contains(&format!("--out {} --resume", out.display())), "{message}");
    let events = journal(&out);
    let count = |kind: &str| events.iter().filter(|e| e["event"] == kind).count();
    assert_eq!(count("measure"), 9, "every reading before the fault is kept");
    assert_eq!(count("retry"), 2);
    assert_eq!(events.last().expect("stop")["event"], "stop");
    assert!(!out.join("report.json").exists());

    let resumed = run(&m, &out, &["--resume"]);
    assert_eq!(resumed.status.code(), Some(0), "{}", stderr(&resumed));
    assert_eq!(report(&out), report(&whole));
}

#[test]
fn intermittent_faults_are_retried_without_changing_the_result() {
    let dir = tempfile::tempdir().expect("tempdir");
    let m = mission(dir.path(), 36, 1.0);
    let whole = dir.path().join("whole");
    assert_eq!(run(&m, &whole, &[]).status.code(), Some(0));
    let out = dir.path().join("flaky");
    let flaky = run(&m, &out, &["--sim-fault", "total-station:every=3", "--sim-fault", "drive:every=4"]);
    assert_eq!(flaky.status.code(), Some(0), "{}", stderr(&flaky));
    // A failed command draws no noise, so the readings are the same.
    assert_eq!(report(&out), report(&whole));
    let retries: Vec<Value> = journal(&out).into_iter().filter(|e| e["event"] == "retry").collect();
    // n successes with every k-th command failing take c = n + ⌊(n−1)/(k−1)⌋
    // commands, ⌊c/k⌋ of them failed: 34 measurements (28 of the children,
    // 6 of control; k = 3) → 50 commands, 16 retries; 21 drives (k = 4) →
    // 27 commands, 6 retries.
    assert_eq!(retries.iter().filter(|e| e["device"] == "total-station").count(), 16);
    assert_eq!(retries.iter().filter(|e| e["device"] == "drive").count(), 6);
}

#[test]
fn resume_refuses_another_mission_and_a_missing_run() {
    let dir = tempfile::tempdir().expect("tempdir");
    let m = mission(dir.path(), 36, 1.0);
    let out = dir.path().join("r");
    let nothing = run(&m, &out, &["--resume"]);
    assert_eq!(nothing.status.code(), Some(2));
    assert!(stderr(&nothing).contains("no run to resume"), "{}", stderr(&nothing));
    assert!(!out.exists(), "nothing created by a resume with nothing to resume");
    std::fs::create_dir(&out).expect("an empty directory");
    assert_eq!(run(&m, &out, &["--resume"]).status.code(), Some(2));
    assert_eq!(std::fs::read_dir(&out).expect("out").count(), 0, "still empty (no scans/, no lock)");
    std::fs::remove_dir(&out).expect("remove");

    assert!(!run(&m, &out, &["--abort-after-events", "10"]).status.success());
    let other = mission(dir.path(), 72, 1.0);
    let refused = run(&other, &out, &["--resume"]);
    assert_eq!(refused.status.code(), Some(2));
    assert!(stderr(&refused).contains("not the mission this run started with"), "{}", stderr(&refused));
    // Issue 34, U10: the same mission with another seed names the seeds,
    // not the mission file.
    let seeded = run(&m, &out, &["--resume", "--seed", "9"]);
    assert_eq!(seeded.status.code(), Some(2));
    let text = stderr(&seeded);
    assert!(text.contains("started with seed") && text.contains("this resume has seed 9"), "{text}");
    assert!(!text.contains("not the mission"), "{text}");
}
