//! NMEA 0183 `XDR` tilt lines (device_protocols.md §3):
//! `$IIXDR,A,<pitch>,D,PITCH,A,<roll>,D,ROLL*hh` CR LF, angles in degrees,
//! the checksum the XOR of the characters between `$` and `*`.
//!
//! Sign convention (ours, fixed here): PITCH is positive nose **up** about
//! the sensor's y (left) axis, ROLL positive right side **down** about its x
//! (forward) axis. The model's [`crate::Tilt`] has pitch positive nose down
//! (right-handed about +y) and roll right-handed about +x, so
//! `pitch_rad = −PITCH`, `roll_rad = +ROLL`.

use super::{ProtocolError, text_excerpt};
use crate::devices::Tilt;

/// Longest sentence NMEA 0183 allows, characters including `$` and CR LF.
pub const MAX_LINE: usize = 82;

/// XOR of the bytes of `body` (between `$` and `*`).
pub fn checksum(body: &str) -> u8 {
    body.bytes().fold(0, |a, b| a ^ b)
}

/// An XDR line (CR LF included) with `talker` (two letters) and the angles
/// in degrees, three decimals.
pub fn format_xdr(talker: &str, pitch_deg: f64, roll_deg: f64) -> String {
    let body = format!("{talker}XDR,A,{pitch_deg:.3},D,PITCH,A,{roll_deg:.3},D,ROLL");
    format!("${body}*{:02X}\r\n", checksum(&body))
}

/// The line for a [`Tilt`] (the inverse of [`TiltLine::tilt`]).
pub fn format_tilt(talker: &str, tilt: &Tilt) -> String {
    format_xdr(talker, -tilt.pitch_rad.to_degrees(), tilt.roll_rad.to_degrees())
}

/// A parsed tilt line.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TiltLine {
    /// PITCH, degrees, nose up positive.
    pub pitch_deg: f64,
    /// ROLL, degrees, right side down positive.
    pub roll_deg: f64,
}

impl TiltLine {
    /// In the model's convention.
    pub fn tilt(&self) -> Tilt {
        Tilt { roll_rad: self.roll_deg.to_radians(), pitch_rad: -self.pitch_deg.to_radians() }
    }
}

