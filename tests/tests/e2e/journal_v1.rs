//! A run written with journal schema version 1 (before the journal was
//! typed; `tests/fixtures/journal-v1`, made by commit 838db10: three
//! stations of the hall, a retried tilt reading) still re-fuses and
//! resumes to the report it was written with.

use serde_json::Value;
use tests::cps_survey;

fn fixture() -> std::path::PathBuf {
    fixture_named("journal-v1")
}

/// The run fixture `name` in `tests/fixtures`.
pub(crate) fn fixture_named(name: &str) -> std::path::PathBuf {
    tests::workspace().join("tests/fixtures").join(name)
}

fn copy() -> (tempfile::TempDir, std::path::PathBuf) {
    copy_of(&fixture())
}

/// A copy of the run fixture `fixture` in a temporary directory.
pub(crate) fn copy_of(fixture: &std::path::Path) -> (tempfile::TempDir, std::path::PathBuf) {
    let dir = tempfile::tempdir().expect("tempdir");
    let run = dir.path().join("run");
    std::fs::create_dir_all(run.join("scans")).expect("dirs");
    for entry in walk(fixture) {
        let rel = entry.strip_prefix(fixture).expect("inside");
        std::fs::copy(&entry, run.join(rel)).expect("copy");
    }
    (dir, run)
}

fn walk(dir: &std::path::Path) -> Vec<std::path::PathBuf> {
    let mut out = Vec::new();
    for e in std::fs::read_dir(dir).expect("dir").flatten() {
        let p = e.path();
        if p.is_dir() { out.extend(walk(&p)) } else { out.push(p) }
    }
    out
}

/// Whether `new` holds everything `old` does (later versions only add
/// keys): every key of an object with a value that holds the old one,
/// arrays element by element, anything else equal.
/// Writes `journal` (a cut one) into the copy `run`, resumes the run and
/// checks its report against `expected`.
pub(crate) fn resumes_to(run: &std::path::Path, journal: &str, expected: &Value) {
    std::fs::write(run.join("journal.jsonl"), journal).expect("cut journal");
    std::fs::remove_file(run.join("report.json")).expect("remove");
    let resumed = cps_survey([
        "run".into(),
        run.join("mission.toml").into_os_string(),
        "--out".into(),
        run.to_path_buf().into_os_string(),
        "--resume".into(),
        "--quiet".into(),
    ]);
    assert_eq!(resumed.code, 0, "{}", resumed.stderr);
    assert!(resumed.stdout.contains("journal events replayed"), "{}", resumed.stdout);
    let report = json(&run.join("report.json"));
    for key in ["stations", "final", "fusion", "accepted"] {
        assert!(holds(&report[key], &expected[key]), "{key}: {}\n{}", report[key], expected[key]);
    }
}

pub(crate) fn holds(new: &Value, old: &Value) -> bool {
    match (new, old) {
        (Value::Object(n), Value::Object(o)) => o.iter().all(|(k, v)| n.get(k).is_some_and(|nv| holds(nv, v))),
        (Value::Array(n), Value::Array(o)) => n.len() == o.len() && n.iter().zip(o).all(|(a, b)| holds(a, b)),
        _ => new == old,
    }
}

pub(crate) fn json(path: &std::path::Path) -> Value {
    serde_json::from_str(&std::fs::read_to_string(path).expect("file")).expect("JSON")
}

#[test]
fn a_version_1_run_re_fuses() {
    let (_tmp, run) = copy();
    let fused = cps_survey(["fuse".into(), run.clone().into_os_string(), "--mode".into(), "direct".into()]);
    assert_eq!(fused.code, 0, "{}", fused.stderr);
    let original = scanner::io::read(&run.join("cloud.ply")).expect("the v1 cloud");
    let again = scanner::io::read(&run.join("fusion/direct/cloud.ply")).expect("the re-fused cloud");
    assert_eq!(again.points, original.points, "the same points at the same poses");
    let report = json(&run.join("report.json"));
    let fusion = json(&run.join("fusion/direct/fusion.json"));
    assert!(holds(&fusion["scans"], &report["fusion"]["scans"]), "{}\n{}", fusion["scans"], report["fusion"]["scans"]);
}

#[test]
fn a_version_1_run_resumes_to_the_same_report() {
    let expected = json(&fixture().join("report.json"));
    let lines: Vec<String> =
        std::fs::read_to_string(fixture().join("journal.jsonl")).expect("journal").lines().map(String::from).collect();
    assert!(lines.iter().all(|l| l.contains("\"v\":1")), "the fixture is version 1");
    // Cut after the second scan (mid-run), and once more inside a line.
    let second_scan =
        lines.iter().enumerate().filter(|(_, l)| l.contains("\"event\":\"scan\"")).nth(1).expect("scan").0;
    for torn in [false, true] {
        let (_tmp, run) = copy();
        let mut text = lines[..=second_scan].join("\n") + "\n";
        if torn {
            text += &lines[second_scan + 1][..40];
        }
        resumes_to(&run, &text, &expected);
        // The journal goes on in the version it was started with.
        let journal = std::fs::read_to_string(run.join("journal.jsonl")).expect("journal");
        let events: Vec<Value> = journal.lines().map(|l| serde_json::from_str(l).expect("a JSON line")).collect();
        assert!(events.iter().all(|e| e["v"] == 1));
        assert_eq!(events.iter().filter(|e| e["event"] == "resume").count(), 1);
        assert_eq!(events.last().map(|e| e["event"].clone()), Some(Value::from("end")));
    }
}
