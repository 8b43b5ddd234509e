//! A mission over serial ports: `cps-survey emulate`'s team on
//! pseudo-terminals, the mission with `[backend] kind = "serial"` and those
//! ports, run through the serial drivers end to end — and compared with
//! the same mission on the `sim` backend and with the emulator's truth.

use std::path::Path;
use tests::Edit;

use missions::Mission;
use missions::commands::emulate::{EmulatorFault, backend_toml, start};
use missions::planning::Planned;
use serde_json::Value;
use tests::{cps_survey, example, run_mission, temp_mission};

/// The hall example with fewer slices per scan (the test's time), on `kind`.
fn hall(kind: &str, extra_backend: &str) -> String {
    let text = std::fs::read_to_string(example("hall.toml")).expect("hall.toml");
    text.edit("slices = 180", "slices = 24")
        .edit("kind = \"sim\"", &format!("kind = \"{kind}\"\n{extra_backend}"))
        .edit("[output]\nformats = [\"ply\"]", "[output]\nformats = [\"ply\"]\nrerun = false")
}

fn report(dir: &Path) -> Value {
    serde_json::from_str(&std::fs::read_to_string(dir.join("report.json")).expect("report.json")).expect("json")
}

fn lines(path: &Path) -> Vec<Value> {
    std::fs::read_to_string(path)
        .expect("readable")
        .lines()
        .map(|l| serde_json::from_str(l).expect("a JSON line"))
        .collect()
}

fn xy(v: &Value) -> [f64; 2] {
    [v["x_m"].as_f64().expect("x"), v["y_m"].as_f64().expect("y")]
}

#[test]
fn a_mission_over_serial_ports_matches_the_simulator() {
    let sim_mission = temp_mission(&hall("sim", ""));
    let m = Mission::load(&sim_mission.path).expect("valid");
    let dir = tempfile::tempdir().expect("tempdir");
    let truth_log = dir.path().join("truth.jsonl");
    let team = start(&m, &Planned::new(&m).expect("plan"), Some(&truth_log), &[]).expect("the team on ptys");
    let serial_text = format!("{}\n{}", hall("serial", ""), backend_toml(&m, &team));
    let serial_mission = temp_mission(&serial_text);

    let serial = run_mission(&serial_mission.path, &dir.path().join("serial"));
    assert_eq!(serial.code, 0, "{}\n{}", serial.stdout, serial.stderr);
    let sim = run_mission(&sim_mission.path, &dir.path().join("sim"));
    assert_eq!(sim.code, 0, "{}", sim.stderr);
    let (rs, rm) = (report(&dir.path().join("serial")), report(&dir.path().join("sim")));
    assert_eq!(rs["backend"], "serial");
    assert!(rs["final"]["error_xy_m"].is_null() && rs["stations"][1]["truth"].is_null(), "no truth on serial");

    // The emulator's truth: the parent after each of its moves.
    let truths: Vec<[f64; 2]> = lines(&truth_log)
        .iter()
        .filter(|l| l["moved"] == "start" || l["moved"] == "parent")
        .map(|l| [l["parent"][0].as_f64().expect("x"), l["parent"][1].as_f64().expect("y")])
        .collect();
    let (ss, sm) = (rs["stations"].as_array().expect("stations"), rm["stations"].as_array().expect("stations"));
    assert_eq!((ss.len(), sm.len(), truths.len()), (22, 22, 22));
    for (k, ((s, m), t)) in ss.iter().zip(sm).zip(&truths).enumerate() {
        let sigma = |r: &Value| {
            let c = &r["covariance"];
            (c[0][0].as_f64().expect("cxx") + c[1][1].as_f64().expect("cyy")).sqrt()
        };
        let (p, q) = (xy(&s["pose"]), xy(&m["pose"]));
        let error = (p[0] - t[0]).hypot(p[1] - t[1]);
        // The positioning draws the same noise on both backends (same
        // seeds, same order); only the wire's rounding differs.
        let sim_error = m["error_m"].as_f64().expect("sim error");
        assert!((error - sim_error).abs() < 1e-4, "station {k}: {error} vs {sim_error}");
        assert!((p[0] - q[0]).hypot(p[1] - q[1]) < 1e-4, "station {k}: {p:?} vs {q:?}");
        assert!((sigma(s) - sigma(m)).abs() <= 0.01 * sigma(m) + 1e-9, "station {k}");
        // And the error is one the covariance explains.
        assert!(error <= 4.0 * sigma(s) + 1e-4, "station {k}: {error} m vs σ {}", sigma(s));
    }
    // The scans came over the LMS protocol: the fused cloud lies on the hall.
    let cloud = scanner::io::read(&dir.path().join("serial/cloud.ply")).expect("cloud");
    let scene = cps::geom::builtin("hall").expect("hall");
    let on = missions::run::runner::on_surface_fraction(&scene, &cloud.points, 0.05);
    assert!(cloud.len() > 20_000 && on > 0.99, "{} points, {:.2} % on surfaces", cloud.len(), 100.0 * on);

    // Real instruments' steps carry their UTC time, and the run's rosbag2
    // is stamped with it: each scan at its journaled time.
    let events = lines(&dir.path().join("serial/journal.jsonl"));
    let steps: Vec<&Value> = events
        .iter()
        .filter(|e| ["drive", "measure", "tilt", "scan"].contains(&e["event"].as_str().unwrap_or("")))
        .collect();
    assert!(
        steps.iter().all(|e| e["unix_time_s"].as_f64().is_some_and(|t| t > 1.7e9)),
        "every step of the serial run is timed"
    );
    let sim_events = lines(&dir.path().join("sim/journal.jsonl"));
    assert!(sim_events.iter().all(|e| e.get("unix_time_s").is_none()), "the simulator's steps keep the mission clock");
    let bag = dir.path().join("bag");
    let exported = cps_survey([
        "export".into(),
        dir.path().join("serial").into_os_string(),
        "--ros2-bag".into(),
        bag.clone().into_os_string(),
    ]);
    assert_eq!(exported.code, 0, "{}", exported.stderr);
    let bytes = std::fs::read(bag.join("bag.mcap")).expect("the bag");
    let scan_times: Vec<u64> = events
        .iter()
        .filter(|e| e["event"] == "scan")
        .map(|e| (e["unix_time_s"].as_f64().expect("time") * 1e9).round() as u64)
        .collect();
    let stamps: Vec<u64> = mcap::MessageStream::new(&bytes)
        .expect("MCAP")
        .map(|m| m.expect("message"))
        .filter(|m| m.channel.topic == "/cps/scan")
        .map(|m| m.log_time)
        .collect();
    assert_eq!(stamps.len(), scan_times.len());
    for (a, b) in stamps.iter().zip(&scan_times) {
        assert!(a.abs_diff(*b) < 1_000, "a scan stamped {a} ns, journaled at {b} ns");
    }
}

