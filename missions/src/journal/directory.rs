//! The run directory's guards: one writer at a time (an advisory lock,
//! held while a command writes there) and no symbolic link where a run
//! writes its files (a link would carry the write outside the directory).

use std::fs::{File, OpenOptions, TryLockError};
use std::io::{Read as _, Seek as _, SeekFrom, Write as _};
use std::path::Path;

use anyhow::{Context, Result, bail};

/// The lock file in a run directory (hidden: it is not an output).
pub const LOCK_FILE: &str = ".cps-survey.lock";

/// The names a run writes at the top of its directory (besides its
/// `cloud.*`, and everything under `scans/` and `fusion/`).
const WRITTEN: [&str; 9] = [
    "mission.toml",
    "scene.toml",
    "journal.jsonl",
    "report.json",
    "stations.csv",
    "adjustment.txt",
    "mission.rrd",
    "pipe_deviation.ply",
    LOCK_FILE,
];

/// The directories whose every entry a run (or `fuse`) writes.
const WRITTEN_DIRS: [&str; 2] = ["scans", "fusion"];

/// The lock on a run directory; released when dropped (or when the
/// process ends, however it ends).
#[derive(Debug)]
pub struct DirLock {
    _file: File,
}

/// Locks `dir` (which exists) for `command`, or says who holds it.
pub fn lock(dir: &Path, command: &str) -> Result<DirLock> {
    let path = dir.join(LOCK_FILE);
    refuse_link(&path)?;
    let mut file = OpenOptions::new()
        .read(true)
        .write(true)
        .create(true)
        .truncate(false)
        .open(&path)
        .with_context(|| format!("opening {}", path.display()))?;
    match file.try_lock() {
        Ok(()) => {}
        Err(TryLockError::WouldBlock) => {
            let mut holder = String::new();
            file.read_to_string(&mut holder).ok();
            bail!(
                "{} is in use by another cps-survey ({}): a run directory has one writer at a time; \
                 wait for it to end or choose another --out directory",
                dir.display(),
                holder.trim()
            );
        }
        Err(TryLockError::Error(e)) => return Err(e).with_context(|| format!("locking {}", path.display())),
    }
    let holder = format!("process {}: {command}", std::process::id());
    file.set_len(0)
        .and_then(|()| file.seek(SeekFrom::Start(0)))
        .and_then(|_| file.write_all(holder.as_bytes()))
        .with_context(|| format!("writing {}", path.display()))?;
    Ok(DirLock { _file: file })
}

/// The guards of a command that writes into a finished (or stopped) run
/// directory (`fuse`, `adjust`): no links where it writes, and the lock.
/// Nothing when `dir` holds no journal: the reader says what is missing.
pub fn guard(dir: &Path, command: &str) -> Result<Option<DirLock>> {
    if !dir.join("journal.jsonl").is_file() {
        return Ok(None);
    }
    refuse_links(dir)?;
    lock(dir, command).map(Some)
}

/// Refuses a symbolic link where a run writes: the names of `WRITTEN`,
/// `cloud.*`, and the entries of `scans/` and `fusion/` (recursively).
pub fn refuse_links(dir: &Path) -> Result<()> {
    for name in WRITTEN {
        refuse_link(&dir.join(name))?;
    }
    let Ok(entries) = std::fs::read_dir(dir) else { return Ok(()) };
    for entry in entries.flatten() {
        if entry.file_name().to_string_lossy().starts_with("cloud.") {
            refuse_link(&entry.path())?;
        }
    }
    for sub in WRITTEN_DIRS {
        refuse_links_under(&dir.join(sub))?;
    }
    Ok(())
}

fn refuse_links_under(path: &Path) -> Result<()> {
    refuse_link(path)?;
    if path.is_dir() {
        for entry in std::fs::read_dir(path).with_context(|| format!("reading {}", path.display()))? {
            let entry = entry.with_context(|| format!("reading {}", path.display()))?;
            refuse_links_under(&entry.path())?;
        }
    }
    Ok(())
}

fn refuse_link(path: &Path) -> Result<()> {
    if std::fs::symlink_metadata(path).is_ok_and(|m| m.file_type().is_symlink()) {
        bail!(
            "{} is a symbolic link: a run writes only its own files in its directory; \
             remove the link or choose another --out directory",
            path.display()
        );
    }
    Ok(())
}
