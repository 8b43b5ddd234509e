//! The run journal, `journal.jsonl`: one JSON object per line with a schema
//! version, appended and flushed as each command is given and each reading
//! taken — the record a killed run resumes from and `fuse` re-fuses from.
//!
//! Every event has `"v"` and `"event"`. Step events (`drive`, `measure`,
//! `tilt`, `scan`, `fix`, `station`) are replayed in order on `--resume`;
//! the informational ones (`retry`, `stop`, `resume`) are skipped.

use std::collections::VecDeque;
use std::fs::{File, OpenOptions};
use std::io::{Seek, SeekFrom, Write};
use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail};
use serde_json::{Value, json};

/// Journal schema version.
pub const VERSION: u64 = 1;

/// Events a replay skips: they record what happened but are not steps.
const INFORMATIONAL: [&str; 3] = ["retry", "stop", "resume"];

/// An open journal: appends live events, and on resume first hands back the
/// recorded ones.
#[derive(Debug)]
pub struct Journal {
    file: File,
    path: PathBuf,
    /// Recorded step events still to replay, with their line numbers.
    replay: VecDeque<(usize, Value)>,
    written: usize,
    abort_after: Option<usize>,
}

/// One line of a journal, parsed.
#[derive(Debug, Clone)]
pub struct Line {
    /// Line number, 1-based.
    pub line: usize,
    /// The event.
    pub event: Value,
}

/// Reads a journal. A last line without its newline is a write cut short by
/// a kill: it is returned separately (as its byte offset) so a resume can
/// drop it; any other unparsable line is an error naming it.
pub fn read(path: &Path) -> Result<(Vec<Line>, Option<u64>)> {
    let text = std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
    let mut lines = Vec::new();
    let mut offset = 0u64;
    let mut torn = None;
    for (i, raw) in text.split_inclusive('\n').enumerate() {
        if !raw.ends_with('\n') {
            torn = Some(offset);
            break;
        }
        let event: Value = serde_json::from_str(raw)
            .with_context(|| format!("{}:{}: not a JSON journal event", path.display(), i + 1))?;
        let version = event.get("v").and_then(Value::as_u64);
        if version != Some(VERSION) {
            bail!("{}:{}: journal schema version {:?}; expected {VERSION}", path.display(), i + 1, version);
        }
        if event.get("event").and_then(Value::as_str).is_none() {
            bail!("{}:{}: an event without an \"event\" name", path.display(), i + 1);
        }
        lines.push(Line { line: i + 1, event });
        offset += raw.len() as u64;
    }
    Ok((lines, torn))
}

/// The `"event"` name of an event.
pub fn name(event: &Value) -> &str {
    event.get("event").and_then(Value::as_str).unwrap_or("?")
}

impl Journal {
    /// Starts a new journal at `path`; an existing one is never overwritten.
    pub fn create(path: &Path) -> Result<Self> {
        let file = OpenOptions::new().write(true).create_new(true).open(path).map_err(|e| {
            if e.kind() == std::io::ErrorKind::AlreadyExists {
                anyhow::anyhow!(
                    "{} already holds a run; continue it with --resume or choose another --out directory",
                    path.display()
                )
            } else {
                anyhow::Error::new(e).context(format!("creating {}", path.display()))
            }
        })?;
        Ok(Self { file, path: path.to_path_buf(), replay: VecDeque::new(), written: 0, abort_after: None })
    }

    /// Opens an existing journal to continue it: returns it with its start
    /// event, and queues its step events for replay. A torn last line is cut
    /// off the file.
    pub fn resume(path: &Path) -> Result<(Self, Value)> {
        if !path.exists() {
            bail!("{} does not exist: there is no run to resume there", path.display());
        }
        let (lines, torn) = read(path)?;
        let mut lines = lines.into_iter();
        let start = lines.next().filter(|l| name(&l.event) == "start").with_context(|| {
            format!("{}:1: a journal starts with a \"start\" event; this one cannot be resumed", path.display())
        })?;
        let mut file =
            OpenOptions::new().write(true).open(path).with_context(|| format!("opening {}", path.display()))?;
        if let Some(offset) = torn {
            file.set_len(offset).with_context(|| format!("cutting the torn last line of {}", path.display()))?;
        }
        file.seek(SeekFrom::End(0))?;
        let replay = lines.filter(|l| !INFORMATIONAL.contains(&name(&l.event))).map(|l| (l.line, l.event)).collect();
        Ok((Self { file, path: path.to_path_buf(), replay, written: 0, abort_after: None }, start.event))
    }

