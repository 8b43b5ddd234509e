//! Hostile input through the command line: each is refused with exit 2 and
//! a message naming the file, field or flag — no panic, no abort, no write
//! outside the run directory. The files are made here.

use tests::Edit;
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
    // (And a name with a bidirectional control, issue 34, S13: it named
    // `runs/hall\u{202e}gnp.exe/`, shown as "hallexe.png".)
    for name in ["..", "../../x", "/abs/x", "hall\u{202e}gnp.exe"] {
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
        .edit("[1000.0, 0.0, 0.0]]", "[1e7, 0.0, 0.0]]")
        .edit("stride_m = 10.0", "stride_m = 0.01");
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
    // A reading recorded twice (issue 34, U7: a 900-byte line with the
    // record's JSON and a Rust value): named in words, both lines.
    let journal = std::fs::read_to_string(out.join("journal.jsonl")).expect("journal");
    let mut lines: Vec<&str> = journal.lines().collect();
    let k = lines
        .iter()
        .position(|l| l.contains("\"event\":\"measure\"") && l.contains("\"phase\":\"fix\""))
        .expect("a fix");
    lines.insert(k, lines[k]);
    std::fs::write(out.join("journal.jsonl"), lines.join("\n") + "\n").expect("journal");
    let adjusted = cps_survey(["adjust", out.to_str().expect("utf-8")]);
    assert_eq!(adjusted.code, 2, "{}", adjusted.stderr);
    let want = format!("journal.jsonl:{}: the fix reading of child 0 in cycle", k + 2);
    assert!(adjusted.stderr.contains(&want), "{want}: {}", adjusted.stderr);
    assert!(adjusted.stderr.contains(&format!("again (line {} recorded it)", k + 1)), "{}", adjusted.stderr);
    assert!(!adjusted.stderr.contains('{') && adjusted.stderr.len() < 300, "{}", adjusted.stderr);
}

