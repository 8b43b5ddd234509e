//! E57 through the `e57` crate. Writing: one `data3D` per scan of the
//! cloud, its points in the scan's frame (f32) with the scan's pose (f64),
//! name, acquisition time and a GUID of its own; points in no scan in one
//! more `data3D` of world coordinates (f64 when georeferenced); intensity
//! as a unit float, colour as integers (limits 0–255 when every colour of
//! the `data3D` is an 8-bit one, as scanners and most readers have it —
//! pye57 reads no other — else 0–65,535) and each
//! point's `timeStamp` (f64 seconds after its scan's `acquisitionStart`,
//! which is the first point's time when the scan states none) when
//! present; the CRS's WKT in `coordinateMetadata`.
//! Reading takes every point cloud in the file with its pose applied
//! ([`read`]), or each one in its own frame with its pose
//! ([`read_e57_scans`]).

use std::path::Path;

use e57::{
    CartesianCoordinate, ColorLimits, DateTime, E57Reader, E57Writer, Quaternion, Record, RecordDataType, RecordName,
    RecordValue, Transform, Translation,
};
use nalgebra::{Isometry3, Point3};

use super::{PointCloud, TimeBase};
use crate::error::{Result, ScannerError};

/// The colour records we write, 8 or 16 bits, and the `timeStamp` record.
const COLOR_NAMES: [RecordName; 3] = [RecordName::ColorRed, RecordName::ColorGreen, RecordName::ColorBlue];
const TIME_STAMP_F64: Record = Record { name: RecordName::TimeStamp, data_type: RecordDataType::F64 };

/// One `data3D`'s points as read: coordinates (with or without its pose)
/// and what every valid point carries.
#[derive(Default)]
struct Read {
    points: Vec<Point3<f32>>,
    intensity: Option<Vec<f32>>,
    color: Option<Vec<[u16; 3]>>,
    /// GPS seconds (`timeStamp` + `acquisitionStart`), or the `timeStamp`s
    /// as they are when the scan states no start.
    time: Option<Vec<f64>>,
    /// What `time` counts from.
    time_base: TimeBase,
}

/// Reads `pc`'s valid points (`posed`: with its pose applied); each
/// attribute kept when every valid point has it. Colours are scaled from
/// the file's limits to 16 bits.
fn read_data3d(
    reader: &mut E57Reader<std::io::BufReader<std::fs::File>>,
    path: &Path,
    k: usize,
    pc: &e57::PointCloud,
    posed: bool,
) -> Result<Read> {
    // The simple reader gives no timeStamp: read from the raw records,
    // point for point in the same order.
    let stamps: Option<Vec<Option<f64>>> = match pc.prototype.iter().position(|r| r.name == RecordName::TimeStamp) {
        None => None,
        Some(at) => {
            let dt = pc.prototype[at].data_type.clone();
            let invalid = pc.prototype.iter().position(|r| r.name == RecordName::IsTimeStampInvalid);
            let raw = reader.pointcloud_raw(pc).map_err(|e| ScannerError::whole_file(path, e))?;
            let mut all = Vec::new();
            for (i, values) in raw.enumerate() {
                let values =
                    values.map_err(|e| ScannerError::whole_file(path, format!("data3D[{k}] point {i}: {e}")))?;
                let bad = invalid.and_then(|j| values.get(j)).is_some_and(|v| !matches!(v, RecordValue::Integer(0)));
                let t = values.get(at).and_then(|v| v.to_f64(&dt).ok()).filter(|t| t.is_finite() && !bad);
                all.push(t);
            }
            Some(all)
        }
    };
    let mut iter = reader.pointcloud_simple(pc).map_err(|e| ScannerError::whole_file(path, e))?;
    iter.apply_pose(posed);
    iter.normalize_intensity(false);
    let mut out = Read {
        intensity: Some(Vec::new()),
        color: pc.has_color().then(Vec::new),
        time: stamps.as_ref().map(|_| Vec::new()),
        ..Read::default()
    };
    for (i, p) in iter.enumerate() {
        let p = p.map_err(|e| ScannerError::whole_file(path, format!("data3D[{k}] point {i}: {e}")))?;
        let Some(point) = cartesian(path, &format!("data3D[{k}] point {i}"), &p.cartesian)? else { continue };
        out.points.push(point);
        keep(&mut out.intensity, p.intensity);
        let unit = |v: f32| (f64::from(v).clamp(0.0, 1.0) * 65_535.0).round() as u16;
        keep(&mut out.color, p.color.map(|c| [unit(c.red), unit(c.green), unit(c.blue)]));
        keep(&mut out.time, stamps.as_ref().and_then(|s| s.get(i).copied().flatten()));
    }
    if out.points.is_empty() {
        out.intensity = None;
    }
    match (pc.acquisition_start.as_ref().map(|t| t.gps_time), out.time.as_mut()) {
        (Some(start), Some(time)) => time.iter_mut().for_each(|t| *t += start),
        (None, Some(_)) => out.time_base = TimeBase::Relative,
        (_, None) => {}
    }
    Ok(out)
}

