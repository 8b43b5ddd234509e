//! The one output stage of `run` and `fuse`: the merged cloud in each of
//! the mission's `[output] formats`, written a scan at a time as the scans
//! come ([`CloudFiles`]), and with `[pipe]` the pipe inspection
//! of that cloud (its deviation map, the recording's `world/pipe/…`, the
//! report). A fit that fails is reported ([`PipeReport::Failed`]) after
//! everything else has been written, not raised — the acceptance fails —
//! while a file that cannot be written is an error.

use std::path::Path;
use std::time::Instant;

use anyhow::Result;
use nalgebra::Point3;
use scanner::io::{CloudHeader, PointCloud};

use crate::documents::pipe::PipeReport;
use crate::documents::run::Timings;
use crate::inspection::DEVIATION_FILE;
use crate::mission::Mission;
use crate::view::recording::Recorder;

/// What the output stage wrote.
#[derive(Debug, Clone, PartialEq)]
pub struct Written {
    /// Points in the merged cloud.
    pub points: usize,
    /// The files, relative to the directory they were written to.
    pub files: Vec<String>,
    /// The pipe inspection, with `[pipe]`.
    pub pipe: Option<PipeReport>,
}

impl Written {
    /// Whether the outputs did their job: a pipe mission without its
    /// deviation map has not.
    pub fn complete(&self) -> bool {
        !matches!(self.pipe, Some(PipeReport::Failed { .. }))
    }
}

/// Checks, before any work, that the output stage can write into `dir`
/// (which need not exist yet): refuses a `dir` that is not a directory,
/// and a target of [`CloudFiles`] — a cloud file, the deviation map, and
/// `extra` (the caller's own files) — that exists as something other than
/// a file, naming it. A survey that cannot be written is refused before it
/// is measured, not after.
pub fn check_targets(mission: &Mission, dir: &Path, extra: &[&str]) -> Result<()> {
    use anyhow::bail;
    if dir.exists() && !dir.is_dir() {
        bail!("{}: exists and is not a directory; expected the output directory", dir.display());
    }
    let clouds = mission.output.formats.iter().map(|f| crate::output::cloud_file(f));
    let pipe = mission.pipe.as_ref().map(|_| DEVIATION_FILE.to_string());
    // (A symbolic link is the run directory's guard's to name.)
    if let Some((name, _)) = crate::output::taken(dir, clouds.chain(pipe).chain(extra.iter().map(|e| e.to_string()))) {
        let path = dir.join(&name);
        bail!("{}: exists and is not a file; the outputs write {name} there (remove or rename it)", path.display());
    }
    Ok(())
}

/// The merged cloud's files, one per `[output] formats`, written a scan
/// at a time ([`crate::output::CloudFiles`]: a run holds one scan's
/// points, not the cloud's; with `[pipe]`, the inspection needs the whole
/// cloud: its world points are kept). Dropped unfinished, the files go.
#[derive(Debug)]
pub struct CloudFiles {
    files: crate::output::CloudFiles,
    /// With `[pipe]`: every point, world coordinates (f32).
    pipe: Option<Vec<Point3<f32>>>,
}

impl CloudFiles {
    /// Opens the files in `dir` for the mission's cloud (relative to its
    /// cloud origin, in its CRS, each point with its scan) of `points`
    /// points — or an unknown count, stated when finished.
    pub fn create(mission: &Mission, dir: &Path, points: Option<usize>) -> Result<Self> {
        let header = CloudHeader {
            origin: mission.cloud_origin(),
            crs: Some(mission.crs.clone()),
            points,
            intensity: false,
            source: true,
            timed: false,
            color: false,
            time: None,
        };
        let files = crate::output::CloudFiles::create(dir, &mission.output.formats, &header)?;
        Ok(Self { files, pipe: mission.pipe.as_ref().map(|_| Vec::new()) })
    }

    /// Appends one scan's points (see [`crate::output::part`]) to every file.
    pub fn push(&mut self, part: &PointCloud, timings: &mut Timings) -> Result<()> {
        let started = Instant::now();
        self.files.push(part)?;
        if let Some(world) = &mut self.pipe {
            // The inspection works in world coordinates (f32).
            if part.georeferenced() {
                world.extend((0..part.len()).map(|i| Point3::from(part.coordinates(i)).cast::<f32>()));
            } else {
                world.extend_from_slice(&part.points);
            }
        }
        timings.cloud_files_s += started.elapsed().as_secs_f64();
        Ok(())
    }

    /// Finishes the files in `dir` and, with `[pipe]`, inspects the cloud
    /// (logging the result to `rec`); the time each takes goes to
    /// `timings`.
    pub fn finish(self, mission: &Mission, dir: &Path, rec: &mut Recorder, timings: &mut Timings) -> Result<Written> {
        let started = Instant::now();
        let points = self.files.points();
        let mut files = self.files.finish()?;
        timings.cloud_files_s += started.elapsed().as_secs_f64();
        let pipe = pipe(mission, dir, self.pipe.as_deref().unwrap_or(&[]), &mut files, rec, timings)?;
        Ok(Written { points, files, pipe })
    }
}

/// With `[pipe]`, the inspection of the merged cloud's `world` points:
/// the deviation map (its name added to `files`), the recording's
/// `world/pipe/…`, the report.
fn pipe(
    mission: &Mission,
    dir: &Path,
    world: &[Point3<f32>],
    files: &mut Vec<String>,
    rec: &mut Recorder,
    timings: &mut Timings,
) -> Result<Option<PipeReport>> {
    let Some(plan) = &mission.pipe else { return Ok(None) };
    let started = Instant::now();
    let result = crate::inspection::inspect(plan, world);
    if let Ok(inspection) = &result {
        crate::inspection::write_deviation_map(dir, world, inspection)?;
        files.push(DEVIATION_FILE.into());
    }
    timings.pipe_s = Some(started.elapsed().as_secs_f64());
    Ok(Some(match result {
        Ok(inspection) => {
            let t = Instant::now();
            rec.pipe(world, &inspection, plan.threshold_m)?;
            timings.recording_s += t.elapsed().as_secs_f64();
            crate::inspection::report(plan, &inspection)
        }
        Err(e) => {
            let error = format!("{e:#}");
            rec.warn(format!("pipe inspection failed: {error}"))?;
            PipeReport::Failed { error }
        }
    }))
}
