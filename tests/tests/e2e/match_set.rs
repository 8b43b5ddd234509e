//! `cps-survey match` end to end on the real scans in `data/`: the 3DTK set
//! from its odometry against the reference transforms, the PCL room scans
//! from their odometry guess, the outputs, and bad input.

use std::ffi::OsString;
use std::path::Path;

use nalgebra::{Isometry3, Matrix4, Point3, UnitQuaternion};
use serde_json::Value;
use tests::{Edit, cps_survey, workspace};

pub(super) fn data(rel: &str) -> OsString {
    workspace().join("data").join(rel).into_os_string()
}

pub(super) fn pose(v: &Value) -> Isometry3<f64> {
    let m: Vec<Vec<f64>> = serde_json::from_value(v.clone()).expect("4×4");
    rigid(&Matrix4::from_fn(|r, c| m[r][c]))
}

fn rigid(m: &Matrix4<f64>) -> Isometry3<f64> {
    Isometry3::from_parts(
        nalgebra::Translation3::from(m.fixed_view::<3, 1>(0, 3).into_owned()),
        nalgebra::Rotation3::from_matrix(&m.fixed_view::<3, 3>(0, 0).into_owned()).into(),
    )
}

/// (rotation error in degrees, translation error in metres).
fn error(estimate: &Isometry3<f64>, reference: &Isometry3<f64>) -> (f64, f64) {
    let d = reference.inverse() * estimate;
    (d.rotation.angle().to_degrees(), d.translation.vector.norm())
}

/// Asserts that every scan of a `match --json` report but the first lands
/// within `deg`° and `m` metres of its truth relative to the first.
fn assert_parts_land(label: &str, v: &Value, truths: &[Isometry3<f64>], deg: f64, m: f64) {
    let poses: Vec<Isometry3<f64>> =
        v["scans"].as_array().expect("scans").iter().map(|s| pose(&s["world_from_scan"])).collect();
    assert_eq!(poses.len(), truths.len(), "{label}: scans");
    for k in 1..poses.len() {
        let (d, t) = error(&(poses[0].inverse() * poses[k]), &(truths[0].inverse() * truths[k]));
        assert!(d < deg && t < m, "{label}: part {k} {d}° {t} m off; restart {}", v["restart"]);
    }
}

fn matrix_file(rel: &str) -> Matrix4<f64> {
    scanner::io::read_matrix4(Path::new(&data(rel))).expect("matrix")
}

/// `--init-poses` for the PCL room pair: room_scan2 at its odometry guess,
/// written into `dir`.
fn room_odometry(dir: &Path) -> std::path::PathBuf {
    let odometry = matrix_file("pcl_room_scans/odometry_T_scan1_scan2.txt");
    let init = dir.join("init.json");
    std::fs::write(&init, serde_json::json!([init_entry("room_scan2.pcd", &odometry)]).to_string())
        .expect("init poses");
    init
}

/// `cps-survey match ARGS --out OUT`, its text output.
fn run_text(args: &[OsString], out: &Path) -> tests::Run {
    let mut all: Vec<OsString> = vec!["match".into()];
    all.extend(args.iter().cloned());
    all.extend(["--out".into(), out.as_os_str().to_owned()]);
    cps_survey(all)
}

/// Runs the example mission `name` (with `edits` to its text, and no
/// `.rrd`) into `dir/run`: the run directory and how the run ended.
fn example_run(name: &str, edits: &[(&str, &str)], dir: &Path) -> (std::path::PathBuf, tests::Run) {
    let text = edits
        .iter()
        .fold(std::fs::read_to_string(tests::example(name)).expect("example"), |t, (from, to)| t.edit(from, to))
        .edit("[output]", "[output]\nrerun = false");
    let mission = tests::temp_mission(&text);
    let run_dir = dir.join("run");
    let done = tests::run_mission(&mission.path, &run_dir);
    (run_dir, done)
}

/// `cps-survey match ARGS --out OUT --json`, and its JSON.
fn run(args: &[OsString], out: &Path) -> (tests::Run, Option<Value>) {
    let mut args = args.to_vec();
    args.push("--json".into());
    let run = run_text(&args, out);
    let json = serde_json::from_str(&run.stdout).ok();
    (run, json)
}

/// `args` with the corner test off (`--corner-ratio 0`): the scenarios of
/// sessions 35–53 that exercise the restarts were found and measured
/// without it (the default until session 56); at the defaults their
/// schedules land, and the mechanism they test is not reached.
fn corners_off(args: &[OsString]) -> Vec<OsString> {
    let mut args = args.to_vec();
    args.extend(["--corner-ratio".into(), "0".into()]);
    args
}

/// `args` without the scanners' positions estimated from the scans'
/// spacing (`--no-viewpoint-estimate`): the bench's PLY parts tested as
/// they were before session 67, without free space — for the tests of
/// what sets the restarts off and keeps them, which the free space of the
/// estimated scanners would pre-empt (each of them also lands at the
/// defaults).
fn without_estimates(args: &[OsString]) -> Vec<OsString> {
    let mut args = args.to_vec();
    args.push("--no-viewpoint-estimate".into());
    args
}

/// At the defaults (the corner test at 0.1) the scans `args` name land
/// within `deg`° / `m` metres of `truths`, exit 0, none named; returns
/// the JSON report.
fn lands_at_the_defaults(
    label: &str,
    args: &[OsString],
    out: &Path,
    truths: &[Isometry3<f64>],
    deg: f64,
    m: f64,
) -> Value {
    let (r, v) = run(args, out);
    let v = v.unwrap_or_else(|| panic!("{label}: {}", r.stderr));
    assert_eq!(r.code, 0, "{label}: {}\n{}", r.stdout, r.stderr);
    assert_eq!(v["untrusted"], serde_json::json!([]), "{label}: {}", v["restart"]);
    assert!(v["settings"]["corner_ratio"].as_f64().is_some_and(|r| (r - 0.1).abs() < 1e-12), "{}", v["settings"]);
    assert_parts_land(label, &v, truths, deg, m);
    v
}

#[test]
fn the_3dtk_set_lands_on_the_references_from_its_odometry() {
    let dir = tempfile::tempdir().expect("temp dir");
    let out = dir.path().join("out");
    let (run, v) = run(&[data("3dtk_dat"), "--formats".into(), "ply,las".into()], &out);
    assert_eq!(run.code, 0, "{}", run.stderr);
    let v = v.expect("one JSON object");
    assert_eq!(v["schema_version"], 1);
    assert_eq!(v["mode"], "graph");
    let scans = v["scans"].as_array().expect("scans");
    assert_eq!(scans.len(), 3);
    let poses: Vec<Isometry3<f64>> = scans.iter().map(|s| pose(&s["world_from_scan"])).collect();
    assert_eq!(poses[0], Isometry3::identity(), "scan000's pose (identity) is the frame");
    for (a, b) in [(0, 1), (1, 2)] {
        let reference =
            scanner::io::from_3dtk_axes(&matrix_file(&format!("3dtk_dat/reference_T_scan{a:03}_scan{b:03}.txt")));
        let (deg, m) = error(&(poses[a].inverse() * poses[b]), &reference);
        assert!(deg < 0.35 && m < 0.03, "{a}←{b}: {deg}° {m} m off the reference");
    }
    for s in scans {
        assert!(s["degenerate_directions"].as_array().expect("list").is_empty(), "{s}");
        assert_eq!(s["covariance"].as_array().expect("6×6").len(), 6);
        // Graph mode's poses are the adjustment: no departure from it.
        assert!(s["departure"].is_null(), "{s}");
    }
    // Verified: every pair matched again from the final poses agrees
    // (within 2.3 % of the scans' radius; issue 38).
    assert_eq!(v["untrusted"], serde_json::json!([]), "{}", v["checks"]);
    assert_eq!(v["checks"].as_array().map(Vec::len), Some(3), "{}", v["checks"]);
    // Each stage as it ran: its runs, and the restart's, add up to the
    // matches. (The set's three links disagree more than their covariances
    // allow — the variance factor is about 100 —, which sets off the
    // restart without the first stage; it lands in a nearby fit the scans
    // agree with no better, and the schedule's poses stay.)
    let stages = v["stages"].as_array().expect("stages");
    assert_eq!(stages.len(), 4, "{stages:?}");
    assert_eq!(v["restart"]["trigger"], "disagreeing", "{}", v["restart"]);
    assert_eq!(v["restart"]["kept"], false, "{}", v["restart"]);
    let restart = v["restart"]["stages"].as_array().expect("the restart's stages");
    assert_eq!(restart.len(), 3, "{restart:?}");
    // Every ICP run is accounted for, a further restart's too (none runs
    // here: the result is trusted, and the scans agree 0.9993× as much as
    // at the odometry's poses — the criterion's edge, so not asserted).
    let further = v["restart"]["further"].as_array().expect("further restarts");
    assert!(further.iter().all(|f| f["kept"] == false), "{}", v["restart"]);
    let further_stages = further.iter().flat_map(|f| f["stages"].as_array().expect("stages"));
    let runs: u64 =
        stages.iter().chain(restart).chain(further_stages).map(|s| s["matches"].as_u64().expect("runs")).sum();
    assert_eq!(Some(runs), v["matches"].as_u64());
    assert!(stages.iter().all(|s| s["seconds"].as_f64().is_some_and(|t| t > 0.0) && s["settled"] == true));
    let links = v["links"].as_array().expect("links");
    assert_eq!(links.len(), 3, "every pair of the three overlaps");
    assert!(links.iter().all(|l| l["accepted"] == true && l["rmse_m"].as_f64().expect("rmse") < 0.1), "{links:?}");
    // The three links are one lone cycle, which misses by 2.1° (the 3DTK
    // set's references agree with the adjustment to 0.35°): which link is
    // wrong no test can tell, so all are kept and the cycle is named once,
    // on the link that disagrees most (its χ² beyond the gate).
    let named: Vec<&Value> = links.iter().filter(|l| l["cycle"].is_object()).collect();
    assert_eq!(named.len(), 1, "{links:?}");
    let cycle = &named[0]["cycle"];
    assert_eq!(cycle["scans"].as_array().map(Vec::len), Some(3), "{cycle}");
    let miss = cycle["angle_deg"].as_f64().expect("angle");
    assert!((1.0..4.0).contains(&miss), "{cycle}");
    // The noise calibration: the halves' factors carried on by their step
    // from the quarters', between 1 and 2.
    let noise = &v["noise"];
    for key in ["variance_scale", "range_scale", "rotation_scale", "translation_scale"] {
        let (h, q) =
            (noise["halves"][key].as_f64().expect("halves"), noise["quarters"][key].as_f64().expect("quarters"));
        let carried = h * (h / q).clamp(1.0, 2.0);
        assert!((noise[key].as_f64().expect(key) - carried).abs() < 1e-12 * carried, "{key}: {noise}");
    }
    // Three scans: four halvings each, as many as bring the halves toward
    // 96 degrees of freedom (`fusion::noise::halvings`).
    assert_eq!(noise["halvings"], noise["halves"]["matched"], "{noise}");
    assert_eq!((noise["halvings"].as_u64(), noise["quarters"]["matched"].as_u64()), (Some(12), Some(12)), "{noise}");
    let text = cps_survey([OsString::from("match"), data("3dtk_dat"), "--out".into(), dir.path().join("text").into()]);
    assert_eq!(text.code, 0, "{}", text.stderr);
    assert!(text.stdout.contains("covariances calibrated on the scans' halves and quarters: ×"), "{}", text.stdout);
    let kept: Vec<&str> = text.stdout.lines().filter(|l| l.trim_start().starts_with("kept ")).collect();
    assert_eq!(kept.len(), 1, "{}", text.stdout);
    assert!(kept[0].contains("no other cycle tells which of its links is wrong"), "{}", kept[0]);
    // The outputs: poses.json is the JSON printed; the frames are the poses
    // (3DTK axes, cm); the cloud holds every point once; the link table.
    let saved: Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("poses.json")).expect("poses.json")).expect("JSON");
    assert_eq!(saved["scans"], v["scans"]);
    for (k, p) in poses.iter().enumerate() {
        let frames = scanner::io::read_3dtk_frames(&out.join(format!("frames/scan{k:03}.frames"))).expect("frames");
        let (deg, m) = error(&frames, p);
        assert!(deg < 1e-6 && m < 1e-6, "scan{k:03}.frames: {deg}° {m} m from poses.json");
    }
    let cloud = scanner::io::read(&out.join("cloud.las")).expect("LAS");
    let points: usize = (0..3)
        .map(|k| scanner::io::read(Path::new(&data(&format!("3dtk_dat/scan{k:03}.3d")))).expect("scan").len())
        .sum();
    assert_eq!(cloud.len(), points);
    assert_eq!(scanner::io::read(&out.join("cloud.ply")).expect("PLY").len(), points);
    let csv = std::fs::read_to_string(out.join("links.csv")).expect("links.csv");
    assert_eq!(csv.lines().count(), 4, "{csv}");
    assert!(csv.starts_with("source,targets,overlap,correspondences,rmse_m,converged,accepted,reason"));
    assert!(out.join("match.rrd").metadata().expect("match.rrd").len() > 1000);
}

#[test]
fn the_room_scans_land_on_the_reference_from_their_odometry_guess() {
    let dir = tempfile::tempdir().expect("temp dir");
    let init = room_odometry(dir.path());
    let (run, v) = run(
        &[
            data("pcl_room_scans/room_scan1.pcd"),
            data("pcl_room_scans/room_scan2.pcd"),
            "--init-poses".into(),
            init.into_os_string(),
        ],
        &dir.path().join("out"),
    );
    assert_eq!(run.code, 0, "{}", run.stderr);
    let v = v.expect("JSON");
    let reference = rigid(&matrix_file("pcl_room_scans/reference_T_scan1_scan2.txt"));
    let poses: Vec<Isometry3<f64>> =
        v["scans"].as_array().expect("scans").iter().map(|s| pose(&s["world_from_scan"])).collect();
    let (deg, m) = error(&(poses[0].inverse() * poses[1]), &reference);
    assert!(deg < 0.3 && m < 0.02, "{deg}° {m} m off the reference");
    // Without `--joint-covariance`, no joint covariance — but the verified
    // pair's relative σ.
    assert!(v["joint_covariance"].is_null(), "{}", v["joint_covariance"]);
    let check = &v["checks"][0];
    assert!(check["relative_sigma_xyz_m"].as_f64().is_some_and(|m| m > 0.0 && m < 0.01), "{check}");
}

/// `--joint-covariance`: the 3DTK set's poses' 18×18 joint covariance in
/// graph mode and in two modes without a link graph (there with the
/// stacked departures, whole in pairwise mode and as far as they exceed
/// the adjustment's noise in incremental mode, `departure_weight`) —
/// symmetric, positive semi-definite, each scan's own
/// covariance its diagonal block, the first scan's rows zero, and what two
/// poses share off it: each checked pair's relative covariance
/// Cᵢ + Cⱼ − Cᵢⱼ − Cⱼᵢ positive semi-definite and not Cᵢ + Cⱼ. (Its
/// numbers rest on the adjustment's, checked by Monte Carlo in
/// `fusion::links`' tests.)
#[test]
fn the_joint_covariance_holds_each_poses_own_and_what_two_share() {
    use nalgebra::{DMatrix, Matrix6};
    let dir = tempfile::tempdir().expect("temp dir");
    for mode in ["graph", "pairwise", "incremental"] {
        let (run, v) =
            run(&[data("3dtk_dat"), "--mode".into(), mode.into(), "--joint-covariance".into()], &dir.path().join(mode));
        assert_eq!(run.code, 0, "{mode}: {}", run.stderr);
        let v = v.expect("JSON");
        // The share of the departures' ξξᵀ carried: none in graph mode
        // (its poses are the adjustment), whole in pairwise mode, in
        // incremental mode as far as they exceed the adjustment's noise.
        let weight = v["departure_weight"].as_f64();
        match mode {
            "graph" => assert!(v["departure_weight"].is_null(), "{}", v["departure_weight"]),
            "pairwise" => assert_eq!(weight, Some(1.0)),
            _ => assert!(weight.is_some_and(|w| (0.0..1.0).contains(&w)), "{mode}: {weight:?}"),
        }
        let rows: Vec<Vec<f64>> = serde_json::from_value(v["joint_covariance"].clone()).expect("rows of numbers");
        assert_eq!(rows.len(), 18, "{mode}");
        assert!(rows.iter().all(|r| r.len() == 18), "{mode}");
        let joint = DMatrix::from_fn(18, 18, |r, c| rows[r][c]);
        let block = |i: usize, j: usize| Matrix6::from_fn(|r, c| joint[(6 * i + r, 6 * j + c)]);
        let largest = joint.amax();
        assert!(largest > 0.0, "{mode}");
        assert!((&joint - joint.transpose()).amax() <= 1e-12 * largest, "{mode}: not symmetric");
        let least = joint.clone().symmetric_eigen().eigenvalues.min();
        assert!(least >= -1e-12 * largest, "{mode}: eigenvalue {least:e} of {largest:e}");
        assert!(joint.rows(0, 6).iter().all(|x| *x == 0.0), "{mode}: the first scan holds the frame");
        for (i, s) in v["scans"].as_array().expect("scans").iter().enumerate() {
            let own: Vec<Vec<f64>> = serde_json::from_value(s["covariance"].clone()).expect("6×6");
            assert_eq!(block(i, i), Matrix6::from_fn(|r, c| own[r][c]), "{mode}: scan {i}");
            // Less w·ξξᵀ, the adjustment's: positive semi-definite.
            if let Some(w) = weight {
                let d: Vec<f64> = serde_json::from_value(s["departure"].clone()).expect("a departure");
                let d = nalgebra::Vector6::from_column_slice(&d);
                let adjustment = block(i, i) - w * d * d.transpose();
                let least = adjustment.symmetric_eigen().eigenvalues.min();
                assert!(least >= -1e-12 * largest, "{mode}: scan {i}'s adjustment, eigenvalue {least:e}");
            }
        }
        let (one, two) = (block(1, 1), block(2, 2));
        let relative = one + two - block(1, 2) - block(2, 1);
        let least = relative.symmetric_eigen().eigenvalues.min();
        assert!(least >= -1e-12 * relative.amax(), "{mode}: the relative covariance's eigenvalue {least:e}");
        assert!((relative - (one + two)).amax() > 1e-3 * (one + two).amax(), "{mode}: scans 1 and 2 share nothing");
        // Each verified pair's relative σ (`checks[]`, with or without
        // the flag) is that of this relative covariance: its rotation, and
        // the displacement it gives the source scan's origin (ω × p + v,
        // p from the first scan's origin).
        let poses: Vec<Isometry3<f64>> =
            v["scans"].as_array().expect("scans").iter().map(|s| pose(&s["world_from_scan"])).collect();
        for c in v["checks"].as_array().expect("checks") {
            let (a, b) = (c["source"].as_u64().expect("index") as usize, c["target"].as_u64().expect("index") as usize);
            let r = block(a, a) + block(b, b) - block(a, b) - block(b, a);
            let p = poses[a].translation.vector - poses[0].translation.vector;
            let at = nalgebra::Matrix3x6::from_fn(|i, k| match k {
                0..3 => nalgebra::Vector3::ith(k, 1.0).cross(&p)[i],
                _ => f64::from(u8::from(i == k - 3)),
            });
            let (xyz, rot) = ((at * r * at.transpose()).trace().sqrt(), (r[(0, 0)] + r[(1, 1)] + r[(2, 2)]).sqrt());
            let (m, deg) =
                (c["relative_sigma_xyz_m"].as_f64().expect("σ"), c["relative_sigma_rot_deg"].as_f64().expect("σ"));
            assert!((m - xyz).abs() <= 1e-9 * m && m > 0.0, "{mode}: {c}");
            assert!((deg - rot.to_degrees()).abs() <= 1e-9 * deg && deg > 0.0, "{mode}: {c}");
        }
    }
}

#[test]
fn bad_input_is_named_and_exits_2() {
    let dir = tempfile::tempdir().expect("temp dir");
    let out = dir.path().join("out");
    let expect = |args: Vec<OsString>, wanted: &[&str]| {
        let (run, _) = run(&args, &out);
        assert_eq!(run.code, 2, "{args:?}: {}", run.stderr);
        for w in wanted {
            assert!(run.stderr.contains(w), "{args:?}: expected \"{w}\" in {}", run.stderr);
        }
    };
    // A directory without scans.
    let empty = dir.path().join("empty");
    std::fs::create_dir(&empty).expect("dir");
    expect(vec![empty.clone().into_os_string()], &["no 3DTK scans (scanNNN.3d)"]);
    // .3d and .pose files that do not pair up.
    let mismatched = dir.path().join("mismatched");
    std::fs::create_dir(&mismatched).expect("dir");
    for f in ["scan000.3d", "scan000.pose", "scan001.3d", "scan002.pose"] {
        let from = if f.ends_with(".3d") { "3dtk_dat/scan000.3d" } else { "3dtk_dat/scan000.pose" };
        std::fs::copy(Path::new(&data(from)), mismatched.join(f)).expect("copy");
    }
    expect(vec![mismatched.into_os_string()], &["no pose for scan001.3d", "no scan for scan002.pose"]);
    // A scan with too few points.
    let few = dir.path().join("few.xyz");
    std::fs::write(&few, "1 0 0\n0 1 0\n0 0 1\n").expect("xyz");
    expect(
        vec![data("pcl_room_scans/room_scan1.pcd"), few.clone().into_os_string()],
        &["few.xyz", "3 points", "expected more than 250"],
    );
    // Init poses: scans that do not overlap at their starts (the pair is
    // named), a pose that is not rigid, a scan that is not there.
    let init_case = |name: &str, json: &str, wanted: &[&str]| {
        let file = dir.path().join(name);
        std::fs::write(&file, json).expect("init poses");
        let rooms = [data("pcl_room_scans/room_scan1.pcd"), data("pcl_room_scans/room_scan2.pcd")];
        expect([&rooms[..], &["--init-poses".into(), file.into_os_string()]].concat(), wanted);
    };
    init_case(
        "twice.json",
        r#"[{"file": "room_scan2.pcd", "world_from_scan": [[1,0,0,0],[0,1,0,0],[0,0,1,0],[0,0,0,1]]},
            {"file": "room_scan2.pcd", "world_from_scan": [[1,0,0,9],[0,1,0,0],[0,0,1,0],[0,0,0,1]]}]"#,
        &["twice.json", "entries 0 and 1 both give the pose of", "room_scan2.pcd", "one entry per scan"],
    );
    expect(
        vec![data("3dtk_dat"), "--formats".into(), "ply,las,ply".into()],
        &["--formats ply,las,ply", "ply is listed twice"],
    );
    init_case(
        "far.json",
        r#"[{"file": "room_scan2.pcd", "world_from_scan": [[1,0,0,500],[0,1,0,0],[0,0,1,0],[0,0,0,1]]}]"#,
        &["room_scan2.pcd and", "room_scan1.pcd do not overlap"],
    );
    init_case(
        "sheared.json",
        r#"[{"file": "room_scan2.pcd", "world_from_scan": [[1,0.2,0,0],[0,1,0,0],[0,0,1,0],[0,0,0,1]]}]"#,
        &["sheared.json", "entry 0", "room_scan2.pcd", "not a rotation"],
    );
    init_case(
        "stray.json",
        r#"[{"file": "room_scan3.pcd", "world_from_scan": [[1,0,0,0],[0,1,0,0],[0,0,1,0],[0,0,0,1]]}]"#,
        &["stray.json", "room_scan3.pcd", "not among the scans"],
    );
    // A missing file, and one scan alone.
    expect(vec![dir.path().join("missing.ply").into_os_string()], &["missing.ply"]);
    expect(vec![data("pcl_room_scans/room_scan1.pcd")], &["one scan: expected at least two"]);
    assert!(!out.exists(), "nothing written for input refused");
}

