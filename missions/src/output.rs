//! The one output stage of every cloud the tool writes (`run`, `fuse`,
//! `match`): where the merged cloud's coordinates count from, what its
//! files are called, its files written a scan at a time, and each scan's
//! part of it.
//!
//! **Origin.** A merged cloud's points are stored relative to an origin:
//! the first pose's position, each axis rounded to the kilometre (zero
//! for a site within 500 m of its datum's origin). The files add it back
//! in f64 (LAS offsets, E57 and PLY doubles), so a survey at national-grid
//! coordinates keeps its 0.1 mm while every scan is moved in f32.

use std::path::Path;

use anyhow::Result;
use nalgebra::{Isometry3, Point3, Translation3, Vector3};
use scanner::io::{CloudHeader, CloudWriter, Format, PointCloud, ScanInfo};

/// The origin of a merged cloud whose first pose stands at `first`: each
/// axis rounded to the kilometre (a coordinate that is not finite counts
/// as 0).
pub fn cloud_origin(first: &Vector3<f64>) -> Vector3<f64> {
    first.map(|v| if v.is_finite() { (v / 1000.0).round() * 1000.0 } else { 0.0 })
}

/// The file name of the merged cloud in `format` (an `[output] formats`
/// name): `cloud.<format>`, `cloud.copc.laz` for COPC.
pub fn cloud_file(format: &str) -> String {
    if format == "copc" { "cloud.copc.laz".into() } else { format!("cloud.{format}") }
}

/// The first of `names` in `dir` that exists as neither a file nor a
/// symbolic link (a directory, say): an output file cannot replace it.
pub fn taken(dir: &Path, names: impl IntoIterator<Item = String>) -> Option<(String, std::fs::Metadata)> {
    names.into_iter().find_map(|name| {
        let meta = std::fs::symlink_metadata(dir.join(&name)).ok()?;
        (!meta.file_type().is_file() && !meta.file_type().is_symlink()).then_some((name, meta))
    })
}

/// Who a scan is in the merged cloud.
#[derive(Debug, Clone, PartialEq)]
pub struct ScanLabel {
    /// Its name (the scan file's stem, the E57 `data3D`'s name).
    pub name: String,
    /// The number every one of its points carries (LAS `point_source_id`).
    pub number: u16,
    /// When it was taken, GPS seconds.
    pub gps_time_s: Option<f64>,
}

/// `world_from_scan` as seen from `origin`: the transform whose points are
/// world coordinates minus the origin (exact in f64, small in f32).
pub fn relative(origin: &Vector3<f64>, world_from_scan: &Isometry3<f64>) -> Isometry3<f64> {
    Translation3::from(-origin) * world_from_scan
}

/// One scan's part of the merged cloud: its `points` (its own frame)
/// moved by `world_from_scan` relative to `origin`, each with the scan's
/// number, the scan with its name, pose and time.
pub fn part(
    points: &[Point3<f32>],
    world_from_scan: &Isometry3<f64>,
    origin: &Vector3<f64>,
    label: ScanLabel,
) -> PointCloud {
    let n = points.len();
    PointCloud {
        points: fusion::direct::transform(points, &relative(origin, world_from_scan)),
        source: Some(vec![label.number; n]),
        origin: *origin,
        scans: vec![ScanInfo {
            name: label.name,
            points: 0..n,
            world_from_scan: *world_from_scan,
            gps_time_s: label.gps_time_s,
        }],
        ..PointCloud::default()
    }
}

/// The points of a scan's `part` for a viewer (f32 world coordinates):
/// the part's own when its origin is zero, else `body` moved by
/// `world_from_scan` anew.
pub fn viewed(part: &PointCloud, body: &[Point3<f32>], world_from_scan: &Isometry3<f64>) -> Vec<Point3<f32>> {
    if part.origin == Vector3::zeros() { part.points.clone() } else { fusion::direct::transform(body, world_from_scan) }
}

/// A merged cloud's files, one per format, written a scan at a time
/// ([`scanner::io::CloudWriter`]: one scan's points held, not the
/// cloud's). Dropped unfinished, the files go.
#[derive(Debug)]
pub struct CloudFiles {
    files: Vec<(String, CloudWriter)>,
    points: usize,
}

impl CloudFiles {
    /// Opens `cloud.<format>` in `dir` for every one of `formats`, each
    /// with `header`.
    pub fn create(dir: &Path, formats: &[String], header: &CloudHeader) -> Result<Self> {
        let mut files = Vec::with_capacity(formats.len());
        for format in formats {
            let name = cloud_file(format);
            let path = dir.join(&name);
            files.push((name, CloudWriter::create(&path, Format::from_path(&path)?, header.clone())?));
        }
        Ok(Self { files, points: 0 })
    }

    /// Appends one scan's `part` ([`part`]) to every file.
    pub fn push(&mut self, part: &PointCloud) -> Result<()> {
        for (_, writer) in &mut self.files {
            writer.push(part)?;
        }
        self.points += part.len();
        Ok(())
    }

    /// Points written so far.
    pub fn points(&self) -> usize {
        self.points
    }

    /// Finishes every file; their names.
    pub fn finish(self) -> Result<Vec<String>> {
        let mut names = Vec::with_capacity(self.files.len());
        for (name, writer) in self.files {
            writer.finish()?;
            names.push(name);
        }
        Ok(names)
    }
}
