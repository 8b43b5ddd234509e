//! E57 through the `e57` crate. Writing: one `data3D` per scan of the
//! cloud, its points in the scan's frame (f32) with the scan's pose (f64),
//! name, acquisition time and a GUID of its own; points in no scan in one
//! more `data3D` of world coordinates (f64 when georeferenced); intensity
//! as a unit float when present; the CRS's WKT in `coordinateMetadata`.
//! Reading takes every point cloud in the file with its pose applied
//! ([`read`]), or each one in its own frame with its pose
//! ([`read_e57_scans`]).

use std::path::Path;

use e57::{
    CartesianCoordinate, DateTime, E57Reader, E57Writer, Quaternion, Record, RecordValue, Transform, Translation,
};
use nalgebra::{Isometry3, Point3};

use super::PointCloud;
use crate::error::{Result, ScannerError};

pub(super) fn read(path: &Path) -> Result<PointCloud> {
    let mut reader = E57Reader::from_file(path).map_err(|e| ScannerError::whole_file(path, e))?;
    let mut cloud = PointCloud::default();
    let mut intensity = Vec::new();
    let mut all_have_intensity = true;
    for pc in reader.pointclouds() {
        let mut points = reader.pointcloud_simple(&pc).map_err(|e| ScannerError::whole_file(path, e))?;
        points.normalize_intensity(false);
        for (i, p) in points.enumerate() {
            let p = p.map_err(|e| ScannerError::whole_file(path, format!("point {i}: {e}")))?;
            if let Some(point) = cartesian(path, &format!("point {i}"), &p.cartesian)? {
                cloud.points.push(point);
                match p.intensity {
                    Some(v) => intensity.push(v),
                    None => all_have_intensity = false,
                }
            }
        }
    }
    if all_have_intensity && !cloud.points.is_empty() {
        cloud.intensity = Some(intensity);
    }
    Ok(cloud)
}

/// A valid Cartesian coordinate as f32 (`None` for an invalid one), or an
/// error naming `what` when it does not fit.
fn cartesian(path: &Path, what: &str, c: &CartesianCoordinate) -> Result<Option<Point3<f32>>> {
    let CartesianCoordinate::Valid { x, y, z } = *c else { return Ok(None) };
    let point = Point3::new(x as f32, y as f32, z as f32);
    if !point.iter().all(|v| v.is_finite()) {
        return Err(ScannerError::whole_file(
            path,
            format!("{what}: ({x}, {y}, {z}) m: expected coordinates within ±{:e}", f32::MAX),
        ));
    }
    Ok(Some(point))
}

/// One `data3D` of an E57 file, in its own frame.
#[derive(Debug, Clone, PartialEq)]
pub struct E57Scan {
    /// Its name (`data3D[k]` when it has none).
    pub name: String,
    /// Its pose (identity when the file gives none).
    pub world_from_scan: Isometry3<f64>,
    /// Its valid Cartesian points in its own frame.
    pub points: Vec<Point3<f32>>,
    /// Their intensities as recorded (not normalised), when every point
    /// has one.
    pub intensity: Option<Vec<f32>>,
    /// When it was taken (its `acquisitionStart`), GPS seconds.
    pub gps_time_s: Option<f64>,
}

/// The coordinate reference system an E57 file names
/// (`coordinateMetadata`: usually WKT), if it names one.
pub fn read_e57_crs(path: &Path) -> Result<Option<String>> {
    let reader = E57Reader::from_file(path).map_err(|e| ScannerError::whole_file(path, e))?;
    Ok(reader.coordinate_metadata().map(str::trim).filter(|c| !c.is_empty()).map(String::from))
}