/// A scan that no link reaches at the last stage (here: a last stage of
/// 1 mm, which no pair of real scans meets) keeps the coarser stages'
/// registration, is blind in every direction, the text names it, and the
/// exit is 1.
#[test]
fn a_scan_without_links_is_reported() {
    let dir = tempfile::tempdir().expect("temp dir");
    let init = room_odometry(dir.path());
    let mut args: Vec<OsString> = vec![
        "match".into(),
        data("pcl_room_scans/room_scan1.pcd"),
        data("pcl_room_scans/room_scan2.pcd"),
        "--init-poses".into(),
        init.into_os_string(),
        "--schedule".into(),
        "0.5/2,0.25/1,0.1/0.001".into(),
        "--out".into(),
        dir.path().join("text").into_os_string(),
    ];
    // Its outputs are written, and the exit says the result is not trusted.
    let text = cps_survey(args.clone());
    assert_eq!(text.code, 1, "{}", text.stderr);
    assert!(text.stdout.contains("not trusted: room_scan2 has no accepted link at the last stage"), "{}", text.stdout);
    assert!(dir.path().join("text/poses.json").is_file());
    args.truncate(args.len() - 1);
    args.extend([dir.path().join("json").into_os_string(), "--json".into()]);
    let run = cps_survey(args);
    assert_eq!(run.code, 1);
    let v: Value = serde_json::from_str(&run.stdout).expect("JSON");
    assert_eq!(v["links"].as_array().map(Vec::len), Some(0));
    assert_eq!(v["scans"][1]["degenerate_directions"].as_array().map(Vec::len), Some(6));
    // The coarse stages' registration is kept (the odometry guess is 0.69 m off).
    let reference = rigid(&matrix_file("pcl_room_scans/reference_T_scan1_scan2.txt"));
    let (deg, m) = error(&pose(&v["scans"][1]["world_from_scan"]), &reference);
    assert!(deg < 0.5 && m < 0.05, "{deg}° {m} m");
}

/// A multi-scan E57 (here the one `match` writes: each scan in its own
/// frame with its registered pose) is a scan set whose poses are the
/// start: matched again it stays where it is, every scan named by its
/// `data3D`.
#[test]
fn a_multi_scan_e57_starts_from_its_poses() {
    let dir = tempfile::tempdir().expect("temp dir");
    let first = dir.path().join("first");
    let (run1, v1) = run(&[data("3dtk_dat"), "--formats".into(), "e57".into()], &first);
    assert_eq!(run1.code, 0, "{}", run1.stderr);
    let e57 = first.join("cloud.e57");
    let scans = scanner::io::read_e57_scans(&e57).expect("E57");
    assert_eq!(scans.iter().map(|s| s.name.as_str()).collect::<Vec<_>>(), ["scan000", "scan001", "scan002"]);
    let (run2, v2) = run(&[e57.into_os_string()], &dir.path().join("second"));
    assert_eq!(run2.code, 0, "{}", run2.stderr);
    let (v1, v2) = (v1.expect("JSON"), v2.expect("JSON"));
    let files: Vec<&str> =
        v2["scans"].as_array().expect("scans").iter().map(|s| s["file"].as_str().expect("file")).collect();
    assert!(files[1].ends_with("cloud.e57#scan001"), "{files:?}");
    for k in 0..3 {
        let (a, b) = (pose(&v1["scans"][k]["world_from_scan"]), pose(&v2["scans"][k]["world_from_scan"]));
        let (deg, m) = error(&b, &a);
        assert!(deg < 0.01 && m < 0.001, "scan {k}: moved {deg}° {m} m from where the E57 put it");
    }
}

/// The WKT in a LAS file's CRS record.
fn las_wkt(path: &Path) -> String {
    let header = las::Reader::from_path(path).expect("LAS").header().clone();
    let vlr = header.all_vlrs().find(|v| v.user_id == "LASF_Projection" && v.record_id == 2112).expect("WKT VLR");
    assert!(header.has_wkt_crs(), "{}: global encoding's WKT bit", path.display());
    String::from_utf8_lossy(&vlr.data).trim_end_matches('\0').to_string()
}

/// `match` writes a CRS in every output (LAS 1.4 requires one): `--crs`,
/// else the one a georeferenced E57 names in its coordinateMetadata, else
/// a local frame; a CRS the tool cannot honour is refused naming its source.
#[test]
fn match_writes_the_crs_it_was_given_or_the_e57s() {
    let dir = tempfile::tempdir().expect("temp dir");
    let local = dir.path().join("local");
    let (r, v) = run(&[data("3dtk_dat"), "--formats".into(), "las".into()], &local);
    assert_eq!(r.code, 0, "{}", r.stderr);
    let crs = &v.expect("JSON")["crs"];
    assert_eq!((crs["local"].as_bool(), crs["epsg"].is_null()), (Some(true), true), "{crs}");
    assert!(las_wkt(&local.join("cloud.las")).starts_with("LOCAL_CS[\"cps-survey match local frame\""));

    let given = dir.path().join("given");
    let args = [data("3dtk_dat"), "--formats".into(), "las,e57".into(), "--crs".into(), "EPSG:25832".into()];
    let (r, v) = run(&args, &given);
    assert_eq!(r.code, 0, "{}", r.stderr);
    let v = v.expect("JSON");
    assert_eq!((v["crs"]["name"].as_str(), v["crs"]["epsg"].as_u64()), (Some("EPSG:25832"), Some(25832)));
    let wkt = v["crs"]["wkt"].as_str().expect("wkt").to_string();
    assert_eq!(las_wkt(&given.join("cloud.las")), wkt);
    let e57 = given.join("cloud.e57");
    assert_eq!(scanner::io::read_e57_crs(&e57).expect("E57").as_deref(), Some(wkt.as_str()));

    // The E57 names its CRS: matched again without --crs, the outputs keep it.
    let again = dir.path().join("again");
    let (r, v) = run(&[e57.clone().into_os_string(), "--formats".into(), "las".into()], &again);
    assert_eq!(r.code, 0, "{}", r.stderr);
    assert_eq!(v.expect("JSON")["crs"]["epsg"].as_u64(), Some(25832));
    assert_eq!(las_wkt(&again.join("cloud.las")), wkt);

    // Refused: a CRS in feet, naming the option.
    let (r, _) = run(&[data("3dtk_dat"), "--crs".into(), "EPSG:2263".into()], &dir.path().join("feet"));
    assert_eq!(r.code, 2);
    assert!(r.stderr.contains("--crs: EPSG:2263 has its coordinates in US survey foot"), "{}", r.stderr);
}

/// `match` keeps what came in: each scan's own number (3DTK `scanNNN`; the
/// set's scan001 and scan002, numbered 1 and 2 where the input order
/// would say 0 and 1) in
/// LAS `point_source_id` and `poses.json`, its name in E57 and the frames
/// files — also when its E57 is matched again — and the inputs'
/// intensities (the small_gicp frames' 0–215; they came out 0).
#[test]
fn match_keeps_the_inputs_scan_numbers_names_and_intensities() {
    let dir = tempfile::tempdir().expect("temp dir");
    let set = dir.path().join("set");
    std::fs::create_dir_all(&set).expect("set");
    for k in ["001", "002"] {
        for ext in ["3d", "pose"] {
            let name = format!("scan{k}.{ext}");
            std::fs::copy(workspace().join("data/3dtk_dat").join(&name), set.join(&name)).expect("copy");
        }
    }
    let first = dir.path().join("first");
    let (r, v) = run(&[set.into_os_string(), "--formats".into(), "las,e57".into()], &first);
    assert_eq!(r.code, 0, "{}", r.stderr);
    let numbers = |v: &Value, key: &str| -> Vec<Value> {
        v["scans"].as_array().expect("scans").iter().map(|s| s[key].clone()).collect()
    };
    let v = v.expect("JSON");
    assert_eq!(numbers(&v, "number"), [serde_json::json!(1), serde_json::json!(2)]);
    assert_eq!(numbers(&v, "name"), [serde_json::json!("scan001"), serde_json::json!("scan002")]);
    let ids: std::collections::BTreeSet<u16> =
        las_points(&first.join("cloud.las")).iter().map(|p| p.point_source_id).collect();
    assert_eq!(ids.into_iter().collect::<Vec<_>>(), [1, 2]);
    let e57 = first.join("cloud.e57");
    let names: Vec<String> = scanner::io::read_e57_scans(&e57).expect("E57").into_iter().map(|s| s.name).collect();
    assert_eq!(names, ["scan001", "scan002"]);
    assert!(first.join("frames/scan002.frames").is_file());
    let (r, v) = run(&[e57.into_os_string()], &dir.path().join("again"));
    assert_eq!(r.code, 0, "{}", r.stderr);
    assert_eq!(numbers(&v.expect("JSON"), "number"), [serde_json::json!(1), serde_json::json!(2)]);

    // Intensities through LAS and E57, and E57 matched again.
    let pair = dir.path().join("pair");
    let inputs = [data("small_gicp_pair/target.ply"), data("small_gicp_pair/source.ply")];
    let mut args = inputs.to_vec();
    args.extend(["--formats".into(), "las,e57".into()]);
    let (r, _) = run(&args, &pair);
    assert_eq!(r.code, 0, "{}", r.stderr);
    let mut want: Vec<u16> = inputs
        .iter()
        .flat_map(|f| scanner::io::read(Path::new(f)).expect("PLY").intensity.expect("intensity"))
        .map(|v| v as u16)
        .collect();
    want.sort_unstable();
    assert_eq!(want.last(), Some(&215));
    let las_intensities = |path: &Path| {
        let mut got: Vec<u16> = las_points(path).iter().map(|p| p.intensity).collect();
        got.sort_unstable();
        got
    };
    assert_eq!(las_intensities(&pair.join("cloud.las")), want, "LAS intensities against the inputs'");
    let again = dir.path().join("pair-again");
    let (r, _) = run(&[pair.join("cloud.e57").into_os_string(), "--formats".into(), "las".into()], &again);
    assert_eq!(r.code, 0, "{}", r.stderr);
    assert_eq!(las_intensities(&again.join("cloud.las")), want, "through E57 and back");
}

/// The 3DTK set as PLY in `set`, each scan's points scaled by `factor` and
/// moved by `shift` in its own frame, with `--init-poses` from its
/// odometry scaled and moved alike (the same world): the inputs and the
/// flag.
fn three_dtk_copy(set: &Path, factor: f64, shift: nalgebra::Vector3<f64>) -> Vec<OsString> {
    std::fs::create_dir_all(set).expect("set");
    let mut entries = Vec::new();
    let mut inputs = Vec::new();
    for k in 0..3 {
        let name = format!("scan{k:03}");
        let mut cloud = scanner::io::read(Path::new(&data(&format!("3dtk_dat/{name}.3d")))).expect("scan");
        let s = shift.cast::<f32>();
        cloud.points.iter_mut().for_each(|p| *p = Point3::from(p.coords * factor as f32 + s));
        let path = set.join(format!("{name}.ply"));
        scanner::io::write(&path, &cloud, scanner::io::Format::Ply(scanner::io::PlyEncoding::BinaryLittleEndian))
            .expect("PLY");
        let mut pose = scanner::io::read_3dtk_pose(Path::new(&data(&format!("3dtk_dat/{name}.pose")))).expect("pose");
        pose.translation.vector *= factor;
        entries
            .push(init_entry(&format!("{name}.ply"), &(pose * nalgebra::Translation3::from(-shift)).to_homogeneous()));
        inputs.push(path.into_os_string());
    }
    let init = set.join("init.json");
    std::fs::write(&init, serde_json::to_string(&entries).expect("JSON")).expect("init");
    inputs.extend(["--init-poses".into(), init.into_os_string()]);
    inputs
}

/// The 3DTK set at 1:100 and at 100:1 (scans as PLY, starts from the
/// odometry scaled): `--schedule auto` scales the recipe with the scans, so
/// each copy lands on the scaled reference to the same relative accuracy.
#[test]
fn a_scaled_copy_of_the_3dtk_set_registers_alike_with_the_auto_schedule() {
    let dir = tempfile::tempdir().expect("temp dir");
    let mut errors = Vec::new();
    let mut matches: Vec<(&str, Vec<u64>)> = Vec::new();
    for factor in [0.01f64, 1.0, 100.0] {
        let set = dir.path().join(format!("x{factor}"));
        let mut args = three_dtk_copy(&set, factor, nalgebra::Vector3::zeros());
        args.extend(["--schedule".into(), "auto".into()]);
        // Every other mode too: the same number of matches at every scale
        // (simultaneous's queue re-queued on a fixed 1 cm, chasing noise at
        // 100:1 into a set its verification refused, exit 1).
        for mode in ["pairwise", "incremental", "simultaneous"] {
            let mut a = args.clone();
            a.extend(["--mode".into(), mode.into()]);
            let (r, v) = run(&a, &set.join(format!("out-{mode}")));
            assert_eq!(r.code, 0, "×{factor} {mode}: {}", r.stderr);
            let v = v.expect("JSON");
            assert_eq!(v["untrusted"], serde_json::json!([]), "×{factor} {mode}: {}", v["checks"]);
            let runs: Vec<u64> =
                v["stages"].as_array().expect("stages").iter().map(|s| s["matches"].as_u64().expect("runs")).collect();
            match matches.iter().find(|(m, _)| *m == mode) {
                // (Within a couple: a borderline "moved" may tip either
                // way in floating point at another scale.)
                Some((_, first)) => assert!(
                    runs.len() == first.len() && runs.iter().zip(first).all(|(a, b)| a.abs_diff(*b) <= 2.max(b / 10)),
                    "×{factor} {mode}: runs per stage {runs:?} against {first:?}"
                ),
                None => matches.push((mode, runs)),
            }
        }
        let (r, v) = run(&args, &set.join("out"));
        assert_eq!(r.code, 0, "×{factor}: {}", r.stderr);
        let v = v.expect("JSON");
        let radius = v["settings"]["radius_m"].as_f64().expect("radius");
        assert!((radius / factor - 5.46).abs() < 0.05, "×{factor}: radius {radius} m");
        let poses: Vec<Isometry3<f64>> =
            v["scans"].as_array().expect("scans").iter().map(|s| pose(&s["world_from_scan"])).collect();
        for (a, b) in [(0, 1), (1, 2)] {
            let mut reference =
                scanner::io::from_3dtk_axes(&matrix_file(&format!("3dtk_dat/reference_T_scan{a:03}_scan{b:03}.txt")));
            reference.translation.vector *= factor;
            let (deg, m) = error(&(poses[a].inverse() * poses[b]), &reference);
            assert!(deg < 0.35 && m / factor < 0.03, "×{factor} {a}←{b}: {deg}° {} (scaled) m off", m / factor);
            errors.push((factor, deg, m / factor));
        }
    }
    // The same relative accuracy at every scale (errors[2k + link]).
    for (i, e) in errors.iter().enumerate() {
        let same = errors[2 + i % 2];
        assert!((e.1 - same.1).abs() < 0.01 && (e.2 - same.2).abs() < 1e-3, "{e:?} against {errors:?}");
    }
}

/// The 3DTK set with every scan's points 60 m from its scanner (and at
/// 1:100, 0.6 m: an object scanned from afar): the blind-direction test
/// runs about each match's centroid, so no scan is blind anywhere (about
/// the scanner it flagged 2–5 directions on every scan, issue 38) and the
/// set lands on the reference as from its own scanners.
#[test]
fn a_set_seen_from_afar_is_not_blind_and_lands_alike() {
    let dir = tempfile::tempdir().expect("temp dir");
    for factor in [1.0f64, 0.01] {
        let shift = nalgebra::Vector3::new(0.0, 60.0, 8.0) * factor;
        let set = dir.path().join(format!("afar{factor}"));
        let args = three_dtk_copy(&set, factor, shift);
        let (r, v) = run(&args, &set.join("out"));
        assert_eq!(r.code, 0, "×{factor}: {}", r.stderr);
        let v = v.expect("JSON");
        for s in v["scans"].as_array().expect("scans") {
            assert!(s["degenerate_directions"].as_array().expect("list").is_empty(), "×{factor}: {s}");
        }
        for l in v["links"].as_array().expect("links") {
            assert!(l["degenerate_directions"].as_array().is_none_or(|d| d.is_empty()), "×{factor}: {l}");
        }
        let poses: Vec<Isometry3<f64>> =
            v["scans"].as_array().expect("scans").iter().map(|s| pose(&s["world_from_scan"])).collect();
        let moved = Isometry3::from(nalgebra::Translation3::from(shift));
        for (a, b) in [(0, 1), (1, 2)] {
            let mut reference =
                scanner::io::from_3dtk_axes(&matrix_file(&format!("3dtk_dat/reference_T_scan{a:03}_scan{b:03}.txt")));
            reference.translation.vector *= factor;
            // Compared at the scanners (a turn's error times 60 m is not
            // the match's).
            let (deg, m) = error(&(moved.inverse() * poses[a].inverse() * poses[b] * moved), &reference);
            assert!(
                deg < 0.35 && m / factor < 0.03,
                "×{factor} {a}←{b}: {deg}° {} (scaled) m off; restart {}, links {}",
                m / factor,
                v["restart"],
                v["links"]
            );
        }
    }
}

/// The 3DTK scans at 1:100 (a 5 cm set) under the building recipe: the
/// 0.5 m stage leaves a scan a handful of cells — refused before any match,
/// naming the stage, the scan and the spacing found (issue 38: it failed
/// with "target point count = 3 is out of range", blaming a good scan).
/// The report states the spacing and radius it measured.
#[test]
fn a_schedule_too_coarse_for_the_scans_is_refused_with_the_spacing_found() {
    let dir = tempfile::tempdir().expect("temp dir");
    let mut inputs = Vec::new();
    for k in 0..2 {
        let mut cloud = scanner::io::read(Path::new(&data(&format!("3dtk_dat/scan{k:03}.3d")))).expect("scan");
        cloud.points.iter_mut().for_each(|p| *p *= 0.01);
        let path = dir.path().join(format!("small{k}.ply"));
        scanner::io::write(&path, &cloud, scanner::io::Format::Ply(scanner::io::PlyEncoding::BinaryLittleEndian))
            .expect("PLY");
        inputs.push(path.into_os_string());
    }
    inputs.extend(["--schedule".into(), "0.5/2,0.25/1,0.1/0.5,0.05/0.2".into()]);
    let (r, _) = run(&inputs, &dir.path().join("out"));
    assert_eq!(r.code, 2, "{}", r.stderr);
    for part in
        ["--schedule 0.5/2,0.25/1,0.1/0.5,0.05/0.2: stage 0.5/2 leaves", "small0.ply in", "apart over the surface"]
    {
        assert!(r.stderr.contains(part), "{part}: {}", r.stderr);
    }
    assert!(!dir.path().join("out").exists(), "refused before anything was written");
    let (r, _) = run(&[&inputs[..2], &["--max-matches-per-scan".into(), "0".into()]].concat(), &dir.path().join("m0"));
    assert_eq!(r.code, 2, "{}", r.stderr);
    assert!(r.stderr.contains("--max-matches-per-scan 0: expected at least 1"), "{}", r.stderr);
    // Issue 34, S10: a stage that leaves a scan one point ran "0 ICP runs",
    // exit 0.
    let rooms = [data("pcl_room_scans/room_scan1.pcd"), data("pcl_room_scans/room_scan2.pcd")];
    let (r, _) = run(&[&rooms[..], &["--schedule".into(), "1e6/1e6".into()]].concat(), &dir.path().join("s10"));
    assert_eq!(r.code, 2, "{}", r.stderr);
    assert!(
        r.stderr.contains("stage 1000000/1000000 leaves") && r.stderr.contains("expected at least 50"),
        "{}",
        r.stderr
    );
    // The same scans at full size: the scales in the report.
    let (r, v) = run(&[data("3dtk_dat")], &dir.path().join("full"));
    assert_eq!(r.code, 0, "{}", r.stderr);
    let settings = &v.expect("JSON")["settings"];
    let (spacing, radius) = (settings["spacing_m"].as_f64().expect("m"), settings["radius_m"].as_f64().expect("m"));
    assert!((0.03..0.1).contains(&spacing) && (4.0..8.0).contains(&radius), "{settings}");
    // The recipe scaled to the radius (5.46 m: × 0.99).
    let last = &settings["schedule"][3];
    let k = radius / 5.5;
    assert!((last[0].as_f64().expect("m") - 0.05 * k).abs() < 1e-12, "{settings}");
    assert!((last[1].as_f64().expect("m") - 0.2 * k).abs() < 1e-12, "{settings}");
    assert_eq!(settings["auto_schedule"], true);
}

/// `match` keeps each point's colour and time (issue 33, item 13): LAS
/// inputs with 16-bit colours and adjusted standard GPS times come out of
/// LAS (read by the `las` crate) and E57 with every point's colour and
/// time, paired by the time; PLY has them in 8 bits.
#[test]
fn match_keeps_every_points_colour_and_time() {
    use scanner::io::{Format, TimeBase};
    let dir = tempfile::tempdir().expect("temp dir");
    let mut inputs = Vec::new();
    let mut want = std::collections::BTreeMap::new(); // time (µs) → colour
    let mut t = 1_448_000_000.0;
    for name in ["target", "source"] {
        let mut cloud = scanner::io::read(Path::new(&data(&format!("small_gicp_pair/{name}.ply")))).expect("PLY");
        let n = cloud.len();
        cloud.color = Some((0..n).map(|i| [(i * 7919 % 65_536) as u16, (i % 65_536) as u16, 40_000]).collect());
        cloud.time = Some((0..n).map(|i| t + i as f64 * 1e-5).collect());
        cloud.time_base = TimeBase::Gps;
        t += 10.0;
        for (c, t) in cloud.color.iter().flatten().zip(cloud.time.iter().flatten()) {
            want.insert((t * 1e6).round() as i64, *c);
        }
        let path = dir.path().join(format!("{name}.las"));
        scanner::io::write(&path, &cloud, Format::Las).expect("written");
        inputs.push(path.into_os_string());
    }
    let out = dir.path().join("out");
    let mut args = inputs.clone();
    args.extend(["--formats".into(), "las,e57,ply".into()]);
    let (r, _) = run(&args, &out);
    assert_eq!(r.code, 0, "{}", r.stderr);
    let points = las_points(&out.join("cloud.las"));
    assert!(points.len() > want.len() * 9 / 10, "{} of {} points", points.len(), want.len());
    for p in &points {
        let key = ((p.gps_time.expect("a time") + 1e9) * 1e6).round() as i64;
        let c = p.color.expect("a colour");
        assert_eq!(want.get(&key), Some(&[c.red, c.green, c.blue]), "LAS point at {key} µs");
    }
    for scan in scanner::io::read_e57_scans(&out.join("cloud.e57")).expect("E57") {
        assert_eq!(scan.time_base, TimeBase::Gps, "{}", scan.name);
        for (t, c) in scan.time.expect("times").iter().zip(scan.color.expect("colours")) {
            assert_eq!(want.get(&((t * 1e6).round() as i64)), Some(&c), "E57 {} point at {t}", scan.name);
        }
    }
    let ply = scanner::io::read(&out.join("cloud.ply")).expect("PLY");
    assert_eq!((ply.len(), ply.time_base), (points.len(), TimeBase::Gps));
    for (t, c) in ply.time.expect("times").iter().zip(ply.color.expect("colours")) {
        let w = want[&((t * 1e6).round() as i64)];
        assert!((0..3).all(|k| (i32::from(w[k]) - i32::from(c[k])).abs() <= 128), "PLY {c:?} for {w:?}");
    }
}

fn las_points(path: &Path) -> Vec<las::Point> {
    let mut reader = las::Reader::from_path(path).expect("LAS");
    reader.read_all().expect("points").points().map(|p| p.expect("a point")).collect()
}

/// The same scans at national-grid coordinates report the σ they have at
/// the origin (covariances in the world's axes about the first scan's
/// origin): carried to the world's origin, 0.76 mm became 415,802 mm.
#[test]
fn a_set_at_national_grid_coordinates_reports_the_sigma_it_has_at_the_origin() {
    let dir = tempfile::tempdir().expect("temp dir");
    let offset = nalgebra::Translation3::new(500_000.0, 5_500_000.0, 300.0);
    let init = dir.path().join("utm.json");
    let entries: Vec<Value> = (0..3)
        .map(|k| {
            let pose =
                scanner::io::read_3dtk_pose(Path::new(&data(&format!("3dtk_dat/scan{k:03}.pose")))).expect("pose");
            init_entry(&format!("scan{k:03}.3d"), &(offset * pose).to_homogeneous())
        })
        .collect();
    std::fs::write(&init, serde_json::to_string(&entries).expect("JSON")).expect("init poses");
    let (r, near) = run(&[data("3dtk_dat")], &dir.path().join("near"));
    assert_eq!(r.code, 0, "{}", r.stderr);
    let far_args =
        [data("3dtk_dat"), "--init-poses".into(), init.into_os_string(), "--crs".into(), "EPSG:25832".into()];
    let (r, far) = run(&far_args, &dir.path().join("far"));
    assert_eq!(r.code, 0, "{}", r.stderr);
    let sigma_mm = |v: &Value, k: usize| {
        let c = &v["scans"][k]["covariance"];
        (3..6).map(|i| c[i][i].as_f64().expect("variance")).sum::<f64>().sqrt() * 1e3
    };
    let (near, far) = (near.expect("JSON"), far.expect("JSON"));
    for k in 1..3 {
        let (a, b) = (sigma_mm(&near, k), sigma_mm(&far, k));
        // (The set's variance factor, in the hundreds — its three links
        // miss their cycle —, makes these centimetres: measured 44–56 mm.)
        assert!(a > 0.0 && a < 100.0, "scan {k}: σxyz {a} mm at the origin");
        assert!((a - b).abs() <= 1e-3 * a, "scan {k}: σxyz {b} mm at UTM against {a} mm at the origin");
        let (p, q) = (pose(&near["scans"][k]["world_from_scan"]), pose(&far["scans"][k]["world_from_scan"]));
        let (deg, m) = error(&q, &(offset * p));
        assert!(deg < 1e-6 && m < 1e-4, "scan {k}: {deg}° {m} m from the origin's result shifted");
    }
}

