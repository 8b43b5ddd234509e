//! The real `cps-survey` process: exit codes 0 / 1 / 2 and the error on stderr.

use std::process::Command;

fn cps_survey(args: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_cps-survey")).args(args).output().expect("the binary runs")
}

fn example(name: &str) -> String {
    format!("{}/examples/{name}", env!("CARGO_MANIFEST_DIR"))
}

#[test]
fn success_is_0() {
    let out = cps_survey(&["predict", &example("paper-1km.toml"), "--json"]);
    assert_eq!(out.status.code(), Some(0));
    assert!(out.stderr.is_empty());
    // The versioned header first, then the document.
    let stdout = String::from_utf8_lossy(&out.stdout);
    let head =
        format!("{{\"schema_version\":1,\"tool_version\":\"{}\",\"mission\":\"paper-1km\"", env!("CARGO_PKG_VERSION"));
    assert!(stdout.starts_with(&head), "{stdout:.200}");
}

#[test]
fn acceptance_failure_is_1_and_bad_input_is_2() {
    let dir = tempfile::tempdir().expect("tmp");
    let text = std::fs::read_to_string(example("paper-1km.toml")).expect("read");
    let strict = dir.path().join("strict.toml");
    std::fs::write(&strict, text.replace("max_final_sigma_xy_m = 0.25", "max_final_sigma_xy_m = 0.01")).expect("write");
    assert_eq!(cps_survey(&["predict", strict.to_str().expect("utf-8")]).status.code(), Some(1));

    let bad = dir.path().join("bad.toml");
    std::fs::write(&bad, text.replace("stride_m = 10.0", "stride_m = -1")).expect("write");
    let out = cps_survey(&["predict", bad.to_str().expect("utf-8")]);
    assert_eq!(out.status.code(), Some(2));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains(&format!("{}:", bad.display())) && err.contains("plan.stride_m"), "{err}");
    assert!(out.stdout.is_empty());
}

#[test]
fn usage_errors_are_2() {
    assert_eq!(cps_survey(&["predict"]).status.code(), Some(2));
    assert_eq!(cps_survey(&["no-such-command"]).status.code(), Some(2));
}
