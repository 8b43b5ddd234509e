//! A run directory read back by `fuse`, `adjust` and `export`: the mission
//! as run, its plan and the journal's scans with their poses.

use std::path::Path;

use anyhow::{Context, Result, bail};
use cps::ParentPose;
use nalgebra::Matrix4;
use scanner::Tilt;

use super::fuse::{Correlation, ScanView};
use crate::documents::records::matrix4;
use crate::journal::{self, Event};
use crate::mission::Mission;
use crate::planning::Planned;

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