/// Parses one sentence (line ending optional): the checksum must be present
/// and right; the transducers may come in any order among others (e.g. a
/// temperature), PITCH and ROLL must be there as angular displacements in
/// degrees.
pub fn parse_xdr(line: &str) -> Result<TiltLine, ProtocolError> {
    let text = line.trim_end_matches(['\r', '\n']);
    let malformed = |reason: String| ProtocolError::Malformed {
        what: "NMEA XDR sentence",
        reason,
        excerpt: text_excerpt(text, 40),
    };
    if text.len() + 2 > MAX_LINE {
        return Err(malformed(format!("{} characters; NMEA 0183 allows {MAX_LINE}", text.len() + 2)));
    }
    let inner = text.strip_prefix('$').ok_or_else(|| malformed("expected it to start with '$'".into()))?;
    let (body, sum) =
        inner.rsplit_once('*').ok_or_else(|| malformed("no '*hh' checksum (required for tilt lines)".into()))?;
    let received = u8::from_str_radix(sum, 16)
        .ok()
        .filter(|_| sum.len() == 2)
        .ok_or_else(|| malformed(format!("checksum {sum:?}; expected two hex digits")))?;
    let computed = checksum(body);
    if received != computed {
        return Err(ProtocolError::Checksum {
            what: "NMEA checksum",
            received: u16::from(received),
            computed: u16::from(computed),
        });
    }
    let fields: Vec<&str> = body.split(',').collect();
    let head = fields[0];
    if head.len() != 5 || !head.ends_with("XDR") || !head.is_ascii() {
        return Err(malformed(format!("sentence {head:?}; expected a talker and XDR, e.g. IIXDR")));
    }
    let quads = &fields[1..];
    if quads.is_empty() || !quads.len().is_multiple_of(4) {
        return Err(malformed(format!(
            "{} fields after {head}; expected groups of 4 (type, value, unit, id)",
            quads.len()
        )));
    }
    let mut pitch = None;
    let mut roll = None;
    for q in quads.chunks_exact(4) {
        let slot = match q[3] {
            "PITCH" => &mut pitch,
            "ROLL" => &mut roll,
            _ => continue,
        };
        if q[0] != "A" || q[2] != "D" {
            return Err(malformed(format!(
                "{} is type {:?} in {:?}; expected A (angle) in D (degrees)",
                q[3], q[0], q[2]
            )));
        }
        let v: f64 = q[1]
            .parse()
            .ok()
            .filter(|v: &f64| v.is_finite() && v.abs() <= 180.0)
            .ok_or_else(|| malformed(format!("{} = {:?}; expected degrees within ±180", q[3], q[1])))?;
        *slot = Some(v);
    }
    match (pitch, roll) {
        (Some(pitch_deg), Some(roll_deg)) => Ok(TiltLine { pitch_deg, roll_deg }),
        _ => Err(malformed("expected both a PITCH and a ROLL transducer".into())),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_documented_line() {
        assert_eq!(format_xdr("II", 1.25, -0.5), "$IIXDR,A,1.250,D,PITCH,A,-0.500,D,ROLL*3B\r\n");
        let t = parse_xdr("$IIXDR,A,1.250,D,PITCH,A,-0.500,D,ROLL*3B").expect("valid");
        assert_eq!(t, TiltLine { pitch_deg: 1.25, roll_deg: -0.5 });
        // Nose up is the model's negative pitch; the round trip holds.
        let tilt = Tilt { roll_rad: 0.01, pitch_rad: -0.02 };
        let back = parse_xdr(&format_tilt("II", &tilt)).expect("valid").tilt();
        assert!((back.roll_rad - 0.01).abs() < 1e-5 && (back.pitch_rad + 0.02).abs() < 1e-5, "{back:?}");
        assert!(format_tilt("II", &tilt).contains(",A,1.146,D,PITCH,"));
        // Another order and an extra transducer.
        let body = "YXXDR,C,21.5,C,TEMP,A,-0.500,D,ROLL,A,2.000,D,PITCH";
        let line = format!("${body}*{:02X}\n", checksum(body));
        assert_eq!(parse_xdr(&line).expect("valid"), TiltLine { pitch_deg: 2.0, roll_deg: -0.5 });
    }

    #[test]
    fn bad_lines_are_refused() {
        assert!(matches!(
            parse_xdr("$IIXDR,A,1.250,D,PITCH,A,-0.500,D,ROLL*3C"),
            Err(ProtocolError::Checksum { received: 0x3C, computed: 0x3B, .. })
        ));
        let body = |b: &str| format!("${b}*{:02X}", checksum(b));
        for bad in [
            "$IIXDR,A,1.250,D,PITCH,A,-0.500,D,ROLL".to_string(),
            body("IIXDR,A,1.250,D,PITCH"),
            body("IIXDR,A,1.250,D,PITCH,A,-0.5,R,ROLL"),
            body("IIXDR,A,nan,D,PITCH,A,-0.5,D,ROLL"),
            body("IIXDR,A,1.0,D,PITCH,A,-0.5,D"),
            body("IIGGA,A,1.0,D,PITCH,A,-0.5,D,ROLL"),
            format!("{}{}", body("IIXDR,A,1.0,D,PITCH,A,-0.5,D,ROLL"), "x".repeat(80)),
        ] {
            assert!(matches!(parse_xdr(&bad), Err(ProtocolError::Malformed { .. })), "{bad}");
        }
    }

    #[test]
    fn lines_split_at_any_ending_and_overlong_ones_are_dropped() {
        use crate::protocol::{Line, LineSplitter};
        let mut s = LineSplitter::new(MAX_LINE, true);
        let mut lines = s.push(b"XDR,partial\r\n$A\r");
        lines.extend(s.push(b"\n$B\n$C\r"));
        lines.extend(s.push(&[b'x'; 100]));
        lines.extend(s.push(b"\r\n$D"));
        assert_eq!(
            lines,
            [
                Line::Text("$A".into()),
                Line::Text("$B".into()),
                Line::Text("$C".into()),
                Line::Dropped(format!("a line longer than {MAX_LINE} characters")),
            ]
        );
    }
}