/// `match`'s outputs replace what is in their place, never write through
/// it (issue 34, W1: links at frames/, match.rrd and the temporary names
/// wrote into the linked directory and files); a directory where an
/// output file goes is refused before the registration, with nothing
/// written and no `.partial` left (F4); a scan of one repeated point and a
/// scan given twice are named (U5, U3). (F3, a recording that cannot be
/// written whole: `missions/tests/disk_full.rs`.)
#[test]
#[cfg(unix)]
fn match_replaces_links_and_leaves_no_partial_file() {
    use std::os::unix::fs::symlink;
    let dir = tempfile::tempdir().expect("temp dir");
    let init = room_odometry(dir.path());
    let rooms = [data("pcl_room_scans/room_scan1.pcd"), data("pcl_room_scans/room_scan2.pcd")];
    let args = |extra: &[&str]| -> Vec<OsString> {
        let mut a = rooms.to_vec();
        a.extend(["--init-poses".into(), init.clone().into_os_string()]);
        a.extend(extra.iter().map(OsString::from));
        a
    };
    // W1: links in every output's place.
    let (victim, out) = (dir.path().join("victim"), dir.path().join("o"));
    std::fs::create_dir_all(victim.join("fr")).expect("victim");
    std::fs::create_dir_all(&out).expect("out");
    for (link, target) in [
        ("poses.json", "poses.json"),
        ("frames", "fr"),
        ("match.rrd", "m.rrd"),
        ("match.rrd.partial", "p.rrd"),
        ("cloud.ply.partial", "c.ply"),
        ("links.csv", "l.csv"),
    ] {
        symlink(victim.join(target), out.join(link)).expect("link");
    }
    symlink(victim.join("f1"), victim.join("fr/room_scan1.frames")).expect("link");
    let (r, _) = run(&args(&[]), &out);
    assert_eq!(r.code, 0, "{}", r.stderr);
    let mut left: Vec<String> = std::fs::read_dir(&victim)
        .expect("victim")
        .map(|e| e.expect("entry").file_name().to_string_lossy().into_owned())
        .collect();
    left.sort();
    assert_eq!(left, ["fr"], "nothing written into the linked places");
    assert_eq!(std::fs::read_dir(victim.join("fr")).expect("fr").count(), 1, "only the link that was there");
    for name in ["poses.json", "match.rrd", "links.csv", "cloud.ply"] {
        let meta = std::fs::symlink_metadata(out.join(name)).expect(name);
        assert!(meta.is_file(), "{name} is match's own file");
    }
    assert!(std::fs::symlink_metadata(out.join("frames")).expect("frames").is_dir());
    assert!(!out.join("match.rrd.partial").exists() && !out.join("cloud.ply.partial").exists());

    // F4: a directory where the cloud goes.
    let blocked = dir.path().join("blocked");
    std::fs::create_dir_all(blocked.join("cloud.ply")).expect("dir");
    let (r, _) = run(&args(&[]), &blocked);
    assert_eq!(r.code, 2, "{}", r.stderr);
    assert!(r.stderr.contains("cloud.ply is a directory"), "{}", r.stderr);
    assert_eq!(std::fs::read_dir(&blocked).expect("blocked").count(), 1, "nothing written");

    // U5, U3.
    let same = dir.path().join("same.xyz");
    std::fs::write(&same, "1 2 3\n".repeat(1000)).expect("xyz");
    let (r, _) = run(&[same.into_os_string(), rooms[0].clone()], &dir.path().join("u5"));
    assert_eq!(r.code, 2, "{}", r.stderr);
    assert!(r.stderr.contains("same.xyz: its 1000 points all lie at one position"), "{}", r.stderr);
    let (r, _) = run(&[rooms[0].clone(), rooms[0].clone()], &dir.path().join("u3"));
    assert_eq!(r.code, 2, "{}", r.stderr);
    assert!(r.stderr.contains("hold the same points: expected each scan once"), "{}", r.stderr);
}

/// A link whose match hit the iteration cap is not used (issue 34, S6: a
/// 1e-4 m Huber width left the room scan 1.1 m off, its link "accepted",
/// exit 0): rejected with the reason, the scan not trusted, exit 1.
#[test]
fn a_link_that_did_not_converge_is_rejected_and_the_exit_says_so() {
    let dir = tempfile::tempdir().expect("temp dir");
    let rooms = [data("pcl_room_scans/room_scan1.pcd"), data("pcl_room_scans/room_scan2.pcd")];
    let (r, v) = run(&[&rooms[..], &["--huber".into(), "1e-4".into()]].concat(), &dir.path().join("o"));
    assert_eq!(r.code, 1, "{}", r.stderr);
    let v = v.expect("JSON");
    let link = &v["links"][0];
    assert_eq!((link["converged"].as_bool(), link["accepted"].as_bool()), (Some(false), Some(false)), "{link}");
    assert!(link["reason"].as_str().expect("reason").starts_with("did not converge in 100 iterations"), "{link}");
}

/// `--out` is match's own (issue 34, W2–W4): a run directory is refused
/// (its cloud is the run's), so is a directory holding an input (an input
/// named `cloud.ply` was overwritten), and a second match into the same
/// directory leaves none of the first one's outputs beside its own.
#[test]
fn match_writes_only_into_a_directory_of_its_own_and_leaves_nothing_stale() {
    let dir = tempfile::tempdir().expect("temp dir");
    let rooms = [data("pcl_room_scans/room_scan1.pcd"), data("pcl_room_scans/room_scan2.pcd")];
    // W3: a run directory.
    let run_dir = dir.path().join("run");
    std::fs::create_dir(&run_dir).expect("dir");
    std::fs::write(run_dir.join("journal.jsonl"), "").expect("journal");
    std::fs::write(run_dir.join("cloud.ply"), "the run's").expect("cloud");
    let (r, _) = run(&rooms, &run_dir);
    assert_eq!(r.code, 2, "{}", r.stderr);
    assert!(r.stderr.contains("a run directory (it holds journal.jsonl)"), "{}", r.stderr);
    assert_eq!(std::fs::read_to_string(run_dir.join("cloud.ply")).expect("cloud"), "the run's");
    // W2: an --out that holds an input.
    let inputs = dir.path().join("in");
    std::fs::create_dir(&inputs).expect("dir");
    let copy = inputs.join("room_scan2.pcd");
    std::fs::copy(Path::new(&rooms[1]), &copy).expect("copy");
    let (r, _) = run(&[rooms[0].clone(), copy.clone().into_os_string()], &inputs);
    assert_eq!(r.code, 2, "{}", r.stderr);
    assert!(r.stderr.contains("holds the input") && r.stderr.contains("room_scan2.pcd"), "{}", r.stderr);
    // W4: 3DTK with las, then the room pair with ply only, into one --out.
    let out = dir.path().join("out");
    let (r, _) = run(&[data("3dtk_dat"), "--formats".into(), "ply,las".into()], &out);
    assert_eq!(r.code, 0, "{}", r.stderr);
    assert!(out.join("cloud.las").is_file() && out.join("frames/scan002.frames").is_file());
    let (r, _) = run(&rooms, &out);
    assert_eq!(r.code, 0, "{}", r.stderr);
    assert!(!out.join("cloud.las").exists(), "the first match's LAS is gone");
    let mut frames: Vec<String> = std::fs::read_dir(out.join("frames"))
        .expect("frames")
        .map(|e| e.expect("entry").file_name().to_string_lossy().into_owned())
        .collect();
    frames.sort();
    assert_eq!(frames, ["room_scan1.frames", "room_scan2.frames"]);
}

/// The points of `cloud` whose azimuth about z lies within `width_deg`
/// from `from_deg`, in the frame of `world_from_wedge` (`cloud` holds
/// world coordinates), written as binary PLY to `path`.
fn write_wedge(
    path: &Path,
    cloud: &scanner::io::PointCloud,
    from_deg: f32,
    width_deg: f32,
    world_from_wedge: &Isometry3<f64>,
) -> OsString {
    let (from, width) = (from_deg.to_radians(), width_deg.to_radians());
    let wedge = cloud.points.iter().filter(|p| (p.y.atan2(p.x) - from).rem_euclid(std::f32::consts::TAU) < width);
    write_part(path, wedge, world_from_wedge)
}

/// `points` (world coordinates) in the frame of `world_from_part`, written
/// as binary PLY to `path`.
fn write_part<'a>(
    path: &Path,
    points: impl Iterator<Item = &'a Point3<f32>>,
    world_from_part: &Isometry3<f64>,
) -> OsString {
    let part: Vec<Point3<f32>> = points.map(|p| (world_from_part.inverse() * p.cast::<f64>()).cast::<f32>()).collect();
    scanner::io::write(
        path,
        &scanner::io::PointCloud::from_points(part),
        scanner::io::Format::Ply(scanner::io::PlyEncoding::BinaryLittleEndian),
    )
    .expect("PLY");
    path.as_os_str().to_owned()
}

/// The bench's cut (`fusion/benches/covariance_nees.py`) of a scan whose
/// up is z (`source` under the shared data: small_gicp's street frame,
/// the PCL room): four 150° wedges, the first centred at `first_deg`, each written as PLY in the frame of its truth (the first
/// is the world; `truths` and `starts` give the other three as the bench's
/// 3×4 rows), with an `--init-poses` file of `starts`; `dealt`: each point
/// where wedges overlap goes to one of them by the bench's hash of its
/// index, else to all. Returns the inputs (the PLYs, `--init-poses` and its
/// file) and the truths.
fn bench_wedges(
    dir: &Path,
    source: &str,
    first_deg: f64,
    dealt: bool,
    truths: &[[[f64; 4]; 3]; 3],
    starts: &[[[f64; 4]; 3]; 3],
) -> (Vec<OsString>, Vec<Isometry3<f64>>) {
    let scan = scanner::io::read(Path::new(&data(source))).expect("source scan");
    let rows = |m: &[[f64; 4]; 3]| {
        rigid(&Matrix4::from_fn(|r, c| {
            if r < 3 {
                m[r][c]
            } else if c == 3 {
                1.0
            } else {
                0.0
            }
        }))
    };
    let truths: Vec<Isometry3<f64>> = std::iter::once(Isometry3::identity()).chain(truths.iter().map(rows)).collect();
    let starts: Vec<Isometry3<f64>> = std::iter::once(Isometry3::identity()).chain(starts.iter().map(rows)).collect();
    // The bench's cut to the last point (the frame holds 5,032 points at
    // the scanner, (±0, ±0, 0), 497 with x = −0: which wedge holds those
    // decides whether the first stage drags them): azimuth within 75° of
    // each centre, in double precision, signed zeros as NumPy's dot
    // products leave them (+0: azimuth 0, not ±180°).
    let inside: Vec<[bool; 4]> = scan
        .points
        .iter()
        .map(|p| {
            let azimuth = (f64::from(p.y) + 0.0).atan2(f64::from(p.x) + 0.0);
            std::array::from_fn(|k| {
                let d = azimuth - std::f64::consts::TAU * k as f64 / 4.0 - first_deg.to_radians();
                d.sin().atan2(d.cos()).abs() <= 75f64.to_radians()
            })
        })
        .collect();
    let owner = |i: usize, k: usize| {
        if !inside[i][k] {
            return false;
        }
        if !dealt {
            return true;
        }
        let count = inside[i].iter().filter(|&&x| x).count() as u64;
        let pick = (((i as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15) >> 32) * count) >> 32;
        inside[i][..k].iter().filter(|&&x| x).count() as u64 == pick
    };
    (write_parts(dir, &scan.points, owner, &truths, &starts), truths)
}

/// The parts of `points` (world coordinates; part `k` holds point `i`
/// where `owner(i, k)`), each written as `partK.ply` into `dir` in the
/// frame of its truth, with an `--init-poses` file of `starts`: the
/// inputs of a `match` (the PLYs, `--init-poses` and its file).
pub(super) fn write_parts(
    dir: &Path,
    points: &[Point3<f32>],
    owner: impl Fn(usize, usize) -> bool,
    truths: &[Isometry3<f64>],
    starts: &[Isometry3<f64>],
) -> Vec<OsString> {
    let mut inputs: Vec<OsString> = Vec::new();
    let mut entries = Vec::new();
    for (k, (truth, start)) in truths.iter().zip(starts).enumerate() {
        let name = format!("part{k}.ply");
        let part = points.iter().enumerate().filter(|&(i, _)| owner(i, k)).map(|(_, p)| p);
        inputs.push(write_part(&dir.join(&name), part, truth));
        entries.push(init_entry(&name, &start.to_homogeneous()));
    }
    let init = dir.join("init.json");
    std::fs::write(&init, serde_json::to_string(&entries).expect("JSON")).expect("init");
    inputs.extend(["--init-poses".into(), init.into_os_string()]);
    inputs
}

/// small_gicp's street frame (an HDL-32E's), under the shared data.
const STREET: &str = "small_gicp_pair/target.ply";

/// One entry of an `--init-poses` file: `file` at `world_from_scan` (4×4).
fn init_entry(file: &str, world_from_scan: &Matrix4<f64>) -> Value {
    let rows: Vec<Vec<f64>> = (0..4).map(|r| (0..4).map(|c| world_from_scan[(r, c)]).collect()).collect();
    serde_json::json!({ "file": file, "world_from_scan": rows })
}

/// Four 150° wedges of the PCL room scan, each overlapping the next by 60°
/// (truth: one frame), written as PLY with starts `offset_m` and
/// `offset_deg` off per wedge (deterministic directions); returns the
/// inputs and the `--init-poses` file.
fn room_wedges(dir: &Path, offset_m: f64, offset_deg: f64) -> Vec<OsString> {
    let room = scanner::io::read(Path::new(&data("pcl_room_scans/room_scan1.pcd"))).expect("room");
    std::fs::create_dir_all(dir).expect("dir");
    let mut inputs = Vec::new();
    let mut entries = Vec::new();
    for k in 0..4 {
        let name = format!("wedge{k}.ply");
        inputs.push(write_wedge(&dir.join(&name), &room, k as f32 * 90.0, 150.0, &Isometry3::identity()));
        let a = 1.3 * k as f64 + 0.4;
        let start = if k == 0 {
            Isometry3::identity()
        } else {
            Isometry3::from_parts(
                nalgebra::Translation3::new(a.cos() * offset_m, a.sin() * offset_m, 0.0),
                UnitQuaternion::from_axis_angle(
                    &nalgebra::Unit::new_normalize(nalgebra::Vector3::new(a.sin(), 0.3, 1.0)),
                    offset_deg.to_radians() * if k % 2 == 0 { 1.0 } else { -1.0 },
                ),
            )
        };
        entries.push(init_entry(&name, &start.to_homogeneous()));
    }
    let init = dir.join("init.json");
    std::fs::write(&init, serde_json::to_string(&entries).expect("JSON")).expect("init");
    inputs.extend(["--init-poses".into(), init.into_os_string()]);
    inputs
}

/// `--only-covered`: the room's four 150° wedges (truth: identity), from
/// starts 0.5 m / 5° off. Where a wedge ends, its neighbour's points beyond
/// the cut pair with the cut's edge; left out, the wedges land closer.
#[test]
fn only_covered_pairs_bring_wedges_closer() {
    let dir = tempfile::tempdir().expect("temp dir");
    let inputs = room_wedges(&dir.path().join("w"), 0.5, 5.0);
    let worst = |v: &Value| -> (f64, f64) {
        v["scans"]
            .as_array()
            .expect("scans")
            .iter()
            .map(|s| error(&pose(&s["world_from_scan"]), &Isometry3::identity()))
            .fold((0.0, 0.0), |(d, m), (a, b)| (a.max(d), b.max(m)))
    };
    let (r, v) = run(&inputs, &dir.path().join("all"));
    assert_eq!(r.code, 0, "{}", r.stderr);
    let v = v.expect("JSON");
    assert_eq!(v["settings"]["only_covered"], false);
    let all = worst(&v);
    let mut args = inputs.clone();
    args.push("--only-covered".into());
    let (r, v) = run(&args, &dir.path().join("covered"));
    assert_eq!(r.code, 0, "{}", r.stderr);
    let v = v.expect("JSON");
    assert_eq!(v["settings"]["only_covered"], true);
    let covered = worst(&v);
    // (0.0022° / 0.37 mm against 0.0078° / 0.84 mm.)
    assert!(covered.0 < 0.01 && covered.1 < 0.001, "{covered:?}");
    assert!(covered.0 < 0.5 * all.0 && covered.1 < 0.6 * all.1, "{covered:?} against {all:?} with every pair");
}

/// Issue 38, "no silent failure": four wedges of the room, overlapping
/// 60° pairwise. From starts 0.5 m / 5° off every mode lands them within
/// 0.1° and 5 mm, and the verification (each overlapping pair matched once
/// more from the final poses) finds every pair consistent. From 1 m / 10°
/// the coarse stages trap them in the room's other symmetric fit (90° off;
/// every link was "used" and the exit 0): every mode now lands, by the
/// restart from the starts without the coarse stage or — where that is
/// trapped too and named — by a further restart without the first two
/// stages. With a schedule of three stages (0.3/1.2, 0.15/0.6, 0.03/0.12
/// m) some modes stay trapped: they exit 1 and name scans of inconsistent
/// pairs — only scans that are indeed off. (Measured with the corner test
/// off; at the defaults the first restart alone lands them from 1 m / 10°
/// in every mode.)
#[test]
fn wedges_from_rough_starts_land_or_are_named_with_exit_1() {
    let dir = tempfile::tempdir().expect("temp dir");
    let off = |v: &Value| -> Vec<(f64, f64)> {
        v["scans"]
            .as_array()
            .expect("scans")
            .iter()
            .map(|s| error(&pose(&s["world_from_scan"]), &Isometry3::identity()))
            .collect()
    };
    let (mut rescued, mut further, mut trapped) = (Vec::new(), Vec::new(), Vec::new());
    let three = "0.3/1.2,0.15/0.6,0.03/0.12";
    for (m, deg, schedule) in [(0.5, 5.0, None), (1.0, 10.0, None), (1.0, 10.0, Some(three))] {
        let lands = schedule.is_none();
        let inputs = corners_off(&room_wedges(&dir.path().join(format!("w{m}")), m, deg));
        for mode in ["graph", "pairwise", "incremental", "simultaneous"] {
            let mut args = inputs.clone();
            args.extend(["--mode".into(), mode.into()]);
            if let Some(s) = schedule {
                args.extend(["--schedule".into(), s.into()]);
            }
            let (r, v) = run(&args, &dir.path().join(format!("o{m}-{mode}-{}", schedule.is_some())));
            let v = v.expect("JSON");
            let errors = off(&v);
            let untrusted: Vec<usize> = v["untrusted"]
                .as_array()
                .expect("untrusted")
                .iter()
                .map(|i| i.as_u64().expect("index") as usize)
                .collect();
            if lands || r.code == 0 {
                assert_eq!(r.code, 0, "{m} m {mode}: {}", r.stderr);
                assert!(untrusted.is_empty(), "{m} m {mode}: {}", v["checks"]);
                // With the three stages simultaneous mode's restart ends
                // 0.11° / 3.7 mm off (its last stage re-queues a scan only
                // beyond 0.05°): landed, not trapped.
                let (deg, metres) = if lands { (0.1, 0.005) } else { (0.2, 0.01) };
                for (k, (d, e)) in errors.iter().enumerate() {
                    assert!(*d < deg && *e < metres, "{m} m {mode} {schedule:?}: wedge {k} {d}° {e} m off");
                }
                if m > 0.5 {
                    // Landed from 1 m / 10° only by a restart without the
                    // coarse stages that trapped it.
                    let by_further =
                        v["restart"]["further"].as_array().expect("further restarts").iter().any(|f| f["kept"] == true);
                    assert!(v["restart"]["kept"] == true || by_further, "{m} m {mode}: {}", v["restart"]);
                    if by_further {
                        assert_eq!(v["restart"]["kept"], false, "{}", v["restart"]);
                        further.push(mode);
                    }
                    rescued.push(mode);
                }
            } else {
                trapped.push(mode);
                assert_eq!(r.code, 1, "{m} m {mode}: {errors:?}");
                // The trap this test is about: a wedge in the room's other
                // symmetric fit (90° off; 10.8° in one mode since the pairs
                // are matched both ways).
                assert!(errors.iter().any(|(d, _)| *d > 5.0), "the trap this test is about: {errors:?}");
                assert!(!untrusted.is_empty(), "{m} m {mode}: {}", v["checks"]);
                for &k in &untrusted {
                    assert!(errors[k].0 > 1.0, "{m} m {mode}: wedge {k} named but right: {errors:?}");
                }
                // A link the graph rejects as disagreeing names the cycle of
                // used links it contradicts, from its target round to its
                // source, and by how much.
                for l in v["links"].as_array().expect("links") {
                    if l["reason"].as_str().is_some_and(|r| r.contains("disagrees with the other links")) {
                        let cycle = &l["cycle"];
                        let scans = cycle["scans"].as_array().expect("a cycle");
                        assert!(scans.len() >= 3, "{l}");
                        assert_eq!((scans.first(), scans.last()), (l["targets"].get(0), Some(&l["source"])), "{l}");
                        assert!(cycle["angle_deg"].as_f64().expect("angle") > 1.0, "{l}");
                    }
                }
                if mode == "graph" {
                    assert!(
                        v["links"].as_array().expect("links").iter().any(|l| !l["cycle"].is_null()),
                        "{}",
                        v["links"]
                    );
                }
            }
        }
    }
    // The further restarts are what rescued some (in this session's runs:
    // every mode but incremental, where the first restart lands them).
    assert!(!further.is_empty(), "rescued by the first restart alone: {rescued:?}");
    // The trap is still there with three stages: a restart is kept only
    // where the scans agree clearly better (the others stay named).
    assert!(!trapped.is_empty(), "every mode landed with the three stages too");
    // The text output names them, and the further restart that ran.
    let mut args = corners_off(&room_wedges(&dir.path().join("text"), 1.0, 10.0));
    args.extend(["--mode".into(), "pairwise".into(), "--schedule".into(), three.into()]);
    let r = run_text(&args, &dir.path().join("t"));
    assert_eq!(r.code, 1, "{}", r.stderr);
    // (Named by the free space of the wedges' estimated scanners; without
    // them, by their pairs matched again from the final poses.)
    assert!(
        r.stdout.contains("not trusted: wedge")
            && r.stdout.contains("placed in another scan's free space")
            && r.stdout.contains("again without the first 2 stages"),
        "{}",
        r.stdout
    );
    // At the defaults (the corner test on) every mode lands them from
    // 1 m / 10°, the restart without the coarse stage alone.
    let truths = [Isometry3::identity(); 4];
    let inputs = room_wedges(&dir.path().join("defaults"), 1.0, 10.0);
    for mode in ["graph", "pairwise", "incremental", "simultaneous"] {
        let mut args = inputs.clone();
        args.extend(["--mode".into(), mode.into()]);
        lands_at_the_defaults(mode, &args, &dir.path().join(format!("d-{mode}")), &truths, 0.1, 0.005);
    }
}

