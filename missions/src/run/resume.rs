//! A run directory: made ready for a new run or for `--resume` (the
//! journal opened, the mission checked to be the one the run started with),
//! and read back by `fuse` and `adjust` — the mission as run, its plan and
//! the journal's scans with their poses.

use std::path::Path;

use anyhow::{Context, Result, bail};
use cps::ParentPose;
use nalgebra::Matrix4;
use scanner::Tilt;

use super::directory;
use super::fuse::{Correlation, ScanView};
use super::journal::{self, EndRecord, Event, Journal, Start};
use crate::documents::records::matrix4;
use crate::mission::Mission;
use crate::planning::Planned;

/// How the journaled run ended, if it did: the `end` event's record.
fn finished(read: &journal::Read) -> Option<EndRecord> {
    read.events.iter().rev().find(|n| !n.event.informational()).and_then(|n| match &n.event {
        Event::End(e) => Some(e.data),
        _ => None,
    })
}

/// The journal of the run in `dir`, opened to write: a new one (with the
/// mission and its scene file copied beside it), or with `resume` the
/// interrupted run's, whose mission must be `mission`. The journal aborts
/// the process after `abort_after` events (a crash test).
pub fn open(
    mission: &Mission,
    planned: &Planned,
    dir: &Path,
    resume: bool,
    abort_after: Option<usize>,
) -> Result<Journal> {
    let journal_path = dir.join("journal.jsonl");
    let mission_copy = dir.join("mission.toml");
    if !resume && journal_path.exists() && finished(&journal::read_without_cross_covariances(&journal_path)?).is_some()
    {
        bail!(
            "{} holds a finished run (its outputs are there; a run is never overwritten): \
             choose another --out directory",
            dir.display()
        );
    }
    if resume {
        if !journal_path.exists() {
            bail!("{} does not exist: there is no run to resume there", journal_path.display());
        }
        directory::refuse_links(dir)?;
        let lock = directory::lock(dir, &format!("run {} --resume", mission.source.file.display()))?;
        let read = journal::read(&journal_path)?;
        let start = read.start(&journal_path)?.clone();
        let as_run =
            std::fs::read_to_string(&mission_copy).with_context(|| format!("reading {}", mission_copy.display()))?;
        let scene_changed = match &mission.backend.scene_file {
            Some((_, text)) => std::fs::read_to_string(dir.join("scene.toml")).ok().as_ref() != Some(text),
            None => false,
        };
        if as_run == mission.source.text && !scene_changed && start.seed != mission.backend.seed {
            // (Issue 34, U10: this blamed the mission file.)
            bail!(
                "the run in {} started with seed {} (its journal's start); this resume has seed {}: resume with \
                 --seed {} (or the mission's own seed, without --seed)",
                dir.display(),
                start.seed,
                mission.backend.seed,
                start.seed
            );
        }
        if as_run != mission.source.text || scene_changed {
            bail!(
                "{} is not the mission this run started with ({}{}); resume with that file",
                mission.source.file.display(),
                mission_copy.display(),
                if scene_changed { ", and its scene file changed since: see scene.toml there" } else { "" }
            );
        }
        if let Some(end) = finished(&read) {
            bail!(
                "the run in {} is finished (acceptance {}): nothing to resume; its outputs are there",
                dir.display(),
                if end.accepted { "passed" } else { "FAILED" }
            );
        }
        let mut journal = Journal::resume(&journal_path, read)?;
        journal.hold(lock);
        journal.abort_after(abort_after);
        journal.append(Event::Resume)?;
        return Ok(journal);
    }
    std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    directory::refuse_links(dir)?;
    if !journal_path.exists() {
        refuse_others_outputs(dir)?;
    }
    let lock = directory::lock(dir, &format!("run {}", mission.source.file.display()))?;
    let mut journal = Journal::create(&journal_path)?;
    journal.hold(lock);
    journal.abort_after(abort_after);
    scanner::io::replace_file(&mission_copy, mission.source.text.as_bytes())
        .with_context(|| format!("writing {}", mission_copy.display()))?;
    if let Some((_, text)) = &mission.backend.scene_file {
        scanner::io::replace_file(&dir.join("scene.toml"), text.as_bytes())
            .with_context(|| format!("writing {}/scene.toml", dir.display()))?;
    }
    journal.append(Event::Start(Start {
        mission: mission.name.clone(),
        seed: mission.backend.seed,
        scene: mission.backend.scene.clone(),
        stations: planned.stations(),
        children: mission.children.clone(),
    }))?;
    Ok(journal)
}

/// A run directory read back.
#[derive(Debug)]
pub struct RunDir {
    /// The mission as run (`mission.toml`, with `scene.toml` for its scene file).
    pub mission: Mission,
    /// Its plan.
    pub planned: Planned,
    /// The journal.
    pub journal: journal::Read,
    /// The scans taken, with their poses (a run interrupted before its end
    /// gives the scans taken so far); empty from [`load_journal`].
    pub views: Vec<ScanView>,
}

/// Reads the run in `dir` without its scans: its mission (`mission.toml`,
/// with `scene.toml` for its scene file), its plan and its journal (without
/// the fixes' cross-covariances, which only [`load`] needs).
pub fn load_journal(dir: &Path) -> Result<RunDir> {
    let (mission, planned) = mission_of(dir)?;
    let journal = journal::read_without_cross_covariances(&dir.join("journal.jsonl"))?;
    Ok(RunDir { mission, planned, journal, views: Vec::new() })
}

