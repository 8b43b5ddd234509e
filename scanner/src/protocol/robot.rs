//! Our line protocol for the robots' drives and the scan head: the
//! controllers of real robot bases and turntables differ from site to site,
//! so the survey speaks one small protocol and an adapter on each robot
//! translates it. NMEA 0183 framing, proprietary sentences `$PCPS…`:
//!
//! | Direction | Sentence | Meaning |
//! |---|---|---|
//! | host → drive | `$PCPSM,seq,x_m,y_m,heading_rad*hh` | drive to this pose (the robot's own frame of belief) |
//! | drive → host | `$PCPSO,seq,x_m,y_m,heading_rad,distance_m*hh` | arrived: dead-reckoned pose, distance driven |
//! | host → drive | `$PCPSL,seq,x_m,y_m,heading_rad,keep_heading*hh` | relocalise: the robot now believes this pose (`keep_heading` 1: keep its own heading) |
//! | host → head | `$PCPSH,seq,angle_rad*hh` | turn the head to this angle |
//! | head → host | `$PCPSA,seq,angle_rad*hh` | reached this angle |
//! | device → host | `$PCPSK,seq*hh` | done (relocalise) |
//! | device → host | `$PCPSE,seq,message*hh` | refused, with the reason |
//!
//! `seq` (0–65535) pairs a reply with its request. A request repeated with
//! the same `seq` (a retry after a lost reply) is answered again from the
//! device's last reply, not executed twice: a drive must not move twice.
//! Numbers are decimal, in metres and radians.

use super::nmea::checksum;
use super::{ProtocolError, text_excerpt};

/// Longest sentence, characters (longer than NMEA's 82: an error message
/// may be long).
pub const MAX_LINE: usize = 160;

/// A message of the robot protocol.
#[derive(Debug, Clone, PartialEq)]
pub enum Message {
    /// `M`: drive to the pose.
    Move {
        /// x, m.
        x_m: f64,
        /// y, m.
        y_m: f64,
        /// Heading, rad.
        heading_rad: f64,
    },
    /// `O`: arrived.
    Odometry {
        /// Dead-reckoned x, m.
        x_m: f64,
        /// Dead-reckoned y, m.
        y_m: f64,
        /// Dead-reckoned heading, rad.
        heading_rad: f64,
        /// Distance driven, m.
        distance_m: f64,
    },
    /// `L`: relocalise.
    Relocalise {
        /// x, m.
        x_m: f64,
        /// y, m.
        y_m: f64,
        /// Heading, rad.
        heading_rad: f64,
        /// Keep the robot's own heading.
        keep_heading: bool,
    },
    /// `H`: turn the head.
    Head {
        /// Angle, rad.
        angle_rad: f64,
    },
    /// `A`: the head's angle reached.
    Angle {
        /// Angle, rad.
        angle_rad: f64,
    },
    /// `K`: done.
    Done,
    /// `E`: refused.
    Error {
        /// Why.
        message: String,
    },
}

/// A sentence: its sequence number and message.
#[derive(Debug, Clone, PartialEq)]
pub struct Sentence {
    /// Pairs a reply with its request.
    pub seq: u16,
    /// The message.
    pub message: Message,
}

impl Sentence {
    /// The line, `$` to CR LF.
    pub fn format(&self) -> String {
        let f = |x: f64| format!("{x:.9}");
        let (kind, fields): (char, Vec<String>) = match &self.message {
            Message::Move { x_m, y_m, heading_rad } => ('M', vec![f(*x_m), f(*y_m), f(*heading_rad)]),
            Message::Odometry { x_m, y_m, heading_rad, distance_m } => {
                ('O', vec![f(*x_m), f(*y_m), f(*heading_rad), f(*distance_m)])
            }
            Message::Relocalise { x_m, y_m, heading_rad, keep_heading } => {
                ('L', vec![f(*x_m), f(*y_m), f(*heading_rad), u8::from(*keep_heading).to_string()])
            }
            Message::Head { angle_rad } => ('H', vec![f(*angle_rad)]),
            Message::Angle { angle_rad } => ('A', vec![f(*angle_rad)]),
            Message::Done => ('K', vec![]),
            // The framing characters cannot appear in a field.
            Message::Error { message } => ('E', vec![message.replace(['$', '*', ',', '\r', '\n'], " ")]),
        };
        let mut body = format!("PCPS{kind},{}", self.seq);
        for field in fields {
            body.push(',');
            body.push_str(&field);
        }
        format!("${body}*{:02X}\r\n", checksum(&body))
    }

