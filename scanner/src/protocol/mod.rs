//! The wire formats of the real instruments, without any I/O: encoders,
//! streaming decoders and typed errors (`../shared/docs/device_protocols.md`
//! is the specification).
//!
//! - [`sick`]: SICK LMS-2xx binary telegrams (STX, address, length,
//!   payload, status, the SICK CRC-16), ACK/NAK, measured values (B0h);
//! - [`geocom`]: Leica GeoCOM ASCII RPC (`%R1Q`/`%R1P`, transaction ids,
//!   the optional CRC-16/ARC), return codes as a typed enum;
//! - [`nmea`]: NMEA 0183 `XDR` tilt lines with their checksum.
//!
//! The drivers ([`crate::serial`]) and the emulators ([`crate::emulate`])
//! are built on these; fuzz targets exercise the three decoders.

pub mod geocom;
pub mod nmea;
pub mod robot;
pub mod sick;

use thiserror::Error;

/// A malformed or unexpected message on the wire.
#[derive(Debug, Clone, PartialEq, Error)]
#[non_exhaustive]
pub enum ProtocolError {
    /// A checksum or CRC does not match.
    #[error("{what} mismatch: received {received:#06x}, computed {computed:#06x}")]
    Checksum {
        /// Which check (`SICK CRC-16`, `GeoCOM CRC-16/ARC`, `NMEA checksum`).
        what: &'static str,
        /// The value in the message.
        received: u16,
        /// The value computed over the message.
        computed: u16,
    },
    /// A message that does not follow the grammar.
    #[error("malformed {what}: {reason} (in {excerpt:?})")]
    Malformed {
        /// The kind of message.
        what: &'static str,
        /// What is wrong and what was expected.
        reason: String,
        /// The start of the offending text or bytes.
        excerpt: String,
    },
    /// The device rejected a request (SICK NAK, the 92h "not allowed"
    /// reply, an A0h/BBh/F7h "refused").
    #[error("request {request:#04x} refused: {reason}")]
    Refused {
        /// The request's command code.
        request: u8,
        /// Why, as far as the device says.
        reason: String,
    },
    /// A reply to another request (code or transaction id).
    #[error("unexpected reply: expected {expected}, received {received}")]
    Unexpected {
        /// What was expected.
        expected: String,
        /// What came.
        received: String,
    },
}

/// Splits a byte stream into lines at CR, LF or CR LF (empty lines are
/// skipped), dropping lines longer than its maximum (reported once each)
/// and, if asked, the first line (a partial one when a port is opened
/// mid-stream).
#[derive(Debug, Clone)]
pub struct LineSplitter {
    buf: Vec<u8>,
    max: usize,
    overlong: bool,
    skip_first: bool,
}

/// What a [`LineSplitter`] yields.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Line {
    /// A complete line without its ending.
    Text(String),
    /// A line that was too long or not text, dropped.
    Dropped(String),
}

impl LineSplitter {
    /// A splitter for lines of at most `max` bytes; with `skip_first` the
    /// first line is discarded.
    pub fn new(max: usize, skip_first: bool) -> Self {
        Self { buf: Vec::with_capacity(max), max, overlong: false, skip_first }
    }

    /// Forgets the partial line and discards the next one (after input
    /// was dropped mid-line).
    pub fn restart(&mut self) {
        self.buf.clear();
        self.overlong = false;
        self.skip_first = true;
    }

    /// Feeds bytes; returns the lines they complete.
    pub fn push(&mut self, bytes: &[u8]) -> Vec<Line> {
        let mut out = Vec::new();
        for &b in bytes {
            if b == b'\r' || b == b'\n' {
                if self.buf.is_empty() && !self.overlong {
                    continue;
                }
                let line = std::mem::take(&mut self.buf);
                let overlong = std::mem::take(&mut self.overlong);
                if std::mem::take(&mut self.skip_first) {
                    continue;
                }
                out.push(match (overlong, String::from_utf8(line)) {
                    (false, Ok(s)) => Line::Text(s),
                    (true, _) => Line::Dropped(format!("a line longer than {} characters", self.max)),
                    (false, Err(e)) => Line::Dropped(format!("a line that is not text: {e}")),
                });
            } else if self.buf.len() >= self.max {
                self.overlong = true;
            } else {
                self.buf.push(b);
            }
        }
        out
    }
}

/// The first `n` bytes of `bytes` in hex, for messages.
pub(crate) fn hex_excerpt(bytes: &[u8], n: usize) -> String {
    let mut s: String = bytes.iter().take(n).map(|b| format!("{b:02X} ")).collect();
    if bytes.len() > n {
        s.push('…');
    }
    s.trim_end().to_string()
}

/// The first `n` characters of `text`, for messages.
pub(crate) fn text_excerpt(text: &str, n: usize) -> String {
    let mut s: String = text.chars().take(n).collect();
    if text.chars().count() > n {
        s.push('…');
    }
    s
}
