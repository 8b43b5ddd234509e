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

/// Statistics' levels and iteration caps outside what gives an answer are
/// refused before anything runs (S3, S4: at α = 1e-16 the global test's
/// bound was null, the exit code wrong and every MDB NaN; H2: register's
/// cap of 2^64 − 1 with zero tolerances never ended).
#[test]
fn levels_and_caps_that_give_no_answer_are_refused() {
    for (args, wanted) in [
        (vec!["adjust", "nowhere", "--alpha", "1e-16"], "expected a significance level from 0.000001 to 0.5"),
        (vec!["adjust", "nowhere", "--alpha0", "1e-16"], "expected a significance level from 0.000001 to 0.5"),
        (vec!["adjust", "nowhere", "--alpha", "0.9"], "expected a significance level"),
        (vec!["adjust", "nowhere", "--power", "0.9999999"], "expected a power from 0.5 to 0.999999"),
        (
            vec!["register", "a.ply", "b.ply", "--iterations", "18446744073709551615"],
            "expected a whole number of iterations from 1 to 10000",
        ),
        (vec!["register", "a.ply", "b.ply", "--iterations", "0"], "from 1 to 10000"),
    ] {
        let out = cps_survey(&args);
        assert_eq!(out.status.code(), Some(2), "{args:?}");
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert!(stderr.contains(wanted), "{args:?}: {stderr}");
    }
}
