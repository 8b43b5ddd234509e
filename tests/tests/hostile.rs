//! Hostile input through the command line: each is refused with exit 2 and
//! a message naming the file, field or flag — no panic, no abort, no write
//! outside the run directory. The files are made here.

use tests::{cps_survey, example, temp_mission};

#[test]
fn a_scan_file_whose_header_lies_is_refused() {
    let dir = tempfile::tempdir().expect("tempdir");
    let mut pcd =
        b"VERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\nWIDTH 4611686018427387904\nHEIGHT 1\nPOINTS 4611686018427387904\nDATA binary\n"
            .to_vec();
    pcd.extend_from_slice(&[0u8; 24]);
    let bad = dir.path().join("p.pcd");
    std::fs::write(&bad, pcd).expect("write");
    let good = dir.path().join("good.xyz");
    std::fs::write(&good, "0 0 0\n1 0 0\n0 1 0\n0 0 1\n").expect("write");
    let run = cps_survey(["register", bad.to_str().expect("utf-8"), good.to_str().expect("utf-8")]);
    assert_eq!(run.code, 2, "{}", run.stderr);
    assert!(run.stderr.contains("p.pcd") && run.stderr.contains("truncated"), "{}", run.stderr);
}

#[test]
fn emulate_refuses_an_endless_or_absurd_duration() {
    for s in ["inf", "1e19", "-1", "nan"] {
        let run = cps_survey(["emulate", example("hall.toml").to_str().expect("utf-8"), &format!("--seconds={s}")]);
        assert_eq!(run.code, 2, "--seconds={s}: {}", run.stderr);
        assert!(run.stderr.contains("--seconds"), "{}", run.stderr);
    }
}

#[test]
fn a_mission_name_is_a_name_not_a_path() {
    // `run` without --out writes to runs/<name>/: a name that is a path is
    // refused, by every command, before anything is written.
    let dir = tempfile::tempdir().expect("tempdir");
    for name in ["..", "../../x", "/abs/x"] {
        let text = std::fs::read_to_string(example("indoor-compact.toml")).expect("example").replacen(
            "name = \"indoor-compact\"",
            &format!("name = \"{name}\""),
            1,
        );
        assert!(text.contains(&format!("name = \"{name}\"")));
        let mission = temp_mission(&text);
        let path = mission.path.to_str().expect("utf-8");
        let out = dir.path().join("out");
        for args in [vec!["validate", path], vec!["run", path, "--quiet", "--out", out.to_str().expect("utf-8")]] {
            let run = cps_survey(args);
            assert_eq!(run.code, 2, "{name}: {}", run.stderr);
            assert!(run.stderr.contains("mission.name"), "{}", run.stderr);
        }
        assert!(!out.exists(), "nothing written");
    }
}

#[test]
fn a_route_of_a_billion_stations_is_refused_at_once() {
    let text = std::fs::read_to_string(example("paper-1km.toml"))
        .expect("example")
        .replace("[1000.0, 0.0, 0.0]]", "[1e7, 0.0, 0.0]]")
        .replace("stride_m = 10.0", "stride_m = 0.01");
    let mission = temp_mission(&text);
    let run = cps_survey(["validate", mission.path.to_str().expect("utf-8")]);
    assert_eq!(run.code, 2);
    assert!(run.stderr.contains("plan.stride_m") && run.stderr.contains("1000000001 stations"), "{}", run.stderr);
}

#[test]
fn a_changed_scan_file_is_refused_and_a_lost_pose_file_rewritten() {
    let dir = tempfile::tempdir().expect("tempdir");
    let hall = example("hall.toml");
    // A run the total station stops half-way (exit 2, the journal kept).
    let out = dir.path().join("r");
    let mut args: Vec<std::ffi::OsString> = vec!["run".into(), hall.clone().into_os_string(), "--out".into()];
    args.extend([
        out.clone().into_os_string(),
        "--quiet".into(),
        "--sim-fault".into(),
        "total-station:after=40".into(),
    ]);
    let stopped = cps_survey(args);
    assert_eq!(stopped.code, 2, "{}", stopped.stderr);
    // A pose file lost: --resume writes it again (it is derived from the
    // journal) and finishes.
    let pose = out.join("scans/scan003.pose");
    let before = std::fs::read_to_string(&pose).expect("the pose file");
    std::fs::remove_file(&pose).expect("remove");
    let mut resume: Vec<std::ffi::OsString> = vec!["run".into(), hall.into_os_string(), "--out".into()];
    resume.extend([out.clone().into_os_string(), "--quiet".into(), "--resume".into()]);
    let resumed = cps_survey(resume);
    assert_eq!(resumed.code, 0, "{}", resumed.stderr);
    assert_eq!(std::fs::read_to_string(&pose).expect("rewritten"), before);
    // A scan file cut short: fuse refuses it, naming it, and writes nothing.
    let scan = out.join("scans/scan005.3d");
    let bytes = std::fs::read(&scan).expect("scan");
    std::fs::write(&scan, &bytes[..bytes.len() / 2]).expect("truncate");
    let fused = cps_survey(["fuse", out.to_str().expect("utf-8")]);
    assert_eq!(fused.code, 2);
    assert!(fused.stderr.contains("scans/scan005.3d") && fused.stderr.contains("has changed"), "{}", fused.stderr);
    assert!(!out.join("fusion").exists(), "nothing written");
}

#[test]
fn a_team_of_two_hundred_thousand_children_is_refused() {
    let names: Vec<String> = (0..200_000).map(|i| format!("\"c{i}\"")).collect();
    let text = std::fs::read_to_string(example("indoor-compact.toml"))
        .expect("example")
        .replace("children = [\"left\", \"right\"]", &format!("children = [{}]", names.join(", ")));
    assert!(text.contains("\"c199999\""));
    let mission = temp_mission(&text);
    let run = cps_survey(["validate", mission.path.to_str().expect("utf-8")]);
    assert_eq!(run.code, 2, "{}", run.stderr);
    assert!(
        run.stderr.contains("team.children") && run.stderr.contains("200000 children; expected at most 32"),
        "{}",
        run.stderr
    );
}

#[test]
fn montecarlo_refuses_a_hundred_million_trials() {
    let hall = example("hall.toml");
    let run = cps_survey(["montecarlo", hall.to_str().expect("utf-8"), "--trials", "100000000"]);
    assert_eq!(run.code, 2, "{}", run.stderr);
    assert!(run.stderr.contains("--trials 100000000: expected at most 100000"), "{}", run.stderr);
}
