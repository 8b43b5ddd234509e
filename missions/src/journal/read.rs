//! A journal read back, line by line with its line numbers, and the scan
//! files it names checked against it.

use std::fs::File;
use std::path::Path;

use anyhow::{Context, Result, bail};

use super::records::{Event, READS, Scanned, Start, VERSION};

/// One event of a journal with its 1-based line number.
#[derive(Debug, Clone)]
pub struct Numbered {
    /// Line number, 1-based.
    pub line: usize,
    /// The event.
    pub event: Event,
    /// Its schema version.
    pub version: u32,
}

/// A journal read from its file.
#[derive(Debug, Clone)]
pub struct Read {
    /// Every complete line's event.
    pub events: Vec<Numbered>,
    /// Byte offset of a torn last line (a write cut short by a kill), to cut.
    pub torn: Option<u64>,
}

impl Read {
    /// The `start` event, which must come first.
    pub fn start(&self, path: &Path) -> Result<&Start> {
        match self.events.first().map(|n| &n.event) {
            Some(Event::Start(s)) => Ok(s),
            _ => bail!("{}:1: a journal starts with a \"start\" event; this one does not", path.display()),
        }
    }

    /// The version the journal was started with (its `start` line's).
    pub fn version(&self) -> u32 {
        self.events.first().map_or(VERSION, |n| n.version)
    }
}

/// Now, UNIX seconds (UTC).
pub fn unix_now() -> f64 {
    std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).map_or(0.0, |d| d.as_secs_f64())
}

/// A CRC-32 (IEEE) as journaled: 8 lower-case hex digits.
pub fn crc32_hex(crc: u32) -> String {
    format!("{crc:08x}")
}

/// CRC-32 of a file's bytes (see [`crc32_hex`]).
pub fn file_crc32(path: &Path) -> Result<String> {
    Ok(crc32_hex(scanner::io::file_crc32(path)?))
}

/// Checks that a scan file in `dir` is the one `scanned` records: its
/// checksum (journals of version 2), else it is left to the point count.
pub fn check_scan_file(dir: &Path, scanned: &Scanned) -> Result<()> {
    let path = dir.join(&scanned.file);
    if let Some(recorded) = &scanned.crc32 {
        let found = file_crc32(&path)?;
        if &found != recorded {
            bail!(
                "{} has changed since the run wrote it: CRC-32 {found}, the journal recorded {recorded} ({} points); \
                 a scan is never rewritten — restore the file",
                path.display(),
                scanned.points
            );
        }
    }
    Ok(())
}

/// Reads a journal. A last line without its newline is a write cut short by
/// a kill (even inside a multi-byte character): it is returned separately
/// (as its byte offset) so a resume can drop it; any other line that is not
/// an event of a known version is an error naming it.
pub fn read(path: &Path) -> Result<Read> {
    read_lines(path, true)
}

/// Reads a journal as [`read`] does, without the fixes'
/// `scan_cross_covariances` (only the fusion's joint prior needs them, and
/// they are most of a long journal's bytes): their arrays are skipped
/// unparsed and read as absent.
pub fn read_without_cross_covariances(path: &Path) -> Result<Read> {
    read_lines(path, false)
}

/// A line with its `scan_cross_covariances` array replaced by `null` (the
/// array holds numbers only, so its brackets balance).
fn without_cross_covariances(text: &str) -> std::borrow::Cow<'_, str> {
    const KEY: &str = "\"scan_cross_covariances\":";
    let Some(at) = text.find(KEY) else { return text.into() };
    let from = at + KEY.len();
    let mut depth = 0usize;
    for (i, b) in text.as_bytes()[from..].iter().enumerate() {
        match b {
            b'[' => depth += 1,
            b']' if depth > 1 => depth -= 1,
            b']' => return format!("{}null{}", &text[..from], &text[from + i + 1..]).into(),
            _ if depth == 0 => break,
            _ => {}
        }
    }
    // Not an array: left for the parser to judge.
    text.into()
}

fn read_lines(path: &Path, cross_covariances: bool) -> Result<Read> {
    use std::io::BufRead;
    let file = File::open(path).with_context(|| format!("reading {}", path.display()))?;
    // Line by line: a long journal is never held whole.
    let mut reader = std::io::BufReader::with_capacity(1 << 20, file);
    let mut events = Vec::new();
    let mut offset = 0u64;
    let mut torn = None;
    let mut raw = Vec::new();
    for i in 0.. {
        raw.clear();
        let n = reader.read_until(b'\n', &mut raw).with_context(|| format!("reading {}", path.display()))?;
        if n == 0 {
            break;
        }
        if raw.last() != Some(&b'\n') {
            torn = Some(offset);
            break;
        }
        let text = std::str::from_utf8(&raw)
            .with_context(|| format!("{}:{}: not UTF-8 text: not a journal line", path.display(), i + 1))?;
        // Parsed once (its numbers are most of the work), then typed.
        let text = if cross_covariances { text.into() } else { without_cross_covariances(text) };
        let mut value: serde_json::Value = serde_json::from_str(&text)
            .with_context(|| format!("{}:{}: not a JSON journal event", path.display(), i + 1))?;
        let version: Option<u32> = value
            .as_object_mut()
            .and_then(|o| o.remove("v"))
            .and_then(|v| v.as_u64())
            .and_then(|v| u32::try_from(v).ok());
        let version = match version {
            Some(v) if READS.contains(&v) => v,
            _ => bail!(
                "{}:{}: journal schema version {version:?}; this build reads versions {READS:?}",
                path.display(),
                i + 1
            ),
        };
        let event: Event = serde_json::from_value(value)
            .with_context(|| format!("{}:{}: not a journal event of version {}", path.display(), i + 1, VERSION))?;
        events.push(Numbered { line: i + 1, event, version });
        offset += raw.len() as u64;
    }
    Ok(Read { events, torn })
}
