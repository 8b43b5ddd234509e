//! `cps-survey emulate MISSION`: the mission's whole team on
//! pseudo-terminals — the total station (GeoCOM), the tilt sensor (NMEA
//! XDR), the LMS-2xx, the scan head and every drive (our robot protocol) —
//! answering from one simulated world built as the `sim` backend builds it
//! (same scene, start, seed and noise streams). A mission with
//! `[backend] kind = "serial"` and the printed ports then runs over the
//! serial drivers.

use std::io::Write;
use std::path::{Path, PathBuf};
use std::str::FromStr;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use anyhow::{Context, Result, bail};
use scanner::emulate::geocom::GeoComEmulator;
use scanner::emulate::nmea::NmeaTiltEmulator;
use scanner::emulate::robot::{Body, RobotEmulator};
use scanner::emulate::sick::LmsEmulator;
use scanner::emulate::{Emulator, Faults};
use scanner::sim::SimWorld;
use serde::Serialize;

use crate::documents::ports::{InstrumentJson, PortsJson};

use super::Outcome;
use crate::journal::TruthRecord;
use crate::mission::Mission;
use crate::planning::Planned;

/// `emulate`'s arguments.
#[derive(Debug, Clone, clap::Args)]
pub struct EmulateArgs {
    /// The mission file (TOML).
    pub mission: PathBuf,
    /// Print one JSON object with the ports instead of the TOML table.
    #[arg(long)]
    pub json: bool,
    /// Append the simulated truth to this file (JSON lines: at the start
    /// and after every drive move).
    #[arg(long, value_name = "FILE")]
    pub truth: Option<PathBuf>,
    /// Inject a fault: ROLE:KIND=N, ROLE total-station, tilt, scanner, head,
    /// parent or a child's name, KIND drop-every, duplicate-every,
    /// corrupt-every, nak-every, delay-ms, stop-after or baud. Repeatable.
    #[arg(long, value_name = "FAULT")]
    pub fault: Vec<EmulatorFault>,
    /// Stop after this many seconds (at most a year) instead of running
    /// until stopped.
    #[arg(long, value_name = "S", value_parser = parse_seconds)]
    pub seconds: Option<Duration>,
}

/// The longest `--seconds`: a year.
const MAX_SECONDS: f64 = 365.0 * 24.0 * 3600.0;

fn parse_seconds(s: &str) -> Result<Duration, String> {
    let x: f64 = s.trim().parse().map_err(|_| format!("\"{s}\" is not a number of seconds"))?;
    if !(x.is_finite() && (0.0..=MAX_SECONDS).contains(&x)) {
        return Err(format!("{s} s is out of range; expected 0 to {MAX_SECONDS} s (a year)"));
    }
    Ok(Duration::from_secs_f64(x))
}

/// Runs `emulate`: prints the ports, then serves until stopped (Ctrl-C) or
/// for `--seconds`.
pub fn run(args: &EmulateArgs, out: &mut dyn Write) -> Result<Outcome> {
    let mission = Mission::load(&args.mission)?;
    let planned = Planned::new(&mission)?;
    let team = start(&mission, &planned, args.truth.as_deref(), &args.fault)?;
    if args.json {
        crate::documents::write_line(out, &ports_json(&mission, &team))?;
    } else {
        writeln!(
            out,
            "# cps-survey emulate {}: {} instruments on pseudo-terminals (seed {}); Ctrl-C stops.\n\
             # Put this table in the mission with [backend] kind = \"serial\":",
            args.mission.display(),
            team.served.len(),
            mission.backend.seed
        )?;
        write!(out, "{}", backend_toml(&mission, &team))?;
    }
    out.flush()?;
    let until = args.seconds.map(|s| Instant::now() + s);
    while until.is_none_or(|u| Instant::now() < u) {
        std::thread::sleep(Duration::from_millis(100));
    }
    Ok(Outcome::Success)
}

/// The emulators' line rates (the LMS powers on at 9600 and switches to
/// the mission's `scanner_baud` when the driver asks).
pub const TOTAL_STATION_BAUD: u32 = 9600;
/// The tilt sensor's rate.
pub const TILT_BAUD: u32 = 9600;
/// The tilt sensor's sentences per second.
pub const TILT_RATE_HZ: f64 = 20.0;
/// The drives' and the head's rate.
pub const ROBOT_BAUD: u32 = 115_200;