/// Appends `more` to `all`, or drops `all` when a part has none.
fn extend<T>(all: &mut Option<Vec<T>>, more: Option<Vec<T>>) {
    *all = all.take().zip(more).map(|(mut all, more)| {
        all.extend(more);
        all
    });
}

/// Appends `value` to `all`, or drops `all` when a point has none.
fn keep<T>(all: &mut Option<Vec<T>>, value: Option<T>) {
    *all = all.take().zip(value).map(|(mut all, v)| {
        all.push(v);
        all
    });
}

pub(super) fn read(path: &Path) -> Result<PointCloud> {
    let mut reader = E57Reader::from_file(path).map_err(|e| ScannerError::whole_file(path, e))?;
    let mut cloud = PointCloud {
        intensity: Some(Vec::new()),
        color: Some(Vec::new()),
        time: Some(Vec::new()),
        ..PointCloud::default()
    };
    let mut bases = Vec::new();
    for (k, pc) in reader.pointclouds().into_iter().enumerate() {
        let part = read_data3d(&mut reader, path, k, &pc, true)?;
        let n = part.points.len();
        cloud.points.extend(part.points);
        if n > 0 {
            extend(&mut cloud.intensity, part.intensity);
            extend(&mut cloud.color, part.color);
            bases.push(part.time_base);
            extend(&mut cloud.time, part.time);
        }
    }
    if cloud.points.is_empty() {
        (cloud.intensity, cloud.color, cloud.time) = (None, None, None);
    }
    // Times of different bases make no one column.
    cloud.time_base = bases.first().copied().unwrap_or_default();
    if cloud.time.is_none() || bases.iter().any(|b| *b != cloud.time_base) {
        (cloud.time, cloud.time_base) = (None, TimeBase::default());
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
    /// Whether the file gives its pose: a posed `data3D` is a scan in its
    /// scanner's frame (a scanner's own; the cloud of points in no scan
    /// this crate writes has none).
    pub posed: bool,
    /// Its valid Cartesian points in its own frame.
    pub points: Vec<Point3<f32>>,
    /// Their intensities as recorded (not normalised), when every point
    /// has one.
    pub intensity: Option<Vec<f32>>,
    /// Their colours (16 bits a channel, from the file's limits), when
    /// every point has one.
    pub color: Option<Vec<[u16; 3]>>,
    /// Their times, when every point has one: GPS seconds when the scan
    /// states its `acquisitionStart`, else the file's `timeStamp`
    /// ([`TimeBase::Relative`]).
    pub time: Option<Vec<f64>>,
    /// What `time` counts from (the default when there are no times).
    pub time_base: TimeBase,
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
            // A unit quaternion, as E57 says, to 1e-3 (normalised then);
            // w = 1e300 squared overflows to a NaN rotation (issue 34, U4).
            let norm = q.norm();
            if !values.iter().all(|v| v.is_finite()) || !norm.is_finite() || (norm - 1.0).abs() > 1e-3 {
                return Err(ScannerError::whole_file(
                    path,
                    format!(
                        "data3D[{k}]: pose {values:?} (quaternion norm {norm:e}): expected a finite unit quaternion and translation"
                    ),
                ));
            }
            Ok(Isometry3::from_parts(
                nalgebra::Translation3::new(t.translation.x, t.translation.y, t.translation.z),
                nalgebra::UnitQuaternion::from_quaternion(q),
            ))
        })?;
        let name = pc.name.clone().unwrap_or_else(|| format!("data3D[{k}]"));
        let read = read_data3d(&mut reader, path, k, &pc, false)?;
        scans.push(E57Scan {
            name,
            world_from_scan,
            posed: pc.transform.is_some(),
            points: read.points,
            intensity: read.intensity,
            color: read.color,
            time: read.time,
            time_base: read.time_base,
            gps_time_s: pc.acquisition_start.as_ref().map(|t| t.gps_time),
        });
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
            let meta = Data3d {
                name: &scan.name,
                pose: Some(&scan.world_from_scan),
                gps_time_s: start_time(part, scan.points.clone(), scan.gps_time_s),
                eight_bit: eight_bit(part, scan.points.clone()),
            };
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
        let start = start_time(part, (0..part.len()).filter(|&i| keep(i)), None);
        let eight_bit = eight_bit(part, (0..part.len()).filter(|&i| keep(i)));
        let meta = Data3d { name: "cps-survey-cloud", pose: None, gps_time_s: start, eight_bit };
        add_data3d(&mut self.writer, &self.path, part, &meta, georeferenced, points)?;
        self.data3d += 1;
        Ok(())
    }

    /// Finishes the file (an empty cloud gets one empty `data3D`).
    pub(super) fn finish(mut self, cloud: &super::CloudHeader) -> Result<()> {
        if self.data3d == 0 {
            let empty = PointCloud {
                origin: cloud.origin,
                intensity: cloud.intensity.then(Vec::new),
                color: cloud.color.then(Vec::new),
                time: cloud.time.map(|_| Vec::new()),
                time_base: cloud.time.unwrap_or_default(),
                ..PointCloud::default()
            };
            self.add_world(&empty, |_| true)?;
        }
        let path = self.path.clone();
        self.writer.finalize().map_err(|e| ScannerError::whole_file(&path, e))
    }
}