/// The run's mission and its plan.
fn mission_of(dir: &Path) -> Result<(Mission, Planned)> {
    let mission_path = dir.join("mission.toml");
    if !mission_path.exists() {
        bail!("{} is not a run directory: {} is missing", dir.display(), mission_path.display());
    }
    let scene_copy = dir.join("scene.toml");
    let mission = if scene_copy.exists() {
        Mission::load_with_scene(&mission_path, &scene_copy)?
    } else {
        Mission::load(&mission_path)?
    };
    let planned = Planned::new(&mission)?;
    Ok((mission, planned))
}

/// Reads the run in `dir`: its mission, its plan, its journal and the
/// scans the journal names with their poses — each `scan` event's file
/// (body frame, 3DTK layout), the `tilt` event before it, the `fix` event
/// of that station (the CPS pose, its covariance and its link in the chain
/// of scan stations — a version 1 or 2 journal's cross-covariances with the
/// earlier scan stations), and the team's state (the truth and the
/// drive's believed pose).
pub fn load(dir: &Path) -> Result<RunDir> {
    let (mission, planned) = mission_of(dir)?;
    let journal_path = dir.join("journal.jsonl");
    let journal = journal::read(&journal_path)?;
    let dance = &planned.dance;
    let mut pose = (dance.station_pose(0), mission.plan.start_covariance);
    let mut cross: Vec<Matrix4<f64>> = Vec::new();
    let mut chain: Option<journal::ChainRecord> = None;
    let by_chain = journal.version() >= 3;
    let mut tilt = None;
    let mut views = Vec::new();
    for n in &journal.events {
        let at = |what: &str| format!("{}:{}: {what}", journal_path.display(), n.line);
        match &n.event {
            Event::Fix(f) => {
                let d = &f.data;
                pose = ((&d.pose).into(), matrix4(&d.covariance));
                cross = d.scan_cross_covariances.iter().flatten().map(matrix4).collect();
                chain = d.chain.clone();
            }
            Event::Tilt(t) => tilt = Some(Tilt { roll_rad: t.data.roll_rad, pitch_rad: t.data.pitch_rad }),
            Event::Scan(s) => {
                let station = s.key.station;
                let file = s.data.file.clone();
                let tilt = tilt.take().with_context(|| at("a scan without a tilt reading before it"))?;
                journal::check_scan_file(dir, &s.data).with_context(|| at(&format!("checking {file}")))?;
                let cloud = scanner::io::read(&dir.join(&file)).with_context(|| at(&format!("reading {file}")))?;
                if cloud.len() != s.data.points {
                    bail!(at(&format!(
                        "{file} holds {} points; the journal recorded {}: the file changed since the run wrote it",
                        cloud.len(),
                        s.data.points
                    )));
                }
                let truth = s.sim.as_ref().and_then(|c| c.truth.as_ref()).map(|t| {
                    let p = ParentPose::new(t.parent[0], t.parent[1], t.parent[2], t.parent[3]);
                    (p, Tilt { roll_rad: t.tilt[0], pitch_rad: t.tilt[1] })
                });
                let nominal = dance.station_pose(station.min(dance.stations.len() - 1));
                let believed = s.sim.as_ref().and_then(|c| c.parent_believed());
                let correlation = if by_chain {
                    // A station without a chain link (a robot alone, or a
                    // start without a resection) is independent of the
                    // earlier ones.
                    Correlation::Chain(match chain.take() {
                        Some(record) => record.link(&at("the fix before this scan"))?,
                        None => cps::chain::ChainLink {
                            parent_columns: nalgebra::DMatrix::from_fn(4, 4, |r, c| pose.1[(r, c)]),
                            from_previous: None,
                        },
                    })
                } else {
                    Correlation::Earlier(std::mem::take(&mut cross))
                };
                let estimate = (pose.0, pose.1, correlation);
                let truth = truth.as_ref().map(|(p, t)| (p, t));
                views.push(ScanView::new(station, &s.data, cloud.points, estimate, tilt, (believed, &nominal), truth));
            }
            _ => {}
        }
    }
    Ok(RunDir { mission, planned, journal, views })
}

/// Refuses a new run into a directory that holds a run's outputs but no
/// journal (issue 34, W5: `report.json`, `stations.csv`, `adjustment.txt`,
/// `cloud.ply` there were overwritten): they are another run's, or
/// another command's, and not this one's to replace.
fn refuse_others_outputs(dir: &Path) -> Result<()> {
    let mut names: Vec<String> = ["report.json", "stations.csv", "adjustment.txt", "mission.toml", "scene.toml"]
        .into_iter()
        .chain(["mission.rrd", "scans", "fusion", crate::inspection::DEVIATION_FILE])
        .map(String::from)
        .collect();
    names.extend(crate::mission::OUTPUT_FORMATS.iter().map(|f| crate::output::cloud_file(f)));
    let found: Vec<&String> = names.iter().filter(|n| std::fs::symlink_metadata(dir.join(n)).is_ok()).collect();
    if !found.is_empty() {
        bail!(
            "{} holds {} but no journal.jsonl: outputs that are not this run's to overwrite; choose another --out \
             directory (or an empty one)",
            dir.display(),
            found.iter().map(|n| n.as_str()).collect::<Vec<_>>().join(", ")
        );
    }
    Ok(())
}