/// A fault for one emulated instrument (`--fault ROLE:KIND=N`).
#[derive(Debug, Clone, PartialEq)]
pub struct EmulatorFault {
    /// `total-station`, `tilt`, `scanner`, `head`, `parent` or a child's name.
    pub role: String,
    /// The fault.
    pub faults: Faults,
}

impl FromStr for EmulatorFault {
    type Err = String;

    /// `ROLE:KIND=N` with KIND one of drop-every, duplicate-every,
    /// corrupt-every, nak-every, delay-ms, stop-after, baud.
    fn from_str(s: &str) -> Result<Self, String> {
        let expected = "expected ROLE:KIND=N with KIND drop-every, duplicate-every, corrupt-every, nak-every, \
                        delay-ms, stop-after or baud";
        let (role, rule) = s.split_once(':').ok_or_else(|| format!("fault \"{s}\": {expected}"))?;
        let (kind, n) = rule.split_once('=').ok_or_else(|| format!("fault \"{s}\": {expected}"))?;
        let n: u64 = n.parse().map_err(|_| format!("fault \"{s}\": \"{n}\" is not a whole number; {expected}"))?;
        let k = usize::try_from(n).map_err(|_| format!("fault \"{s}\": {n} is too large"))?;
        let mut f = Faults::default();
        match kind {
            "drop-every" | "duplicate-every" | "corrupt-every" | "nak-every" if n < 1 => {
                return Err(format!("fault \"{s}\": {kind} needs N ≥ 1"));
            }
            "drop-every" => f.drop_every = Some(k),
            "duplicate-every" => f.duplicate_every = Some(k),
            "corrupt-every" => f.corrupt_every = Some(k),
            "nak-every" => f.nak_every = Some(k),
            "delay-ms" => f.delay = std::time::Duration::from_millis(n),
            "stop-after" => f.stop_after = Some(k),
            "baud" => f.baud = Some(u32::try_from(n).map_err(|_| format!("fault \"{s}\": {n} Bd is too large"))?),
            _ => return Err(format!("fault \"{s}\": unknown kind \"{kind}\"; {expected}")),
        }
        Ok(Self { role: role.to_string(), faults: f })
    }
}

/// One emulated instrument.
#[derive(Debug)]
pub struct Served {
    /// Its role (`total-station`, `tilt`, `scanner`, `head`, `parent`, a
    /// child's name).
    pub role: String,
    /// Its line rate at power-on.
    pub baud: u32,
    /// The running emulator.
    pub emulator: Emulator,
}

/// The team on pseudo-terminals.
#[derive(Debug)]
pub struct EmulatedTeam {
    /// Every instrument.
    pub served: Vec<Served>,
    /// The world they answer from.
    pub world: SimWorld,
}

impl EmulatedTeam {
    /// The port of `role`.
    pub fn path(&self, role: &str) -> Option<&str> {
        self.served.iter().find(|s| s.role == role).map(|s| s.emulator.path())
    }
}

/// One line of the truth log: the checkpoint's truth and who moved.
#[derive(Serialize)]
struct TruthLine<'a> {
    #[serde(flatten)]
    truth: TruthRecord,
    moved: &'a str,
}

fn truth_line(world: &SimWorld, robot: &str) -> String {
    let line = TruthLine { truth: crate::run::backend::truth_record(&world.truth()), moved: robot };
    serde_json::to_string(&line).unwrap_or_default()
}