/// A `data3D`'s `acquisitionStart` for `points` of `part`: the scan's
/// own (`given`), else its first point's GPS time; none for times of an
/// unstated epoch (their `timeStamp`s are written as they are).
fn start_time(part: &PointCloud, mut points: impl Iterator<Item = usize>, given: Option<f64>) -> Option<f64> {
    match (&part.time, part.time_base) {
        (Some(_), TimeBase::Relative) => None,
        (Some(t), TimeBase::Gps) => given.or_else(|| points.next().map(|i| t[i])),
        (None, _) => given,
    }
}

/// Whether every colour of `points` of `part` is an 8-bit one (× 257).
fn eight_bit(part: &PointCloud, mut points: impl Iterator<Item = usize>) -> bool {
    part.color.as_ref().is_none_or(|c| points.all(|i| c[i].iter().all(|v| v % 257 == 0)))
}

/// What a `data3D` says of itself.
struct Data3d<'a> {
    name: &'a str,
    pose: Option<&'a Isometry3<f64>>,
    gps_time_s: Option<f64>,
    /// Colours written in 8 bits (every one is an 8-bit value).
    eight_bit: bool,
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
    let (data_type, max) =
        if meta.eight_bit { (RecordDataType::U8, u8::MAX.into()) } else { (RecordDataType::U16, u16::MAX.into()) };
    if cloud.color.is_some() {
        prototype.extend(COLOR_NAMES.map(|name| Record { name, data_type: data_type.clone() }));
    }
    if cloud.time.is_some() {
        prototype.push(TIME_STAMP_F64);
    }
    let mut pc = writer.add_pointcloud(&guid(), prototype).map_err(|e| ScannerError::whole_file(path, e))?;
    if cloud.color.is_some() {
        let (lo, hi) = (Some(RecordValue::Integer(0)), Some(RecordValue::Integer(max)));
        pc.set_color_limits(Some(ColorLimits {
            red_min: lo.clone(),
            red_max: hi.clone(),
            green_min: lo.clone(),
            green_max: hi.clone(),
            blue_min: lo,
            blue_max: hi,
        }));
    }
    pc.set_name(Some(meta.name.to_string()));
    pc.set_transform(meta.pose.map(transform));
    pc.set_acquisition_start(meta.gps_time_s.map(|gps_time| DateTime { gps_time, atomic_reference: false }));
    for (i, xyz) in points {
        let mut values = xyz.to_vec();
        if let Some(v) = &cloud.intensity {
            values.push(RecordValue::Single(v[i]));
        }
        if let Some(c) = &cloud.color {
            let scale = if meta.eight_bit { 257 } else { 1 };
            values.extend(c[i].map(|v| RecordValue::Integer(i64::from(v / scale))));
        }
        if let Some(t) = &cloud.time {
            values.push(RecordValue::Double(t[i] - meta.gps_time_s.unwrap_or(0.0)));
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