/// Reads every `data3D` of an E57 file in its own frame with its pose —
/// a terrestrial scanner's scans with their registration.
pub fn read_e57_scans(path: &Path) -> Result<Vec<E57Scan>> {
    let mut reader = E57Reader::from_file(path).map_err(|e| ScannerError::whole_file(path, e))?;
    let mut scans = Vec::new();
    for (k, pc) in reader.pointclouds().into_iter().enumerate() {
        let world_from_scan = pc.transform.as_ref().map_or(Ok(Isometry3::identity()), |t| {
            let q = nalgebra::Quaternion::new(t.rotation.w, t.rotation.x, t.rotation.y, t.rotation.z);
            let values = [q.w, q.i, q.j, q.k, t.translation.x, t.translation.y, t.translation.z];
            if !values.iter().all(|v| v.is_finite()) || q.norm() < 1e-9 {
                return Err(ScannerError::whole_file(
                    path,
                    format!("data3D[{k}]: pose {values:?}: expected a finite unit quaternion and translation"),
                ));
            }
            Ok(Isometry3::from_parts(
                nalgebra::Translation3::new(t.translation.x, t.translation.y, t.translation.z),
                nalgebra::UnitQuaternion::from_quaternion(q),
            ))
        })?;
        let name = pc.name.clone().unwrap_or_else(|| format!("data3D[{k}]"));
        let mut iter = reader.pointcloud_simple(&pc).map_err(|e| ScannerError::whole_file(path, e))?;
        iter.apply_pose(false);
        iter.normalize_intensity(false);
        let mut points = Vec::new();
        let mut intensity = Some(Vec::new());
        for (i, p) in iter.enumerate() {
            let p = p.map_err(|e| ScannerError::whole_file(path, format!("data3D[{k}] point {i}: {e}")))?;
            if let Some(point) = cartesian(path, &format!("data3D[{k}] point {i}"), &p.cartesian)? {
                points.push(point);
                intensity = intensity.zip(p.intensity).map(|(mut all, v)| {
                    all.push(v);
                    all
                });
            }
        }
        let intensity = intensity.filter(|v| !v.is_empty());
        let gps_time_s = pc.acquisition_start.as_ref().map(|t| t.gps_time);
        scans.push(E57Scan { name, world_from_scan, points, intensity, gps_time_s });
    }
    Ok(scans)
}

/// An E57 file written part by part: one `data3D` per scan of each part,
/// in the scan's own frame with its pose; a part's points in no scan in
/// one more, in the cloud's coordinates (64-bit when georeferenced).
pub(super) struct E57Stream {
    writer: E57Writer<std::fs::File>,
    path: std::path::PathBuf,
    data3d: usize,
}

impl std::fmt::Debug for E57Stream {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("E57Stream").field("path", &self.path).field("data3d", &self.data3d).finish_non_exhaustive()
    }
}

impl E57Stream {
    /// Creates `path` with the cloud's CRS and the creation time.
    pub(super) fn create(path: &Path, cloud: &super::CloudHeader) -> Result<Self> {
        let mut writer = E57Writer::from_file(path, &guid()).map_err(|e| ScannerError::whole_file(path, e))?;
        writer.set_coordinate_metadata(cloud.crs.as_ref().map(|c| c.wkt.clone()));
        let now = std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).map_or(0.0, |d| d.as_secs_f64());
        writer.set_creation(Some(DateTime { gps_time: super::gps_time_of_unix(now), atomic_reference: false }));
        Ok(Self { writer, path: path.to_path_buf(), data3d: 0 })
    }

    /// Adds `part`'s scans (and its points in none).
    pub(super) fn push(&mut self, part: &PointCloud) -> Result<()> {
        let (writer, path) = (&mut self.writer, self.path.as_path());
        let mut covered = vec![false; part.len()];
        for scan in &part.scans {
            covered[scan.points.clone()].iter_mut().for_each(|c| *c = true);
            let scan_from_world = scan.world_from_scan.inverse();
            let points = scan.points.clone().map(|i| {
                let local = scan_from_world * nalgebra::Point3::from(part.coordinates(i));
                (i, [local.x, local.y, local.z].map(|v| RecordValue::Single(v as f32)))
            });
            let meta = Data3d { name: &scan.name, pose: Some(&scan.world_from_scan), gps_time_s: scan.gps_time_s };
            add_data3d(writer, path, part, &meta, false, points)?;
            self.data3d += 1;
        }
        if covered.iter().any(|c| !c) {
            self.add_world(part, |i| !covered[i])?;
        }
        Ok(())
    }

    /// `part`'s points where `keep` in one `data3D` in the cloud's
    /// coordinates.
    fn add_world(&mut self, part: &PointCloud, keep: impl Fn(usize) -> bool) -> Result<()> {
        let georeferenced = part.georeferenced();
        let points = (0..part.len()).filter(|&i| keep(i)).map(|i| {
            let p = &part.points[i];
            let values = if georeferenced {
                part.coordinates(i).map(RecordValue::Double)
            } else {
                [p.x, p.y, p.z].map(RecordValue::Single)
            };
            (i, values)
        });
        let meta = Data3d { name: "cps-survey-cloud", pose: None, gps_time_s: None };
        add_data3d(&mut self.writer, &self.path, part, &meta, georeferenced, points)?;
        self.data3d += 1;
        Ok(())
    }

    /// Finishes the file (an empty cloud gets one empty `data3D`).
    pub(super) fn finish(mut self, cloud: &super::CloudHeader) -> Result<()> {
        if self.data3d == 0 {
            let empty =
                PointCloud { origin: cloud.origin, intensity: cloud.intensity.then(Vec::new), ..PointCloud::default() };
            self.add_world(&empty, |_| true)?;
        }
        let path = self.path.clone();
        self.writer.finalize().map_err(|e| ScannerError::whole_file(&path, e))
    }
}