    /// Aborts the process right after the `n`-th event this journal writes
    /// (a crash at a chosen point, for testing `--resume`).
    pub fn abort_after(&mut self, n: Option<usize>) {
        self.abort_after = n;
    }

    /// True while recorded events remain to be replayed.
    pub fn replaying(&self) -> bool {
        !self.replay.is_empty()
    }

    /// The next recorded step event, which must match `key` (every field of
    /// `key` equal), or `None` once the record is exhausted and the run goes
    /// live.
    pub fn next_recorded(&mut self, key: &Value) -> Result<Option<Value>> {
        let Some((line, event)) = self.replay.pop_front() else { return Ok(None) };
        let matches = key.as_object().is_some_and(|k| k.iter().all(|(field, value)| event.get(field) == Some(value)));
        if !matches {
            bail!(
                "{}:{line}: the journal records {event} where this mission's run takes {key}; \
                 the journal belongs to another mission or plan",
                self.path.display()
            );
        }
        Ok(Some(event))
    }

    /// Appends `event` (with the schema version) and flushes it to the disk.
    pub fn append(&mut self, mut event: Value) -> Result<()> {
        event["v"] = json!(VERSION);
        let mut line = serde_json::to_string(&event)?;
        line.push('\n');
        self.file
            .write_all(line.as_bytes())
            .and_then(|()| self.file.flush())
            .with_context(|| format!("writing {}", self.path.display()))?;
        self.written += 1;
        if self.abort_after == Some(self.written) {
            std::process::abort();
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_torn_last_line_is_cut_and_steps_replay_in_order() {
        let dir = tempfile::tempdir().expect("tempdir");
        let path = dir.path().join("journal.jsonl");
        let mut j = Journal::create(&path).expect("create");
        j.append(json!({"event": "start", "mission": "m"})).expect("append");
        j.append(json!({"event": "drive", "robot": "c1", "distance_m": 1.5})).expect("append");
        j.append(json!({"event": "retry", "device": "x"})).expect("append");
        j.append(json!({"event": "measure", "child": 0})).expect("append");
        drop(j);
        assert!(Journal::create(&path).is_err(), "an existing journal is never overwritten");
        let mut f = OpenOptions::new().append(true).open(&path).expect("open");
        f.write_all(br#"{"event": "fix", "v""#).expect("torn write");
        drop(f);

        let (mut j, start) = Journal::resume(&path).expect("resume");
        assert_eq!(start["mission"], "m");
        let drive = j.next_recorded(&json!({"event": "drive", "robot": "c1"})).expect("match").expect("recorded");
        assert_eq!(drive["distance_m"], 1.5);
        let wrong = j.next_recorded(&json!({"event": "measure", "child": 1})).expect_err("child differs");
        assert!(wrong.to_string().contains("journal.jsonl:4"), "{wrong}");
        assert!(!j.replaying());
        assert!(j.next_recorded(&json!({"event": "tilt"})).expect("live").is_none());
        j.append(json!({"event": "tilt"})).expect("append");
        let (lines, torn) = read(&path).expect("read");
        assert_eq!(torn, None, "the torn line was cut before appending");
        assert_eq!(
            lines.iter().map(|l| name(&l.event)).collect::<Vec<_>>(),
            ["start", "drive", "retry", "measure", "tilt"]
        );
    }

    #[test]
    fn a_corrupt_middle_line_is_named() {
        let dir = tempfile::tempdir().expect("tempdir");
        let path = dir.path().join("journal.jsonl");
        std::fs::write(&path, "{\"v\":1,\"event\":\"start\"}\nnot json\n{\"v\":1,\"event\":\"end\"}\n").expect("write");
        let e = Journal::resume(&path).expect_err("corrupt");
        assert!(format!("{e:#}").contains("journal.jsonl:2"), "{e:#}");
        std::fs::write(&path, "{\"v\":7,\"event\":\"start\"}\n").expect("write");
        assert!(format!("{:#}", Journal::resume(&path).expect_err("version")).contains("version"));
    }
}
