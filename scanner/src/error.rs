//! The one error type of the `scanner` crate.

use std::fmt;
use std::path::PathBuf;

use thiserror::Error;

/// Where in a file a problem was found.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Location {
    /// 1-based text line.
    Line(usize),
    /// Byte offset from the start of the file.
    Byte(u64),
    /// The file as a whole.
    File,
}

impl fmt::Display for Location {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Location::Line(l) => write!(f, "line {l}"),
            Location::Byte(b) => write!(f, "byte {b}"),
            Location::File => write!(f, "file"),
        }
    }
}

/// Everything that can go wrong with a device or a scan file. Device errors
/// name the device; file errors name the file and the line or byte.
#[derive(Debug, Error)]
#[non_exhaustive]
pub enum ScannerError {
    /// The total station cannot see its target.
    #[error("{device}: no line of sight to {target}: blocked by '{blocked_by}' {at_m:.2} m from the instrument")]
    NoLineOfSight {
        /// Device name.
        device: String,
        /// What was aimed at.
        target: String,
        /// The scene object in the way.
        blocked_by: String,
        /// Distance of the obstruction, metres.
        at_m: f64,
    },
    /// A value a device was asked for or measured is out of its range.
    #[error("{device}: {what} = {value} is out of range: expected {expected}")]
    OutOfRange {
        /// Device name.
        device: String,
        /// What the value is.
        what: String,
        /// The value.
        value: f64,
        /// The accepted range.
        expected: String,
    },
    /// Any other device failure.
    #[error("{device}: {message}")]
    Device {
        /// Device name.
        device: String,
        /// What happened.
        message: String,
    },
    /// A scan file is malformed.
    #[error("{}: {location}: {message}", path.display())]
    File {
        /// The file.
        path: PathBuf,
        /// Where in it.
        location: Location,
        /// What is wrong and what was expected.
        message: String,
    },
    /// Reading or writing a file failed.
    #[error("{}: {source}", path.display())]
    Io {
        /// The file.
        path: PathBuf,
        /// The I/O error.
        #[source]
        source: std::io::Error,
    },
    /// An error of the CPS model or the scene.
    #[error(transparent)]
    Cps(#[from] cps::CpsError),
    /// A device did not answer in time (after its retries).
    #[error("{device}: no answer to {waiting_for} within {waited_s:.2} s ({attempts} attempt(s))")]
    Timeout {
        /// Device name (and port).
        device: String,
        /// The request or data waited for.
        waiting_for: String,
        /// Total time waited, seconds.
        waited_s: f64,
        /// Attempts made.
        attempts: usize,
    },
    /// A device sent something the protocol does not allow, or rejected a
    /// request, on every attempt.
    #[error("{device}: {source}")]
    Protocol {
        /// Device name (and port).
        device: String,
        /// What was wrong.
        #[source]
        source: crate::protocol::ProtocolError,
    },
    /// A total station answered with a GeoCOM error code.
    #[error("{device}: {request} failed: {code}")]
    Instrument {
        /// Device name (and port).
        device: String,
        /// The request, e.g. `AUT_FineAdjust (9037)`.
        request: String,
        /// The instrument's return code.
        code: crate::protocol::geocom::ReturnCode,
    },
    /// A tilt sensor's last valid reading is too old.
    #[error("{device}: no valid reading for {age_s:.2} s (stale; expected one every {period_s:.2} s)")]
    Stale {
        /// Device name (and port).
        device: String,
        /// Time since the last valid reading (or since asked), seconds.
        age_s: f64,
        /// The sensor's nominal period, seconds.
        period_s: f64,
    },
}

impl ScannerError {
    pub(crate) fn file(path: impl Into<PathBuf>, location: Location, message: impl Into<String>) -> Self {
        ScannerError::File { path: path.into(), location, message: message.into() }
    }

    /// A format library's error about the file as a whole.
    pub(crate) fn whole_file(path: &std::path::Path, e: impl std::fmt::Display) -> Self {
        Self::file(path, Location::File, e.to_string())
    }

    pub(crate) fn io(path: impl Into<PathBuf>, source: std::io::Error) -> Self {
        ScannerError::Io { path: path.into(), source }
    }
}

/// Result alias of the `scanner` crate.
pub type Result<T, E = ScannerError> = std::result::Result<T, E>;