    /// Parses one line (line ending optional); the checksum is required.
    pub fn parse(line: &str) -> Result<Self, ProtocolError> {
        let text = line.trim_end_matches(['\r', '\n']);
        let malformed = |reason: String| ProtocolError::Malformed {
            what: "robot sentence",
            reason,
            excerpt: text_excerpt(text, 40),
        };
        let body = text.strip_prefix("$PCPS").ok_or_else(|| malformed("expected it to start with $PCPS".into()))?;
        let (body, sum) = body.rsplit_once('*').ok_or_else(|| malformed("no *hh checksum".into()))?;
        let received = u8::from_str_radix(sum, 16)
            .ok()
            .filter(|_| sum.len() == 2)
            .ok_or_else(|| malformed(format!("checksum \"{sum}\"; expected two hex digits")))?;
        let computed = checksum(&format!("PCPS{body}"));
        if received != computed {
            return Err(ProtocolError::Checksum {
                what: "robot sentence checksum",
                received: received.into(),
                computed: computed.into(),
            });
        }
        let mut fields = body.split(',');
        let kind = fields.next().unwrap_or("");
        let seq: u16 = fields
            .next()
            .and_then(|s| s.parse().ok())
            .ok_or_else(|| malformed("expected a sequence number 0–65535 after the kind".into()))?;
        let rest: Vec<&str> = fields.collect();
        let numbers = |n: usize| -> Result<Vec<f64>, ProtocolError> {
            if rest.len() != n {
                return Err(malformed(format!("{} fields after the sequence number; expected {n}", rest.len())));
            }
            rest.iter()
                .map(|s| {
                    s.parse::<f64>()
                        .ok()
                        .filter(|v| v.is_finite())
                        .ok_or_else(|| malformed(format!("\"{s}\" is not a finite number")))
                })
                .collect()
        };
        let message = match kind {
            "M" => numbers(3).map(|v| Message::Move { x_m: v[0], y_m: v[1], heading_rad: v[2] })?,
            "O" => {
                numbers(4).map(|v| Message::Odometry { x_m: v[0], y_m: v[1], heading_rad: v[2], distance_m: v[3] })?
            }
            "L" => {
                let v = numbers(4)?;
                let keep_heading = match v[3] {
                    0.0 => false,
                    1.0 => true,
                    k => return Err(malformed(format!("keep_heading {k}; expected 0 or 1"))),
                };
                Message::Relocalise { x_m: v[0], y_m: v[1], heading_rad: v[2], keep_heading }
            }
            "H" => numbers(1).map(|v| Message::Head { angle_rad: v[0] })?,
            "A" => numbers(1).map(|v| Message::Angle { angle_rad: v[0] })?,
            "K" => numbers(0).map(|_| Message::Done)?,
            "E" => Message::Error { message: rest.join(",") },
            other => return Err(malformed(format!("kind \"{other}\"; expected M, O, L, H, A, K or E"))),
        };
        Ok(Sentence { seq, message })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sentences_round_trip_and_checksums_are_checked() {
        let all = [
            Message::Move { x_m: 6.0, y_m: -3.25, heading_rad: 0.1 },
            Message::Odometry { x_m: 6.0, y_m: -3.25, heading_rad: 0.1, distance_m: 4.0 },
            Message::Relocalise { x_m: 1.0, y_m: 2.0, heading_rad: -3.0, keep_heading: true },
            Message::Head { angle_rad: 2.5 },
            Message::Angle { angle_rad: 2.5 },
            Message::Done,
            Message::Error { message: "blocked".into() },
        ];
        for (k, message) in all.into_iter().enumerate() {
            let s = Sentence { seq: 65520 + k as u16, message };
            let line = s.format();
            assert!(line.ends_with("\r\n") && line.len() <= MAX_LINE, "{line}");
            assert_eq!(Sentence::parse(&line), Ok(s), "{line}");
        }
        // The checksum computed independently (Python: XOR of b"PCPSK,7" = 0x40).
        assert_eq!(Sentence { seq: 7, message: Message::Done }.format(), "$PCPSK,7*40\r\n");
        assert!(matches!(Sentence::parse("$PCPSK,7*41"), Err(ProtocolError::Checksum { .. })));
        for bad in ["$PCPSK,7", "$GPXDR,1*00", "$PCPSM,1,2,3*"] {
            assert!(matches!(Sentence::parse(bad), Err(ProtocolError::Malformed { .. })), "{bad}");
        }
        // Right checksums, wrong contents.
        for body in ["PCPSM,1,2", "PCPSK,x", "PCPSQ,1", "PCPSL,1,0,0,0,2", "PCPSH,1,NaN", "PCPSK,70000"] {
            let line = format!("${body}*{:02X}", checksum(body));
            assert!(matches!(Sentence::parse(&line), Err(ProtocolError::Malformed { .. })), "{line}");
        }
    }
}
