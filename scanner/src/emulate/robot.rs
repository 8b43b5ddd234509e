//! A robot's drive or the scan head speaking our robot protocol
//! ([`crate::protocol::robot`]), moving the simulated world: a drive moves
//! with [`SimDrive`]'s odometry error, the head with [`SimHead`]. A request
//! repeated with the last sequence number is answered from the last reply
//! (a retried move does not move twice). Corruption faults spoil a reply's
//! checksum; NAK faults lose the request (a busy controller).

use super::{Device, FaultState};
use crate::devices::{Drive, PlanarPose, ScanHead};
use crate::protocol::robot::{MAX_LINE, Message, Sentence};
use crate::protocol::{Line, LineSplitter};
use crate::sim::{SimDrive, SimHead};

/// What the emulated controller moves.
#[derive(Debug)]
pub enum Body {
    /// A robot base.
    Drive(Box<SimDrive>),
    /// The scan head.
    Head(SimHead),
}

/// Called after each executed move (e.g. to log the simulated truth).
pub type MoveHook = Box<dyn FnMut() + Send>;

/// The emulated controller.
pub struct RobotEmulator {
    body: Body,
    name: String,
    baud: u32,
    lines: LineSplitter,
    last: Option<(String, String)>,
    on_move: Option<MoveHook>,
}

impl std::fmt::Debug for RobotEmulator {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("RobotEmulator").field("name", &self.name).field("body", &self.body).finish_non_exhaustive()
    }
}

impl RobotEmulator {
    /// A controller named `name` for `body` at `baud`.
    pub fn new(name: impl Into<String>, body: Body, baud: u32) -> Self {
        Self { body, name: name.into(), baud, lines: LineSplitter::new(MAX_LINE, false), last: None, on_move: None }
    }

    /// Calls `hook` after every executed move.
    pub fn on_move(mut self, hook: MoveHook) -> Self {
        self.on_move = Some(hook);
        self
    }

    fn execute(&mut self, message: Message) -> Message {
        let refused = |e: crate::ScannerError| Message::Error { message: e.to_string() };
        let reply = match (&mut self.body, message) {
            (Body::Drive(d), Message::Move { x_m, y_m, heading_rad }) => {
                match d.move_to(&PlanarPose { x_m, y_m, heading_rad }) {
                    Ok(o) => Message::Odometry {
                        x_m: o.pose.x_m,
                        y_m: o.pose.y_m,
                        heading_rad: o.pose.heading_rad,
                        distance_m: o.distance_m,
                    },
                    Err(e) => refused(e),
                }
            }
            (Body::Drive(d), Message::Relocalise { x_m, y_m, heading_rad, keep_heading }) => {
                d.relocalise(PlanarPose { x_m, y_m, heading_rad }, keep_heading);
                return Message::Done;
            }
            (Body::Head(h), Message::Head { angle_rad }) => match h.move_to(angle_rad) {
                Ok(a) => Message::Angle { angle_rad: a },
                Err(e) => refused(e),
            },
            (_, other) => {
                return Message::Error { message: format!("{} does not take {other:?}", self.name) };
            }
        };
        if let Some(hook) = &mut self.on_move {
            hook();
        }
        reply
    }
}

impl Device for RobotEmulator {
    fn name(&self) -> &str {
        &self.name
    }

    fn baud(&self) -> u32 {
        self.baud
    }

    fn input(&mut self, bytes: &[u8], faults: &mut FaultState) -> Vec<Vec<u8>> {
        let mut out = Vec::new();
        for line in self.lines.push(bytes) {
            let Line::Text(text) = line else { continue };
            // A damaged request is ignored: the host times out and retries.
            let Ok(request) = Sentence::parse(&text) else { continue };
            if faults.nak_now() {
                continue;
            }
            let mut reply = match &self.last {
                Some((asked, answered)) if *asked == text => answered.clone(),
                _ => {
                    let message = self.execute(request.message);
                    let answered = Sentence { seq: request.seq, message }.format();
                    self.last = Some((text, answered.clone()));
                    answered
                }
            };
            if faults.corrupt_now() {
                super::spoil_nmea_checksum(&mut reply);
            }
            out.push(reply.into_bytes());
        }
        out
    }
}
