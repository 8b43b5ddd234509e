//! `export --ros2-bag` and `[output] ros2_bag` (issue 37): a run as a
//! rosbag2 directory of standard messages. CI reads the bags with rosbags
//! and mcap-ros2-support (`.ci/check_ros2.py`); here the MCAP is read back
//! with the `mcap` crate's reader and the CDR bytes checked by hand against
//! the journal.

use std::collections::BTreeMap;
use tests::Edit;

use serde_json::Value;
use tests::cps_survey;

use super::journal_v1::{copy_of, fixture_named};

/// The v2 fixture's run copied and exported: (its temporary directory,
/// the run, the bag, what `export` said), the export checked to succeed.
fn exported_fixture() -> (tempfile::TempDir, std::path::PathBuf, std::path::PathBuf, tests::Run) {
    let (tmp, run) = copy_of(&fixture_named("journal-v2"));
    let bag = run.with_file_name("bag");
    let done = export(&run, &bag);
    assert_eq!(done.code, 0, "{}", done.stderr);
    (tmp, run, bag, done)
}

fn export(run: &std::path::Path, bag: &std::path::Path) -> tests::Run {
    cps_survey(["export".into(), run.as_os_str().to_owned(), "--ros2-bag".into(), bag.as_os_str().to_owned()])
}

/// Per topic: (type, messages' bytes).
fn read_bag(dir: &std::path::Path) -> BTreeMap<String, (String, Vec<Vec<u8>>)> {
    let meta = std::fs::read_to_string(dir.join("metadata.yaml")).expect("metadata.yaml");
    assert!(meta.contains("storage_identifier: mcap") && meta.contains("version: 8"), "{meta}");
    let name = dir.file_name().expect("name").to_string_lossy().into_owned();
    let bytes = std::fs::read(dir.join(format!("{name}.mcap"))).expect("the .mcap");
    let mut out: BTreeMap<String, (String, Vec<Vec<u8>>)> = BTreeMap::new();
    for m in mcap::MessageStream::new(&bytes).expect("an MCAP") {
        let m = m.expect("a message");
        let schema = m.channel.schema.as_ref().expect("a schema");
        assert_eq!((schema.encoding.as_str(), m.channel.message_encoding.as_str()), ("ros2msg", "cdr"));
        assert!(std::str::from_utf8(&schema.data).expect("text").contains("MSG: std_msgs/Header"));
        let entry = out.entry(m.channel.topic.clone()).or_insert_with(|| (schema.name.clone(), Vec::new()));
        entry.1.push(m.data.into_owned());
    }
    for (topic, (_, messages)) in &out {
        assert!(meta.contains(&format!("name: \"{topic}\"")), "{topic} not in metadata.yaml");
        assert!(meta.contains(&format!("message_count: {}", messages.len())), "{topic}");
    }
    out
}

fn f64_at(bytes: &[u8], at: usize) -> f64 {
    f64::from_le_bytes(bytes[at..at + 8].try_into().expect("8 bytes"))
}

fn journal(run: &std::path::Path) -> Vec<Value> {
    let text = std::fs::read_to_string(run.join("journal.jsonl")).expect("journal");
    text.lines().map(|l| serde_json::from_str(l).expect("JSON")).collect()
}