/// Issue 38, "registration without a guess": `--init global` finds every
/// start from the scans' shape alone. The real pairs and the 3DTK set from
/// no guess at all (identity, their poses ignored) land on their
/// references; eight 120° wedges of the room, each turned 34°–180° and
/// moved up to 2 m (a turntable's set), land on one another.
#[test]
fn init_global_registers_scans_that_come_with_no_guess() {
    let dir = tempfile::tempdir().expect("temp dir");
    let global = |inputs: Vec<OsString>, out: &str| -> Value {
        let mut args = inputs;
        args.extend(["--init".into(), "global".into()]);
        let (r, v) = run(&args, &dir.path().join(out));
        let v = v.expect("JSON");
        assert_eq!(r.code, 0, "{out}: {} {} {}", r.stderr, v["untrusted"], v["checks"]);
        assert_eq!(v["untrusted"], serde_json::json!([]), "{out}: {}", v["checks"]);
        assert!(v["settings"]["global"]["matches"].as_array().is_some_and(|m| !m.is_empty()), "{out}: {v}");
        v
    };
    let poses = |v: &Value| -> Vec<Isometry3<f64>> {
        v["scans"].as_array().expect("scans").iter().map(|s| pose(&s["world_from_scan"])).collect()
    };
    // The room pair: 40.8° and 2 m apart.
    let v = global(vec![data("pcl_room_scans/room_scan1.pcd"), data("pcl_room_scans/room_scan2.pcd")], "room");
    let p = poses(&v);
    let reference = rigid(&matrix_file("pcl_room_scans/reference_T_scan1_scan2.txt"));
    let (deg, m) = error(&(p[0].inverse() * p[1]), &reference);
    // The reference (small_gicp's GICP) and Open3D's point-to-plane agree
    // to 0.05°; our one-way match landed 0.05° or 0.11° from it by which
    // scan was the source, matched both ways 0.12° / 0.8 mm in either order.
    assert!(deg < 0.15 && m < 0.01, "room: {deg}° {m} m off the reference");
    // small_gicp's pair.
    let v = global(vec![data("small_gicp_pair/target.ply"), data("small_gicp_pair/source.ply")], "sg");
    let p = poses(&v);
    let reference = rigid(&matrix_file("small_gicp_pair/T_target_source.txt"));
    let (deg, m) = error(&(p[0].inverse() * p[1]), &reference);
    // (Where `match` lands from the identity, which is near: 0.14°, 10 mm
    // from small_gicp's own GICP result matched one way, 0.21° / 11 mm
    // matched both ways; the reference is good to about 0.2°.)
    assert!(deg < 0.25 && m < 0.015, "small_gicp: {deg}° {m} m off the reference");
    // The 3DTK set, its odometry not used.
    let v = global(vec![data("3dtk_dat")], "3dtk");
    let p = poses(&v);
    for (a, b) in [(0, 1), (1, 2)] {
        let reference =
            scanner::io::from_3dtk_axes(&matrix_file(&format!("3dtk_dat/reference_T_scan{a:03}_scan{b:03}.txt")));
        let (deg, m) = error(&(p[a].inverse() * p[b]), &reference);
        assert!(deg < 0.35 && m < 0.03, "3DTK {a}←{b}: {deg}° {m} m off the reference");
    }
    // Eight wedges of the room, 120° each every 45°, turned and moved.
    let room = scanner::io::read(Path::new(&data("pcl_room_scans/room_scan1.pcd"))).expect("room");
    let set = dir.path().join("wedges");
    std::fs::create_dir_all(&set).expect("dir");
    let turns = [0.0f64, 34.0, 60.0, 90.0, 120.0, 150.0, 180.0, -100.0];
    let mut truth = Vec::new();
    let mut inputs = Vec::new();
    for (k, turn) in turns.iter().enumerate() {
        let from = k as f32 * 45.0;
        // The wedge in a frame turned by `turn` about a tilted axis and
        // moved: world_from_wedge is that motion.
        let world_from_wedge = Isometry3::from_parts(
            nalgebra::Translation3::new(0.25 * k as f64, -0.15 * k as f64, 0.02 * k as f64),
            UnitQuaternion::from_axis_angle(
                &nalgebra::Unit::new_normalize(nalgebra::Vector3::new(0.05, -0.03, 1.0)),
                turn.to_radians(),
            ),
        )
        .inverse();
        inputs.push(write_wedge(&set.join(format!("wedge{k}.ply")), &room, from, 120.0, &world_from_wedge));
        truth.push(world_from_wedge);
    }
    let v = global(inputs, "wedges-out");
    let p = poses(&v);
    for k in 1..turns.len() {
        let (deg, m) = error(&(p[0].inverse() * p[k]), &(truth[0].inverse() * truth[k]));
        assert!(deg < 0.1 && m < 0.01, "wedge {k} (turned {}°): {deg}° {m} m off", turns[k]);
    }
    // Two featureless planes: no transform to find, said so, naming the
    // scan (exit 2), never a guess.
    let plane = |name: &str, dx: f64, dz: f64| -> OsString {
        let text: String = (0..100)
            .flat_map(|x| (0..100).map(move |y| format!("{} {} {dz}\n", x as f64 * 0.05 + dx, y as f64 * 0.05)))
            .collect();
        let path = dir.path().join(name);
        std::fs::write(&path, text).expect("xyz");
        path.into_os_string()
    };
    let (r, _) = run(
        &[plane("plane1.xyz", 0.0, 0.0), plane("plane2.xyz", 0.001, 0.001), "--init".into(), "global".into()],
        &dir.path().join("planes"),
    );
    assert_eq!(r.code, 2, "{}", r.stderr);
    assert!(r.stderr.contains("plane2.xyz: global registration: no three of its"), "{}", r.stderr);
    // Two planes that do register: blind in the plane, where the start from
    // their shape says nothing — named, exit 1.
    let (r, v) = run(
        &[plane("p1.xyz", 0.0, 0.0), plane("p2.xyz", 0.01, 0.0), "--init".into(), "global".into()],
        &dir.path().join("blind"),
    );
    let v = v.expect("JSON");
    assert_eq!(r.code, 1, "{}", r.stderr);
    assert_eq!(v["blind_without_start"], serde_json::json!([1]), "{v}");
    // Given starts and --init global: one or the other.
    let (r, _) = run(
        &[data("3dtk_dat"), "--init".into(), "global".into(), "--init-poses".into(), data("3dtk_dat/scan000.pose")],
        &dir.path().join("both"),
    );
    assert_eq!(r.code, 2, "{}", r.stderr);
    assert!(r.stderr.contains("not both"), "{}", r.stderr);
}

/// The simulated corridor's 20 scans (`corridor-icp.toml` run with direct
/// fusion, then `match RUN/scans` from the odometry's poses) register within
/// 2 cm of the simulator's truth, and the verification trusts them: pairs
/// matched again on their own slide along the corridor's axis (more than
/// 5 % of their radius — six right scans were named "not trusted", exit 1)
/// where the set's other links hold them; a slide along what a pair sees
/// weakly is not a disagreement, a turn is.
#[test]
fn the_corridor_registers_and_its_slides_along_the_axis_are_not_disagreements() {
    let dir = tempfile::tempdir().expect("temp dir");
    let (run_dir, done) = example_run(
        "corridor-icp.toml",
        &[("mode = \"icp\"", "mode = \"direct\""), ("max_station_error_m = 0.25", "max_station_error_m = 100.0")],
        dir.path(),
    );
    assert_eq!(done.code, 0, "{}", done.stderr);
    let (r, v) = run(&[run_dir.join("scans").into_os_string()], &dir.path().join("out"));
    let v = v.expect("JSON");
    assert_eq!(r.code, 0, "{}: {}", r.stderr, v["checks"]);
    assert_eq!(v["untrusted"], serde_json::json!([]));
    let slid =
        v["checks"].as_array().expect("checks").iter().filter(|c| c["relative_motion"].as_f64() > Some(0.05)).count();
    assert!(slid > 0, "the slides this test is about: {}", v["checks"]);
    let report: Value =
        serde_json::from_str(&std::fs::read_to_string(run_dir.join("report.json")).expect("report")).expect("JSON");
    for (k, s) in v["scans"].as_array().expect("scans").iter().enumerate() {
        let m = pose(&s["world_from_scan"]);
        let truth = &report["stations"][k]["truth"];
        let dx = m.translation.x - truth["x_m"].as_f64().expect("x");
        let dy = m.translation.y - truth["y_m"].as_f64().expect("y");
        assert!(dx.hypot(dy) < 0.02, "scan {k}: {dx} {dy} m off the truth");
    }
}

/// Issue 38, narrow overlaps: small_gicp's outdoor frame (a street) cut
/// into four 150° wedges every 90° — neighbours overlap in 60° sectors of
/// the road and the façades along it — each in a frame of its own, the
/// starts 0.1 m and 2° off. The auto schedule's first stage (0.7 m cells)
/// dragged some of them metres and degrees off with exit 0, or (in
/// simultaneous mode) made the schedule fail with exit 2; the restart from
/// the starts without it lands every one, in graph and simultaneous mode.
#[test]
fn street_wedges_that_the_coarse_stage_dragged_land_by_the_restart() {
    let dir = tempfile::tempdir().expect("temp dir");
    let street = scanner::io::read(Path::new(&data(STREET))).expect("street");
    let truths: Vec<Isometry3<f64>> = (0..4)
        .map(|k| {
            let k = f64::from(k);
            Isometry3::from_parts(
                nalgebra::Translation3::new(0.3 * (1.7 * k).cos(), 0.3 * (1.7 * k).sin(), 0.05 * k),
                UnitQuaternion::from_euler_angles(0.02 * k.sin(), -0.015 * k, (37.0 * k - 50.0).to_radians()),
            )
        })
        .collect();
    let (mut restarted, mut rescued_from_failure) = (0, 0);
    for variant in 0..6 {
        let set = dir.path().join(format!("v{variant}"));
        std::fs::create_dir_all(&set).expect("dir");
        let mut inputs: Vec<OsString> = Vec::new();
        let mut entries = Vec::new();
        for (k, truth) in truths.iter().enumerate() {
            let name = format!("wedge{k}.ply");
            inputs.push(write_wedge(&set.join(&name), &street, k as f32 * 90.0 - 75.0, 150.0, truth));
            // The start: 0.1 m and 2° off the truth, in directions that
            // differ by wedge and variant.
            let a = 2.1 * variant as f64 + 1.3 * k as f64;
            let off = Isometry3::from_parts(
                nalgebra::Translation3::new(0.1 * a.cos() * 0.8, 0.1 * a.sin() * 0.8, 0.06),
                UnitQuaternion::from_axis_angle(
                    &nalgebra::Unit::new_normalize(nalgebra::Vector3::new(a.sin(), a.cos(), 1.0)),
                    2f64.to_radians(),
                ),
            );
            let start = if k == 0 { *truth } else { off * truth };
            entries.push(init_entry(&name, &start.to_homogeneous()));
        }
        let init = set.join("init.json");
        std::fs::write(&init, serde_json::to_string(&entries).expect("JSON")).expect("init");
        inputs.extend(["--init-poses".into(), init.into_os_string()]);
        for mode in ["graph", "simultaneous"] {
            let mut args = inputs.clone();
            args.extend(["--mode".into(), mode.into()]);
            let (r, v) = run(&args, &dir.path().join(format!("o{variant}-{mode}")));
            assert_eq!(r.code, 0, "variant {variant} {mode}: {}", r.stderr);
            let v = v.expect("JSON");
            assert_parts_land(&format!("variant {variant} {mode}"), &v, &truths, 0.15, 0.01);
            restarted += usize::from(v["restart"]["kept"] == true);
            rescued_from_failure += usize::from(v["restart"]["schedule_error"].is_string());
        }
    }
    // The trap this test is about: without the restart these land off.
    // (Variant 5 ended 88° and 3 m off without it in graph mode; in
    // simultaneous mode four variants ended in exit 2 — "0 correspondences
    // within 2.88 m", "do not overlap at stage 2" — and two 33–40 m off.)
    assert!(restarted >= 1, "no variant needed the restart");
    assert!(rescued_from_failure >= 1, "no variant's schedule failed");
}

/// Issue 38, no silent failure without a link graph: one trial of
/// `fusion/benches/covariance_nees.py` (the street's four 150° wedges, the
/// first centred at 78.04°, each under a random transform; the starts
/// 0.1 m / 2° off), its cut and transforms written out here. In pairwise
/// mode the schedule's first stage dragged three wedges 3.1° off together
/// — within the second stage's reach, so no scan "moved" — and the exit
/// was 0. The verification's matches, adjusted together, now disagree
/// more than their covariances allow (variance factor above 1), which
/// sets off the restart without the first stage: it lands them.
#[test]
fn pairwise_wedges_dragged_together_land_by_the_disagreeing_restart() {
    let dir = tempfile::tempdir().expect("temp dir");
    let truths: [[[f64; 4]; 3]; 3] = [
        [
            [0.7930456915029207, -0.6091163719613865, -0.007468373132891266, 0.44240621927702073],
            [0.609034149004219, 0.7930707783752812, -0.010777097658102811, -0.36021542217946045],
            [0.012487455119476267, 0.0039982365892282075, 0.9999140350894249, 0.4170193427783013],
        ],
        [
            [0.7901257098114829, -0.6129447070535261, -0.0003857330260748141, -0.2148180529889514],
            [0.6127433922016287, 0.7898497564792969, 0.026132307644687863, -0.029096546167939663],
            [-0.015712988517194604, -0.020884163489652326, 0.9996584185146424, 0.22684584918469852],
        ],
        [
            [0.9652786956845933, -0.2612164088554377, 0.0017399431366792414, 0.3755743303551009],
            [0.2611624520562932, 0.965178948561356, 0.014958973559029524, -0.32188408695460535],
            [-0.005586885840469761, -0.013985170669826668, 0.9998865944235583, -0.41511252953761524],
        ],
    ];
    let starts: [[[f64; 4]; 3]; 3] = [
        [
            [0.7884818270488575, -0.6150537753261348, 0.0022938767978934165, 0.43224289720833065],
            [0.6150516607227208, 0.7884851522388672, 0.0016184378497640707, -0.35146637487063237],
            [-0.002804114105832278, 0.00013474390129060944, 0.9999960593863171, 0.44109427055621586],
        ],
        [
            [0.7813008870738981, -0.6237394675319279, -0.022759624349429915, -0.2115073838757284],
            [0.6240838927339892, 0.7812415989462367, 0.01344837930452287, 0.011676430382189379],
            [0.009392480371593837, -0.024711145641485487, 0.9996505092248764, 0.22446164422666773],
        ],
        [
            [0.9683035471267679, -0.24961183964269368, 0.00906477423375969, 0.31120286495568084],
            [0.24950189829991035, 0.9683032072795045, 0.011734628965851491, -0.27218379879202353],
            [-0.01170655228750476, -0.00910100447286736, 0.9998900581319552, -0.47347016215795923],
        ],
    ];
    let (mut inputs, truths) = bench_wedges(dir.path(), STREET, 78.035_497_933_699_5, false, &truths, &starts);
    inputs.extend(["--mode".into(), "pairwise".into()]);
    // (Measured 0.04° / 2.5 mm; the trap was 3.1° / 33–55 mm.)
    let v = lands_at_the_defaults("wedges", &inputs, &dir.path().join("out"), &truths, 0.15, 0.01);
    assert_eq!(v["restart"]["trigger"], "disagreeing", "{}", v["restart"]);
    assert_eq!(v["restart"]["kept"], true, "{}", v["restart"]);
    // The restart's result carries its own variance factor, the
    // verification's: its matches agree.
    let factor = v["variance_factor"].as_f64().expect("a variance factor in pairwise mode");
    assert!(factor.is_finite() && factor > 0.0, "{factor}");
    // Each pose's departure from where the verification's matches agree:
    // small for a set that landed, and part of its covariance (ξξᵀ).
    for (k, s) in v["scans"].as_array().expect("scans").iter().enumerate() {
        let d: Vec<f64> =
            s["departure"].as_array().expect("a departure").iter().map(|x| x.as_f64().expect("number")).collect();
        let c = |i: usize| s["covariance"][i][i].as_f64().expect("number");
        let (turn, shift) = (d[..3].iter().map(|x| x * x).sum::<f64>(), d[3..].iter().map(|x| x * x).sum::<f64>());
        if k == 0 {
            assert_eq!(turn + shift, 0.0, "the first scan holds the frame: {s}");
        }
        assert!(turn.sqrt() < 0.15f64.to_radians() && shift.sqrt() < 0.02, "part {k}: {d:?}");
        assert!(turn <= c(0) + c(1) + c(2) && shift <= c(3) + c(4) + c(5), "part {k}: {d:?} beyond its covariance");
    }
}

/// Issue 38, no silent failure: one trial of
/// `fusion/benches/covariance_nees.py` (seed 31, the street's four 150°
/// wedges, the first centred at 23.48°, each point of an overlap dealt to
/// one wedge; starts 0.1 m / 2° off). In simultaneous mode the schedule
/// left wedges 1–3 1.3° and 2.6 m off together, consistently: the
/// verification named nothing, and the restart without the first stage
/// landed them in the same place (the second stage dragged them too) —
/// exit 0. A restart that only repeats the schedule's long move now sets
/// off the further restarts (`restart.repeated`): the schedule without its
/// first two stages lands them, the scans agreeing 1.58× better there.
#[test]
fn a_restart_that_repeats_the_schedules_long_move_is_checked_by_a_shorter_one() {
    let dir = tempfile::tempdir().expect("temp dir");
    let truths: [[[f64; 4]; 3]; 3] = [
        [
            [0.9728122403171706, 0.23158705045540265, 0.0019450322502197715, 0.3563493167248065],
            [-0.23152932254962172, 0.9727014774565963, -0.015684659813589324, -0.0982757490828351],
            [-0.005524299847115028, 0.014807897052639978, 0.9998750963475777, -0.05071517402555492],
        ],
        [
            [0.9121005806739354, -0.4099111197612434, 0.006738295804835703, -0.18959663968411145],
            [0.40995154233569525, 0.9120844971457268, -0.006450038993007301, 0.19370814872911768],
            [-0.0035019524346454074, 0.008645459068798036, 0.9999564952369855, -0.06347145122570375],
        ],
        [
            [0.8615811311919106, -0.5076195261065539, 0.0006091710970878308, 0.22172240444593083],
            [0.5075198878709064, 0.8613869554376267, -0.02088244280248068, 0.16881177551463833],
            [0.010075603682681362, 0.018301085138699894, 0.9997817524305871, -0.10452374613457527],
        ],
    ];
    let starts: [[[f64; 4]; 3]; 3] = [
        [
            [0.9739905659388777, 0.22551056068205788, -0.02207633309517231, 0.3860404179852083],
            [-0.22593638424757842, 0.9739535055423286, -0.01916557630075276, -0.08015272013354593],
            [0.017179282150185677, 0.02365493738468334, 0.9995725667514747, -0.0995581958694494],
        ],
        [
            [0.920507466915959, -0.39070845585655084, 0.003592474656060368, -0.21980390812658723],
            [0.3907231151854834, 0.9204925264554344, -0.005381077907160592, 0.21251539499420918],
            [-0.0012044134324335934, 0.006356985282438638, 0.9999790688441448, -0.07244068685194859],
        ],
        [
            [0.8726413983807253, -0.4880873502341384, 0.01636240732747446, 0.1824867651028517],
            [0.488355031106926, 0.871966916448558, -0.03439564233659288, 0.1597382652927906],
            [0.002520600064655572, 0.038005725366200685, 0.9992743424178883, -0.13745223780489238],
        ],
    ];
    let (mut inputs, truths) = bench_wedges(dir.path(), STREET, 23.478_531_578_008_702, true, &truths, &starts);
    inputs.extend(["--mode".into(), "simultaneous".into()]);
    // (Measured 0.007° / 1.5 mm; the trap was 1.3° / 2.6 m.)
    let v = lands_at_the_defaults("wedges", &inputs, &dir.path().join("out"), &truths, 0.1, 0.01);
    let restart = &v["restart"];
    assert_eq!(restart["trigger"], "moved", "{restart}");
    assert_eq!(restart["repeated"], true, "{restart}");
    // The restart is the schedule's fit again (measured 1.3e-4 apart).
    let f = |x: &Value| x.as_f64().expect("a number");
    let (before, after) = (f(&restart["schedule_disagreement_m2"]), f(&restart["restart_disagreement_m2"]));
    assert!((before - after).abs() < 1e-3 * before && restart["kept"] == false, "{restart}");
    // The first further restart lands the wedges, 1.5× better: kept.
    let further = restart["further"].as_array().expect("further");
    let kept = further.iter().find(|x| x["kept"] == true).expect("a further restart kept");
    let a = f(&kept["disagreement_m2"]);
    assert!(before > fusion::scanset::RESTART_RATIO * a, "{a} against {before}");
    assert_eq!(kept["untrusted"].as_array().map(Vec::len), Some(0), "{kept}");
    // Without it the text names the reason the further restarts ran.
    let text = run_text(&inputs, &dir.path().join("text"));
    assert!(text.stdout.contains("the restart only repeated the schedule's long move"), "{}", text.stdout);
}

/// Issue 38, no silent failure: one trial of
/// `fusion/benches/covariance_nees.py` (seed 71, the street's four 150°
/// wedges, the first centred at 35.88°, each point of an overlap dealt to
/// one wedge; starts 0.1 m / 2° off). In graph mode the schedule moved
/// part3 2.73 m and left wedges 1–3 2.4° and 1.8 m off together, the
/// loop's closing link rejected (a tree: σ̂₀² 1), nothing named; the
/// restart repeated it (`restart.repeated`), and so did the schedule
/// without its first two stages — its own first stage dragged them as
/// far —, which was taken as corroboration: exit 0. Every shorter schedule
/// now runs after a repeated one: the last two stages and the finest alone
/// land the wedges, the scans agreeing 1.45× better — under the 1.5×, so
/// the two registrations are judged as undecided scans are: the better
/// kept, and trusted because the other shorter schedule lands there too.
#[test]
fn a_repeated_schedule_that_a_shorter_one_only_drags_as_far_is_not_corroborated_by_it() {
    let dir = tempfile::tempdir().expect("temp dir");
    let truths: [[[f64; 4]; 3]; 3] = [
        [
            [0.7864691467058539, 0.617544698895412, 0.010238464042082313, -0.2518128764001131],
            [-0.6174973822432777, 0.7865357281565862, -0.007650572258859579, -0.17904830580050957],
            [-0.012777488112519268, -0.0003052857079409645, 0.9999183179631079, -0.3893789674317456],
        ],
        [
            [0.881980940921759, -0.4712309486402052, -0.007142331161502345, -0.2550324730581328],
            [0.4712298361293295, 0.8820083134334005, -0.0019433414248780927, 0.17096949678656292],
            [0.0072153580849166135, -0.00165168944436995, 0.9999726048895968, 0.4023464681588208],
        ],
        [
            [0.7754496264151373, -0.6312403873793958, 0.014609936130396833, -0.09411584627132208],
            [0.6312067099514597, 0.7755794021321633, 0.0073946129425465626, -0.4671337600225358],
            [-0.015998943867576044, 0.003487739873686505, 0.9998659257448949, -0.07570317128496751],
        ],
    ];
    let starts: [[[f64; 4]; 3]; 3] = [
        [
            [0.8119681142231392, 0.5836977823537474, -0.0021634140233539882, -0.24618992937529896],
            [-0.5836242817912144, 0.8117943172945843, -0.019305028150949078, -0.22043467861458987],
            [-0.009512054909871477, 0.01693768825834777, 0.9998112999600748, -0.3872162059340373],
        ],
        [
            [0.8594039355700958, -0.5107532435596602, -0.023579646306011396, -0.24791544869061977],
            [0.5111423583413183, 0.8593645542477645, 0.015035039468402431, 0.1417661899971614],
            [0.012584317061551342, -0.02497372811230561, 0.9996088974535324, 0.4334737073908421],
        ],
        [
            [0.7965535980015493, -0.6045226815300195, -0.007395473381785575, -0.053324153313375436],
            [0.6045237082891167, 0.7962878260659905, 0.021835388145716214, -0.5083268231081955],
            [-0.007311061972186231, -0.021863795984541065, 0.9997342260811046, -0.12679670745169913],
        ],
    ];
    let (mut inputs, truths) = bench_wedges(dir.path(), STREET, 35.876_229_613_760_266, true, &truths, &starts);
    inputs.extend(["--mode".into(), "graph".into()]);
    lands_at_the_defaults("wedges", &inputs, &dir.path().join("estimated"), &truths, 0.1, 0.01);
    let inputs = without_estimates(&inputs);
    // (Measured 0.03° / 4 mm; the trap was 2.4° / 1.8 m.)
    let v = lands_at_the_defaults("wedges", &inputs, &dir.path().join("out"), &truths, 0.1, 0.01);
    let restart = &v["restart"];
    assert_eq!(restart["trigger"], "moved", "{restart}");
    assert_eq!(restart["repeated"], true, "{restart}");
    let f = |x: &Value| x.as_f64().expect("a number");
    let before = f(&restart["schedule_disagreement_m2"]);
    // The first further restart lands where the schedule did (its own
    // first stage dragged the wedges beyond its second stage's reach);
    // the later ones land apart from it, the scans agreeing better, but
    // not 1.5× better (measured 1.45×).
    let further = restart["further"].as_array().expect("further");
    assert_eq!(further.len(), 3, "{restart}");
    let (dragged, reach) = (f(&further[0]["moved_m"]), f(&further[0]["stages"][1]["max_correspondence_m"]));
    assert!(dragged > reach && (f(&further[0]["disagreement_m2"]) - before).abs() < 1e-3 * before, "{restart}");
    for x in &further[1..] {
        let a = f(&x["disagreement_m2"]);
        assert!(a < before && before < fusion::scanset::RESTART_RATIO * a, "{a} against {before}");
    }
    // One of them kept, verified; the wedges it moves are undecided, and
    // corroborated by the other.
    let kept: Vec<&Value> = further.iter().filter(|x| x["kept"] == true).collect();
    assert_eq!(kept.len(), 1, "{restart}");
    assert_eq!(kept[0]["untrusted"].as_array().map(Vec::len), Some(0), "{restart}");
    let undecided: Vec<u64> =
        restart["undecided"].as_array().expect("undecided").iter().map(|u| u["scan"].as_u64().expect("scan")).collect();
    assert_eq!(undecided, [1, 2, 3], "{restart}");
    assert_eq!(restart["corroborated"], true, "{restart}");
    let text = run_text(&inputs, &dir.path().join("text"));
    assert!(
        text.stdout.contains("the schedule's (the restart repeated it) and a shorter schedule's registrations place"),
        "{}",
        text.stdout
    );
}

