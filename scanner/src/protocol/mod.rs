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