#[test]
fn a_run_exports_as_a_rosbag2_of_standard_messages() {
    let (_tmp, run, bag, done) = exported_fixture();
    assert!(done.stdout.contains("/cps/scan"), "{}", done.stdout);
    let topics = read_bag(&bag);
    let kind = |t: &str| topics.get(t).map(|(k, _)| k.as_str());
    assert_eq!(kind("/tf"), Some("tf2_msgs/msg/TFMessage"));
    assert_eq!(kind("/tf_static"), Some("tf2_msgs/msg/TFMessage"));
    assert_eq!(kind("/cps/parent/pose"), Some("geometry_msgs/msg/PoseWithCovarianceStamped"));
    assert_eq!(kind("/cps/ahead/pose"), Some("geometry_msgs/msg/PoseWithCovarianceStamped"));
    assert_eq!(kind("/cps/scan"), Some("sensor_msgs/msg/PointCloud2"));
    assert_eq!(kind("/cps/route"), Some("nav_msgs/msg/Path"));
    assert_eq!(kind("/cps/ellipses"), Some("visualization_msgs/msg/MarkerArray"));

    let events = journal(&run);
    let scans: Vec<&Value> = events.iter().filter(|e| e["event"] == "scan").collect();
    assert_eq!(topics["/cps/scan"].1.len(), scans.len());
    // PointCloud2: CDR header, stamp (8), frame "parent/scanner" (4 + 15),
    // padding to 4, height and width.
    for (cloud, scan) in topics["/cps/scan"].1.iter().zip(&scans) {
        assert_eq!(&cloud[..4], &[0, 1, 0, 0]);
        assert_eq!(u32::from_le_bytes(cloud[12..16].try_into().expect("4")), 15);
        assert_eq!(&cloud[16..31], b"parent/scanner\0");
        let at = 4 + (27usize).next_multiple_of(4);
        let (height, width) = (
            u32::from_le_bytes(cloud[at..at + 4].try_into().expect("4")),
            u32::from_le_bytes(cloud[at + 4..at + 8].try_into().expect("4")),
        );
        assert_eq!((height as u64) * (width as u64), scan["data"]["points"].as_u64().expect("points"));
    }
    // The fixes' poses: frame "map" (4 + 4 bytes), then the position at 16.
    let fixes: Vec<&Value> = events.iter().filter(|e| e["event"] == "fix").collect();
    let poses = &topics["/cps/parent/pose"].1;
    for fix in &fixes {
        let x = fix["data"]["pose"]["x_m"].as_f64().expect("x");
        let y = fix["data"]["pose"]["y_m"].as_f64().expect("y");
        let cxx = fix["data"]["covariance"][0][0].as_f64().expect("cov");
        let found = poses.iter().any(|p| {
            &p[16..20] == b"map\0" && f64_at(p, 4 + 16) == x && f64_at(p, 4 + 24) == y && f64_at(p, 4 + 16 + 56) == cxx
        });
        assert!(found, "station {}: no /cps/parent/pose at ({x}, {y})", fix["station"]);
    }

    // An existing target is never overwritten.
    let again = export(&run, &bag);
    assert_eq!(again.code, 2);
    assert!(again.stderr.contains("already exists"), "{}", again.stderr);
}

#[test]
fn an_interrupted_run_exports_what_it_measured() {
    let (_tmp, run) = copy_of(&fixture_named("journal-v2"));
    let lines: Vec<String> =
        std::fs::read_to_string(run.join("journal.jsonl")).expect("journal").lines().map(String::from).collect();
    let second_scan =
        lines.iter().enumerate().filter(|(_, l)| l.contains("\"event\":\"scan\"")).nth(1).expect("scan").0;
    std::fs::write(run.join("journal.jsonl"), lines[..=second_scan].join("\n") + "\n").expect("cut");
    let bag = run.with_file_name("bag");
    let done = export(&run, &bag);
    assert_eq!(done.code, 0, "{}", done.stderr);
    let topics = read_bag(&bag);
    assert_eq!(topics["/cps/scan"].1.len(), 2, "the two scans taken");
}

