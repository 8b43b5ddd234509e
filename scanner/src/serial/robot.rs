//! A robot's drive and the scan head over our robot protocol
//! ([`crate::protocol::robot`]). A request is sent again with the same
//! sequence number when its reply is late or damaged (the controller
//! answers a repeat from its last reply, so a move is never driven twice);
//! after the last attempt the error is typed ([`ScannerError::Timeout`],
//! [`ScannerError::Protocol`]); a refusal (`E`) is a [`ScannerError::Device`]
//! error with the controller's reason.

use std::time::{Duration, Instant};

use super::Port;
use crate::devices::{Drive, HeadKind, Odometry, PlanarPose, ScanHead};
use crate::error::{Result, ScannerError};
use crate::protocol::robot::{MAX_LINE, Message, Sentence};
use crate::protocol::{Line, LineSplitter, ProtocolError};

/// Request/reply over one port.
#[derive(Debug)]
pub struct RobotLink {
    port: Port,
    lines: LineSplitter,
    seq: u16,
    timeout: Duration,
    attempts: usize,
    /// Replies dropped as damaged or late.
    pub discarded: usize,
}

impl RobotLink {
    /// A link on `port` whose replies are due within `timeout`, with
    /// `attempts` tries per request.
    pub fn new(port: Port, timeout: Duration, attempts: usize) -> Self {
        Self { port, lines: LineSplitter::new(MAX_LINE, false), seq: 0, timeout, attempts, discarded: 0 }
    }

    /// The device's name for messages.
    pub fn device(&self) -> &str {
        self.port.device()
    }

    /// Sends `message`, returns the reply's message.
    pub fn call(&mut self, message: Message) -> Result<Message> {
        self.seq = self.seq.wrapping_add(1);
        let line = Sentence { seq: self.seq, message }.format();
        let started = Instant::now();
        let mut last: Option<ProtocolError> = None;
        let attempts = self.attempts.max(1);
        for _ in 0..attempts {
            self.port.write(line.as_bytes())?;
            let deadline = Instant::now() + self.timeout;
            loop {
                let bytes = self.port.read_before(deadline)?;
                if bytes.is_empty() {
                    break;
                }
                for l in self.lines.push(&bytes) {
                    let Line::Text(text) = l else {
                        self.discarded += 1;
                        continue;
                    };
                    match Sentence::parse(&text) {
                        Ok(reply) if reply.seq == self.seq => {
                            return match reply.message {
                                Message::Error { message } => {
                                    Err(ScannerError::Device { device: self.device().into(), message })
                                }
                                m => Ok(m),
                            };
                        }
                        Ok(_) => self.discarded += 1,
                        Err(e) => {
                            self.discarded += 1;
                            last = Some(e);
                        }
                    }
                }
            }
        }
        Err(match last {
            Some(source) => ScannerError::Protocol { device: self.device().into(), source },
            None => ScannerError::Timeout {
                device: self.device().into(),
                waiting_for: format!("the reply to {}", line.trim_end()),
                waited_s: started.elapsed().as_secs_f64(),
                attempts,
            },
        })
    }

    fn unexpected(&self, expected: &str, got: &Message) -> ScannerError {
        ScannerError::Protocol {
            device: self.device().into(),
            source: ProtocolError::Unexpected { expected: expected.into(), received: format!("{got:?}") },
        }
    }
}

/// A robot base.
#[derive(Debug)]
pub struct SerialDrive {
    link: RobotLink,
}

impl SerialDrive {
    /// A drive on `link`.
    pub fn new(link: RobotLink) -> Self {
        Self { link }
    }

    /// The robot now believes it stands at `pose` (from the CPS); with
    /// `keep_heading` it keeps its own heading.
    pub fn relocalise(&mut self, pose: &PlanarPose, keep_heading: bool) -> Result<()> {
        let m = Message::Relocalise { x_m: pose.x_m, y_m: pose.y_m, heading_rad: pose.heading_rad, keep_heading };
        match self.link.call(m)? {
            Message::Done => Ok(()),
            other => Err(self.link.unexpected("K (done)", &other)),
        }
    }
}

impl Drive for SerialDrive {
    fn name(&self) -> &str {
        self.link.device()
    }

    fn move_to(&mut self, target: &PlanarPose) -> Result<Odometry> {
        let m = Message::Move { x_m: target.x_m, y_m: target.y_m, heading_rad: target.heading_rad };
        match self.link.call(m)? {
            Message::Odometry { x_m, y_m, heading_rad, distance_m } => {
                Ok(Odometry { pose: PlanarPose { x_m, y_m, heading_rad }, distance_m })
            }
            other => Err(self.link.unexpected("O (odometry)", &other)),
        }
    }
}

/// The scan head's turntable or pitching mount.
#[derive(Debug)]
pub struct SerialHead {
    link: RobotLink,
    kind: HeadKind,
}

impl SerialHead {
    /// A head of `kind` on `link`.
    pub fn new(link: RobotLink, kind: HeadKind) -> Self {
        Self { link, kind }
    }
}

impl ScanHead for SerialHead {
    fn kind(&self) -> HeadKind {
        self.kind
    }

    fn move_to(&mut self, angle_rad: f64) -> Result<f64> {
        match self.link.call(Message::Head { angle_rad })? {
            Message::Angle { angle_rad } => Ok(angle_rad),
            other => Err(self.link.unexpected("A (angle)", &other)),
        }
    }
}
