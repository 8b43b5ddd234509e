//! The `cps-survey` command line: argument parsing and dispatch.

use std::io::Write;
use std::path::PathBuf;

use clap::{Parser, Subcommand};

use crate::mission::Mission;
use crate::recording::Viewer;
use crate::runner::RunOptions;

/// Survey large buildings with a team of robots that position each other.
#[derive(Debug, Parser)]
#[command(name = "cps-survey", version, about)]
pub struct Cli {
    /// What to do.
    #[command(subcommand)]
    pub command: Command,
}

/// The subcommands.
#[derive(Debug, Subcommand)]
pub enum Command {
    /// Predict the pose covariance after every dance cycle of a mission's plan.
    Predict {
        /// The mission file (TOML).
        mission: PathBuf,
        /// Print one JSON object instead of the table.
        #[arg(long)]
        json: bool,
        /// Also draw σ_xy and σ_θ versus distance and a top view with the
        /// 95 % ellipses (SVG).
        #[arg(long, value_name = "FILE.svg")]
        plot: Option<PathBuf>,
        /// Also write the plan to a Rerun recording (route, stations, moves,
        /// sight lines, predicted ellipsoids per step).
        #[arg(long, value_name = "FILE.rrd")]
        rrd: Option<PathBuf>,
    },
    /// Check a mission's plan step by step (ranges, line of sight, tracking,
    /// clearance, slope, scan range), analyse its accuracy, and with
    /// --optimize search formation, stride and strategy (exit 1 when the
    /// plan breaks a constraint or misses the acceptance tolerance).
    Plan {
        /// The mission file (TOML).
        mission: PathBuf,
        /// Search [plan.search] for the best plan that keeps every constraint.
        #[arg(long)]
        optimize: bool,
        /// Write the chosen plan as a complete mission file.
        #[arg(long, value_name = "FILE", requires = "optimize")]
        out: Option<PathBuf>,
        /// Print one JSON object instead of the text report.
        #[arg(long)]
        json: bool,
        /// Also draw σ_xy and σ_θ versus distance (as written and optimized)
        /// and a top view with the 95 % ellipses and violations (SVG).
        #[arg(long, value_name = "FILE.svg")]
        plot: Option<PathBuf>,
        /// Also write the plan (and the optimized one) to a Rerun recording:
        /// route, stations, moves and sight lines green or red, predicted
        /// ellipsoids per step, violations.
        #[arg(long, value_name = "FILE.rrd")]
        rrd: Option<PathBuf>,
    },
    /// Check a mission file and report every problem with file:line:column.
    Validate {
        /// The mission file (TOML).
        mission: PathBuf,
    },
    /// Run a mission on the simulator: dance, scans, fusion, outputs.
    Run {
        /// The mission file (TOML).
        mission: PathBuf,
        /// The run directory (default `runs/<mission name>/`).
        #[arg(long)]
        out: Option<PathBuf>,
        /// No progress bars.
        #[arg(long)]
        quiet: bool,
        /// Continue the interrupted run in the --out directory from its journal.
        #[arg(long)]
        resume: bool,
        /// Also stream the recording to a newly started Rerun viewer.
        #[arg(long, conflicts_with = "connect")]
        spawn: bool,
        /// Also stream the recording to a running Rerun viewer.
        #[arg(long, value_name = "URL", num_args = 0..=1,
              default_missing_value = "rerun+http://127.0.0.1:9876/proxy")]
        connect: Option<String>,
        /// Log every ICP iteration of the fusion (modes icp and cps-icp) to
        /// the recording, on its own timeline `icp_iteration`.
        #[arg(long)]
        log_icp_iterations: bool,
        /// Inject a fault into a simulated device: DEVICE:after=N (stops
        /// answering after N commands) or DEVICE:every=K (every K-th command
        /// fails); DEVICE is drive, total-station, tilt or scanner. Repeatable.
        #[arg(long, value_name = "FAULT")]
        sim_fault: Vec<crate::backend::Fault>,
        /// Abort the process after writing N journal events (crash test).
        #[arg(long, value_name = "N", hide = true)]
        abort_after_events: Option<usize>,
    },
    /// Simulate a mission's positioning N times and compare the spread with
    /// the prediction (exit 1 when the final NEES is outside its interval).
    Montecarlo {
        /// The mission file (TOML).
        mission: PathBuf,
        /// Number of seeded trials (≥ 2).
        #[arg(long, default_value_t = 1000)]
        trials: usize,
        /// Print one JSON object instead of the table.
        #[arg(long)]
        json: bool,
    },
    /// Re-fuse a finished (or interrupted) run's scans from its journal into
    /// RUN_DIR/fusion/<mode>/, without re-running it.
    Fuse {
        /// The run directory (holds mission.toml, journal.jsonl and scans/).
        run_dir: PathBuf,
        /// direct, icp or cps-icp (default: the mission's [fusion] mode).
        #[arg(long, value_parser = parse_mode)]
        mode: Option<crate::mission::FusionMode>,
        /// Print one JSON object instead of the table.
        #[arg(long)]
        json: bool,
    },
    /// Align one scan file to another with ICP.
    Register(crate::register::RegisterArgs),
    /// Serve a mission's instruments on pseudo-terminals (total station,
    /// tilt sensor, LMS-2xx, scan head, drives), answering from the
    /// simulated world; prints the [backend.serial] table with the ports and
    /// runs until stopped (Ctrl-C).
    Emulate {
        /// The mission file (TOML).
        mission: PathBuf,
        /// Print one JSON object with the ports instead of the TOML table.
        #[arg(long)]
        json: bool,
        /// Append the simulated truth to this file (JSON lines: at the
        /// start and after every drive move).
        #[arg(long, value_name = "FILE")]
        truth: Option<PathBuf>,
        /// Inject a fault: ROLE:KIND=N, ROLE total-station, tilt, scanner,
        /// head, parent or a child's name, KIND drop-every, duplicate-every,
        /// corrupt-every, nak-every, delay-ms, stop-after or baud. Repeatable.
        #[arg(long, value_name = "FAULT")]
        fault: Vec<crate::emulate::EmulatorFault>,
        /// Stop after this many seconds instead of running until stopped.
        #[arg(long, value_name = "S")]
        seconds: Option<f64>,
    },
}