/// Issue 38, no silent failure: one trial of
/// `fusion/benches/covariance_nees.py` (seed 41, the street's four 150°
/// wedges, the first centred at 126.50°, each point of an overlap dealt to
/// one wedge; starts 0.1 m / 2° off). In simultaneous mode the schedule's
/// first stage was abandoned at its cap and left wedges 1–3 1.43 m along
/// the street together — within the second stage's reach of their starts,
/// the verification naming nothing, the variance factor below 1: no
/// restart, exit 0. A queue abandoned at its cap now sets off the restart
/// (`restart.trigger` "abandoned"): without that stage the wedges land,
/// the scans agreeing 1.83× better there than at the schedule's result.
#[test]
fn a_schedule_whose_queue_was_abandoned_at_its_cap_is_checked_by_a_restart() {
    let dir = tempfile::tempdir().expect("temp dir");
    let truths: [[[f64; 4]; 3]; 3] = [
        [
            [0.8090627804950588, 0.5877191156379142, 0.0019126764997020543, -0.43053648055711125],
            [-0.587689733894345, 0.8089795436401612, 0.01314818036652522, 0.49066805663896784],
            [0.006180120775401752, -0.011761763708927305, 0.999911729614998, 0.00856421209114977],
        ],
        [
            [0.9897181798214825, -0.1430220431602255, 0.0016185490805966638, -0.44653968653090914],
            [0.14295570763594856, 0.9895000720296213, 0.02129021154614192, -0.000167068934762149],
            [-0.004646523986476515, -0.020839928590301683, 0.9997720276098918, -0.014299527582064542],
        ],
        [
            [0.9301827586658685, 0.36705039179978133, 0.005834840219017219, 0.18484480226478983],
            [-0.36705996808176483, 0.9301970691401755, 0.000626414272674382, 0.10428390444295166],
            [-0.005197625666416929, -0.002724416020778595, 0.9999827809741413, 0.1794167332803781],
        ],
    ];
    let starts: [[[f64; 4]; 3]; 3] = [
        [
            [0.82022320805641, 0.5720181327232828, 0.005398592540653404, -0.3891525762396344],
            [-0.5719648102062701, 0.8199170662289413, 0.024336400560301678, 0.45432579165863796],
            [0.00949446424801166, -0.023049085498012264, 0.9996892491201197, 0.014081991562116234],
        ],
        [
            [0.9877694669144064, -0.1559141962472959, 0.0014978785628762534, -0.393410226358321],
            [0.15584730218709722, 0.9875506644404639, 0.02133784347589814, 0.027788100466107725],
            [-0.0048061036852148345, -0.020843429942262796, 0.9997712002231355, 0.02632882218207442],
        ],
        [
            [0.932604282643814, 0.36083671704290593, 0.006790848850826345, 0.22761717402482481],
            [-0.36083672087662155, 0.9326281438371662, -0.0012673554548682847, 0.0872396885341159],
            [-0.006790645140486021, -0.0012684465064588027, 0.9999761388063398, 0.14999661527296448],
        ],
    ];
    let (mut inputs, truths) = bench_wedges(dir.path(), STREET, 126.503_358_111_421_6, true, &truths, &starts);
    inputs.extend(["--mode".into(), "simultaneous".into()]);
    // With the wedges' scanners estimated from their spacing, the free
    // space names the schedule's trap at once, and the restart lands them.
    let v = lands_at_the_defaults("wedges", &inputs, &dir.path().join("estimated"), &truths, 0.1, 0.01);
    assert_eq!(v["restart"]["trigger"], "untrusted", "{}", v["restart"]);
    // Without them, the abandoned queue alone sets the restart off.
    let inputs = without_estimates(&inputs);
    // (Measured 0.018° / 0.7 mm; the trap was 0.13° / 1.43 m.)
    let v = lands_at_the_defaults("wedges", &inputs, &dir.path().join("out"), &truths, 0.1, 0.01);
    // The schedule's first stage was abandoned, and nothing else set the
    // restart off: no scan beyond the second stage's reach.
    let stages = v["stages"].as_array().expect("stages");
    assert_eq!(stages[0]["settled"], false, "{}", v["stages"]);
    let restart = &v["restart"];
    assert_eq!(restart["trigger"], "abandoned", "{restart}");
    let f = |x: &Value| x.as_f64().expect("a number");
    assert!(f(&restart["moved_m"]) < f(&stages[1]["max_correspondence_m"]), "{restart}");
    assert_eq!(restart["schedule_untrusted"].as_array().map(Vec::len), Some(0), "{restart}");
    // Kept by the disagreement (measured 1.83×: 0.0170 against 0.0093).
    let (before, after) = (f(&restart["schedule_disagreement_m2"]), f(&restart["restart_disagreement_m2"]));
    assert!(before > fusion::scanset::RESTART_RATIO * after && restart["kept"] == true, "{restart}");
    let text = run_text(&inputs, &dir.path().join("text"));
    assert!(
        text.stdout.contains("a simultaneous queue of the schedule was abandoned at its iteration cap"),
        "{}",
        text.stdout
    );
}

/// Issue 38, no silent failure: one trial of
/// `fusion/benches/covariance_nees.py` (seed 23, the street's four 150°
/// wedges, the first centred at 55.09°, each point of an overlap dealt to
/// one wedge; starts 0.1 m / 2° off) where simultaneous matching settles
/// in a compromise of its metascan matches, 0.19–0.68° and 16–25 mm off,
/// and ended there with exit 0 before session 39: each pair, matched again
/// alone from the final poses, moves under 2.4 % of its radius (as right
/// real pairs do), so the verification named none, and the restart (set
/// off by the disagreeing links) landed them but was passed over, the
/// scans agreeing with it only 1.01× better. The poses' departure from
/// where the verified pairs agree is the miss, and thousands of that
/// agreement's σ² (right poses: at most 768): the verification names the
/// schedule's scans, and the restart, which it names nothing of, is kept.
#[test]
fn a_simultaneous_compromise_apart_from_where_its_pairs_agree_is_named_and_the_restart_kept() {
    let dir = tempfile::tempdir().expect("temp dir");
    let truths: [[[f64; 4]; 3]; 3] = [
        [
            [0.9747033395693688, 0.22348832122347528, 0.0025239074928216174, 0.2668577280362795],
            [-0.2234772489523392, 0.9747007468292201, -0.0040463973179586535, -0.09310407994409431],
            [-0.0033643770617748387, 0.003380001075932875, 0.9999886282151977, 0.19477108426433876],
        ],
        [
            [0.8472492597503067, 0.5311954891242905, 0.00021020600145812748, 0.15383244837831],
            [-0.5311955285448389, 0.8472492257273975, 0.00024486382926328586, -0.1707426856298082],
            [-4.802631042428238e-05, -0.0003191211861307932, 0.9999999479275697, -0.48339989162643004],
        ],
        [
            [0.8460141079103489, 0.5331521504460278, 0.0029855805855260836, 0.4794585665872546],
            [-0.533159655348572, 0.84600951293635, 0.0029471901519910115, 0.29225235981710673],
            [-0.0009545288096857591, -0.0040851555632733195, 0.999991200150669, 0.21372525833605216],
        ],
    ];
    let starts: [[[f64; 4]; 3]; 3] = [
        [
            [0.9716182210958336, 0.23628756144752183, 0.011234800387685599, 0.25866656180182535],
            [-0.23587929640289312, 0.9713374464625218, -0.02940276565467355, -0.06371693640604285],
            [-0.017860290116446416, 0.025918206050017382, 0.999504505558682, 0.2127771685359245],
        ],
        [
            [0.8295853687528992, 0.558195608670817, 0.014344978624324206, 0.10871994787522857],
            [-0.5582578962011921, 0.8296673744973732, 0.00041112486525356884, -0.21531129732022614],
            [-0.011672072658064081, -0.008349260760811146, 0.9998970209799672, -0.45169207529967925],
        ],
        [
            [0.8309188324208125, 0.556317742462291, -0.009190394447128438, 0.4466361809456569],
            [-0.5561839760607019, 0.8309458140148304, 0.013727306528950687, 0.2705729551402739],
            [0.01527346397326025, -0.006294727388148263, 0.9998635395419548, 0.1814575444544122],
        ],
    ];
    let (mut inputs, truths) = bench_wedges(dir.path(), STREET, 55.091_036_479_109_38, true, &truths, &starts);
    inputs.extend(["--mode".into(), "simultaneous".into()]);
    // (Measured 0.05–0.07°, 1–6 mm.)
    let v = lands_at_the_defaults("wedges", &inputs, &dir.path().join("out"), &truths, 0.15, 0.01);
    let restart = &v["restart"];
    assert_eq!(restart["trigger"], "disagreeing", "{restart}");
    assert_eq!(restart["kept"], true, "{restart}");
    // The schedule's compromise named by its departure alone: every pair
    // matched again agreed with it. (part3, 0.19° off, departed 3,022 σ²
    // but moved its points less than the finest voxel.)
    assert_eq!(restart["schedule_untrusted"], serde_json::json!([1, 2]), "{restart}");
    assert_eq!(restart["restart_untrusted"], serde_json::json!([]), "{restart}");
    for k in 1..4 {
        let departure = v["scans"][k]["departure_chi2"].as_f64().expect("a departure's χ²");
        // (`fusion::verify::MAX_DEPARTURE_CHI2`; measured 48–105, the
        // points moved 8–11 mm, under the finest voxel's 40 mm.)
        assert!(departure < 1500.0, "part {k}: {departure}");
        let moved = v["scans"][k]["departure_m"].as_f64().expect("a departure's motion");
        assert!(moved < 0.02, "part {k}: {moved} m");
    }
}

/// Issue 38, no silent failure when two registrations disagree and the
/// data barely choose: one trial of `fusion/benches/covariance_nees.py`
/// (the street's four 150° wedges, the first centred at 88.51°, each
/// point of an overlap dealt to one wedge as two real scans share none;
/// starts 0.1 m / 2° off). In pairwise mode the schedule left all three
/// wedges 5.9° off together with exit 0; the restart (set off by the
/// disagreeing matches) landed them within 0.05°, but the scans agreed
/// with it only 1.42× better — not the 1.5× that keeps a restart. Two
/// registrations 0.9–1.0 m and 5.9° apart (`restart.undecided`): from
/// session 29 the three wedges were named, exit 1, with the right poses.
/// Every further restart from the starts (three: without the first two
/// stages, three, four) lands where the restart did — the schedule's is
/// the one only its coarse first stage reaches: `restart.corroborated`,
/// nothing named, exit 0 (session 35). Since the verification matches
/// its pairs both ways in the modes without a link graph (session 37,
/// for the covariances that rest on them), it names the schedule's
/// part3 itself: the restart is kept as the one nothing names, the
/// further restarts still land where it did, exit 0.
#[test]
fn registrations_the_data_barely_choose_between_are_settled_by_the_verification() {
    let dir = tempfile::tempdir().expect("temp dir");
    let truths: [[[f64; 4]; 3]; 3] = [
        [
            [0.88361780724401, -0.46818602691281247, -0.004627626268717256, -0.12348214314341532],
            [0.4681050086364385, 0.8835867923596431, -0.012332122975256554, -0.26569526453380565],
            [0.009862637110200682, 0.00873066842757557, 0.9999132481460781, 0.07714069238940224],
        ],
        [
            [0.7149898540608821, -0.6991348257943026, 6.286150288727575e-05, 0.17034717970836588],
            [0.6991348280708386, 0.7149898470439069, -0.00010393502499454768, -0.05548146402800158],
            [2.7719259259142133e-05, 0.00011826115436604147, 0.9999999926229709, 0.1689648077818653],
        ],
        [
            [0.8654881531006351, 0.5006641063390946, 0.016300597109535294, -0.26971157715792027],
            [-0.5007811150663999, 0.8655654449556355, 0.003838657526499643, 0.0728551031506085],
            [-0.012187355550110695, -0.011485343809757234, 0.9998597677885969, 0.4466843969832247],
        ],
    ];
    let starts: [[[f64; 4]; 3]; 3] = [
        [
            [0.8600986669830091, -0.509896981821779, -0.015341153251676318, -0.15714018686739833],
            [0.5093304985704672, 0.8600467441391784, -0.030033999426620727, -0.2962296794489899],
            [0.028508354565115312, 0.018018485636682735, 0.9994311421480473, 0.016925385783371126],
        ],
        [
            [0.7219296498695894, -0.6918313553791356, -0.013673198361762067, 0.21064860865008875],
            [0.6916855830034133, 0.7220586659648341, -0.014224527068127196, -0.08684298289557618],
            [0.019713825209736094, 0.0008115536654768185, 0.9998053342907548, 0.21301209248494873],
        ],
        [
            [0.8745402167616155, 0.4845573016051697, 0.019586493500951922, -0.2958209532031364],
            [-0.48442663730170277, 0.8747594491353661, -0.011257851524838783, 0.07551202121528125],
            [-0.022588544422133656, 0.0003572247296048229, 0.999744782457694, 0.472462894285128],
        ],
    ];
    let (mut inputs, truths) = bench_wedges(dir.path(), STREET, 88.506_831_693_977_05, true, &truths, &starts);
    inputs.extend(["--mode".into(), "pairwise".into()]);
    lands_at_the_defaults("wedges at the defaults", &inputs, &dir.path().join("defaults"), &truths, 0.15, 0.01);
    let inputs = corners_off(&inputs);
    let (r, v) = run(&inputs, &dir.path().join("out"));
    assert_eq!(r.code, 0, "{}\n{}", r.stdout, r.stderr);
    let v = v.expect("JSON");
    let restart = &v["restart"];
    assert_eq!(restart["trigger"], "disagreeing", "{restart}");
    // part3 by its pairs; part1 and part2, 5.9° off with it, by their
    // departure from where their pairs agree (session 39).
    assert_eq!(restart["schedule_untrusted"], serde_json::json!([1, 2, 3]), "{restart}");
    assert_eq!(restart["restart_untrusted"], serde_json::json!([]), "{restart}");
    assert_eq!(restart["undecided"], serde_json::json!([]), "{restart}");
    let further = restart["further"].as_array().expect("further restarts");
    assert_eq!(further.len(), 3, "{restart}");
    for f in further {
        // Not kept (no better than the restart), each where it landed.
        // (Measured 5.5866e-3–5.5871e-3 m² a point.)
        let a = f["disagreement_m2"].as_f64().expect("further's");
        let kept = restart["restart_disagreement_m2"].as_f64().expect("restart's");
        assert!(f["kept"] == false && (a / kept - 1.0).abs() < 1e-3, "{restart}");
    }
    assert_eq!(v["untrusted"], serde_json::json!([]), "{}", v["untrusted"]);
    let (schedule, restarted) = (
        restart["schedule_disagreement_m2"].as_f64().expect("schedule's"),
        restart["restart_disagreement_m2"].as_f64().expect("restart's"),
    );
    assert!(schedule > restarted && schedule <= 1.5 * restarted, "{restart}");
    assert_eq!(restart["kept"], true, "{restart}");
    // (Measured 0.005–0.041° / 0.4–1.6 mm; the schedule's 5.9° / 77 mm.)
    assert_parts_land("wedges", &v, &truths, 0.15, 0.01);
    // The text says why.
    let text = run_text(&inputs, &dir.path().join("text"));
    assert_eq!(text.code, 0, "{}", text.stderr);
    assert!(
        text.stdout.contains(
            "the verification names none there against part1, part2, part3 at the schedule's poses: its poses kept"
        ) && !text.stdout.contains("not trusted"),
        "{}",
        text.stdout
    );
}

/// Issue 38, "no silent failure", a slide along a street: the bench's
/// street wedges (`fusion/benches/covariance_nees.py`, `NEES_PARTS=2`, 16
/// trials, graph mode, trial 12) from starts 0.1 m / 2° off. The auto
/// schedule slid part3 1.2 m along the street, and the restart without
/// its first stage landed the same poses (its second stage slid it alike);
/// its links agree with the cycle they close, their residuals 3–4× the
/// set's others — exit 0. The scans agree 1.11× worse there than at the
/// starts: a further restart from the starts without the first two stages
/// lands every part, the scans agreeing 2× better, exit 0. Given as PCD
/// with each part's scanner position (VIEWPOINT: where the LiDAR stood, in
/// the part's frame) the verification also names part3 at the schedule's
/// poses (part0's and part2's points where its scanner saw through), and
/// the same further restart lands it. (That with the corner test off; at
/// the defaults the same slide left a tree of links and a pair creeping at
/// its cap, and no restart ran — session 56, below.)
#[test]
fn a_slide_along_the_street_lands_by_a_further_restart() {
    let dir = tempfile::tempdir().expect("temp dir");
    let truths: [[[f64; 4]; 3]; 3] = [
        [
            [0.9355299227322029, -0.35321674406827874, 0.004657830233316952, 0.44289659526088265],
            [0.3532233794826053, 0.935538779043406, -0.0006611299876453393, -0.4209439536071726],
            [-0.0041240586278268295, 0.0022637614223262287, 0.999988933701097, 0.3600854021545682],
        ],
        [
            [0.9125997540201193, 0.4087493708069689, -0.009254232940917246, 0.41606880372053623],
            [-0.40872950394712415, 0.9126466682957399, 0.0040313089466690565, 0.21562496447122315],
            [0.010093639856640293, 0.00010350648624298066, 0.9999490525626051, -0.3865212889413653],
        ],
        [
            [0.984595364782294, -0.1747212381678178, -0.006667576945664116, 0.42917536420935976],
            [0.1748216764823656, 0.9843956259781234, 0.020065716708698025, 0.15777475068560343],
            [0.0030576267131159074, -0.020922248642134874, 0.9997764302235974, 0.4885192866633046],
        ],
    ];
    let starts: [[[f64; 4]; 3]; 3] = [
        [
            [0.935273213459791, -0.3535205727365802, 0.016947590878830174, 0.49847792510423544],
            [0.35360089762518737, 0.9353944518786708, -0.0019038364590639322, -0.43445252544875107],
            [-0.015179637125362262, 0.007773290590309396, 0.9998545667096495, 0.33017789509110707],
        ],
        [
            [0.9285904092664707, 0.37104209473433847, -0.0069004169064135765, 0.42321219130755283],
            [-0.3710093119770911, 0.9286123217660273, 0.005589838154517823, 0.2717286521815087],
            [0.008481877422696474, -0.0026305511708334213, 0.9999605682005286, -0.41459630774135403],
        ],
        [
            [0.9820600020058988, -0.1877469432418765, -0.017585157477420215, 0.38923401018061005],
            [0.18803021825903216, 0.982030749571977, 0.01613207725501014, 0.1403306337521057],
            [0.014240417186122243, -0.019149208820013325, 0.9997152186097461, 0.453962863080858],
        ],
    ];
    let (inputs, truths) = bench_wedges(dir.path(), STREET, 284.010_844_289_681_24, true, &truths, &starts);
    // The same parts as ASCII PCD, each with its scanner's position (the
    // street frame's origin) in its own frame; the starts as they were.
    let mut pcds: Vec<OsString> = Vec::new();
    let mut entries: Value = serde_json::from_str(&std::fs::read_to_string(&inputs[5]).expect("init")).expect("JSON");
    for (k, truth) in truths.iter().enumerate() {
        let part = scanner::io::read(Path::new(&inputs[k])).expect("part");
        let at = truth.inverse() * Point3::origin();
        let mut text = format!(
            "VERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\nWIDTH {n}\nHEIGHT 1\n\
             VIEWPOINT {} {} {} 1 0 0 0\nPOINTS {n}\nDATA ascii\n",
            at.x,
            at.y,
            at.z,
            n = part.points.len()
        );
        for p in &part.points {
            text.push_str(&format!("{} {} {}\n", p.x, p.y, p.z));
        }
        let path = dir.path().join(format!("part{k}.pcd"));
        std::fs::write(&path, text).expect("PCD");
        entries[k]["file"] = format!("part{k}.pcd").into();
        pcds.push(path.into_os_string());
    }
    let init = dir.path().join("init-pcd.json");
    std::fs::write(&init, entries.to_string()).expect("init");
    pcds.extend(["--init-poses".into(), init.into_os_string()]);
    // At the defaults (the corner test on) the schedule slid part3 1.2 m
    // along the street as well, but its link to part2 stopped at the
    // iteration cap and was rejected: the links left were a tree (σ̂₀² 1),
    // and the verification's match of that pair, creeping 0.83 m and 3.7°
    // at its cap — within the tiers of a weak slide —, was taken for
    // agreement: exit 0, nothing named, no restart (session 56). A pair
    // still creeping at its cap, where the scans agree no better than at
    // their starts, sets the restarts off: a further restart lands it.
    // (With the parts' scanners estimated from their spacing the free
    // space names the slide at once; below, as PCD with the scanners'
    // positions stated, the same.)
    let v = lands_at_the_defaults("wedges, estimated", &inputs, &dir.path().join("estimated"), &truths, 0.1, 0.01);
    assert_eq!(v["restart"]["trigger"], "untrusted", "{}", v["restart"]);
    let inputs = without_estimates(&inputs);
    let (r, v) = run(&inputs, &dir.path().join("defaults"));
    let v = v.unwrap_or_else(|| panic!("{}", r.stderr));
    assert_eq!(r.code, 0, "{}\n{}", r.stdout, r.stderr);
    let restart = &v["restart"];
    assert_eq!(restart["trigger"], "creeping", "{restart}");
    let (starts, schedule) = (
        restart["starts_disagreement_m2"].as_f64().expect("starts'"),
        restart["schedule_disagreement_m2"].as_f64().expect("schedule's"),
    );
    assert!(schedule >= starts, "{restart}");
    let further = restart["further"].as_array().expect("further restarts");
    assert!(further.iter().any(|f| f["kept"] == true && f["untrusted"] == serde_json::json!([])), "{restart}");
    assert_parts_land("wedges at the defaults", &v, &truths, 0.1, 0.01);
    let text = run_text(&inputs, &dir.path().join("defaults-text"));
    assert!(text.stdout.contains("a pair matched again from the schedule's poses still moves at its iteration cap"));
    let (inputs, pcds) = (corners_off(&inputs), corners_off(&pcds));
    for (inputs, named) in [(&inputs, serde_json::json!([])), (&pcds, serde_json::json!([3]))] {
        let (r, v) = run(inputs, &dir.path().join(format!("out{}", named.as_array().map_or(0, Vec::len))));
        let v = v.expect("JSON");
        assert_eq!(r.code, 0, "{}\n{}", r.stdout, r.stderr);
        assert_eq!(v["untrusted"], serde_json::json!([]), "{}", v["restart"]);
        let restart = &v["restart"];
        // The schedule's slide — named by free space where the scanners'
        // positions are known —, agreeing worse than the starts; the
        // restart without the first stage the same poses; a further
        // restart kept.
        assert_eq!(restart["schedule_untrusted"], named, "{restart}");
        let (starts, schedule) = (
            restart["starts_disagreement_m2"].as_f64().expect("starts'"),
            restart["schedule_disagreement_m2"].as_f64().expect("schedule's"),
        );
        // (Measured 9.60e-3 and 1.067e-2 m² a point.)
        assert!(schedule > starts, "{restart}");
        assert_eq!(restart["kept"], false, "{restart}");
        let further = restart["further"].as_array().expect("further restarts");
        let kept: Vec<&Value> = further.iter().filter(|f| f["kept"] == true).collect();
        assert_eq!(kept.len(), 1, "{restart}");
        assert_eq!(kept[0]["untrusted"], serde_json::json!([]), "{restart}");
        let landed = kept[0]["disagreement_m2"].as_f64().expect("further's");
        // (Measured 5.38e-3 m² a point.)
        assert!(schedule > 1.5 * landed, "{restart}");
        // (Measured within 0.02° / 2 mm; the schedule's part3 1.2 m off.)
        assert_parts_land("wedges", &v, &truths, 0.1, 0.01);
    }
}

