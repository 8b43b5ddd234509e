//! The examples in docs/ are real: they parse and mean what they say (the
//! README's commands run in `missions/tests/readme.rs`).

use cps::geom::{Ray, parse_scene_toml};
use nalgebra::{Point3, Vector3};

fn mission_doc() -> String {
    std::fs::read_to_string(tests::workspace().join("docs/mission.md")).expect("docs/mission.md")
}

fn simulator_doc() -> String {
    std::fs::read_to_string(tests::workspace().join("docs/simulator.md")).expect("docs/simulator.md")
}

/// The first ```toml block after `marker`.
fn toml_block_after(text: &str, marker: &str) -> String {
    let from = text.find(marker).unwrap_or_else(|| panic!("the page lacks '{marker}'"));
    let rest = &text[from..];
    let start = rest.find("```toml\n").expect("a toml block") + "```toml\n".len();
    let end = rest[start..].find("```").expect("end of block");
    rest[start..start + end].to_string()
}

#[test]
fn scene_file_example_parses() {
    let text = toml_block_after(&simulator_doc(), "A scene file (TOML)");
    let scene = parse_scene_toml(&text).unwrap_or_else(|e| panic!("docs/simulator.md scene example: {e}"));
    assert_eq!(scene.name(), "lab");
    // On top of the hall: the crate is there, and so is pillar 1.
    let down = scene.cast(&Ray::new(Point3::new(3.0, 4.0, 3.0), -Vector3::z()).expect("ray"), 10.0).expect("hit");
    assert_eq!(scene.object_name(down.object), "crate");
    assert!(
        !scene.line_of_sight(&Point3::new(8.0, 6.0, 1.0), &Point3::new(12.0, 6.0, 1.0)),
        "pillar 1 of the base hall"
    );
}

#[test]
fn every_key_of_the_mission_reference_is_read() {
    // The reference shows every key at once, including two that exclude
    // each other's settings (`hops` without parent hops, `[backend.serial]`
    // with the simulator): without those, the reader accepts every key and
    // only the plan (a 1 km route in the hall) breaks constraints.
    let text = toml_block_after(&mission_doc(), "# Mission file reference");
    let mut skipping = false;
    let kept: Vec<&str> = text
        .lines()
        .filter(|l| {
            if l.starts_with('[') {
                skipping = l.starts_with("[backend.serial]");
            }
            !skipping && !l.starts_with("hops =")
        })
        .collect();
    let mission = tests::temp_mission(&kept.join("\n"));
    let run = tests::cps_survey(["validate".into(), mission.path.clone().into_os_string()]);
    assert_eq!(run.code, 2);
    let problems: Vec<&str> =
        run.stderr.lines().filter(|l| l.trim_start().starts_with(&*mission.path.to_string_lossy())).collect();
    assert!(!problems.is_empty());
    for p in problems {
        assert!(
            p.contains(": plan: step ") || p.contains(": plan: … and "),
            "the reference has a key the reader refuses: {p}"
        );
    }
}

/// Nothing in the repository reads data from outside it: no source, script,
/// document or CI step names the data folder beside the developers' clones.
#[test]
fn nothing_reads_data_from_beside_the_repository() {
    let needle = ["shared", "data"].join("/");
    let mut stack = vec![tests::workspace()];
    let mut offenders = Vec::new();
    while let Some(dir) = stack.pop() {
        for entry in std::fs::read_dir(&dir).expect("read_dir") {
            let path = entry.expect("entry").path();
            let name = path.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
            if path.is_dir() {
                if !matches!(name.as_str(), "target" | ".git" | "data" | "runs") {
                    stack.push(path);
                }
            } else if let Ok(text) = std::fs::read_to_string(&path)
                && text.contains(&needle)
            {
                offenders.push(path.display().to_string());
            }
        }
    }
    assert!(offenders.is_empty(), "read data from beside the repository: {offenders:?}");
}