fn parse_mode(s: &str) -> Result<crate::mission::FusionMode, String> {
    crate::mission::FusionMode::from_name(s).ok_or_else(|| {
        format!("unknown fusion mode \"{s}\"; expected one of {}", crate::mission::FUSION_MODES.join(", "))
    })
}

/// How a command that ran ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Outcome {
    /// Everything passed (exit 0).
    Success,
    /// Ran, but failed the mission's acceptance tolerances (exit 1).
    AcceptanceFailed,
}

/// The process exit code of a command's result: 0 success, 1 acceptance
/// failed, 2 error.
pub fn exit_code(result: &anyhow::Result<Outcome>) -> u8 {
    match result {
        Ok(Outcome::Success) => 0,
        Ok(Outcome::AcceptanceFailed) => 1,
        Err(_) => 2,
    }
}

fn plotted(out: &mut dyn Write, file: &std::path::Path, s: &crate::plot::PlotSummary) -> std::io::Result<()> {
    writeln!(
        out,
        "plotted {}: {} parent 95 % ellipses drawn ×{}, {} scene outline segments",
        file.display(),
        s.ellipses,
        s.ellipse_scale,
        s.scene_segments
    )
}

fn recorded(out: &mut dyn Write, file: &std::path::Path) -> std::io::Result<()> {
    writeln!(out, "recorded the plan in {} (view it with `rerun {}`)", file.display(), file.display())
}