/// The building example run into `dir` (no `.rrd`): its scans'
/// directory and the simulator's truth at each scan (position, heading
/// and tilt).
fn building_scans(dir: &Path) -> (OsString, Vec<Isometry3<f64>>) {
    let (run_dir, done) = example_run("building.toml", &[], dir);
    assert_eq!(done.code, 0, "{}", done.stderr);
    let journal = std::fs::read_to_string(run_dir.join("journal.jsonl")).expect("journal");
    let truths: Vec<Isometry3<f64>> = journal
        .lines()
        .map(|l| serde_json::from_str::<Value>(l).expect("JSON line"))
        .filter(|e| e["event"] == "scan")
        .map(|e| {
            let t = &e["sim"]["truth"];
            let p: Vec<f64> = serde_json::from_value(t["parent"].clone()).expect("parent");
            let tilt: Vec<f64> = serde_json::from_value(t["tilt"].clone()).expect("tilt");
            scanner::Tilt { roll_rad: tilt[0], pitch_rad: tilt[1] }
                .world_from_body(&cps::ParentPose::new(p[0], p[1], p[2], p[3]))
        })
        .collect();
    assert_eq!(truths.len(), 13, "the building's stations");
    (run_dir.join("scans").into(), truths)
}

/// Each scan's offset from its truth (`truths`) in a `match --json`
/// report, metres: scan 0 holds the frame at its start, and each truth is
/// carried into that frame.
fn scan_offsets(v: &Value, truths: &[Isometry3<f64>]) -> Vec<f64> {
    let poses: Vec<Isometry3<f64>> =
        v["scans"].as_array().expect("scans").iter().map(|s| pose(&s["world_from_scan"])).collect();
    let frame = poses[0] * truths[0].inverse();
    poses.iter().zip(truths).map(|(p, t)| (p.translation.vector - (frame * t).translation.vector).norm()).collect()
}

/// Issue 38: the building example's own thirteen scans (a façade every
/// 20 m, seen from 7.5 m — at grazing angles in sparse columns, whose
/// normals rough the point-to-plane cost along the wall), from starts
/// within 4 mm of the truth (the CPS's). The schedule slid the scans
/// 0.1–0.5 m along the walls and the scans agreed no better there than
/// at their starts; the restart and the further restarts were each
/// within 1.5× of the best, so the slid poses stood (exit 0, scans up to
/// 0.46 m off, σ 43–121 mm). Now a further restart that moves the scans
/// less is kept: the finest stage alone, every scan within 0.12 m. (That
/// with the corner test off; at the defaults the schedule lands them.)
#[test]
fn a_registration_the_scans_agree_with_no_better_than_their_starts_gives_way_to_one_nearer_them() {
    let dir = tempfile::tempdir().expect("temp dir");
    let (scans, truths) = building_scans(dir.path());
    let offsets = |v: &Value| scan_offsets(v, &truths);
    let (r, v) = run(&corners_off(std::slice::from_ref(&scans)), &dir.path().join("out"));
    let v = v.unwrap_or_else(|| panic!("{}", r.stderr));
    assert_eq!(r.code, 0, "{}", r.stderr);
    assert_eq!(v["untrusted"], serde_json::json!([]));
    let restart = &v["restart"];
    let starts = restart["starts_disagreement_m2"].as_f64().expect("starts'");
    let schedule = restart["schedule_disagreement_m2"].as_f64().expect("schedule's");
    // (Measured 4.67e-2 and 4.78e-2 m² a point.)
    assert!(schedule >= starts, "{restart}");
    let further = restart["further"].as_array().expect("further restarts");
    let last = further.last().expect("a further restart");
    assert_eq!((last["kept"].as_bool(), last["nearer_starts"].as_bool()), (Some(true), Some(true)), "{restart}");
    assert_eq!(last["stages"].as_array().map(Vec::len), Some(1), "the finest stage alone: {restart}");
    // (Measured 0.13 m against the schedule's 0.72 m.)
    let moved = last["moved_m"].as_f64().expect("moved");
    assert!(moved < 0.5 * restart["moved_m"].as_f64().expect("schedule's move"), "{restart}");
    for (k, off) in offsets(&v).iter().enumerate() {
        // (Measured 4–118 mm; up to 0.46 m before.)
        assert!(*off < 0.15, "scan {k}: {off:.3} m from the truth");
    }
    // With the pairs whose normals disagree by more than 18° left out
    // (`--normal-agreement 18`: the far façade's columns, whose normals
    // stand across the wall), the cost along the walls no longer bumps.
    let (r, _) = run(&[scans.clone(), "--normal-agreement".into(), "90".into()], &dir.path().join("bad"));
    assert_eq!(r.code, 2, "{}", r.stderr);
    assert!(r.stderr.contains("--normal-agreement 90: expected degrees in [0, 90) (0: off)"), "{}", r.stderr);
    let args = [scans.clone(), "--normal-agreement".into(), "18".into()];
    let (r, v) = run(&args, &dir.path().join("agreeing"));
    let v = v.unwrap_or_else(|| panic!("{}", r.stderr));
    assert_eq!(r.code, 0, "{}", r.stderr);
    assert!(
        v["settings"]["normal_agreement_deg"].as_f64().is_some_and(|d| (d - 18.0).abs() < 1e-9),
        "{}",
        v["settings"]
    );
    for (k, off) in offsets(&v).iter().enumerate() {
        // (Measured 2–54 mm.)
        assert!(*off < 0.07, "scan {k}: {off:.3} m from the truth with --normal-agreement 18");
    }
    // With the pairs whose target normal's neighbourhood is no one plane
    // left out (`--corner-ratio 0.1`, the default: the ground's normals at
    // the walls' feet, tilted towards the scanner that saw them), the
    // scans land nearer still on average — judged where the scans are sparse (the
    // ten nearest points reaching beyond the stage's correspondence
    // distance) or everywhere (`--corner-everywhere`), alike.
    let (r, _) = run(&[scans.clone(), "--corner-ratio".into(), "1.5".into()], &dir.path().join("bad"));
    assert_eq!(r.code, 2, "{}", r.stderr);
    assert!(r.stderr.contains("--corner-ratio 1.5: expected a ratio in [0, 1] (0: off)"), "{}", r.stderr);
    let args = [scans.clone(), "--corner-ratio".into(), "0".into(), "--corner-everywhere".into()];
    let (r, _) = run(&args, &dir.path().join("bad"));
    assert_eq!(r.code, 2, "{}", r.stderr);
    assert!(r.stderr.contains("--corner-everywhere widens the corner test: it needs --corner-ratio above 0"));
    // (Measured 34 mm on average, 73 mm at most; everywhere 32 and 70 mm;
    // 67 and 118 mm without.)
    for everywhere in [false, true] {
        // (0.1 is the default.)
        let mut args = vec![scans.clone()];
        args.extend(
            everywhere
                .then(|| ["--corner-ratio".into(), "0.1".into(), "--corner-everywhere".into()])
                .into_iter()
                .flatten(),
        );
        let (r, v) = run(&args, &dir.path().join(format!("corners-{everywhere}")));
        let v = v.unwrap_or_else(|| panic!("{}", r.stderr));
        assert_eq!(r.code, 0, "{}", r.stderr);
        let settings = &v["settings"];
        assert!(settings["corner_ratio"].as_f64().is_some_and(|d| (d - 0.1).abs() < 1e-12), "{settings}");
        assert_eq!(settings["corner_everywhere"], everywhere, "{settings}");
        let off = offsets(&v);
        let mean = off.iter().sum::<f64>() / off.len() as f64;
        assert!(mean < 0.045 && off.iter().all(|&o| o < 0.1), "{off:?} m from the truth, {args:?}");
    }
}

/// Issue 38, a wrong fit the restart reached is named too: the bench's
/// street wedges (`NEES_ONLY=small_gicp python3
/// fusion/benches/covariance_nees.py BIN 8 pairwise`, wedges, trial 5: the
/// first centred at 44.39°, points dealt, starts 0.1 m / 2° off). The
/// schedule's links disagreed and its verification named part3; the
/// restart without the first stage (the scans agreeing 1.38× better)
/// placed part1 and part2 3.1° / 60 mm off together, slid along what
/// part1's one link cannot see. Until session 35 the verification named
/// nothing of it and it "rescued" the schedule (exit 0, the bench's silent
/// failure); session 35 let a further restart the scans agree with 1.19×
/// better replace a rescue (`scanset::RESCUE_RATIO`). Now the
/// verification names the restart's fit itself — part2's and part3's
/// pairs settle where their residual is more than 1.5× lower
/// (`verify::MAX_RESIDUAL_GAIN`) — and the further restart, named nothing
/// of, is kept: every part lands.
#[test]
fn a_wrong_fit_the_restart_reached_is_named_and_a_further_restart_lands_it() {
    let dir = tempfile::tempdir().expect("temp dir");
    let truths: [[[f64; 4]; 3]; 3] = [
        [
            [0.9040722465389761, -0.42736481310184293, -0.0035622409232830155, -0.40891325255277133],
            [0.42736567479635945, 0.9040786874275629, -0.0005540262694740946, 0.4708999599936742],
            [0.003457317431329765, -0.0010214997218810059, 0.9999935017261349, -0.2900439004365063],
        ],
        [
            [0.9134711379838678, 0.4059495984032178, -0.02784607022047567, -0.19839847359554996],
            [-0.40638645819035535, 0.913620447476124, -0.012154198987397839, -0.10314335809123443],
            [0.020506746937435604, 0.022418775831719716, 0.9995383293402265, 0.2767914495123881],
        ],
        [
            [0.988728262688016, 0.14884064833222474, 0.01621369686347106, -0.05968917883188296],
            [-0.14866500848524317, 0.9888201162829509, -0.011553912162295123, 0.20423639391914528],
            [-0.01775212139492355, 0.009013270117690911, 0.9998017919306633, 0.4783480942013876],
        ],
    ];
    let starts: [[[f64; 4]; 3]; 3] = [
        [
            [0.9125271553203751, -0.40889284444945895, 0.010041541760819438, -0.3969347723453472],
            [0.40887331623887346, 0.9125822979382998, 0.004020044462210188, 0.45166673708242366],
            [-0.010807500669898428, 0.00043731874253523243, 0.9999415016297641, -0.23347070985595797],
        ],
        [
            [0.9181334765687761, 0.3957566191482127, -0.020189541948969433, -0.1835916851960014],
            [-0.39615256782663355, 0.9179133488780694, -0.022320998091755438, -0.05926551874966601],
            [0.009698567321885966, 0.02849179446479623, 0.9995469751042613, 0.29163371641475877],
        ],
        [
            [0.9923533762015931, 0.12299912289561642, 0.01029526630096783, -0.08832753171345714],
            [-0.1229023974531759, 0.9923727646198196, -0.009554932813867422, 0.17334853829452454],
            [-0.01139199023702094, 0.00821655692641293, 0.9999013505094964, 0.5133998453034213],
        ],
    ];
    let (mut inputs, truths) = bench_wedges(dir.path(), STREET, 44.386_496_214_534_276, true, &truths, &starts);
    inputs.extend(["--mode".into(), "pairwise".into()]);
    lands_at_the_defaults("wedges at the defaults", &inputs, &dir.path().join("defaults"), &truths, 0.1, 0.01);
    let (r, v) = run(&corners_off(&inputs), &dir.path().join("out"));
    let v = v.expect("JSON");
    assert_eq!(r.code, 0, "{}\n{}", r.stdout, r.stderr);
    assert_eq!(v["untrusted"], serde_json::json!([]), "{}", v["restart"]);
    let restart = &v["restart"];
    // The schedule named (part3 by its pairs, part1 and part2 by their
    // departure from where their pairs agree: session 39), the restart
    // named too (the residual test: part1 and part2, the two it left off
    // — part3 too until session 57, whose pair's gain is now weighed
    // against the poses' relative σ), then a further restart kept.
    assert_eq!(restart["schedule_untrusted"], serde_json::json!([1, 2, 3]), "{restart}");
    assert_eq!(restart["restart_untrusted"], serde_json::json!([1, 2]), "{restart}");
    assert_eq!(restart["kept"], false, "{restart}");
    let rescue = restart["restart_disagreement_m2"].as_f64().expect("restart's");
    let further = restart["further"].as_array().expect("further restarts");
    let kept: Vec<&Value> = further.iter().filter(|f| f["kept"] == true).collect();
    assert!(!kept.is_empty(), "{restart}");
    let last = kept[kept.len() - 1];
    assert_eq!(last["untrusted"], serde_json::json!([]), "{restart}");
    // Better than the restart's, but within the 1.5× band (measured
    // 8.24e-3 against 9.83e-3 m² a point): kept because the restart's was
    // named.
    let landed = last["disagreement_m2"].as_f64().expect("further's");
    assert!(landed < rescue && rescue < 1.5 * landed, "{restart}");
    // (Measured 0.011–0.033° / 1.5–3.5 mm; the restart's part1 3.1° off.)
    assert_parts_land("wedges", &v, &truths, 0.1, 0.01);
}

/// Issue 38, a fit the residual says is far closer: two trials of the
/// bench's street wedges (`NEES_SEED=17 python3
/// fusion/benches/covariance_nees.py BIN 8 pairwise,incremental`, points
/// dealt, starts 0.1 m / 2° off) that ended wrong with exit 0. Trial 2, in
/// pairwise mode (the first wedge centred at 287.36°): part2 placed
/// 0.29 m along the street by a link still creeping at its iteration cap;
/// matched again from the final poses its pairs slid back 3.9–8.9 % of
/// their radius, along what they see weakly (within the motion tiers),
/// to a fit with their residual 3.2–3.4× lower. Trial 5, in incremental
/// mode (70.51°): part1 and part2 3.5° off together; part2's pair
/// with part3 slid 9.8 % of its radius to a fit 3.1× closer. The
/// verification now names those scans (`verify::MAX_RESIDUAL_GAIN`), and
/// the restarts land every part: in trial 5 the restart is set off by
/// the names alone (`trigger` "named"; the links' variance factor is
/// below 1).
#[test]
fn a_fit_the_residual_says_is_far_closer_is_named_and_the_restarts_land_it() {
    let dir = tempfile::tempdir().expect("temp dir");
    let truths: [[[f64; 4]; 3]; 3] = [
        [
            [0.881086220197748, -0.4729266940558895, 0.005235897918460105, -0.10903228074378224],
            [0.4729332511135033, 0.8810982577050728, -1.613373029461165e-05, 0.26112312598007525],
            [-0.004605710461745804, 0.002490445432518717, 0.9999862924623968, -0.47624131928560964],
        ],
        [
            [0.8874256354921497, -0.4609507229878444, -0.0004152689946881661, -0.347904254012081],
            [0.46095086225455467, 0.8874255935973949, 0.00034411494289970647, -0.45528600453067114],
            [0.0002099003023932465, -0.0004967950230541889, 0.9999998545682736, 0.10289928114408575],
        ],
        [
            [0.8389162141668094, 0.5437970559410853, 0.022457683714847364, 0.4515371167512484],
            [-0.5438585463422674, 0.8391682742166916, -0.0038064574942119882, -0.49729508162220193],
            [-0.020915716064810106, -0.009020504308940134, 0.9997405480040853, -0.28697343312475876],
        ],
    ];
    let starts: [[[f64; 4]; 3]; 3] = [
        [
            [0.8683398706493013, -0.49498571749441905, 0.031225126377480816, -0.16603566663091548],
            [0.49486327071744285, 0.8688869241043504, 0.012077102935541833, 0.22483200815999488],
            [-0.03310909747470206, 0.004965138166858921, 0.9994394104033495, -0.4628524572608005],
        ],
        [
            [0.9005900884859128, -0.43466856419747973, -0.0008554644570501798, -0.37836961078673587],
            [0.4346536290577612, 0.900538888005183, 0.010292421352946342, -0.4122980575835951],
            [-0.003703413000720696, -0.00964108338777101, 0.9999466656993544, 0.1243603834691144],
        ],
        [
            [0.8280337151644578, 0.5581629783258267, 0.053049563404312876, 0.45112389662208857],
            [-0.5587165396335274, 0.8293427991197143, -0.005133214218607303, -0.48363361190105136],
            [-0.04686144354245392, -0.025389194054158716, 0.9985786869017372, -0.3392313182725019],
        ],
    ];
    let trial2 = dir.path().join("trial2");
    std::fs::create_dir_all(&trial2).expect("dir");
    let (mut inputs, truths) = bench_wedges(&trial2, STREET, 287.362_595_229_900_25, true, &truths, &starts);
    inputs.extend(["--mode".into(), "pairwise".into()]);
    lands_at_the_defaults("trial 2 at the defaults", &inputs, &trial2.join("defaults"), &truths, 0.1, 0.01);
    let (r, v) = run(&without_estimates(&corners_off(&inputs)), &trial2.join("out"));
    let v = v.expect("JSON");
    assert_eq!(r.code, 0, "{}\n{}", r.stdout, r.stderr);
    assert_eq!(v["untrusted"], serde_json::json!([]), "{}", v["restart"]);
    let restart = &v["restart"];
    assert_eq!(restart["schedule_untrusted"], serde_json::json!([2]), "{restart}");
    let further = restart["further"].as_array().expect("further restarts");
    assert!(further.iter().any(|f| f["kept"] == true && f["untrusted"] == serde_json::json!([])), "{restart}");
    // (Measured 0.014–0.036° / 1.7–3.0 mm; the schedule's part2 288 mm off.)
    assert_parts_land("trial 2", &v, &truths, 0.1, 0.01);

    let truths: [[[f64; 4]; 3]; 3] = [
        [
            [0.7708392186010178, 0.6370049246380167, 0.005623615695158828, -0.33155669233364704],
            [-0.6370054501848385, 0.7708568839324703, -0.0019289709000760748, -0.4126518991368767],
            [-0.00556376683403576, -0.0020953474262424155, 0.9999823268527198, -0.3980038344527319],
        ],
        [
            [0.9999448085177545, -0.005333669279143727, 0.009051623634035154, -0.41332032429820376],
            [0.005413676956439876, 0.9999462923203384, -0.00883767936846531, -0.16689770805875048],
            [-0.00900400023338608, 0.00888619417012731, 0.999919978564769, -0.24533455584103014],
        ],
        [
            [0.9076110603159816, -0.4197968055548155, -0.003578440731923849, -0.09855073964452832],
            [0.419790545856635, 0.907617871743975, -0.00238673423862508, 0.17659739465976954],
            [0.00424980017035379, 0.0006640308048410334, 0.9999907490880114, -0.4635315815578297],
        ],
    ];
    let starts: [[[f64; 4]; 3]; 3] = [
        [
            [0.7711178683955268, 0.6366372644047907, 0.0083801319991815, -0.3481262934784019],
            [-0.6366759056716887, 0.7711258647916569, 0.002948183585604213, -0.4100724195394779],
            [-0.004585213002034947, -0.0076088251723969765, 0.999960540022066, -0.3638525638913788],
        ],
        [
            [0.9993981244132945, -0.007216321212306058, 0.03393101276635257, -0.4025306462113377],
            [0.007435754888000342, 0.9999522221046941, -0.006345317732790856, -0.20513325425864273],
            [-0.03388360176302302, 0.00659380133498979, 0.999404034070065, -0.27634854040008716],
        ],
        [
            [0.9063553314526461, -0.42251556210177926, -0.0007828979380041375, -0.13821198031085546],
            [0.4224237032440769, 0.9061939582777625, -0.019254218198636767, 0.2225126837310378],
            [0.008844664206394789, 0.017120448671053137, 0.9998143138365133, -0.4752772209802384],
        ],
    ];
    let trial5 = dir.path().join("trial5");
    std::fs::create_dir_all(&trial5).expect("dir");
    let (mut inputs, truths) = bench_wedges(&trial5, STREET, 70.513_798_323_402_54, true, &truths, &starts);
    inputs.extend(["--mode".into(), "incremental".into()]);
    lands_at_the_defaults("trial 5 at the defaults", &inputs, &trial5.join("defaults"), &truths, 0.1, 0.01);
    let inputs = corners_off(&inputs);
    let (r, v) = run(&inputs, &trial5.join("out"));
    let v = v.expect("JSON");
    assert_eq!(r.code, 0, "{}\n{}", r.stdout, r.stderr);
    assert_eq!(v["untrusted"], serde_json::json!([]), "{}", v["restart"]);
    let restart = &v["restart"];
    assert_eq!(restart["trigger"], "named", "{restart}");
    // part2 and part3 by their pairs, part1 (3.5° off with part2) by its
    // departure from where its pairs agree (session 39).
    assert_eq!(restart["schedule_untrusted"], serde_json::json!([1, 2, 3]), "{restart}");
    assert_eq!(restart["kept"], true, "{restart}");
    // (Measured 0.007–0.018° / 0.5–2.1 mm; the schedule's part1 and part2 3.5° off.)
    assert_parts_land("trial 5", &v, &truths, 0.1, 0.01);
    // The text says why the schedule's result was restarted.
    let text = run_text(&inputs, &trial5.join("text"));
    assert!(
        text.stdout.contains("restart: the verification names scans of the schedule's result (part1, part2, part3)"),
        "{}",
        text.stdout
    );
}

/// Issue 38, a named result gives way to a better one the verification
/// names nothing of: the bench's room wedges
/// (`NEES_ONLY=room python3 fusion/benches/covariance_nees.py BIN 8
/// graph`, trial 5: the first centred at 123.82°, starts 0.1 m / 2° off).
/// The auto schedule left part2 and part3 1.8 m and 2.6–3.0° off together
/// and part1 45 mm off; the verification named part1 and part3 (a pair
/// that moves 1 m when matched again), exit 1 — with part2, the farthest
/// off, not named. The restart without the first stage landed in the same
/// fit. From the starts without the first two stages every part lands,
/// the scans agreeing 1.33× better there: short of the 1.5× that lets a
/// registration replace a trusted one, but this one was not trusted, and
/// the verification names nothing of the new one — it is kept, exit 0.
#[test]
fn a_named_result_gives_way_to_a_better_agreement_that_nothing_names() {
    let dir = tempfile::tempdir().expect("temp dir");
    let truths: [[[f64; 4]; 3]; 3] = [
        [
            [0.8805513234199317, 0.47394399128852377, 0.002541642168128242, -0.019636536229778567],
            [-0.47395078578870153, 0.8805370446456137, 0.005016538352398553, 0.13416718431957542],
            [0.00013954812591741048, -0.005621932787969469, 0.9999841870739997, -0.019222589791083267],
        ],
        [
            [0.7832743569610569, 0.621676113559077, -0.0003025844088323822, -0.284879138487374],
            [-0.6216717891876861, 0.7832705537646909, 0.0033802564008743423, 0.25134527578407295],
            [0.0023384301195954423, -0.0024595599679392353, 0.9999942411380877, 0.48615640543706895],
        ],
        [
            [0.7282028377701524, -0.6853616760949292, 1.961258993669894e-06, 0.4410241154698903],
            [0.6853516048865271, 0.7281921215027686, -0.0054232703010877945, 0.004026334742785798],
            [0.00371547345012198, 0.003950584975245616, 0.9999852939595636, -0.22860696352074117],
        ],
    ];
    let starts: [[[f64; 4]; 3]; 3] = [
        [
            [0.8627275630841174, 0.5056231362998295, 0.006811456031154708, -0.020779831412800265],
            [-0.5056689902333755, 0.8626451045690325, 0.011928783653044384, 0.11426514739914953],
            [0.00015559980263160834, -0.013735632544841676, 0.9999056496426523, -0.0052671961362297515],
        ],
        [
            [0.784931689380933, 0.6195772309394592, 0.002509563106708128, -0.3202974998302338],
            [-0.6195808138634704, 0.7849322621578518, 0.0009792425833565854, 0.24273021238751386],
            [-0.0013631206381622355, -0.0023235156873637978, 0.9999963715819055, 0.5141575000859279],
        ],
        [
            [0.7310525036362935, -0.6823087795558538, -0.004119013001731646, 0.4403831213072431],
            [0.6823055932867207, 0.7309816023294846, 0.011179196101473731, 0.023040778355917092],
            [-0.004616740924390305, -0.010983004908525705, 0.9999290271346344, -0.2762529358659978],
        ],
    ];
    let (inputs, truths) =
        bench_wedges(dir.path(), "pcl_room_scans/room_scan1.pcd", 123.822_614_424_116_82, true, &truths, &starts);
    lands_at_the_defaults("wedges at the defaults", &inputs, &dir.path().join("defaults"), &truths, 0.1, 0.015);
    let (r, v) = run(&corners_off(&inputs), &dir.path().join("out"));
    let v = v.expect("JSON");
    assert_eq!(r.code, 0, "{}\n{}", r.stdout, r.stderr);
    assert_eq!(v["untrusted"], serde_json::json!([]), "{}", v["restart"]);
    let restart = &v["restart"];
    // The schedule's result named, the restart not kept (its scans agree
    // no better: measured 4.49e-3 against 4.43e-3 m² a point).
    let named = restart["schedule_untrusted"].as_array().expect("named");
    assert!(!named.is_empty(), "{restart}");
    assert_eq!(restart["kept"], false, "{restart}");
    let schedule = restart["schedule_disagreement_m2"].as_f64().expect("schedule's");
    let further = restart["further"].as_array().expect("further restarts");
    let kept: Vec<&Value> = further.iter().filter(|f| f["kept"] == true).collect();
    assert_eq!(kept.len(), 1, "{restart}");
    assert_eq!(kept[0]["untrusted"], serde_json::json!([]), "{restart}");
    // Better, but within the 1.5× band (measured 3.34e-3 m² a point).
    let landed = kept[0]["disagreement_m2"].as_f64().expect("further's");
    assert!(landed < schedule && schedule < 1.5 * landed, "{restart}");
    // (Measured 0.011–0.060° / 2.4–7.8 mm; the schedule's part2 1.8 m off.)
    assert_parts_land("wedges", &v, &truths, 0.1, 0.015);
}

