//! The one output stage of `run` and `fuse`: the merged cloud in each of
//! the mission's `[output] formats`, and with `[pipe]` the pipe inspection
//! of that cloud (its deviation map, the recording's `world/pipe/…`, the
//! report). A fit that fails is reported ([`PipeReport::Failed`]) after
//! everything else has been written, not raised — the acceptance fails —
//! while a file that cannot be written is an error.

use std::path::Path;
use std::time::Instant;

use anyhow::Result;
use nalgebra::Point3;
use scanner::io::{Format, PointCloud};

use super::inspection::{DEVIATION_FILE, PipeReport};
use super::report::Timings;
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

/// The file name of the merged cloud in `format` (an `[output] formats`
/// name): `cloud.<format>`, `cloud.copc.laz` for COPC.
pub fn cloud_file(format: &str) -> String {
    if format == "copc" { "cloud.copc.laz".into() } else { format!("cloud.{format}") }
}

/// Checks, before any work, that the output stage can write into `dir`:
/// creates it (and its parents), and refuses a target of [`write`] — a
/// cloud file, the deviation map, and `extra` (the caller's own files) —
/// that exists as something other than a file, naming it. A survey that
/// cannot be written is refused before it is measured, not after.
pub fn check_targets(mission: &Mission, dir: &Path, extra: &[&str]) -> Result<()> {
    use anyhow::{Context, bail};
    if dir.exists() && !dir.is_dir() {
        bail!("{}: exists and is not a directory; expected the output directory", dir.display());
    }
    std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    let clouds = mission.output.formats.iter().map(|f| cloud_file(f));
    let pipe = mission.pipe.as_ref().map(|_| DEVIATION_FILE.to_string());
    for name in clouds.chain(pipe).chain(extra.iter().map(|e| e.to_string())) {
        let path = dir.join(&name);
        if let Ok(meta) = std::fs::symlink_metadata(&path)
            && !meta.file_type().is_file()
        {
            bail!("{}: exists and is not a file; the outputs write {name} there (remove or rename it)", path.display());
        }
    }
    Ok(())
}

/// Writes the merged `cloud` (relative to the mission's cloud origin, each
/// point's scan in `source`, each scan in `scans`) into `dir` as
/// [`cloud_file`] for each of the mission's formats, in the mission's CRS,
/// and, with `[pipe]`, inspects it (logging the result to `rec`); the time
/// each takes goes to `timings`.
pub fn write(
    mission: &Mission,
    dir: &Path,
    mut cloud: PointCloud,
    rec: &mut Recorder,
    timings: &mut Timings,
) -> Result<Written> {
    let started = Instant::now();
    cloud.crs = Some(mission.crs.clone());
    let mut files = Vec::new();
    for format in &mission.output.formats {
        let name = cloud_file(format);
        let path = dir.join(&name);
        scanner::io::write(&path, &cloud, Format::from_path(&path)?)?;
        files.push(name);
    }
    timings.cloud_files_s += started.elapsed().as_secs_f64();
    let pipe = match &mission.pipe {
        None => None,
        Some(plan) => {
            let started = Instant::now();
            // The inspection works in world coordinates (f32).
            let world: std::borrow::Cow<'_, [Point3<f32>]> = if cloud.georeferenced() {
                (0..cloud.len()).map(|i| Point3::from(cloud.coordinates(i)).cast::<f32>()).collect::<Vec<_>>().into()
            } else {
                cloud.points.as_slice().into()
            };
            let result = super::inspection::inspect(plan, &world);
            if let Ok(inspection) = &result {
                super::inspection::write_deviation_map(dir, &world, inspection)?;
                files.push(DEVIATION_FILE.into());
            }
            timings.pipe_s = Some(started.elapsed().as_secs_f64());
            Some(match result {
                Ok(inspection) => {
                    let t = Instant::now();
                    rec.pipe(&world, &inspection, plan.threshold_m)?;
                    timings.recording_s += t.elapsed().as_secs_f64();
                    super::inspection::report(plan, &inspection)
                }
                Err(e) => {
                    let error = format!("{e:#}");
                    rec.warn(format!("pipe inspection failed: {error}"))?;
                    PipeReport::Failed { error }
                }
            })
        }
    };
    Ok(Written { points: cloud.len(), files, pipe })
}