/// Runs a parsed command, writing its report to `out`. Errors mean exit 2.
pub fn run(cli: Cli, out: &mut dyn Write) -> anyhow::Result<Outcome> {
    match cli.command {
        Command::Predict { mission, json, plot, rrd } => {
            let mission = Mission::load(&mission)?;
            let prediction = crate::predict::prediction(&mission)?;
            if json {
                crate::predict::write_json(out, &mission, &prediction)?;
            } else {
                crate::predict::write_table(out, &mission, &prediction)?;
            }
            if let Some(file) = plot {
                let summary = crate::predict::plot(&mission, &prediction, &file)?;
                if !json {
                    plotted(out, &file, &summary)?;
                }
            }
            if let Some(file) = rrd {
                let dance = crate::predict::dance(&mission)?;
                crate::plan::write_rrd(&mission, &file, &[("plan", &dance, &prediction, &[])])?;
                if !json {
                    recorded(out, &file)?;
                }
            }
            out.flush()?;
            Ok(if crate::predict::accepted(&mission, &prediction) {
                Outcome::Success
            } else {
                Outcome::AcceptanceFailed
            })
        }
        Command::Plan { mission, optimize, out: file, json, plot, rrd } => {
            let m = Mission::load(&mission)?;
            let report = crate::plan::plan(&m, optimize)?;
            if json {
                crate::plan::write_json(out, &m, &report)?;
            } else {
                crate::plan::write_table(out, &m, &report)?;
            }
            if let Some(plot) = plot {
                let summary = crate::plan::plot(&m, &report, &plot)?;
                if !json {
                    plotted(out, &plot, &summary)?;
                }
            }
            if let Some(rrd) = rrd {
                crate::plan::record(&m, &report, &rrd)?;
                if !json {
                    recorded(out, &rrd)?;
                }
            }
            if let (Some(file), Some(o)) = (file, &report.optimized) {
                crate::plan::write_mission(&m, o, &file)?;
                if !json {
                    writeln!(out, "wrote {}", file.display())?;
                }
            }
            out.flush()?;
            Ok(if crate::plan::accepted(&m, &report) { Outcome::Success } else { Outcome::AcceptanceFailed })
        }
        Command::Run {
            mission,
            out: dir,
            quiet,
            resume,
            spawn,
            connect,
            log_icp_iterations,
            sim_fault,
            abort_after_events,
        } => {
            let m = Mission::load(&mission)?;
            let dir = dir.unwrap_or_else(|| PathBuf::from("runs").join(&m.name));
            let viewer = match (spawn, connect) {
                (true, _) => Viewer::Spawn,
                (false, Some(url)) => Viewer::Connect(url),
                (false, None) => Viewer::None,
            };
            let options =
                RunOptions { quiet, resume, faults: sim_fault, abort_after_events, viewer, log_icp_iterations };
            let summary = crate::runner::run(&m, &dir, &options)?;
            crate::runner::write_summary(out, &m, &summary)?;
            out.flush()?;
            Ok(if summary.accepted { Outcome::Success } else { Outcome::AcceptanceFailed })
        }
        Command::Montecarlo { mission, trials, json } => {
            let m = Mission::load(&mission)?;
            let mc = crate::montecarlo::run(&m, trials)?;
            if json {
                crate::montecarlo::write_json(out, &m, &mc)?;
            } else {
                crate::montecarlo::write_table(out, &m, &mc)?;
            }
            out.flush()?;
            Ok(if mc.consistent() { Outcome::Success } else { Outcome::AcceptanceFailed })
        }
        Command::Fuse { run_dir, mode, json } => {
            crate::fuse::fuse_run(&run_dir, mode, json, out)?;
            out.flush()?;
            Ok(Outcome::Success)
        }
        Command::Register(args) => {
            crate::register::register(&args, out)?;
            out.flush()?;
            Ok(Outcome::Success)
        }
        Command::Emulate { mission, json, truth, fault, seconds } => {
            let m = Mission::load(&mission)?;
            let team = crate::emulate::start(&m, truth.as_deref(), &fault)?;
            if json {
                writeln!(out, "{}", crate::emulate::ports_json(&m, &team))?;
            } else {
                writeln!(
                    out,
                    "# cps-survey emulate {}: {} instruments on pseudo-terminals (seed {}); Ctrl-C stops.\n\
                     # Put this table in the mission with [backend] kind = \"serial\":",
                    mission.display(),
                    team.served.len(),
                    m.backend.seed
                )?;
                write!(out, "{}", crate::emulate::backend_toml(&m, &team))?;
            }
            out.flush()?;
            let until = seconds.map(|s| std::time::Instant::now() + std::time::Duration::from_secs_f64(s.max(0.0)));
            while until.is_none_or(|u| std::time::Instant::now() < u) {
                std::thread::sleep(std::time::Duration::from_millis(100));
            }
            Ok(Outcome::Success)
        }
        Command::Validate { mission } => {
            let m = Mission::load(&mission)?;
            crate::plan::refuse_violations(&m, &crate::predict::dance(&m)?)?;
            writeln!(out, "{}: ok (mission \"{}\", {} children)", mission.display(), m.name, m.children.len())?;
            Ok(Outcome::Success)
        }
    }
}