/// Issue 38, a slide in all, however weakly seen: the bench's room wedges
/// (`NEES_SEED=11 python3 fusion/benches/covariance_nees.py BIN 8`, room
/// wedges, incremental mode, trial 0: the first centred at 144.90°,
/// starts 0.1 m / 2° off). The schedule dragged two wedges 2.4 m; the
/// restart landed them, the scans agreeing 1.42× better — and the
/// verification, whose re-matched pairs slid only along what they see
/// weakly, named neither registration: "undecided", exit 1 with the right
/// poses. A pair of the schedule's slides 20 % of its radius or more in
/// all: now it names the schedule's slide, the restart (which it names
/// nothing of) is kept, exit 0.
#[test]
fn a_slide_in_all_names_the_schedules_result_and_the_restart_is_kept() {
    let dir = tempfile::tempdir().expect("temp dir");
    let truths: [[[f64; 4]; 3]; 3] = [
        [
            [0.9173276301017165, 0.39798301345531645, 0.01093343738235128, 0.1830286935504275],
            [-0.39792452349685764, 0.9173900604651266, -0.007179871836606289, -0.41718592741369465],
            [-0.012887693811042444, 0.00223561195575324, 0.9999144510343952, -0.02897396249050721],
        ],
        [
            [0.987899472394267, 0.153458518568464, -0.02247477523583556, -0.3170187678050025],
            [-0.15308012699281384, 0.9880553140201759, 0.01769664251646519, -0.44910110603230124],
            [0.02492202164738882, -0.014042062357929258, 0.9995907729274731, -0.002613361658390989],
        ],
        [
            [0.9977565532022786, 0.06449429660310138, 0.01795400366435868, -0.3622185179493279],
            [-0.06451977870846365, 0.9979160722988379, 0.0008430913778452423, 0.09357643094260715],
            [-0.017862214233389483, -0.001999588290548819, 0.9998384584268345, -0.25938181247558045],
        ],
    ];
    let starts: [[[f64; 4]; 3]; 3] = [
        [
            [0.9093859515168499, 0.4155761041611016, 0.01771137583800308, 0.14271482320950515],
            [-0.4158568145691051, 0.9092676454775639, 0.017188911080240902, -0.3662682473875245],
            [-0.008961080304891152, -0.02299675059587157, 0.9996953778535742, -0.04609904141639873],
        ],
        [
            [0.987980216988267, 0.1533064768095945, -0.019804418902007563, -0.30961133880858716],
            [-0.1527442064428252, 0.9878876862646887, 0.02733361894721006, -0.482591190269984],
            [0.02375496238617373, -0.023980064529290777, 0.9994301667786513, 0.013192595579647264],
        ],
        [
            [0.997911531899403, 0.06249704264862008, 0.016330773477200147, -0.31424589205722636],
            [-0.06250502946662423, 0.9980446487176634, -2.1387209799965053e-05, 0.1355092483939051],
            [-0.01630017771570293, -0.0009994129341106758, 0.9998666437981736, -0.2420834125624964],
        ],
    ];
    let (mut inputs, truths) =
        bench_wedges(dir.path(), "pcl_room_scans/room_scan1.pcd", 144.903_123_120_261_57, true, &truths, &starts);
    inputs.extend(["--mode".into(), "incremental".into()]);
    lands_at_the_defaults("wedges at the defaults", &inputs, &dir.path().join("defaults"), &truths, 0.1, 0.01);
    let (r, v) = run(&corners_off(&inputs), &dir.path().join("out"));
    let v = v.expect("JSON");
    assert_eq!(r.code, 0, "{}\n{}", r.stdout, r.stderr);
    assert_eq!(v["untrusted"], serde_json::json!([]), "{}", v["restart"]);
    let restart = &v["restart"];
    assert_eq!(restart["undecided"], serde_json::json!([]), "{restart}");
    assert!(!restart["schedule_untrusted"].as_array().expect("named").is_empty(), "{restart}");
    assert_eq!(restart["restart_untrusted"], serde_json::json!([]), "{restart}");
    assert_eq!(restart["kept"], true, "{restart}");
    // Within the 1.5× band (measured 4.56e-3 against 3.22e-3 m² a point).
    let (schedule, restarted) = (
        restart["schedule_disagreement_m2"].as_f64().expect("schedule's"),
        restart["restart_disagreement_m2"].as_f64().expect("restart's"),
    );
    assert!(restarted < schedule && schedule < 1.5 * restarted, "{restart}");
    // (Measured 0.036–0.047° / 0.7–2.3 mm; the schedule's 2.4 m off.)
    assert_parts_land("wedges", &v, &truths, 0.1, 0.01);
}

/// Links that disagree grossly put a result in doubt (session 74): the
/// bench's room wedges (`NEES_SEED=103 python3
/// fusion/benches/covariance_nees.py BIN 8`, room wedges, graph mode,
/// trial 3: the first centred at 119.60°, starts 0.1 m / 2° off). The
/// schedule's second stage dragged three wedges 29–89 mm and 0.1–0.5° off,
/// the restart without the first stage landed there too (the scans
/// agreeing alike to the fourth digit), and the links disagreed by a
/// variance factor of 37,116 — σ 0.47–0.68 m carried it, nothing named,
/// exit 0. The further restarts now run: the schedule without its first two
/// stages lands every wedge within 8 mm, σ̂₀² 14, the scans agreeing 1.12×
/// better (under the restart's 1.5×), and is kept.
#[test]
fn links_that_disagree_grossly_set_off_the_further_restarts() {
    let dir = tempfile::tempdir().expect("temp dir");
    let truths: [[[f64; 4]; 3]; 3] = [
        [
            [0.9999568923555512, -0.009153444389660212, 0.0015581676527370704, 0.11311890994677276],
            [0.009156990063341242, 0.9999554658523727, -0.0022838224414750623, 0.2112608579264379],
            [-0.0015371934193548855, 0.0022979921169824103, 0.9999961781270075, -0.28998122850390906],
        ],
        [
            [0.9838582318292497, -0.17890870294431885, 0.00382827279638997, -0.3687704382730066],
            [0.17894896338001734, 0.9835697035117306, -0.023830796022448683, -0.26496708509285083],
            [0.0004981636671996373, 0.02413119028617979, 0.9997086763094202, -0.4891261256377757],
        ],
        [
            [0.9188402152431063, -0.39386021174308183, -0.024633157688300104, 0.47273722362177795],
            [0.3934608138745126, 0.9191329061373099, -0.01957776291584227, -0.4254417951600198],
            [0.030352047660875393, 0.008296653619233249, 0.9995048367774487, 0.4003915539995402],
        ],
    ];
    let starts: [[[f64; 4]; 3]; 3] = [
        [
            [0.999918675576517, -0.00797744609574636, 0.009950004376560016, 0.09959675612556691],
            [0.008237671286730964, 0.9996177168259439, -0.026392441710814944, 0.2106300573091607],
            [-0.009735656376221929, 0.026472260226064137, 0.999602139070064, -0.3217066859597614],
        ],
        [
            [0.9776217306589122, -0.21034096903661673, -0.0035254061056527405, -0.39566920708957815],
            [0.21022096285153197, 0.9774213453552056, -0.021322767686085764, -0.23523638539013664],
            [0.007930858796344515, 0.020104486781736125, 0.9997664282671207, -0.4559781862356521],
        ],
        [
            [0.9113920200019707, -0.41053822495309666, -0.028687135254113857, 0.5044458135528449],
            [0.41001128779954327, 0.9118006783471365, -0.022589086804505016, -0.37153139940185265],
            [0.035430632984569985, 0.008825464183938814, 0.9993331683819219, 0.40981957559504556],
        ],
    ];
    let (inputs, truths) =
        bench_wedges(dir.path(), "pcl_room_scans/room_scan1.pcd", 119.595_208_495_788_16, true, &truths, &starts);
    let v = lands_at_the_defaults("wedges", &inputs, &dir.path().join("out"), &truths, 0.1, 0.015);
    let restart = &v["restart"];
    assert_eq!(restart["trigger"], "disagreeing", "{restart}");
    assert_eq!(restart["disagreeing_links"], true, "{restart}");
    assert_eq!(restart["kept"], false, "{restart}");
    let further = restart["further"].as_array().expect("further restarts");
    let kept: Vec<&Value> = further.iter().filter(|f| f["kept"] == true).collect();
    assert_eq!(kept.len(), 1, "{restart}");
    assert_eq!(kept[0]["untrusted"], serde_json::json!([]), "{restart}");
    // Better, but within the 1.5× band (measured 2.924e-3 against 3.271e-3
    // m² a point); the kept links agree (σ̂₀² measured 14).
    let schedule = restart["schedule_disagreement_m2"].as_f64().expect("schedule's");
    let landed = kept[0]["disagreement_m2"].as_f64().expect("further's");
    assert!(landed < schedule && schedule < 1.5 * landed, "{restart}");
    let factor = v["variance_factor"].as_f64().expect("variance factor");
    assert!(factor < fusion::scanset::GROSS_VARIANCE_FACTOR, "{factor}");
}

/// `links[].degenerate_directions` mean one thing in every mode (and in
/// `report.json`): the world's axes, a motion of the source about its
/// partner's origin. The simulated sewer's scans (blind about the pipe's
/// axis and along it, the world's x), each in a frame turned 90° about z
/// from the run's: graph mode's matches are made in the partner's frame,
/// where the pipe runs along y — and were reported so; the other modes'
/// in the world.
#[test]
fn a_links_blind_directions_are_in_the_worlds_axes_in_every_mode() {
    let dir = tempfile::tempdir().expect("temp dir");
    let (run_dir, done) = example_run("sewer.toml", &[("slices = 180", "slices = 60")], dir.path());
    assert!(done.code <= 1, "{}", done.stderr);
    // The same sparse lines in the mission's own ICP fusion: with the
    // sewer's `[fusion] line_ratio` (0.1, the default with its
    // `degeneracy_ratio`) every station stays within 5 mm of the
    // simulator's truth (measured 1.9–4.2 mm; with `line_ratio = 0`
    // stations 3–8 slid 0.12–1.40 m along the pipe, exit 0, each match
    // seeing the axis at 1.1–2.0e-2 of its largest eigenvalue through
    // normals of no clear direction).
    let fused =
        cps_survey(["fuse".into(), run_dir.clone().into_os_string(), "--mode".into(), "icp".into(), "--json".into()]);
    assert_eq!(fused.code, 0, "{}", fused.stderr);
    let report: Value = serde_json::from_str(&fused.stdout).expect("fusion JSON");
    for s in report["scans"].as_array().expect("scans") {
        let error = s["error_xy_m"].as_f64().expect("error");
        assert!(error < 0.005, "station {}: {error} m from the truth: {}", s["station"], fused.stdout);
    }
    let turn = Isometry3::from_parts(
        nalgebra::Translation3::identity(),
        UnitQuaternion::from_axis_angle(&nalgebra::Vector3::z_axis(), std::f64::consts::FRAC_PI_2),
    );
    let set = dir.path().join("turned");
    std::fs::create_dir_all(&set).expect("set");
    let (mut inputs, mut entries, mut cps) = (Vec::<OsString>::new(), Vec::new(), Vec::new());
    for k in 0.. {
        let scan = run_dir.join(format!("scans/scan{k:03}.3d"));
        if !scan.exists() {
            break;
        }
        let mut cloud = scanner::io::read(&scan).expect("scan");
        let t = turn.cast::<f32>();
        cloud.points.iter_mut().for_each(|p| *p = t * *p);
        let path = set.join(format!("scan{k:03}.ply"));
        scanner::io::write(&path, &cloud, scanner::io::Format::Ply(scanner::io::PlyEncoding::BinaryLittleEndian))
            .expect("PLY");
        let pose = scanner::io::read_3dtk_pose(&scan.with_extension("pose")).expect("pose");
        entries.push(init_entry(&format!("scan{k:03}.ply"), &(pose * turn.inverse()).to_homogeneous()));
        cps.push(pose * turn.inverse());
        inputs.push(path.into_os_string());
    }
    assert!(inputs.len() >= 5, "the sewer's scans: {}", inputs.len());
    let init = set.join("init.json");
    std::fs::write(&init, serde_json::to_string(&entries).expect("JSON")).expect("init");
    inputs.extend(["--init-poses".into(), init.into_os_string()]);
    let scans = entries.len();
    // Simultaneous mode's queue creeps along the pipe (docs/match.md): its
    // matches are bounded by `--max-matches-per-scan` (at 100, the default,
    // this run took 5 minutes, 45× the other modes).
    let cap = 5;
    for mode in ["graph", "simultaneous", "pairwise"] {
        let mut args = inputs.clone();
        // The sewer mission's own `[fusion] degeneracy_ratio`, without the
        // line test that comes with it (below): the queue's creep.
        args.extend(["--mode", mode, "--degeneracy-ratio", "0.01", "--line-ratio", "0"].map(OsString::from));
        // (With the corner test too, at the default, the sparse arcs'
        // curvature reads as corners where the line test lets their
        // lines in: a link left with the pipe near its scanner is blind
        // about z there — measured, graph mode's link 4.)
        args.extend(["--corner-ratio", "0"].map(OsString::from));
        if mode == "simultaneous" {
            args.extend(["--max-matches-per-scan".into(), cap.to_string().into()]);
        }
        let (r, v) = run(&args, &dir.path().join(mode));
        let v = v.unwrap_or_else(|| panic!("{mode}: {}", r.stderr));
        if mode == "simultaneous" {
            // Each new scan's start match and at most `cap` queue matches,
            // at every stage of the schedule and of every restart.
            let restart = &v["restart"];
            let further = restart["further"].as_array().into_iter().flatten();
            let stages = [&v["stages"], &restart["stages"]]
                .into_iter()
                .chain(further.map(|f| &f["stages"]))
                .filter_map(Value::as_array)
                .flatten();
            for stage in stages {
                let matches = stage["matches"].as_u64().expect("matches");
                assert!(matches <= (cap + 1) * (scans as u64 - 1), "{mode}: {matches} matches at a stage: {stage}");
            }
        }
        let blind: Vec<&Value> = v["links"]
            .as_array()
            .expect("links")
            .iter()
            .filter(|l| l["degenerate_directions"].as_array().is_some_and(|d| !d.is_empty()))
            .collect();
        // (Simultaneous mode's metascan matches, each against up to eight
        // partners along the pipe, may see it all, so none need be blind
        // there.)
        assert!(mode == "simultaneous" || !blind.is_empty(), "{mode}: no link is blind in a pipe: {}", v["links"]);
        let c = |d: &Value, i: usize| d[i].as_f64().expect("number").abs();
        for l in blind {
            let d = l["degenerate_directions"].as_array().expect("directions");
            // About the pipe or along it (or a screw of both): the world's
            // x, never the scans' own.
            for d in d {
                let in_x = c(d, 0).hypot(c(d, 3));
                assert!(in_x > 0.95, "{mode}: link {}: not about or along the world's x: {d:?}", l["source"]);
                assert!(c(d, 1) < 0.3 && c(d, 4) < 0.3, "{mode}: link {}: the scans' own x: {d:?}", l["source"]);
            }
        }
    }
    // Sparse scan lines (docs/match.md, Known limits): at 60 slices a
    // third of the points' neighbours lie along one slice's arc and their
    // normals along the pipe, so the links above see its axis and the
    // scans slide 0.2–0.6 m along it (measured, exit 0). Judged without
    // them (`--line-ratio 0.1`, the default with a `--degeneracy-ratio`
    // given) the axis is blind on every link and held where the CPS put
    // each scan (3–6 mm from the simulator's truth), in every mode, and
    // simultaneous mode's queues settle without a cap (measured within
    // 7 mm; simultaneous 3 s).
    for mode in ["graph", "pairwise", "incremental", "simultaneous"] {
        let mut args = inputs.clone();
        args.extend(["--mode", mode, "--degeneracy-ratio", "0.01"].map(OsString::from));
        let (r, v) = run(&args, &dir.path().join(format!("lines-{mode}")));
        let v = v.unwrap_or_else(|| panic!("{mode}: {}", r.stderr));
        assert_eq!(r.code, 0, "{mode}: {}", r.stderr);
        // (Graph mode's roll about the pipe, blind on every link and held
        // only by the start's step prior, drifts up to 0.63° at the far
        // end; the other modes hold it within 0.001°.)
        assert_parts_land(mode, &v, &cps, if mode == "graph" { 0.8 } else { 0.2 }, 0.015);
        for l in v["links"].as_array().expect("links").iter().filter(|l| l["accepted"] == true) {
            let d = l["degenerate_directions"].as_array().expect("directions");
            // The world's x within their span (they may mix it with the roll).
            let directions: Vec<nalgebra::Vector6<f64>> =
                d.iter().map(|d| nalgebra::Vector6::from_fn(|i, _| d[i].as_f64().expect("number"))).collect();
            let basis = fusion::icp::degeneracy::orthonormal(&directions);
            let along = basis.iter().map(|q| q[3].powi(2)).sum::<f64>().sqrt();
            assert!(along > 0.95, "{mode}: link {}: the axis is not blind: {d:?}", l["source"]);
        }
        let settled = v["stages"].as_array().expect("stages").iter().all(|s| s["settled"] == true);
        assert!(settled, "{mode}: {}", v["stages"]);
    }
    // At the defaults the scans are found a pipe and matched as above:
    // where they collapsed 3.7 m along it and were named, exit 1 (before
    // session 51), they land.
    let (r, v) = run(&inputs, &dir.path().join("found"));
    let v = v.unwrap_or_else(|| panic!("{}", r.stderr));
    assert_eq!(r.code, 0, "{}", r.stderr);
    assert!(v["settings"]["pipe"]["radius_m"].as_f64().is_some_and(|r| (r - 0.5).abs() < 0.005), "{}", v["settings"]);
    assert_parts_land("graph", &v, &cps, 0.8, 0.015);
    // The ratio is checked.
    let mut args = inputs.clone();
    args.extend(["--line-ratio", "1.5"].map(OsString::from));
    let (r, _) = run(&args, &dir.path().join("bad-ratio"));
    assert_eq!(r.code, 2, "{}", r.stderr);
    assert!(r.stderr.contains("--line-ratio 1.5: expected a ratio in [0, 1) (0: off)"), "{}", r.stderr);
}

/// A pipe at the default blind-direction threshold (issue 38, sessions
/// 49–50): the sewer example's own scans (180 slices) matched with
/// nothing but the scans slid 74–184 mm along the pipe in graph mode and
/// 75–289 mm in pairwise mode, exit 0 — along the axis and the roll,
/// which graph mode's links report blind and pairwise mode's matches hold
/// no better than the start (they report nothing blind), yet moved along
/// them 15–51 in χ² of the scans' own covariance there. Each scan is
/// named for it, and a result named only so gives way to one that names
/// nothing within 1.5× of the best agreement: in graph mode the further
/// restart from the starts with the finest stage alone (kept though the
/// scans agree 1.05× better at the slid poses); in pairwise mode, whose
/// finest stage alone still slides scans, the whole schedule again with a
/// pipe's threshold (0.01) — both exit 0. Given that threshold, every
/// scan lands within 3 mm of the simulator's truth. Since session 51 the
/// scans are found a pipe at the defaults (each on its tube, all round)
/// and matched with that threshold from the first; the fallback is
/// tested with the former defaults given.
#[test]
fn a_pipe_slid_along_what_only_its_start_holds_is_named() {
    let dir = tempfile::tempdir().expect("temp dir");
    let (run_dir, done) = example_run("sewer.toml", &[], dir.path());
    assert_eq!(done.code, 0, "{}", done.stderr);
    let report: Value =
        serde_json::from_str(&std::fs::read_to_string(run_dir.join("report.json")).expect("report")).expect("JSON");
    // Each scan's offset from the simulator's truth, metres.
    let off = |v: &Value| -> Vec<nalgebra::Vector3<f64>> {
        let scans = v["scans"].as_array().expect("scans");
        assert_eq!(scans.len(), 9, "the sewer's stations");
        scans
            .iter()
            .enumerate()
            .map(|(k, s)| {
                let m = pose(&s["world_from_scan"]);
                let truth = &report["stations"][k]["truth"];
                nalgebra::Vector3::new(
                    m.translation.x - truth["x_m"].as_f64().expect("x"),
                    m.translation.y - truth["y_m"].as_f64().expect("y"),
                    m.translation.z - truth["z_m"].as_f64().expect("z"),
                )
            })
            .collect()
    };
    let scans: OsString = run_dir.join("scans").into();
    let all: Vec<usize> = (1..9).collect();

    // At the defaults the scans are found a pipe (each on its tube, all
    // round it, no guess given) and matched with the pipe's threshold
    // and line test: the axis and the roll held, nothing named, nothing
    // restarted.
    let (r, v) = run(std::slice::from_ref(&scans), &dir.path().join("found"));
    let v = v.unwrap_or_else(|| panic!("{}", r.stderr));
    assert_eq!(r.code, 0, "{}", r.stderr);
    let settings = &v["settings"];
    let radius = settings["pipe"]["radius_m"].as_f64().unwrap_or_else(|| panic!("no pipe found: {settings}"));
    assert!((radius - 0.5).abs() < 0.005, "{settings}");
    assert!(settings["pipe"]["share"].as_f64().is_some_and(|s| s > 0.95), "{settings}");
    assert_eq!((settings["degeneracy_ratio"].as_f64(), settings["line_ratio"].as_f64()), (Some(0.01), Some(0.1)));
    assert!(v["restart"].is_null(), "{}", v["restart"]);
    for (k, (d, s)) in off(&v).iter().zip(v["scans"].as_array().expect("scans")).enumerate() {
        // (Measured 1.1–2.8 mm.)
        assert!(d.norm() < 0.005, "scan {k}: {d:?} m from the truth");
        assert!(s["held_chi2"].as_f64().is_none_or(|c| c < 1.0), "{s}");
    }
    let said = run_text(std::slice::from_ref(&scans), &dir.path().join("found-said"));
    assert!(said.stdout.contains("the scans are a pipe (radius 0.50"), "{}", said.stdout);

    // The former defaults given (`--degeneracy-ratio 0.002 --line-ratio
    // 0`, no pipe assumed): the fallback when the scans are not found a
    // pipe (a tunnel's section, a pipe with its floor under water).
    let former = |mode: &str| -> Vec<OsString> {
        [scans.clone()]
            .into_iter()
            .chain(["--mode", mode, "--degeneracy-ratio", "0.002", "--line-ratio", "0"].map(OsString::from))
            .collect()
    };
    // Graph mode: the schedule named every scan for its move along what
    // its links do not see; the finest stage alone from the starts names
    // nothing and is kept.
    let (r, v) = run(&former("graph"), &dir.path().join("graph"));
    let v = v.unwrap_or_else(|| panic!("{}", r.stderr));
    assert_eq!(r.code, 0, "{}", r.stderr);
    let restart = &v["restart"];
    assert_eq!(restart["schedule_untrusted"], serde_json::json!(all), "{restart}");
    let last = restart["further"].as_array().expect("further restarts").last().expect("one").clone();
    assert_eq!((last["kept"].clone(), last["untrusted"].clone()), (Value::Bool(true), serde_json::json!([])), "{last}");
    assert_eq!(last["stages"].as_array().expect("stages").len(), 1, "{last}");
    for (k, (d, s)) in off(&v).iter().zip(v["scans"].as_array().expect("scans")).enumerate() {
        // Along the axis only the start holds it: (measured 0–29 mm
        // along, 1–3 mm across; σ reported 17–41 mm along).
        assert!(d.x.abs() < 0.06 && d.y.hypot(d.z) < 0.005, "scan {k}: {d:?} m from the truth");
        assert!(s["held_chi2"].as_f64().is_none_or(|c| c < fusion::scanset::held_limit(2)), "{s}");
    }

    // Pairwise mode: its matches report nothing blind, yet hold the axis
    // and the roll no better than the start; the schedule named every
    // scan so, its finest stage alone some, and the whole schedule with a
    // pipe's threshold none: kept.
    let pairwise = former("pairwise");
    let (r, v) = run(&pairwise, &dir.path().join("pairwise"));
    let v = v.unwrap_or_else(|| panic!("{}", r.stderr));
    assert_eq!(r.code, 0, "{}", r.stderr);
    let restart = &v["restart"];
    assert_eq!(restart["schedule_untrusted"], serde_json::json!(all), "{restart}");
    let further = restart["further"].as_array().expect("further restarts");
    let (shorter, pipe) = further.split_at(further.len() - 1);
    assert!(shorter.iter().all(|f| f["kept"] == false && f["degeneracy_ratio"].is_null()), "{restart}");
    assert!(shorter.last().is_some_and(|f| f["untrusted"].as_array().is_some_and(|u| !u.is_empty())), "{restart}");
    assert_eq!(pipe[0]["degeneracy_ratio"], 0.01, "{restart}");
    assert_eq!((pipe[0]["kept"].clone(), pipe[0]["untrusted"].clone()), (Value::Bool(true), serde_json::json!([])));
    assert_eq!(pipe[0]["stages"].as_array().expect("stages").len(), 4, "the whole schedule: {restart}");
    for (k, (d, s)) in off(&v).iter().zip(v["scans"].as_array().expect("scans")).enumerate() {
        assert!(d.norm() < 0.005, "scan {k}: {d:?} m from the truth");
        // The axis and the roll reported blind, the move along them nil.
        if k > 0 {
            let held = s["held_directions"].as_array().expect("directions");
            let directions: Vec<nalgebra::Vector6<f64>> =
                held.iter().map(|d| nalgebra::Vector6::from_fn(|i, _| d[i].as_f64().expect("number"))).collect();
            let basis = fusion::icp::degeneracy::orthonormal(&directions);
            assert!(basis.iter().map(|q| q[3].powi(2)).sum::<f64>().sqrt() > 0.95, "{s}");
            assert!(basis.iter().map(|q| q[0].powi(2)).sum::<f64>().sqrt() > 0.95, "{s}");
            assert!(s["held_chi2"].as_f64().is_some_and(|c| c < 1.0), "{s}");
        }
    }
    let said = run_text(&pairwise, &dir.path().join("said"));
    assert_eq!(said.code, 0, "{}", said.stderr);
    let text = format!("{}{}", said.stdout, said.stderr);
    assert!(text.contains("again from the starts with a pipe's blind-direction threshold, 0.01"), "{text}");

    // Simultaneous mode: the schedule's last queue abandoned at its cap,
    // chasing the slide; the restart is the pipe's threshold at once
    // (each shorter schedule would chase the slide again): kept, and no
    // further restart runs (it took 190 s against 20 s before, and lands
    // where the pairwise mode's fallback does).
    let (r, v) = run(&former("simultaneous"), &dir.path().join("simultaneous"));
    let v = v.unwrap_or_else(|| panic!("{}", r.stderr));
    assert_eq!(r.code, 0, "{}", r.stderr);
    let restart = &v["restart"];
    assert!(v["stages"].as_array().expect("stages").iter().any(|s| s["settled"] == false), "{}", v["stages"]);
    assert_eq!(restart["schedule_untrusted"], serde_json::json!(all), "{restart}");
    assert_eq!(restart["degeneracy_ratio"], 0.01, "{restart}");
    assert_eq!(
        (restart["kept"].clone(), restart["restart_untrusted"].clone()),
        (Value::Bool(true), serde_json::json!([]))
    );
    assert_eq!(restart["stages"].as_array().expect("stages").len(), 4, "the whole schedule: {restart}");
    assert_eq!(restart["further"], serde_json::json!([]), "{restart}");
    for (k, d) in off(&v).iter().enumerate() {
        // (Measured within 3 mm.)
        assert!(d.norm() < 0.005, "scan {k}: {d:?} m from the truth");
    }
}

