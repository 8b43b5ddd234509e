//! The run journal, `journal.jsonl`: one typed [`Event`] per line with the
//! schema version (`"v"`), appended and flushed as each command is given
//! and each reading taken — the record a killed run resumes from, and that
//! `fuse` and `adjust` re-compute from.
//!
//! Step events (`drive`, `measure`, `tilt`, `scan`, and the derived `fix`
//! and `end`) are replayed in order on `--resume`; the informational ones
//! (`retry`, `stop`, `resume`) are skipped. Version 1 journals (written
//! before this module was typed) read as version 2 ones: version 2 only
//! adds fields and events. Version 3 journals each fix's [`ChainRecord`]
//! (O(1) numbers per station) where version 2 journaled the station's
//! cross-covariance with every earlier scan station (O(n), so O(n²) bytes
//! per run); a journal goes on in the version it was started with.

pub mod directory;
mod read;
mod records;

use std::collections::VecDeque;
use std::fs::{File, OpenOptions};
use std::io::{Seek, SeekFrom, Write};
use std::path::{Path, PathBuf};

use anyhow::{Context, Result};

pub use read::*;
pub use records::*;

use directory::DirLock;

/// An open journal: appends live events, and on resume first hands back the
/// recorded ones.
#[derive(Debug)]
pub struct Journal {
    file: File,
    path: PathBuf,
    version: u32,
    /// Recorded step events still to replay, with their line numbers.
    replay: VecDeque<(usize, Event)>,
    written: usize,
    abort_after: Option<usize>,
    /// The run directory's lock, held as long as the journal is written.
    lock: Option<DirLock>,
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
        Ok(Self {
            file,
            path: path.to_path_buf(),
            version: VERSION,
            replay: VecDeque::new(),
            written: 0,
            abort_after: None,
            lock: None,
        })
    }

    /// Opens the journal `read` from `path` to continue it: its step events
    /// are queued for replay and a torn last line is cut off the file. The
    /// journal goes on in the version it was started with.
    pub fn resume(path: &Path, read: Read) -> Result<Self> {
        read.start(path)?;
        let version = read.version();
        let mut file =
            OpenOptions::new().write(true).open(path).with_context(|| format!("opening {}", path.display()))?;
        if let Some(offset) = read.torn {
            file.set_len(offset).with_context(|| format!("cutting the torn last line of {}", path.display()))?;
        }
        file.seek(SeekFrom::End(0)).with_context(|| format!("opening {}", path.display()))?;
        let replay =
            read.events.into_iter().skip(1).filter(|n| !n.event.informational()).map(|n| (n.line, n.event)).collect();
        Ok(Self { file, path: path.to_path_buf(), version, replay, written: 0, abort_after: None, lock: None })
    }

    /// Holds the run directory's lock as long as this journal lives.
    pub fn hold(&mut self, lock: DirLock) {
        self.lock = Some(lock);
    }

    /// Aborts the process right after the `n`-th event this journal writes
    /// (a crash at a chosen point, for testing `--resume`).
    pub fn abort_after(&mut self, n: Option<usize>) {
        self.abort_after = n;
    }

    /// The version this journal is written in (its `start` line's).
    pub fn version(&self) -> u32 {
        self.version
    }

    /// True while recorded events remain to be replayed.
    pub fn replaying(&self) -> bool {
        !self.replay.is_empty()
    }

    /// The next recorded step event and its line, or `None` once the record
    /// is exhausted and the run goes live.
    pub fn next_recorded(&mut self) -> Option<(usize, Event)> {
        self.replay.pop_front()
    }

    /// The error for a recorded event that is not the step the run takes.
    pub fn mismatch(&self, line: usize, recorded: &Event, expected: &str) -> anyhow::Error {
        anyhow::anyhow!(
            "{}:{line}: the journal records {} where this mission's run takes {expected}; \
             the journal belongs to another mission or plan",
            self.path.display(),
            recorded.describe()
        )
    }

    /// Appends `event` (with the schema version) and flushes it to the disk.
    pub fn append(&mut self, event: Event) -> Result<()> {
        let mut line = serde_json::to_string(&Line { event, v: self.version })?;
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

    fn start() -> Event {
        Event::Start(Start { mission: "m".into(), seed: 1, scene: "hall".into(), stations: 2, children: vec![] })
    }

    fn tilt(station: usize) -> Event {
        Event::Tilt(Recorded {
            unix_time_s: None,
            key: StationKey { station },
            data: Tilted { roll_rad: 0.1, pitch_rad: -0.2 },
            sim: None,
        })
    }

    #[test]
    fn a_torn_last_line_is_cut_and_steps_replay_in_order() {
        let dir = tempfile::tempdir().expect("tempdir");
        let path = dir.path().join("journal.jsonl");
        let mut j = Journal::create(&path).expect("create");
        j.append(start()).expect("append");
        let drive = Event::Drive(Recorded {
            unix_time_s: None,
            key: DriveKey { cycle: 1, robot: "c1".into(), target: [1.0, 2.0, 0.5] },
            data: Driven { distance_m: 1.5 },
            sim: None,
        });
        j.append(drive.clone()).expect("append");
        let step = StepKey::Tilt(StationKey { station: 0 });
        j.append(Event::Retry(Retry { device: "tilt".into(), attempt: 1, error: "x".into(), step })).expect("append");
        j.append(tilt(0)).expect("append");
        drop(j);
        assert!(Journal::create(&path).is_err(), "an existing journal is never overwritten");
        // A write cut inside a multi-byte character.
        let mut f = OpenOptions::new().append(true).open(&path).expect("open");
        f.write_all("{\"event\": \"fix\", \"robot\": \"b\u{e9}".as_bytes().split_last().expect("bytes").1)
            .expect("torn write");
        drop(f);

        let read = read(&path).expect("read");
        assert!(read.torn.is_some());
        let mut j = Journal::resume(&path, read).expect("resume");
        assert_eq!(j.next_recorded().map(|(_, e)| e), Some(drive));
        assert_eq!(j.next_recorded(), Some((4, tilt(0))));
        assert!(!j.replaying() && j.next_recorded().is_none());
        j.append(tilt(1)).expect("append");
        let again = super::read(&path).expect("read");
        assert_eq!(again.torn, None, "the torn line was cut before appending");
        let names: Vec<&str> = again.events.iter().map(|n| n.event.name()).collect();
        assert_eq!(names, ["start", "drive", "retry", "tilt", "tilt"]);
        assert!(again.events.iter().all(|n| n.version == VERSION));
    }

    #[test]
    fn a_corrupt_middle_line_and_an_unknown_version_are_named() {
        let dir = tempfile::tempdir().expect("tempdir");
        let path = dir.path().join("journal.jsonl");
        std::fs::write(&path, "{\"v\":1,\"event\":\"resume\"}\nnot json\n{\"v\":1,\"event\":\"resume\"}\n")
            .expect("write");
        let e = read(&path).expect_err("corrupt");
        assert!(format!("{e:#}").contains("journal.jsonl:2"), "{e:#}");
        std::fs::write(&path, "{\"v\":7,\"event\":\"resume\"}\n").expect("write");
        assert!(format!("{:#}", read(&path).expect_err("version")).contains("version"));
        std::fs::write(&path, "{\"v\":2,\"event\":\"teleport\"}\n").expect("write");
        assert!(format!("{:#}", read(&path).expect_err("unknown event")).contains("journal.jsonl:1"));
    }
}