#[test]
fn a_team_of_two_hundred_thousand_children_is_refused() {
    let names: Vec<String> = (0..200_000).map(|i| format!("\"c{i}\"")).collect();
    let text = std::fs::read_to_string(example("indoor-compact.toml"))
        .expect("example")
        .edit("children = [\"left\", \"right\"]", &format!("children = [{}]", names.join(", ")));
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

/// `run MISSION --out OUT --quiet` plus `extra`.
fn run_args(mission: &std::path::Path, out: &std::path::Path, extra: &[&str]) -> Vec<std::ffi::OsString> {
    let mut args: Vec<std::ffi::OsString> = vec![
        "run".into(),
        mission.as_os_str().to_owned(),
        "--out".into(),
        out.as_os_str().to_owned(),
        "--quiet".into(),
    ];
    args.extend(extra.iter().map(Into::into));
    args
}

#[test]
fn a_run_directory_has_one_writer_at_a_time() {
    let dir = tempfile::tempdir().expect("tempdir");
    let hall = example("hall.toml");
    let out = dir.path().join("r");
    let stopped = cps_survey(run_args(&hall, &out, &["--sim-fault", "total-station:after=40"]));
    assert_eq!(stopped.code, 2, "{}", stopped.stderr);
    // Another process holds the directory (its lock, as a run writes it).
    let lock_path = out.join(".cps-survey.lock");
    let lock = std::fs::OpenOptions::new().write(true).open(&lock_path).expect("the run's lock file");
    lock.try_lock().expect("free once the run stopped");
    std::fs::write(&lock_path, "process 4242: run elsewhere.toml").expect("holder");
    let journal_before = std::fs::read(out.join("journal.jsonl")).expect("journal");
    for args in [
        run_args(&hall, &out, &["--resume"]),
        vec!["fuse".into(), out.clone().into_os_string()],
        vec!["adjust".into(), out.clone().into_os_string()],
    ] {
        let refused = cps_survey(args);
        assert_eq!(refused.code, 2, "{}", refused.stderr);
        assert!(
            refused.stderr.contains("is in use by another cps-survey (process 4242: run elsewhere.toml)"),
            "{}",
            refused.stderr
        );
    }
    assert_eq!(std::fs::read(out.join("journal.jsonl")).expect("journal"), journal_before, "nothing written");
    drop(lock);
    let resumed = cps_survey(run_args(&hall, &out, &["--resume"]));
    assert_eq!(resumed.code, 0, "{}", resumed.stderr);
}

#[test]
fn a_symbolic_link_in_the_run_directory_is_refused() {
    let dir = tempfile::tempdir().expect("tempdir");
    let mission = temp_mission(&std::fs::read_to_string(example("indoor-compact.toml")).expect("example"));
    let outside = dir.path().join("outside.txt");
    std::fs::write(&outside, "not the run's").expect("outside");
    let elsewhere = dir.path().join("elsewhere");
    std::fs::create_dir(&elsewhere).expect("elsewhere");
    for (name, target) in [("report.json", &outside), ("mission.toml", &outside), ("scans", &elsewhere)] {
        let out = dir.path().join(format!("out-{name}"));
        std::fs::create_dir(&out).expect("out");
        std::os::unix::fs::symlink(target, out.join(name)).expect("symlink");
        let run = cps_survey(run_args(&mission.path, &out, &[]));
        assert_eq!(run.code, 2, "{name}: {}", run.stderr);
        assert!(run.stderr.contains(&format!("{name} is a symbolic link")), "{}", run.stderr);
    }
    assert_eq!(std::fs::read_to_string(&outside).expect("outside"), "not the run's");
    assert_eq!(std::fs::read_dir(&elsewhere).expect("elsewhere").count(), 0, "nothing written through the link");
}

#[test]
fn a_journal_torn_inside_a_multi_byte_character_resumes() {
    let dir = tempfile::tempdir().expect("tempdir");
    let text = std::fs::read_to_string(example("indoor-compact.toml"))
        .expect("example")
        .edit("children = [\"left\", \"right\"]", "children = [\"gauche-é\", \"droite-ü\"]");
    assert!(text.contains("gauche-é"));
    let mission = temp_mission(&text);
    let out = dir.path().join("r");
    let stopped = cps_survey(run_args(&mission.path, &out, &["--sim-fault", "total-station:after=20"]));
    assert_eq!(stopped.code, 2, "{}", stopped.stderr);
    // A kill in the middle of writing "é" (0xC3 0xA9): only its first byte.
    let journal = out.join("journal.jsonl");
    let mut bytes = std::fs::read(&journal).expect("journal");
    let whole = bytes.len();
    bytes.extend_from_slice(b"{\"event\":\"drive\",\"key\":{\"robot\":\"gauche-\xC3");
    std::fs::write(&journal, &bytes).expect("torn");
    let resumed = cps_survey(run_args(&mission.path, &out, &["--resume"]));
    assert_eq!(resumed.code, 0, "{}", resumed.stderr);
    let after = std::fs::read(&journal).expect("journal");
    assert_eq!(after[..whole], bytes[..whole], "every line before the torn one kept");
    assert!(std::str::from_utf8(&after).is_ok(), "the torn bytes cut");
}

#[test]
fn outputs_that_cannot_be_written_are_refused_before_anything_is_measured() {
    let dir = tempfile::tempdir().expect("tempdir");
    let mission = example("indoor-compact.toml");
    // --out is a file.
    let file = dir.path().join("file");
    std::fs::write(&file, "mine").expect("write");
    let refused = cps_survey(run_args(&mission, &file, &[]));
    assert_eq!(refused.code, 2, "{}", refused.stderr);
    assert!(refused.stderr.contains("file: exists and is not a directory"), "{}", refused.stderr);
    assert_eq!(std::fs::read_to_string(&file).expect("kept"), "mine");
    // A cloud file's name is taken by a directory: refused before the
    // survey starts (no journal), not after it.
    let out = dir.path().join("r");
    std::fs::create_dir_all(out.join("cloud.ply")).expect("mkdir");
    let refused = cps_survey(run_args(&mission, &out, &[]));
    assert_eq!(refused.code, 2, "{}", refused.stderr);
    assert!(
        refused.stderr.contains("cloud.ply: exists and is not a file; the outputs write cloud.ply there"),
        "{}",
        refused.stderr
    );
    assert!(!out.join("journal.jsonl").exists(), "nothing measured");
    std::fs::remove_dir(out.join("cloud.ply")).expect("rmdir");
    let done = cps_survey(run_args(&mission, &out, &[]));
    assert_eq!(done.code, 0, "{}", done.stderr);
    // `fuse` checks its directory before it fuses.
    let fusion = out.join("fusion");
    std::fs::create_dir_all(&fusion).expect("mkdir");
    std::fs::write(fusion.join("icp"), "mine").expect("write");
    let refused = cps_survey(["fuse".into(), out.clone().into_os_string(), "--mode".into(), "icp".into()]);
    assert_eq!(refused.code, 2, "{}", refused.stderr);
    assert!(refused.stderr.contains("icp: exists and is not a directory"), "{}", refused.stderr);
    std::fs::create_dir_all(fusion.join("direct").join("fusion.json")).expect("mkdir");
    let refused = cps_survey(["fuse".into(), out.clone().into_os_string(), "--mode".into(), "direct".into()]);
    assert_eq!(refused.code, 2, "{}", refused.stderr);
    assert!(refused.stderr.contains("fusion.json: exists and is not a file"), "{}", refused.stderr);
    assert!(!fusion.join("direct").join("cloud.ply").exists(), "nothing fused");
}

/// Outputs are new files renamed over their names (issue 34, W1, W6, W7):
/// a hard-link snapshot of a run (`cp -al`) keeps its `adjustment.txt`
/// when `adjust` writes a new one, and a symbolic link where `match` or
/// `schemas --out` writes a document is replaced, its target untouched.
#[cfg(unix)]
#[test]
fn outputs_replace_their_files_never_write_through_links() {
    let dir = tempfile::tempdir().expect("tempdir");
    let hall = std::fs::read_to_string(tests::example("hall.toml")).expect("hall");
    let mission = dir.path().join("m.toml");
    std::fs::write(&mission, tests::hall_first_leg(&hall)).expect("mission");
    let out = dir.path().join("run");
    assert_eq!(tests::run_mission(&mission, &out).code, 0);
    let snapshot = dir.path().join("snapshot.txt");
    std::fs::hard_link(out.join("adjustment.txt"), &snapshot).expect("hard link");
    let before = std::fs::read_to_string(&snapshot).expect("snapshot");
    let run = tests::cps_survey(["adjust".into(), out.clone().into_os_string(), "--alpha".into(), "0.2".into()]);
    assert!(run.code <= 1, "{}", run.stderr);
    let after = std::fs::read_to_string(out.join("adjustment.txt")).expect("listing");
    assert_ne!(after, before, "adjust wrote a new listing (α = 0.2)");
    assert_eq!(std::fs::read_to_string(&snapshot).expect("snapshot"), before, "the snapshot kept its bytes");

    // schemas --out: a link where a schema goes.
    let victim = dir.path().join("victim.json");
    std::fs::write(&victim, "precious").expect("victim");
    let schemas = dir.path().join("schemas");
    std::fs::create_dir(&schemas).expect("dir");
    std::os::unix::fs::symlink(&victim, schemas.join("report.schema.json")).expect("link");
    let run = tests::cps_survey(["schemas".into(), "--out".into(), schemas.clone().into_os_string()]);
    assert_eq!(run.code, 0, "{}", run.stderr);
    assert_eq!(std::fs::read_to_string(&victim).expect("victim"), "precious");
    let written = schemas.join("report.schema.json");
    assert!(!std::fs::symlink_metadata(&written).expect("meta").file_type().is_symlink());

    // match --out: links where poses.json and links.csv go.
    let matched = dir.path().join("matched");
    std::fs::create_dir(&matched).expect("dir");
    for name in ["poses.json", "links.csv"] {
        std::os::unix::fs::symlink(&victim, matched.join(name)).expect("link");
    }
    let data = tests::workspace().join("data/3dtk_dat");
    let run =
        tests::cps_survey(["match".into(), data.into_os_string(), "--out".into(), matched.clone().into_os_string()]);
    assert_eq!(run.code, 0, "{}", run.stderr);
    assert_eq!(std::fs::read_to_string(&victim).expect("victim"), "precious");
    for name in ["poses.json", "links.csv"] {
        assert!(!std::fs::symlink_metadata(matched.join(name)).expect("meta").file_type().is_symlink(), "{name}");
    }
}

/// A new run into a directory that holds a run's outputs but no journal
/// (issue 34, W5: `report.json` and the rest were overwritten) is refused,
/// naming them, before anything is written.
#[test]
fn a_run_into_a_directory_of_others_outputs_is_refused() {
    let dir = tempfile::tempdir().expect("tempdir");
    let out = dir.path().join("d");
    std::fs::create_dir(&out).expect("dir");
    std::fs::write(out.join("report.json"), "precious").expect("report");
    std::fs::write(out.join("cloud.ply"), "precious").expect("cloud");
    let r = cps_survey(run_args(&example("hall.toml"), &out, &[]));
    assert_eq!(r.code, 2, "{}", r.stderr);
    assert!(r.stderr.contains("holds report.json, cloud.ply but no journal.jsonl"), "{}", r.stderr);
    assert_eq!(std::fs::read_to_string(out.join("report.json")).expect("kept"), "precious");
    assert_eq!(std::fs::read_dir(&out).expect("d").count(), 2, "nothing written");
}

/// The plan sights control through the scene the simulator measures in —
/// the built-in hall when the mission names none (issue 34, S14: K1 was
/// planned "seen from station 0 (152.1 m)", through the hall's wall, and
/// the run stopped after three retries: "blocked by 'hall'").
#[test]
fn control_the_plan_sees_is_what_the_simulator_sees() {
    let dir = tempfile::tempdir().expect("tempdir");
    let text = std::fs::read_to_string(example("paper-1km.toml"))
        .expect("example")
        .replacen(
            "route_m = [[0.0, 0.0, 0.0], [1000.0, 0.0, 0.0]]",
            "route_m = [[0.0, 0.0, 0.0], [200.0, 0.0, 0.0]]",
            1,
        )
        .replacen("[acceptance]", "control_at = \"every\"\n\n[acceptance]", 1)
        + "\n[[control]]\nname = \"K1\"\nposition_m = [150.0, 25.0, 1.2]\n";
    assert!(text.contains("[200.0, 0.0, 0.0]") && !text.contains("[backend]"), "the example changed");
    let mission = temp_mission(&text);
    let plan = cps_survey(["plan", mission.path.to_str().expect("utf-8"), "--json"]);
    let v: serde_json::Value = serde_json::from_str(&plan.stdout).expect("plan JSON");
    let seen: Vec<u64> = v["control"][0]["seen_from"]
        .as_array()
        .expect("seen_from")
        .iter()
        .map(|s| s["station"].as_u64().expect("station"))
        .collect();
    // Stations 0–3 (x ≤ 30 m) look through the hall (x 0–40 m).
    assert_eq!(seen.first(), Some(&4), "{seen:?}");
    let out = dir.path().join("r");
    let run = cps_survey(run_args(&mission.path, &out, &[]));
    assert_eq!(run.code, 0, "{}", run.stderr);
}

/// Data snooping's removals count wherever they are (issue 34): S1 — a
/// control coordinate given 2 cm off is removed and reported so (it was
/// "0 removal(s)", `removed: []`); S2 — the misclosures leave out what
/// snooping removed (a 0.5 m blunder, removed, still gave 21–55 mm
/// misclosures beside "model accepted").
#[test]
fn snooping_removals_are_reported_and_left_out_of_the_misclosures() {
    let dir = tempfile::tempdir().expect("tempdir");
    let hall = example("hall.toml");
    let json = |out: &std::path::Path, extra: &[&str]| -> serde_json::Value {
        let mut args = vec!["adjust", out.to_str().expect("utf-8"), "--json"];
        args.extend(extra);
        serde_json::from_str(&cps_survey(args).stdout).expect("adjust JSON")
    };
    let horizontal = |v: &serde_json::Value| -> Vec<f64> {
        v["misclosures"]
            .as_array()
            .expect("misclosures")
            .iter()
            .map(|m| m["horizontal_m"].as_f64().expect("m"))
            .collect()
    };
    // S2. A 0.5 m blunder is measured again in the field now (S7): it is
    // planted in the journal, as an instrument without that test records it.
    let blunder = dir.path().join("blunder");
    let run = cps_survey(run_args(&hall, &blunder, &[]));
    assert_eq!(run.code, 0, "{}", run.stderr);
    let journal = std::fs::read_to_string(blunder.join("journal.jsonl")).expect("journal");
    let mut lines: Vec<String> = journal.lines().map(String::from).collect();
    let k = lines.iter().position(|l| l.contains("\"phase\":\"fix\"")).expect("a fix reading");
    let mut event: serde_json::Value = serde_json::from_str(&lines[k]).expect("JSON");
    event["data"]["slope_raw_m"] = serde_json::json!(event["data"]["slope_raw_m"].as_f64().expect("distance") + 0.5);
    lines[k] = event.to_string();
    std::fs::write(blunder.join("journal.jsonl"), lines.join("\n") + "\n").expect("journal");
    let (snooped, plain) = (json(&blunder, &[]), json(&blunder, &["--no-snooping"]));
    assert!(!snooped["removed"].as_array().expect("removed").is_empty());
    let (with, without) = (horizontal(&snooped), horizontal(&plain));
    assert!(!with.is_empty() && with.iter().all(|m| *m < 0.01), "misclosures without the removed: {with:?}");
    assert!(without.iter().any(|m| *m > 0.015), "with the blunder: {without:?}");
    // S1.
    let off = dir.path().join("off");
    assert_eq!(cps_survey(run_args(&hall, &off, &[])).code, 0);
    let mission = off.join("mission.toml");
    let text = std::fs::read_to_string(&mission).expect("mission");
    assert!(text.contains("position_m = [39.9, 3.0, 1.2]"), "hall.toml's control point E1 moved");
    std::fs::write(&mission, text.edit("position_m = [39.9, 3.0, 1.2]", "position_m = [39.88, 3.0, 1.2]"))
        .expect("mission");
    let v = json(&off, &[]);
    let removed = v["removed_coordinates"].as_array().expect("removed_coordinates");
    assert_eq!(removed.len(), 1, "{v}");
    let c = &v["coordinate_observations"][removed[0].as_u64().expect("index") as usize];
    assert_eq!(
        (c["of"].as_str(), c["coordinate"].as_str(), c["removed"].as_bool()),
        (Some("E1"), Some("x"), Some(true))
    );
    let residual = c["residual"].as_f64().expect("residual");
    assert!((residual - 0.02).abs() < 0.005, "E1 x residual {residual} m: about the 2 cm it was given off");
    let listing = std::fs::read_to_string(off.join("adjustment.txt")).expect("listing");
    assert!(listing.contains("removed prior coordinate x of E1") && !listing.contains("nothing removed"), "{listing}");
    assert!(listing.contains("after snooping's 1 removal(s)"), "{listing}");
    // U2: one distance of 1000 m in the journal gave "degenerate geometry:
    // no observation determines the y of station 6" — named now.
    let journal = std::fs::read_to_string(off.join("journal.jsonl")).expect("journal");
    let mut lines: Vec<String> = journal.lines().map(String::from).collect();
    let k = lines.iter().position(|l| l.contains("\"phase\":\"fix\"")).expect("a fix reading");
    let mut event: serde_json::Value = serde_json::from_str(&lines[k]).expect("JSON");
    event["data"]["slope_raw_m"] = serde_json::json!(1000.0);
    lines[k] = event.to_string();
    std::fs::write(off.join("journal.jsonl"), lines.join("\n") + "\n").expect("journal");
    let r = cps_survey(["adjust", off.to_str().expect("utf-8")]);
    assert_eq!(r.code, 2, "{}", r.stderr);
    let want = format!("journal.jsonl:{}: the fix reading of child 0 in cycle 1 measures 1000.000 m", k + 1);
    assert!(r.stderr.contains(&want) && r.stderr.contains("a gross error"), "{want}: {}", r.stderr);
}

/// The hall's measurements in order (the simulator counts them for its
/// blunders): 1–2 the start's control points, 3–4 the first placements, 5–6
/// the first fix's (cycle 1: "ahead", "behind").
fn measure_events(out: &std::path::Path) -> Vec<serde_json::Value> {
    let journal = std::fs::read_to_string(out.join("journal.jsonl")).expect("journal");
    journal
        .lines()
        .map(|l| serde_json::from_str::<serde_json::Value>(l).expect("JSON"))
        .filter(|e| e["event"] == "measure")
        .collect()
}

#[test]
fn a_gross_blunder_is_measured_again_never_journaled_as_a_position() {
    // S7: one 10 m distance or a 10°–180° angle put the fix 1.8·10⁹ m away,
    // journaled it, then blamed the total station, and every --resume
    // replayed it.
    let dir = tempfile::tempdir().expect("tempdir");
    let hall = example("hall.toml");
    let report = |out: &std::path::Path| -> serde_json::Value {
        serde_json::from_str(&std::fs::read_to_string(out.join("report.json")).expect("report")).expect("JSON")
    };
    let worst_error = |r: &serde_json::Value| -> f64 {
        r["stations"].as_array().expect("stations").iter().filter_map(|s| s["error_xy_m"].as_f64()).fold(0.0, f64::max)
    };
    let clean = dir.path().join("clean");
    assert_eq!(cps_survey(run_args(&hall, &clean, &[])).code, 0);
    let clean_worst = worst_error(&report(&clean));
    // (fault, the reading measured again: phase, child; every reading of
    // that fix when two points cannot name one).
    let cases: [(&str, &str, &[u64]); 6] = [
        ("total-station:blunder=5:10", "fix", &[0, 1]),
        ("total-station:blunder=5:-10", "fix", &[0, 1]),
        ("total-station:blunder-angle=5:36000", "fix", &[0, 1]),
        ("total-station:blunder-angle=6:648000", "fix", &[0, 1]),
        ("total-station:blunder=3:10", "placement", &[0]),
        ("total-station:blunder-angle=4:-36000", "placement", &[1]),
    ];
    for (k, (fault, phase, children)) in cases.iter().enumerate() {
        let out = dir.path().join(format!("b{k}"));
        let run = cps_survey(run_args(&hall, &out, &["--sim-fault", fault]));
        assert_eq!(run.code, 0, "{fault}: {}", run.stderr);
        let again: Vec<(String, u64)> = measure_events(&out)
            .iter()
            .filter(|e| e["attempt"] == 1)
            .map(|e| (e["phase"].as_str().expect("phase").to_string(), e["child"].as_u64().expect("child")))
            .collect();
        let want: Vec<(String, u64)> = children.iter().map(|c| (phase.to_string(), *c)).collect();
        assert_eq!(again, want, "{fault}");
        let r = report(&out);
        assert_eq!(r["remeasured"].as_array().expect("remeasured").len(), children.len(), "{fault}: {r}");
        // The survey is as good as without the blunder (other noise draws
        // after it): within a few millimetres of the clean run's worst.
        let worst = worst_error(&r);
        assert!(worst < clean_worst + 0.003, "{fault}: worst station error {worst} m (clean {clean_worst} m)");
        assert!(run.stdout.contains("measured again:"), "{fault}: {}", run.stdout);
    }
    // Blundered again on each re-measurement of "ahead": the fix is refused,
    // nothing journaled as its position, the stop named; a resume measures
    // again and finishes.
    let out = dir.path().join("refused");
    let faults = ["total-station:blunder=5:10", "total-station:blunder=7:10", "total-station:blunder=9:10"];
    let mut args = vec![];
    for f in faults {
        args.extend(["--sim-fault", f]);
    }
    let run = cps_survey(run_args(&hall, &out, &args));
    assert_eq!(run.code, 2, "{}", run.stderr);
    assert!(
        run.stderr.contains("the parent's fix at station 1")
            && run.stderr.contains("also when measured again")
            && run.stderr.contains("--resume"),
        "{}",
        run.stderr
    );
    let journal = std::fs::read_to_string(out.join("journal.jsonl")).expect("journal");
    let last: serde_json::Value = serde_json::from_str(journal.lines().last().expect("lines")).expect("JSON");
    assert_eq!((last["event"].as_str(), last["device"].as_str()), (Some("stop"), Some("total-station")));
    assert!(!journal.lines().any(|l| l.contains("\"event\":\"fix\"") && l.contains("\"station\":1")));
    let resumed = cps_survey(run_args(&hall, &out, &["--resume"]));
    assert_eq!(resumed.code, 0, "{}", resumed.stderr);
    let attempts: Vec<u64> = measure_events(&out)
        .iter()
        .filter(|e| e["cycle"] == 1 && e["phase"] == "fix" && e["child"] == 0)
        .map(|e| e["attempt"].as_u64().unwrap_or(0))
        .collect();
    assert_eq!(attempts, [0, 1, 2, 3], "three in the first session, the fourth on resume");
    assert!(worst_error(&report(&out)) < clean_worst + 0.003);
}
