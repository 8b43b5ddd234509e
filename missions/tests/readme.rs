//! Every command in the README runs as written, in the README's order, from
//! a folder that holds only what a clone ships (`missions/examples/`,
//! `data/`) — as a new user would type them, with the built binary — and
//! exits 0; every subcommand has its example. The README's commands are
//! the default build's (`match` writes `match.rrd`; the headless build
//! refuses what asks for a recording: `tests/headless.rs`).
#![cfg(feature = "recording")]

use std::path::{Path, PathBuf};
use std::process::Command;

fn workspace() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).parent().expect("workspace").to_path_buf()
}

fn copy_tree(from: &Path, to: &Path) {
    std::fs::create_dir_all(to).expect("create");
    for entry in std::fs::read_dir(from).expect("read_dir") {
        let path = entry.expect("entry").path();
        let target = to.join(path.file_name().expect("name"));
        if path.is_dir() {
            copy_tree(&path, &target);
        } else {
            std::fs::copy(&path, &target).expect("copy");
        }
    }
}

/// The README's commands: each line of a fenced block that starts with
/// `cps-survey ` or `cargo run --release -p missions -- `, as the words
/// after the program.
fn commands(readme: &str) -> Vec<(String, Vec<String>)> {
    let mut inside = false;
    let mut found = Vec::new();
    for line in readme.lines() {
        if line.starts_with("```") {
            inside = !inside;
            continue;
        }
        if !inside {
            continue;
        }
        let line = line.split(" # ").next().unwrap_or(line).trim();
        let rest =
            line.strip_prefix("cps-survey ").or_else(|| line.strip_prefix("cargo run --release -p missions -- "));
        if let Some(rest) = rest {
            assert!(!rest.contains(['"', '\'', '\\', '~', '*']), "README: a command the test cannot split: {line}");
            found.push((line.to_string(), rest.split_whitespace().map(str::to_owned).collect()));
        }
    }
    found
}

#[test]
fn every_command_in_the_readme_runs_from_what_a_clone_ships() {
    let root = workspace();
    let readme = std::fs::read_to_string(root.join("README.md")).expect("README.md");
    let commands = commands(&readme);
    let dir = tempfile::tempdir().expect("temp dir");
    copy_tree(&root.join("missions/examples"), &dir.path().join("missions/examples"));
    copy_tree(&root.join("data"), &dir.path().join("data"));
    for (line, args) in &commands {
        let out = Command::new(env!("CARGO_BIN_EXE_cps-survey"))
            .args(args)
            .current_dir(dir.path())
            .output()
            .expect("the binary runs");
        assert_eq!(
            out.status.code(),
            Some(0),
            "README: `{line}` exited {:?}:\n{}",
            out.status.code(),
            String::from_utf8_lossy(&out.stderr)
        );
    }
    // One worked example per command.
    for sub in [
        "run",
        "fuse",
        "montecarlo",
        "predict",
        "plan",
        "validate",
        "emulate",
        "adjust",
        "export",
        "schemas",
        "register",
        "match",
    ] {
        assert!(commands.iter().any(|(_, a)| a.first().map(String::as_str) == Some(sub)), "README: no `{sub}` example");
    }
    // What the examples say they write is there.
    for file in ["runs/hall/mission.rrd", "runs/hall/fusion/cps-icp/fusion.json", "runs/hall-bag/metadata.yaml"] {
        assert!(dir.path().join(file).is_file(), "no {file}");
    }
    for file in ["matched/poses.json", "matched/cloud.las", "room/poses.json", "hall-optimized.toml"] {
        assert!(dir.path().join(file).is_file(), "no {file}");
    }
}