#[test]
fn ros2_bag_in_the_mission_writes_rosbag2_in_the_run() {
    let text = std::fs::read_to_string(fixture_named("journal-v2").join("mission.toml")).expect("mission");
    let mission = tests::temp_mission(&text.edit("rerun = false", "rerun = false\nros2_bag = true"));
    let run = mission.path.with_file_name("run");
    let done = tests::run_mission(&mission.path, &run);
    assert_eq!(done.code, 0, "{}", done.stderr);
    assert!(done.stdout.contains("rosbag2/"), "{}", done.stdout);
    let topics = read_bag(&run.join("rosbag2"));
    assert_eq!(topics["/cps/scan"].1.len(), 4);
    let bad = tests::temp_mission(&text.edit("rerun = false", "rerun = false\nros2_bag = \"yes\""));
    let refused = tests::run_mission(&bad.path, &bad.path.with_file_name("run"));
    assert_eq!(refused.code, 2);
    assert!(refused.stderr.contains("output.ros2_bag"), "{}", refused.stderr);
}

/// `match`'s bag reader on a bag of ours: every scan with the points of
/// its file, in the scanner's frame, and from `/tf` and `/tf_static` at
/// its stamp the pose the run gave it: the same points in the world.
#[test]
fn match_reads_the_scans_and_their_poses_back_from_a_bag() {
    let (_tmp, run, bag, _) = exported_fixture();
    let views = missions::products::load::load(&run).expect("the run").views;
    let options = missions::ros2::read::BagOptions::default();
    for input in [bag.clone(), bag.join("bag.mcap")] {
        let scans = missions::ros2::read::read(&input, &options).expect("the bag reads");
        assert_eq!(scans.len(), views.len());
        for (s, v) in scans.iter().zip(&views) {
            assert_eq!(s.points.len(), v.body.len(), "{}", s.file);
            for (p, b) in s.points.iter().zip(&v.body) {
                let (a, b) = (s.start * p.cast::<f64>(), v.direct() * b.cast::<f64>());
                assert!((a - b).norm() < 1e-6, "{}: {a} vs {b}", s.file);
            }
            // The stamp the label names, as GPS time.
            let stamp: f64 = s.file.rsplit('@').next().and_then(|t| t.parse().ok()).expect("BAG#TOPIC@S.NS");
            assert!((s.gps_time_s - scanner::io::gps_time_of_unix(stamp)).abs() < 1e-6, "{}", s.file);
        }
    }
    // One every 100 s of the mission clock: scans 0 and 2 of 0–3 (53 s apart).
    let every = missions::ros2::read::BagOptions { every_s: Some(100.0), ..options.clone() };
    assert_eq!(missions::ros2::read::read(&bag, &every).expect("reads").len(), 2);
    let far = missions::ros2::read::BagOptions { every_distance_m: Some(5.0), ..options.clone() };
    assert_eq!(missions::ros2::read::read(&bag, &far).expect("reads").len(), 2, "1.5, 8.7 m of 1.5, 5.1, 8.7, 12.3 m");
    // What a user gets wrong is named.
    let no_topic = missions::ros2::read::BagOptions { topic: Some("/points".into()), ..options.clone() };
    let err = missions::ros2::read::read(&bag, &no_topic).expect_err("no such topic").to_string();
    assert!(err.contains("/points") && err.contains("/cps/scan"), "{err}");
    let no_frame = missions::ros2::read::BagOptions { frame: Some("world".into()), ..options.clone() };
    let err = format!("{:#}", missions::ros2::read::read(&bag, &no_frame).expect_err("no such frame"));
    assert!(err.contains("world") && err.contains("map"), "{err}");
    let not_odom = missions::ros2::read::BagOptions { odom: Some("/cps/parent/pose".into()), ..options };
    let err = format!("{:#}", missions::ros2::read::read(&bag, &not_odom).expect_err("not odometry"));
    assert!(err.contains("no nav_msgs/msg/Odometry"), "{err}");
    let flag =
        cps_survey(["match".into(), run.join("scans/scan000.3d").into_os_string(), "--every".into(), "1".into()]);
    assert_eq!(flag.code, 2);
    assert!(flag.stderr.contains("--every: for a rosbag2 input"), "{}", flag.stderr);
}