/// What a `data3D` says of itself.
struct Data3d<'a> {
    name: &'a str,
    pose: Option<&'a Isometry3<f64>>,
    gps_time_s: Option<f64>,
}

/// Adds one `data3D` of `points` (index in `cloud`, coordinates) with
/// `meta` and a new GUID.
fn add_data3d(
    writer: &mut E57Writer<std::fs::File>,
    path: &Path,
    cloud: &PointCloud,
    meta: &Data3d<'_>,
    double: bool,
    points: impl Iterator<Item = (usize, [RecordValue; 3])>,
) -> Result<()> {
    let mut prototype = if double {
        vec![Record::CARTESIAN_X_F64, Record::CARTESIAN_Y_F64, Record::CARTESIAN_Z_F64]
    } else {
        vec![Record::CARTESIAN_X_F32, Record::CARTESIAN_Y_F32, Record::CARTESIAN_Z_F32]
    };
    if cloud.intensity.is_some() {
        prototype.push(Record::INTENSITY_UNIT_F32);
    }
    let mut pc = writer.add_pointcloud(&guid(), prototype).map_err(|e| ScannerError::whole_file(path, e))?;
    pc.set_name(Some(meta.name.to_string()));
    pc.set_transform(meta.pose.map(transform));
    pc.set_acquisition_start(meta.gps_time_s.map(|gps_time| DateTime { gps_time, atomic_reference: false }));
    for (i, xyz) in points {
        let mut values = xyz.to_vec();
        if let Some(v) = &cloud.intensity {
            values.push(RecordValue::Single(v[i]));
        }
        pc.add_point(values).map_err(|e| ScannerError::whole_file(path, format!("point {i}: {e}")))?;
    }
    pc.finalize().map_err(|e| ScannerError::whole_file(path, e))
}

/// An E57 pose: a unit quaternion with w ≥ 0 and a translation.
fn transform(pose: &Isometry3<f64>) -> Transform {
    let q = pose.rotation.quaternion();
    let sign = if q.w < 0.0 { -1.0 } else { 1.0 };
    let t = &pose.translation.vector;
    Transform {
        rotation: Quaternion { w: sign * q.w, x: sign * q.i, y: sign * q.j, z: sign * q.k },
        translation: Translation { x: t.x, y: t.y, z: t.z },
    }
}

/// A new random (version 4) GUID in the braced form E57 files use.
fn guid() -> String {
    let v: u128 =
        rand::random::<u128>() & !(0xf000u128 << 64) & !(0xc000u128 << 48) | (0x4000u128 << 64) | (0x8000u128 << 48);
    let h = format!("{v:032x}");
    format!("{{{}-{}-{}-{}-{}}}", &h[0..8], &h[8..12], &h[12..16], &h[16..20], &h[20..32])
}