/// Starts the mission's team on pseudo-terminals; with `truth`, appends the
/// simulated truth to that file (JSON lines) at the start and after every
/// drive move, flushed.
pub fn start(
    mission: &Mission,
    planned: &Planned,
    truth: Option<&Path>,
    faults: &[EmulatorFault],
) -> Result<EmulatedTeam> {
    let parts = crate::run::backend::sim::parts(mission, &planned.dance)?;
    let world = parts.world.clone();
    let log: Option<Arc<Mutex<std::fs::File>>> = match truth {
        Some(path) => {
            let mut f = std::fs::File::create(path).with_context(|| format!("creating {}", path.display()))?;
            writeln!(f, "{}", truth_line(&world, "start")).with_context(|| format!("writing {}", path.display()))?;
            Some(Arc::new(Mutex::new(f)))
        }
        None => None,
    };
    let hook = |robot: String| -> Option<scanner::emulate::robot::MoveHook> {
        let (log, world) = (log.clone()?, world.clone());
        Some(Box::new(move || {
            let mut f = log.lock().unwrap_or_else(std::sync::PoisonError::into_inner);
            // A full disk must not stop the instruments; the log is a witness.
            let _ = writeln!(f, "{}", truth_line(&world, &robot)).and_then(|()| f.flush());
        }))
    };
    let robot = |name: &str, body: Body| {
        let e = RobotEmulator::new(name, body, ROBOT_BAUD);
        match hook(name.to_string()) {
            Some(h) => e.on_move(h),
            None => e,
        }
    };
    let mut served = Vec::new();
    let mut serve = |role: &str, baud: u32, emulator: Result<Emulator, scanner::ScannerError>| -> Result<()> {
        let emulator = emulator.with_context(|| format!("starting the {role} emulator"))?;
        served.push(Served { role: role.to_string(), baud, emulator });
        Ok(())
    };
    let seed = mission.backend.seed;
    if let Some(inst) = &mission.total_station {
        let ts = GeoComEmulator::new(world.clone(), inst.clone(), seed, TOTAL_STATION_BAUD);
        serve("total-station", TOTAL_STATION_BAUD, Emulator::spawn(ts))?;
    }
    serve("tilt", TILT_BAUD, Emulator::spawn(NmeaTiltEmulator::new(parts.tilt, TILT_RATE_HZ, TILT_BAUD)))?;
    serve("scanner", scanner::emulate::sick::POWER_ON_BAUD, Emulator::spawn(LmsEmulator::new(parts.lms)))?;
    serve("head", ROBOT_BAUD, Emulator::spawn(RobotEmulator::new("head", Body::Head(parts.head), ROBOT_BAUD)))?;
    serve("parent", ROBOT_BAUD, Emulator::spawn(robot("parent", Body::Drive(Box::new(parts.parent)))))?;
    for (name, drive) in mission.children.iter().zip(parts.children) {
        serve(name, ROBOT_BAUD, Emulator::spawn(robot(name, Body::Drive(Box::new(drive)))))?;
    }
    for f in faults {
        let Some(s) = served.iter().find(|s| s.role == f.role) else {
            let roles: Vec<&str> = served.iter().map(|s| s.role.as_str()).collect();
            bail!("fault for \"{}\": no such instrument; this team has {}", f.role, roles.join(", "));
        };
        s.emulator.set_faults(f.faults.clone());
    }
    Ok(EmulatedTeam { served, world })
}

/// The `[backend.serial]` table for the team's ports (what `emulate`
/// prints).
pub fn backend_toml(mission: &Mission, team: &EmulatedTeam) -> String {
    let path = |role: &str| team.path(role).unwrap_or("").to_string();
    let mut t = String::from("[backend.serial]\n");
    if mission.total_station.is_some() {
        t += &format!("total_station = \"{}\"\ntotal_station_baud = {TOTAL_STATION_BAUD}\n", path("total-station"));
    }
    t += &format!("tilt = \"{}\"\ntilt_baud = {TILT_BAUD}\ntilt_rate_hz = {TILT_RATE_HZ}\n", path("tilt"));
    t += &format!("scanner = \"{}\"\nscanner_baud = 500000\n", path("scanner"));
    t += &format!("head = \"{}\"\n", path("head"));
    let drives: Vec<String> = std::iter::once("parent")
        .chain(mission.children.iter().map(String::as_str))
        .map(|r| format!("\"{}\"", path(r)))
        .collect();
    t += &format!(
        "drives = [{}]  # parent, {}\nrobot_baud = {ROBOT_BAUD}\n",
        drives.join(", "),
        mission.children.join(", ")
    );
    t
}

/// The ports as JSON: `{"mission", "seed", "instruments": [{"role", "path", "baud", "protocol"}], "backend_serial"}`.
fn ports_json(mission: &Mission, team: &EmulatedTeam) -> PortsJson {
    let protocol = |role: &str| match role {
        "total-station" => "Leica GeoCOM",
        "tilt" => "NMEA 0183 XDR",
        "scanner" => "SICK LMS-2xx",
        _ => "cps-survey robot ($PCPS)",
    };
    PortsJson {
        mission: mission.name.clone(),
        seed: mission.backend.seed,
        instruments: team
            .served
            .iter()
            .map(|s| InstrumentJson {
                role: s.role.clone(),
                path: s.emulator.path().to_string(),
                baud: s.baud,
                protocol: protocol(&s.role),
            })
            .collect(),
        backend_serial: backend_toml(mission, team),
    }
}