#[test]
fn a_silent_total_station_stops_the_mission_with_every_reading_kept() {
    let m = Mission::load(&temp_mission(&hall("sim", "")).path).expect("valid");
    // GeoCOM: 3 RPCs to connect, 4 per measurement: 5 measurements, then silence.
    let fault: EmulatorFault = "total-station:stop-after=23".parse().expect("fault");
    let team = start(&m, &Planned::new(&m).expect("plan"), None, &[fault]).expect("the team on ptys");
    let quick = "max_retries = 1\nretry_delay_s = 0.01";
    let text = format!("{}\n{}total_station_timeout_s = 0.2\n", hall("serial", quick), backend_toml(&m, &team));
    let mission = temp_mission(&text);
    let dir = tempfile::tempdir().expect("tempdir");
    let run = run_mission(&mission.path, &dir.path().join("run"));
    assert_eq!(run.code, 2, "{}", run.stdout);
    assert!(run.stderr.contains("total station on /dev/"), "{}", run.stderr);
    assert!(run.stderr.contains("--resume"), "{}", run.stderr);
    let events = lines(&dir.path().join("run/journal.jsonl"));
    let measured: Vec<&Value> = events.iter().filter(|e| e["event"] == "measure").collect();
    assert_eq!(measured.len(), 5, "every reading before the fault is journaled");
    assert!(measured.iter().all(|e| e["data"]["slope_raw_m"].as_f64().is_some_and(|d| d > 1.0)));
    assert_eq!(events.iter().filter(|e| e["event"] == "retry").count(), 1);
    assert_eq!(events.last().map(|e| e["event"].clone()), Some("stop".into()));
}

#[test]
fn emulate_prints_the_ports_and_bad_faults_are_named() {
    let path = example("hall.toml");
    let path = path.to_str().expect("utf-8");
    let text = cps_survey(["emulate", path, "--seconds", "0"]);
    assert_eq!(text.code, 0, "{}", text.stderr);
    assert!(
        text.stdout.contains("[backend.serial]") && text.stdout.contains("drives = [\"/dev/pts/"),
        "{}",
        text.stdout
    );
    let json = cps_survey(["emulate", path, "--json", "--seconds", "0"]);
    let v: Value = serde_json::from_str(json.stdout.trim()).expect("one JSON object");
    let roles: Vec<&str> =
        v["instruments"].as_array().expect("list").iter().map(|i| i["role"].as_str().expect("role")).collect();
    assert_eq!(roles, ["total-station", "tilt", "scanner", "head", "parent", "ahead", "behind"]);
    assert_eq!(v["instruments"][2]["protocol"], "SICK LMS-2xx");
    let bad = cps_survey(["emulate", path, "--fault", "laser:stop-after=1", "--seconds", "0"]);
    assert_eq!(bad.code, 2);
    assert!(bad.stderr.contains("\"laser\": no such instrument"), "{}", bad.stderr);
    assert!("scanner:sometimes=3".parse::<EmulatorFault>().is_err());
}