/// A bag cut or damaged anywhere is an error naming it, never a panic.
#[test]
fn a_damaged_bag_is_refused_never_a_panic() {
    let (_tmp, run, bag, _) = exported_fixture();
    let bytes = std::fs::read(bag.join("bag.mcap")).expect("mcap");
    let damaged = run.with_file_name("damaged.mcap");
    let options = missions::ros2::read::BagOptions::default();
    let mut refused = 0;
    for k in 0..97 {
        let at = k * bytes.len() / 97;
        let mut cut = bytes[..at].to_vec();
        let mut flipped = bytes.clone();
        flipped[at] ^= 0x5a;
        for b in [std::mem::take(&mut cut), flipped] {
            std::fs::write(&damaged, &b).expect("write");
            match missions::ros2::read::read(&damaged, &options) {
                Err(e) => {
                    assert!(format!("{e:#}").contains("damaged.mcap"), "{e:#}");
                    refused += 1;
                }
                Ok(scans) => assert!(scans.len() <= 4),
            }
        }
    }
    assert!(refused > 97, "{refused} of 194 damaged bags refused");
}

/// `match --ros2-bag`: the registered scans and poses as a bag, which
/// `match` reads back and registers where it left them.
#[test]
fn match_writes_its_registration_as_a_bag_that_matches_again() {
    let tmp = tempfile::tempdir().expect("tempdir");
    let data = tests::workspace().join("data/3dtk_dat");
    let (out, bag) = (tmp.path().join("m"), tmp.path().join("bag"));
    let args = |input: &std::path::Path, out: &std::path::Path, bag: Option<&std::path::Path>| {
        let mut a: Vec<std::ffi::OsString> =
            vec!["match".into(), input.into(), "--out".into(), out.into(), "--json".into()];
        if let Some(b) = bag {
            a.extend(["--ros2-bag".into(), b.into()]);
        }
        a
    };
    let done = cps_survey(args(&data, &out, Some(&bag)));
    assert_eq!(done.code, 0, "{}", done.stderr);
    let poses: Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("poses.json")).expect("poses")).expect("JSON");
    let topics = read_bag(&bag);
    let scans = poses["scans"].as_array().expect("scans");
    assert_eq!(topics["/cps/scan"].1.len(), scans.len());
    assert_eq!(topics["/cps/pose"].1.len(), scans.len());
    assert_eq!(topics["/tf"].1.len(), scans.len());
    for (p, s) in topics["/cps/pose"].1.iter().zip(scans) {
        let t = &s["world_from_scan"];
        // Header: stamp 8, "map\0" 4 + 4; the position from byte 16.
        for (k, row) in [0, 1, 2].iter().enumerate() {
            assert_eq!(f64_at(p, 4 + 16 + 8 * k), t[*row][3].as_f64().expect("t"), "{}", s["name"]);
        }
    }
    // Matched again from the bag: its poses are the start, and stay.
    let again = cps_survey(args(&bag, &tmp.path().join("m2"), None));
    assert_eq!(again.code, 0, "{}", again.stderr);
    let second: Value =
        serde_json::from_str(&std::fs::read_to_string(tmp.path().join("m2/poses.json")).expect("poses")).expect("JSON");
    for (a, b) in scans.iter().zip(second["scans"].as_array().expect("scans")) {
        let d: f64 = (0..3)
            .map(|r| {
                (a["world_from_scan"][r][3].as_f64().expect("t") - b["world_from_scan"][r][3].as_f64().expect("t"))
                    .powi(2)
            })
            .sum::<f64>()
            .sqrt();
        assert!(d < 2e-3, "{}: {d} m apart", a["name"]);
    }
    let exists = cps_survey(args(&data, &tmp.path().join("m3"), Some(&bag)));
    assert_eq!(exists.code, 2);
    assert!(exists.stderr.contains("--ros2-bag") && exists.stderr.contains("already exists"), "{}", exists.stderr);
}