/// The free-space test (issue 38, "a scan of another place entirely"):
/// where a scanner saw through, another scan's points are placed wrongly.
/// A 3DTK hall scan given with the two PCL room scans was placed 3.3 m
/// from the room with exit 0: it is named now, and only it. And scan000
/// and scan002 of the 3DTK set alone (3.4 m apart by the references,
/// their odometry a good start) slid onto each other down the hall, exit
/// 0 — the coarse stage dragged scan002 3.5 m; the restart without it
/// landed right, but its scans disagreed more, so the slide was kept.
/// The free space names the slide; the restart is kept as the
/// verification names fewer scans there, and the pair lands.
#[test]
fn a_scan_placed_where_another_scanner_saw_through_is_named_with_exit_1() {
    let dir = tempfile::tempdir().expect("temp dir");
    let share = |c: &Value| c["free_space"]["share"].as_f64().expect("a free-space share");
    let checks = |v: &Value| v["checks"].as_array().expect("checks").clone();

    // Another place: the hall scan among the room scans (a PCD's VIEWPOINT,
    // a 3DTK scan's origin).
    let (r, v) = run(
        &[data("pcl_room_scans/room_scan1.pcd"), data("pcl_room_scans/room_scan2.pcd"), data("3dtk_dat/scan000.3d")],
        &dir.path().join("other"),
    );
    assert_eq!(r.code, 1, "{}", r.stderr);
    let v = v.expect("JSON");
    assert_eq!(v["untrusted"], serde_json::json!([2]), "{}", v["checks"]);
    for c in checks(&v) {
        let hall = c["source"] == 2 || c["target"] == 2;
        assert_eq!(share(&c) > 0.12, hall, "{c}");
        assert_eq!(c["consistent"].as_bool(), Some(!hall), "{c}");
    }
    // The restart could not place it either (there is no right place).
    assert!(v["restart"].is_null() || v["restart"]["restart_untrusted"] != serde_json::json!([]), "{}", v["restart"]);

    // The slide: scan002 dragged onto scan000 by the coarse stage, where
    // scan000's scanner saw the hall go on; the restart lands it.
    let set = dir.path().join("set");
    std::fs::create_dir_all(&set).expect("set");
    for name in ["scan000.3d", "scan000.pose", "scan002.3d", "scan002.pose"] {
        std::fs::copy(workspace().join("data/3dtk_dat").join(name), set.join(name)).expect("copy");
    }
    let (r, v) = run(&[set.into_os_string()], &dir.path().join("slide"));
    assert_eq!(r.code, 0, "{}", r.stderr);
    let v = v.expect("JSON");
    let restart = &v["restart"];
    assert_eq!(restart["schedule_untrusted"], serde_json::json!([1]), "{restart}");
    assert_eq!(restart["restart_untrusted"], serde_json::json!([]), "{restart}");
    assert_eq!(restart["kept"], true, "{restart}");
    assert!(
        restart["schedule_disagreement_m2"].as_f64() < restart["restart_disagreement_m2"].as_f64(),
        "the disagreement alone would keep the slide: {restart}"
    );
    let poses: Vec<Isometry3<f64>> =
        v["scans"].as_array().expect("scans").iter().map(|s| pose(&s["world_from_scan"])).collect();
    let reference = scan0_from_scan(2);
    // 1.37° / 0.10 m off the references composed (each good to about
    // ±0.3° / 1.5 cm): two scans 3.4 m apart in a sparse hall, where
    // 3DTK's slam6D lands consecutive pairs 0.85–1.08° / 6–9 cm off — not
    // the 3.4 m slide.
    let (deg, m) = error(&(poses[0].inverse() * poses[1]), &reference);
    assert!(deg < 2.0 && m < 0.15, "0←2: {deg}° {m} m off the references");
    assert!(share(&checks(&v)[0]) < 0.12, "{}", v["checks"]);

    // The three scans land, every pair's free space respected (the 3DTK
    // set's worst 7.7 %).
    let (r, v) = run(&[data("3dtk_dat")], &dir.path().join("set3"));
    assert_eq!(r.code, 0, "{}", r.stderr);
    let v = v.expect("JSON");
    assert_eq!(checks(&v).len(), 3);
    assert!(checks(&v).iter().all(|c| share(c) < 0.12), "{}", v["checks"]);
}

/// Writes `points` alone as a binary PLY (which says nothing of
/// where its scanner stood).
fn write_plain_ply(path: &Path, points: Vec<nalgebra::Point3<f32>>) -> OsString {
    let plain = scanner::io::PointCloud::from_points(points);
    scanner::io::write(path, &plain, scanner::io::Format::Ply(scanner::io::PlyEncoding::BinaryLittleEndian))
        .expect("PLY");
    path.as_os_str().to_owned()
}

/// The scan at `rel` as a plain PLY in `dir`.
fn plain_ply(dir: &Path, rel: &str) -> OsString {
    plain_ply_of(dir, rel, scanner::io::read(Path::new(&data(rel))).expect("scan").points)
}

/// `points` as a plain PLY in `dir`, named after the scan at `rel`.
fn plain_ply_of(dir: &Path, rel: &str, points: Vec<nalgebra::Point3<f32>>) -> OsString {
    let name = Path::new(rel).file_stem().expect("stem").to_string_lossy().into_owned();
    write_plain_ply(&dir.join(format!("{name}.ply")), points)
}

/// Where the 3DTK set's references put scan `k` in scan000's frame
/// (scan000 ← scan001 ← scan002, composed).
fn scan0_from_scan(k: usize) -> Isometry3<f64> {
    (1..=k).fold(Isometry3::identity(), |pose, b| {
        pose * scanner::io::from_3dtk_axes(&matrix_file(&format!(
            "3dtk_dat/reference_T_scan{:03}_scan{b:03}.txt",
            b - 1
        )))
    })
}

/// How far from its frame's origin a scan's reported viewpoint lies (m).
fn viewpoint_from_origin(scan: &Value) -> f64 {
    let p = scan["viewpoint"]["position"].as_array().expect("position");
    p.iter().map(|x| x.as_f64().expect("x").powi(2)).sum::<f64>().sqrt()
}

/// PLY says nothing of where its scanner stood. For the hall scan among
/// the room scans, all three as PLY in their scanners' frames, `match`
/// estimates each scanner's position from its scan's point spacing (which
/// grows with the range) and tests the free space, which the hall scan
/// violates: named, exit 1 (before the pairs were matched both ways it was
/// placed 3.3 m from the room with exit 0). Without the estimate
/// (`--no-viewpoint-estimate`) no free space is tested; told that every
/// scanner stood at its scan's origin (`--scanner-at-origin`), `match`
/// tests it from there, and names the hall scan alike.
#[test]
fn the_free_space_of_scans_that_do_not_say_is_tested_from_estimated_or_told_viewpoints() {
    let dir = tempfile::tempdir().expect("temp dir");
    let inputs: Vec<OsString> =
        ["pcl_room_scans/room_scan1.pcd", "pcl_room_scans/room_scan2.pcd", "3dtk_dat/scan000.3d"]
            .iter()
            .map(|rel| plain_ply(dir.path(), rel))
            .collect();
    let hall_named = |v: &Value| {
        assert_eq!(v["untrusted"], serde_json::json!([2]), "{}", v["checks"]);
        let checks = v["checks"].as_array().expect("checks");
        assert!(checks.iter().all(|c| !c["free_space"].is_null()), "{}", v["checks"]);
        // The hall scan's pairs put points in a room scanner's free space.
        for c in checks {
            let share = c["free_space"]["share"].as_f64().expect("share");
            assert_eq!(share > 0.12, c["source"] == 2, "{c}");
        }
    };
    let (r, v) = run(&inputs, &dir.path().join("estimated"));
    let v = v.expect("JSON");
    assert_eq!(r.code, 1, "{}", r.stderr);
    hall_named(&v);
    // Each scanner where it stood, at its frame's origin, within 5 cm
    // (measured 2–3 cm), turning about its axis: the room scanner's head
    // about the vertical, the hall's SICK nodding about the lateral axis
    // (by the range alone, whose returns crowd towards that axis, the
    // hall scanner was 0.83 m off).
    let axes = [2, 2, 1];
    for (s, axis) in v["scans"].as_array().expect("scans").iter().zip(axes) {
        let vp = &s["viewpoint"];
        assert_eq!(vp["source"], "estimated", "{s}");
        assert_eq!(vp["used"], true, "{s}");
        assert!(vp["explained"].as_f64().expect("explained") > 0.95, "{s}");
        assert!(viewpoint_from_origin(s) < 0.05, "{s}");
        assert!(vp["axis"][axis].as_f64().expect("axis").abs() > 0.999, "{s}");
    }

    let mut plain = inputs.clone();
    plain.push("--no-viewpoint-estimate".into());
    let (_, v) = run(&plain, &dir.path().join("silent"));
    let v = v.expect("JSON");
    assert!(v["checks"].as_array().expect("checks").iter().all(|c| c["free_space"].is_null()), "{}", v["checks"]);
    assert!(v["scans"].as_array().expect("scans").iter().all(|s| s["viewpoint"].is_null()), "{}", v["scans"]);

    let mut told = inputs.clone();
    told.push("--scanner-at-origin".into());
    let (r, v) = run(&told, &dir.path().join("told"));
    let v = v.expect("JSON");
    assert_eq!(r.code, 1, "{}", r.stderr);
    hall_named(&v);
    assert!(
        v["scans"].as_array().expect("scans").iter().all(|s| s["viewpoint"]["source"] == "origin"),
        "{}",
        v["scans"]
    );
}

/// Issue 38, found in session 66: the 3DTK hall scan given as PLY with
/// small_gicp's two street frames (a spinning LiDAR's, PLY too) was placed
/// 1.8 m from them with exit 0 — no file said where a scanner stood, and
/// every other check passed it (matched again it moved 0.31 and 0.54 m,
/// but the corridor's right pairs move as much along their axis). With
/// the scanners' positions estimated from the spacing, the street
/// scanners' free space names it — at 21–22 %, as from the true scanners,
/// since the hall scanner's estimate turns about its nodding axis (by the
/// range alone, 0.8 m off, it was 13–14 % against the 12 % line) —; the
/// street pair alone passes (its free space 1 %). A scan merged from two
/// stations (scan000 and scan001 of the 3DTK set) spaces its points by
/// neither scanner: its estimate explains too little of the spacing to be
/// used, and the merged scan registers with scan002, exit 0, tested from
/// scan002's view alone.
#[test]
fn a_scan_of_another_place_among_lidar_frames_is_named_by_estimated_viewpoints() {
    let dir = tempfile::tempdir().expect("temp dir");
    let street: Vec<OsString> = vec![data("small_gicp_pair/target.ply"), data("small_gicp_pair/source.ply")];
    let mut inputs = street.clone();
    inputs.push(plain_ply(dir.path(), "3dtk_dat/scan000.3d"));
    let (r, v) = run(&inputs, &dir.path().join("other"));
    let v = v.expect("JSON");
    assert_eq!(r.code, 1, "{}", r.stderr);
    assert_eq!(v["untrusted"], serde_json::json!([2]), "{}", v["checks"]);
    for c in v["checks"].as_array().expect("checks") {
        let share = c["free_space"]["share"].as_f64().expect("share");
        assert_eq!(share > 0.12, c["source"] == 2, "{c}");
        assert!(c["source"] != 2 || share > 0.18, "{c}");
    }
    // The LiDAR frames' spacing follows the range (their rings are no
    // turning scanner's lines); the hall scanner turns.
    let scans = v["scans"].as_array().expect("scans");
    assert!(scans[..2].iter().all(|s| s["viewpoint"]["axis"].is_null()), "{}", v["scans"]);
    assert!(scans[2]["viewpoint"]["axis"].is_array(), "{}", v["scans"]);
    // The text says the scanners were estimated, and how to judge
    // without them.
    let text = run_text(&inputs, &dir.path().join("text"));
    assert_eq!(text.code, 1, "{}", text.stderr);
    assert!(
        text.stdout.contains("scanners' positions estimated from their scans' spacing, for the free-space test")
            && text.stdout.contains("not trusted: scan000: placed in another scan's free space")
            && text.stdout.contains("--no-viewpoint-estimate"),
        "{}",
        text.stdout
    );

    let (r, v) = run(&street, &dir.path().join("street"));
    let v = v.expect("JSON");
    assert_eq!(r.code, 0, "{}", r.stderr);
    let c = &v["checks"][0];
    assert!(c["free_space"]["share"].as_f64().expect("share") < 0.05, "{c}");

    let read = |rel: &str| scanner::io::read(Path::new(&data(rel))).expect("scan").points;
    let scan0_from_scan1 = scan0_from_scan(1);
    let mut merged = read("3dtk_dat/scan000.3d");
    merged.extend(read("3dtk_dat/scan001.3d").iter().map(|p| (scan0_from_scan1 * p.cast::<f64>()).cast::<f32>()));
    let merged = write_plain_ply(&dir.path().join("merged.ply"), merged);
    // scan002 started where the references put it.
    let scan0_from_scan2 = scan0_from_scan(2);
    let init = dir.path().join("init.json");
    let starts = serde_json::json!([
        init_entry("merged.ply", &Matrix4::identity()),
        init_entry("scan002.ply", &scan0_from_scan2.to_homogeneous())
    ]);
    std::fs::write(&init, starts.to_string()).expect("init poses");
    let inputs = [merged, plain_ply(dir.path(), "3dtk_dat/scan002.3d"), "--init-poses".into(), init.into_os_string()];
    let (r, v) = run(&inputs, &dir.path().join("merged"));
    let v = v.expect("JSON");
    assert_eq!(r.code, 0, "{}", r.stderr);
    let (m, s2) = (&v["scans"][0]["viewpoint"], &v["scans"][1]["viewpoint"]);
    assert_eq!(m["used"], false, "{m}");
    assert!(m["explained"].as_f64().expect("explained") < 0.7, "{m}");
    assert_eq!(s2["used"], true, "{s2}");
    let c = &v["checks"][0];
    assert_eq!(c["free_space"]["seen_from"], 1, "{c}");
    assert!(c["free_space"]["share"].as_f64().expect("share") < 0.12, "{c}");
}

/// A scan thinned on a voxel grid (one point a cell, as users hand them
/// over) keeps its scanner's spacing only where the returns lay farther
/// apart than a cell; nearer, its points lie about a cell apart. The 3DTK
/// set thinned to 2 cm cells: the turning scanner's fit with its floor
/// finds each scanner within 0.22–0.32 m (without the floor 0.5–1.2 m),
/// and the set's right pairs keep their free space — worst 8.4 % against
/// 7.7 % unthinned (10.4 % without the floor: near the 12 % line). A
/// room scan so thinned among them is named (its pairs 14–26 %).
#[test]
fn a_thinned_sets_scanners_are_found_and_a_thinned_scan_of_another_place_named() {
    let dir = tempfile::tempdir().expect("temp dir");
    // The first point in each 2 cm cell.
    let thinned = |rel: &str| {
        let cell = 0.02f32;
        let mut seen = std::collections::HashSet::new();
        let mut points = scanner::io::read(Path::new(&data(rel))).expect("scan").points;
        points.retain(|p| seen.insert([p.x, p.y, p.z].map(|v| (v / cell).floor() as i64)));
        plain_ply_of(dir.path(), rel, points)
    };
    let init = dir.path().join("init.json");
    let starts = Value::Array(
        (0..3).map(|k| init_entry(&format!("scan{k:03}.ply"), &scan0_from_scan(k).to_homogeneous())).collect(),
    );
    std::fs::write(&init, starts.to_string()).expect("init poses");
    let set: Vec<OsString> =
        ["3dtk_dat/scan000.3d", "3dtk_dat/scan001.3d", "3dtk_dat/scan002.3d"].iter().map(|rel| thinned(rel)).collect();
    let mut inputs = set.clone();
    inputs.extend(["--init-poses".into(), init.into_os_string()]);
    let (r, v) = run(&inputs, &dir.path().join("set"));
    let v = v.expect("JSON");
    assert_eq!(r.code, 0, "{}", r.stderr);
    for s in v["scans"].as_array().expect("scans") {
        let vp = &s["viewpoint"];
        assert_eq!(vp["used"], true, "{s}");
        assert!(viewpoint_from_origin(s) < 0.4, "{s}");
    }
    let checks = v["checks"].as_array().expect("checks");
    assert_eq!(checks.len(), 3, "{}", v["checks"]);
    assert!(checks.iter().all(|c| c["free_space"]["share"].as_f64().expect("share") < 0.1), "{}", v["checks"]);

    let mut inputs = set;
    inputs.push(thinned("pcl_room_scans/room_scan1.pcd"));
    let (r, v) = run(&inputs, &dir.path().join("other"));
    let v = v.expect("JSON");
    assert_eq!(r.code, 1, "{}", r.stderr);
    assert_eq!(v["untrusted"], serde_json::json!([3]), "{}", v["checks"]);
}

/// Issue 38, no silent failure in any mode: the building example's scans
/// (façades seen at grazing angles, starts within 4 mm of the truth).
/// Simultaneous mode's queue slides them along the walls from any start
/// — the schedule moved scan009 5.5 m, the restart kept as a rescue left
/// seven scans 0.9–4.6 m off (the scans agreeing with it 1.010× worse
/// than with their starts), every further restart named —, and returned
/// it with exit 0 (NEES 180); incremental mode left scan009 0.56 m off
/// (1.002× worse). A result the scans agree with no better than with
/// their starts now names every scan it moved beyond the finest stage's
/// reach of its start (`restart.unsupported`), exit 1. In every mode, a
/// scan further from the truth than that reach is named. With the corner
/// test off, incremental mode's restart slid scan009 1.22 m along its
/// façade, the scans agreeing 0.9963× as much as with their starts —
/// better, but not clearly (`fusion::scanset::SUPPORT_RATIO`): exit 0;
/// now the further restarts run and the finest stage alone lands it.
#[test]
fn a_result_the_scans_agree_with_no_better_than_their_starts_names_its_long_moves() {
    let dir = tempfile::tempdir().expect("temp dir");
    let (scans, truths) = building_scans(dir.path());
    let corner_off = ["--corner-ratio", "0"];
    for (mode, extra) in [
        ("graph", &[][..]),
        ("pairwise", &[]),
        ("incremental", &[]),
        ("simultaneous", &[]),
        ("incremental", &corner_off),
    ] {
        let mut args = vec![scans.clone(), "--mode".into(), mode.into()];
        args.extend(extra.iter().map(|a| OsString::from(*a)));
        let out = if extra.is_empty() { dir.path().join(mode) } else { dir.path().join(format!("{mode}-corner-0")) };
        let (r, v) = run(&args, &out);
        let v = v.unwrap_or_else(|| panic!("{mode}: {}", r.stderr));
        let untrusted: Vec<u64> =
            v["untrusted"].as_array().expect("untrusted").iter().map(|u| u.as_u64().expect("index")).collect();
        assert_eq!(r.code, if untrusted.is_empty() { 0 } else { 1 }, "{mode}: {}", r.stderr);
        let reach = v["stages"].as_array().and_then(|s| s.last()).expect("stages")["max_correspondence_m"]
            .as_f64()
            .expect("reach");
        let restart = &v["restart"];
        let unsupported = restart["unsupported"].as_array().expect("unsupported");
        for (k, off) in scan_offsets(&v, &truths).iter().enumerate() {
            assert!(*off <= reach || untrusted.contains(&(k as u64)), "{mode}: scan {k} {off:.3} m off, not named");
        }
        // Each one named so is in `untrusted`, moved beyond the reach, and
        // the scans agree with the result no better than with their starts.
        for u in unsupported {
            assert!(untrusted.contains(&u["scan"].as_u64().expect("scan")), "{mode}: {restart}");
            assert!(u["moved_m"].as_f64().expect("moved") > reach, "{mode}: {restart}");
        }
        if !extra.is_empty() {
            // (Measured: the restart kept, set off by points in free
            // space; two further restarts, the finest stage alone kept,
            // every scan within 0.23 m of the truth.)
            assert!(!restart["further"].as_array().expect("further").is_empty(), "{restart}");
        }
        if mode == "simultaneous" {
            // (Measured: seven scans 0.5–4.6 m from their starts.)
            assert!(unsupported.len() >= 3, "{restart}");
            let starts = restart["starts_disagreement_m2"].as_f64().expect("starts'");
            let kept = restart["restart_disagreement_m2"].as_f64().expect("the restart's");
            assert!(restart["kept"] == true && kept >= starts, "{restart}");
            let text = run_text(&args, &dir.path().join("text"));
            assert_eq!(text.code, 1, "{}", text.stderr);
            assert!(
                text.stdout.contains("beyond the finest stage's reach")
                    && text.stdout.contains("nothing in the data supports such moves"),
                "{}",
                text.stdout
            );
        }
    }
}
