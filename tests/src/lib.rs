//! Helpers for the end-to-end tests of `cps-survey`: paths to the example
//! missions and an in-process runner of the command line that captures its
//! output and exit code.
#![warn(missing_docs)]

use std::path::{Path, PathBuf};

use clap::Parser;
use missions::cli::{Cli, exit_code, run};

/// An edit of an example's text that must find what it replaces: a test
/// whose example changed under it fails naming the text, instead of
/// running on the unedited example.
pub trait Edit {
    /// `self` with every `from` replaced by `to`; panics when there is none.
    fn edit(&self, from: &str, to: &str) -> String;
}

impl Edit for str {
    fn edit(&self, from: &str, to: &str) -> String {
        assert!(self.contains(from), "the text to edit has no `{from}`");
        self.replace(from, to)
    }
}

/// The workspace root.
pub fn workspace() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).parent().map(Path::to_path_buf).unwrap_or_default()
}

/// An example mission by file name (`missions/examples/NAME`).
pub fn example(name: &str) -> PathBuf {
    workspace().join("missions/examples").join(name)
}

/// The hall's route as written in `hall.toml`.
pub const HALL_ROUTE: &str = "route_m = [[1.5, 4.2, 1.5], [37.5, 4.2, 1.5], [37.5, 7.8, 1.5], [1.5, 7.8, 1.5]]";

/// Where `hall.toml` sights its control.
pub const HALL_CONTROL_AT: &str = "control_at = [0, 10, 21]";

/// `hall.toml`'s text with the route cut to its first, straight leg of 8
/// stations (x = 1.5 … 26.7 m at y = 4.2 m), control sighted at its start
/// and end, for tests of mechanisms that need no more of the hall.
pub fn hall_first_leg(hall_text: &str) -> String {
    assert!(hall_text.contains(HALL_ROUTE), "hall.toml's route changed: update HALL_ROUTE");
    assert!(hall_text.contains(HALL_CONTROL_AT), "hall.toml's control_at changed: update HALL_CONTROL_AT");
    hall_text
        .edit(HALL_ROUTE, "route_m = [[1.5, 4.2, 1.5], [26.7, 4.2, 1.5]]")
        .edit(HALL_CONTROL_AT, "control_at = \"start-end\"")
}

/// A mission file in its own temporary directory, removed when dropped.
#[derive(Debug)]
pub struct TempMission {
    _dir: tempfile::TempDir,
    /// The file's path.
    pub path: PathBuf,
}

/// Writes `text` as `mission.toml` in a fresh temporary directory.
pub fn temp_mission(text: &str) -> TempMission {
    let dir = tempfile::tempdir().expect("a temporary directory");
    let path = dir.path().join("mission.toml");
    std::fs::write(&path, text).expect("the mission file is written");
    TempMission { _dir: dir, path }
}

/// What one command produced.
#[derive(Debug)]
pub struct Run {
    /// 0 success, 1 acceptance failed, 2 error.
    pub code: u8,
    /// The report written to standard output.
    pub stdout: String,
    /// The error chain, as `main` prints it (empty on success).
    pub stderr: String,
}

/// Runs `cps-survey ARGS…` in-process.
pub fn cps_survey<I, S>(args: I) -> Run
where
    I: IntoIterator<Item = S>,
    S: Into<std::ffi::OsString> + Clone,
{
    let argv: Vec<std::ffi::OsString> =
        std::iter::once("cps-survey".into()).chain(args.into_iter().map(Into::into)).collect();
    let cli = match Cli::try_parse_from(argv) {
        Ok(cli) => cli,
        Err(e) => return Run { code: 2, stdout: String::new(), stderr: e.to_string() },
    };
    let mut out = Vec::new();
    let result = run(cli, &mut out);
    let stderr = match &result {
        Ok(_) => String::new(),
        Err(e) => e.chain().map(ToString::to_string).collect::<Vec<_>>().join("\n"),
    };
    Run { code: exit_code(&result), stdout: String::from_utf8_lossy(&out).into_owned(), stderr }
}

/// Runs `cps-survey run MISSION --out OUT --quiet` in-process.
pub fn run_mission(mission: &Path, out: &Path) -> Run {
    cps_survey([
        "run".into(),
        mission.as_os_str().to_owned(),
        "--out".into(),
        out.as_os_str().to_owned(),
        "--quiet".into(),
    ])
}

/// Rows per entity path in a Rerun `.rrd` file, read back with Rerun's own
/// decoder: `(path, rows, static)` summed over the file's chunks.
pub fn rrd_rows(path: &Path) -> Result<std::collections::BTreeMap<String, (usize, bool)>, String> {
    use rerun::external::re_log_encoding::DecoderApp;
    use rerun::external::re_log_types::LogMsg;
    let file = std::fs::File::open(path).map_err(|e| format!("{}: {e}", path.display()))?;
    let mut rows = std::collections::BTreeMap::new();
    for msg in DecoderApp::decode_lazy(std::io::BufReader::new(file)) {
        let msg = msg.map_err(|e| format!("{}: {e}", path.display()))?;
        if let LogMsg::ArrowMsg(_, arrow) = msg {
            let chunk = rerun::log::Chunk::from_arrow_msg(&arrow).map_err(|e| format!("{}: {e}", path.display()))?;
            let entry = rows.entry(chunk.entity_path().to_string()).or_insert((0, chunk.is_static()));
            entry.0 += chunk.num_rows();
        }
    }
    Ok(rows)
}

/// A mission's text without its control points: no `[[control]]` tables,
/// no `control_at` (the open traverse of the same plan).
pub fn without_control(text: &str) -> String {
    let mut skipping = false;
    let mut out = Vec::new();
    for line in text.lines() {
        let t = line.trim_start();
        if t.starts_with('[') {
            skipping = t.starts_with("[[control]]");
        }
        if !skipping && !t.starts_with("control_at") {
            out.push(line);
        }
    }
    out.join("\n") + "\n"
}
