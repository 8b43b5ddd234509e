//! A robot's rosbag2 (MCAP storage) as `match`'s scans: the point clouds
//! of one `sensor_msgs/msg/PointCloud2` topic, each with its start pose
//! from `/tf` (and `/tf_static`) or a `nav_msgs/msg/Odometry` topic,
//! interpolated at the cloud's stamp.
//!
//! Clouds of any common layout are read: `x`, `y`, `z` as float32 or
//! float64; `intensity` of any numeric type; a per-point time `time` or
//! `t` (float32/float64 seconds, or uint32 nanoseconds, from the header's
//! stamp); organised or not, either byte order; points with a non-finite
//! coordinate are dropped. Anything else is refused naming the topic, the
//! field and what was expected.

use std::collections::{BTreeMap, HashMap};
use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail};
use nalgebra::{Isometry3, Point3, Quaternion as NQuaternion, Translation3, UnitQuaternion};
use serde::de::DeserializeOwned;

use super::messages::{OdometryHead, PointCloud2, Pose, TfMessage};

/// How far outside the span of a moving frame's transforms a stamp may
/// fall and take the nearest one, seconds.
pub const TF_TOLERANCE_S: f64 = 0.1;

/// What to take from a bag (`match`'s options).
#[derive(Debug, Clone, Default)]
pub struct BagOptions {
    /// The PointCloud2 topic (default: the only one).
    pub topic: Option<String>,
    /// One cloud every this many seconds (default: every cloud).
    pub every_s: Option<f64>,
    /// One cloud every this many metres of travel of the start poses.
    pub every_distance_m: Option<f64>,
    /// The fixed frame (default `map`, else `odom`, else the odometry's).
    pub frame: Option<String>,
    /// Start poses from this `nav_msgs/msg/Odometry` topic instead of `/tf`.
    pub odom: Option<String>,
}

/// Whether `path` is a bag: a directory with `metadata.yaml`, or an `.mcap`.
pub fn is_bag(path: &Path) -> bool {
    (path.is_dir() && path.join("metadata.yaml").is_file())
        || path.extension().is_some_and(|e| e.eq_ignore_ascii_case("mcap"))
}

/// One message as stored.
struct Raw {
    topic: String,
    kind: String,
    log_time: u64,
    data: Vec<u8>,
}

const POINT_CLOUD2: &str = "sensor_msgs/msg/PointCloud2";
const TF_MESSAGE: &str = "tf2_msgs/msg/TFMessage";
const ODOMETRY: &str = "nav_msgs/msg/Odometry";

/// The `.mcap` files of a bag: the directory's (sorted) or the file.
fn mcap_files(path: &Path) -> Result<Vec<PathBuf>> {
    if !path.is_dir() {
        return Ok(vec![path.to_path_buf()]);
    }
    let mut files = Vec::new();
    let mut db3 = false;
    for entry in std::fs::read_dir(path).with_context(|| format!("reading {}", path.display()))? {
        let p = entry.with_context(|| format!("reading {}", path.display()))?.path();
        match p.extension().and_then(|e| e.to_str()) {
            Some("mcap") => files.push(p),
            Some("db3") => db3 = true,
            _ => {}
        }
    }
    if files.is_empty() {
        bail!(
            "{}: no .mcap file in the bag{}: expected rosbag2's MCAP storage (the default since ROS 2 Iron)",
            path.display(),
            if db3 { " (it holds sqlite3 storage, .db3: convert it with `ros2 bag convert`)" } else { "" }
        );
    }
    files.sort();
    Ok(files)
}

/// The largest chunk a bag may claim, decompressed, bytes.
const MAX_CHUNK_BYTES: u64 = 1 << 34;

fn u64_at(b: &[u8], at: usize) -> Option<u64> {
    Some(u64::from_le_bytes(b.get(at..at.checked_add(8)?)?.try_into().ok()?))
}

fn u32_at(b: &[u8], at: usize) -> Option<u32> {
    Some(u32::from_le_bytes(b.get(at..at.checked_add(4)?)?.try_into().ok()?))
}

/// Checks a sequence of MCAP records (opcode · u64 length · content):
/// every one inside `bytes`; each chunk decompressed here, its size and
/// CRC as it claims, and its records checked in turn. The `mcap` crate's
/// reader trusts a damaged length and aborts the process allocating it
/// (found by the damaged-bag test), so nothing reaches it unchecked.
fn check_records(bytes: &[u8], mut at: usize, file: &Path) -> Result<()> {
    let damaged = |at: usize, what: String| {
        anyhow::anyhow!("{}: byte {at}: {what} (a truncated or damaged MCAP)", file.display())
    };
    while at < bytes.len() {
        let (Some(&opcode), Some(len)) = (bytes.get(at), u64_at(bytes, at + 1)) else {
            return Err(damaged(at, "a record cut short".into()));
        };
        let start = at + 9;
        let Some(end) = usize::try_from(len).ok().and_then(|l| start.checked_add(l)).filter(|&e| e <= bytes.len())
        else {
            return Err(damaged(at, format!("a record claims {len} bytes past the end")));
        };
        match opcode {
            // Footer: the summary follows the data's end.
            0x02 => return Ok(()),
            0x06 => {
                let c = &bytes[start..end];
                let size = u64_at(c, 16).ok_or_else(|| damaged(at, "a chunk cut short".into()))?;
                let crc = u32_at(c, 24).ok_or_else(|| damaged(at, "a chunk cut short".into()))?;
                let name_len = u32_at(c, 28).ok_or_else(|| damaged(at, "a chunk cut short".into()))? as usize;
                let name = c.get(32..32 + name_len).ok_or_else(|| damaged(at, "a chunk cut short".into()))?;
                let records_len = u64_at(c, 32 + name_len).ok_or_else(|| damaged(at, "a chunk cut short".into()))?;
                let from = 40 + name_len;
                let records = usize::try_from(records_len)
                    .ok()
                    .and_then(|l| c.get(from..from.checked_add(l)?))
                    .ok_or_else(|| damaged(at, format!("a chunk's records claim {records_len} bytes past it")))?;
                if size > MAX_CHUNK_BYTES || size > 4096 * records_len + (1 << 20) {
                    return Err(damaged(at, format!("a chunk claims {size} bytes decompressed from {records_len}")));
                }
                let plain = match name {
                    b"" => records.to_vec(),
                    b"zstd" => zstd::bulk::decompress(records, size as usize)
                        .map_err(|e| damaged(at, format!("a zstd chunk does not decompress: {e}")))?,
                    b"lz4" => {
                        use std::io::Read;
                        let mut out = Vec::new();
                        lz4::Decoder::new(records)
                            .and_then(|d| d.take(size + 1).read_to_end(&mut out))
                            .map_err(|e| damaged(at, format!("an lz4 chunk does not decompress: {e}")))?;
                        out
                    }
                    other => {
                        return Err(damaged(
                            at,
                            format!(
                                "a chunk compressed with \"{}\": expected zstd, lz4 or none",
                                String::from_utf8_lossy(other)
                            ),
                        ));
                    }
                };
                if plain.len() as u64 != size || (crc != 0 && crc32fast::hash(&plain) != crc) {
                    return Err(damaged(
                        at,
                        format!(
                            "a chunk decompresses to {} bytes, CRC {:08x}; it claims {size}, {crc:08x}",
                            plain.len(),
                            crc32fast::hash(&plain)
                        ),
                    ));
                }
                check_records(&plain, 0, file).map_err(|e| damaged(at, format!("inside a chunk: {e}")))?;
            }
            _ => {}
        }
        at = end;
    }
    Ok(())
}

/// Checks an MCAP file before the `mcap` crate reads it ([`check_records`]).
fn check_mcap(bytes: &[u8], file: &Path) -> Result<()> {
    const MAGIC: &[u8] = b"\x89MCAP0\r\n";
    if !bytes.starts_with(MAGIC) {
        bail!("{}: not an MCAP file (no MCAP magic at the start)", file.display());
    }
    check_records(bytes, MAGIC.len(), file)
}

/// Every message of the kinds `match` reads, in log-time order.
fn messages(path: &Path) -> Result<Vec<Raw>> {
    let mut out = Vec::new();
    for file in mcap_files(path)? {
        let bytes = std::fs::read(&file).with_context(|| format!("reading {}", file.display()))?;
        check_mcap(&bytes, &file)?;
        let stream = mcap::MessageStream::new(&bytes)
            .map_err(|e| anyhow::anyhow!("{}: not an MCAP file: {e}", file.display()))?;
        for m in stream {
            let m = m.map_err(|e| anyhow::anyhow!("{}: {e} (a truncated or damaged MCAP?)", file.display()))?;
            let Some(schema) = m.channel.schema.as_ref() else { continue };
            let kind = schema.name.as_str();
            if ![POINT_CLOUD2, TF_MESSAGE, ODOMETRY].contains(&kind) {
                continue;
            }
            if schema.encoding != "ros2msg" || m.channel.message_encoding != "cdr" {
                bail!(
                    "{}: topic {} ({kind}) has schema encoding \"{}\" and message encoding \"{}\": expected ROS 2's \"ros2msg\" and \"cdr\"",
                    file.display(),
                    m.channel.topic,
                    schema.encoding,
                    m.channel.message_encoding
                );
            }
            out.push(Raw {
                topic: m.channel.topic.clone(),
                kind: kind.into(),
                log_time: m.log_time,
                data: m.data.into_owned(),
            });
        }
    }
    out.sort_by_key(|r| r.log_time);
    Ok(out)
}

/// A CDR message (its encapsulation header first) as `T`.
fn decode<T: DeserializeOwned>(raw: &Raw) -> Result<T> {
    let what = || format!("a {} on {} (log time {} ns)", raw.kind, raw.topic, raw.log_time);
    let Some((head, body)) = raw.data.split_at_checked(4) else {
        bail!("{}: {} bytes: expected a CDR encapsulation header", what(), raw.data.len());
    };
    let decoded = match head[..2] {
        [0, 1] => cdr_encoding::from_bytes::<T, byteorder::LittleEndian>(body),
        [0, 0] => cdr_encoding::from_bytes::<T, byteorder::BigEndian>(body),
        _ => bail!("{}: encapsulation {:02x}{:02x}: expected plain CDR (0000 or 0001)", what(), head[0], head[1]),
    };
    decoded.map(|(t, _)| t).map_err(|e| anyhow::anyhow!("{}: {e}", what()))
}

fn isometry(p: &Pose) -> Result<Isometry3<f64>> {
    let q = NQuaternion::new(p.orientation.w, p.orientation.x, p.orientation.y, p.orientation.z);
    let values = [p.position.x, p.position.y, p.position.z, q.w, q.i, q.j, q.k];
    if values.iter().any(|v| !v.is_finite()) || !(0.5..2.0).contains(&q.norm()) {
        bail!("a transform with {values:?}: expected finite values and a unit quaternion");
    }
    Ok(Isometry3::from_parts(
        Translation3::new(p.position.x, p.position.y, p.position.z),
        UnitQuaternion::from_quaternion(q),
    ))
}

/// A moving frame's parent and its parent_from_child samples (stamp ns).
type Samples = (String, Vec<(u64, Isometry3<f64>)>);

/// The transform tree: each child frame's parent, static or over time.
#[derive(Default)]
struct Tree {
    /// child → (parent, parent_from_child).
    fixed: HashMap<String, (String, Isometry3<f64>)>,
    /// child → (parent, [(stamp ns, parent_from_child)] sorted).
    moving: HashMap<String, Samples>,
}

fn stamp_ns(h: &super::messages::Header) -> u64 {
    (h.stamp.sec.max(0) as u64) * 1_000_000_000 + u64::from(h.stamp.nanosec)
}

fn trim(frame: &str) -> String {
    frame.trim_start_matches('/').to_string()
}

impl Tree {
    fn add(&mut self, parent: &str, child: &str, at: u64, t: Isometry3<f64>, fixed: bool) {
        let (parent, child) = (trim(parent), trim(child));
        if fixed {
            self.fixed.insert(child, (parent, t));
        } else {
            self.moving.entry(child).or_insert_with(|| (parent, Vec::new())).1.push((at, t));
        }
    }

    fn sort(&mut self) {
        for (_, samples) in self.moving.values_mut() {
            samples.sort_by_key(|s| s.0);
        }
    }

    fn frames(&self) -> Vec<String> {
        let mut all: Vec<String> = self
            .fixed
            .iter()
            .map(|(c, (p, _))| (c, p))
            .chain(self.moving.iter().map(|(c, (p, _))| (c, p)))
            .flat_map(|(c, p)| [c.clone(), p.clone()])
            .collect();
        all.sort();
        all.dedup();
        all
    }

    /// parent_from_child at `at`, for a child that has a parent.
    fn step(&self, child: &str, at: u64) -> Result<Option<(String, Isometry3<f64>)>> {
        if let Some((parent, t)) = self.fixed.get(child) {
            return Ok(Some((parent.clone(), *t)));
        }
        let Some((parent, samples)) = self.moving.get(child) else { return Ok(None) };
        let i = samples.partition_point(|s| s.0 <= at);
        let t = match (i.checked_sub(1).map(|k| samples[k]), samples.get(i)) {
            (Some(a), Some(b)) if a.0 != b.0 => {
                let w = (at - a.0) as f64 / (b.0 - a.0) as f64;
                let tr = a.1.translation.vector.lerp(&b.1.translation.vector, w);
                let rot = a.1.rotation.try_slerp(&b.1.rotation, w, 1e-12).unwrap_or(b.1.rotation);
                Isometry3::from_parts(Translation3::from(tr), rot)
            }
            (Some(a), _) if (at - a.0) as f64 * 1e-9 <= TF_TOLERANCE_S => a.1,
            (None, Some(b)) if (b.0 - at) as f64 * 1e-9 <= TF_TOLERANCE_S => b.1,
            (Some(a), Some(_)) => a.1,
            _ => bail!(
                "the transform {parent} → {child} is known from {:.3} s to {:.3} s, not at {:.3} s (±{TF_TOLERANCE_S} s)",
                samples.first().map_or(0.0, |s| s.0 as f64 * 1e-9),
                samples.last().map_or(0.0, |s| s.0 as f64 * 1e-9),
                at as f64 * 1e-9
            ),
        };
        Ok(Some((parent.clone(), t)))
    }

    /// (root, root_from_frame) at `at`.
    fn rooted(&self, frame: &str, at: u64) -> Result<(String, Isometry3<f64>)> {
        let (mut name, mut t) = (frame.to_string(), Isometry3::identity());
        for _ in 0..64 {
            match self.step(&name, at)? {
                Some((parent, step)) => {
                    t = step * t;
                    name = parent;
                }
                None => return Ok((name, t)),
            }
        }
        bail!("the transform tree above {frame} has a loop")
    }

    /// fixed_from_frame at `at`.
    fn lookup(&self, fixed: &str, frame: &str, at: u64) -> Result<Isometry3<f64>> {
        let (r1, root_from_fixed) = self.rooted(fixed, at)?;
        let (r2, root_from_frame) = self.rooted(frame, at)?;
        if r1 != r2 {
            bail!("no transform between {fixed} and {frame} (their trees' roots are {r1} and {r2})");
        }
        Ok(root_from_fixed.inverse() * root_from_frame)
    }
}

/// Reads the field `name` of point `k` as f64.
struct Field {
    offset: usize,
    datatype: u8,
}

fn size_of(datatype: u8) -> Option<usize> {
    match datatype {
        1 | 2 => Some(1),
        3 | 4 => Some(2),
        5..=7 => Some(4),
        8 => Some(8),
        _ => None,
    }
}

impl Field {
    fn read(&self, bytes: &[u8], big: bool) -> f64 {
        let b = &bytes[self.offset..];
        macro_rules! num {
            ($t:ty, $n:expr) => {{
                let a: [u8; $n] = b[..$n].try_into().unwrap_or([0; $n]);
                (if big { <$t>::from_be_bytes(a) } else { <$t>::from_le_bytes(a) }) as f64
            }};
        }
        match self.datatype {
            1 => b[0] as i8 as f64,
            2 => b[0] as f64,
            3 => num!(i16, 2),
            4 => num!(u16, 2),
            5 => num!(i32, 4),
            6 => num!(u32, 4),
            7 => num!(f32, 4),
            _ => num!(f64, 8),
        }
    }
}

const TYPE_NAMES: [&str; 9] = ["?", "int8", "uint8", "int16", "uint16", "int32", "uint32", "float32", "float64"];

/// A cloud's points (finite ones), intensities and per-point times
/// (seconds from its stamp).
type Points = (Vec<Point3<f32>>, Option<Vec<f32>>, Option<Vec<f64>>);

fn points(c: &PointCloud2, topic: &str) -> Result<Points> {
    let step = c.point_step as usize;
    let field = |name: &str, allowed: &[u8], expected: &str| -> Result<Option<Field>> {
        let Some(f) = c.fields.iter().find(|f| f.name == name) else { return Ok(None) };
        let size = size_of(f.datatype);
        if !allowed.contains(&f.datatype) || f.count != 1 || size.is_none_or(|s| f.offset as usize + s > step) {
            bail!(
                "{topic}: PointCloud2 field {name} is {} × {} at offset {} of a {step}-byte point: expected one {expected} inside the point",
                f.count,
                TYPE_NAMES.get(f.datatype as usize).unwrap_or(&"unknown"),
                f.offset
            );
        }
        Ok(Some(Field { offset: f.offset as usize, datatype: f.datatype }))
    };
    let names: Vec<&str> = c.fields.iter().map(|f| f.name.as_str()).collect();
    let mut xyz = Vec::new();
    for axis in ["x", "y", "z"] {
        match field(axis, &[7, 8], "float32 or float64")? {
            Some(f) => xyz.push(f),
            None => bail!("{topic}: PointCloud2 without a field {axis} (fields {names:?}): expected x, y and z"),
        }
    }
    let intensity = field("intensity", &[1, 2, 3, 4, 5, 6, 7, 8], "number")?;
    let time = match field("time", &[6, 7, 8], "float32/float64 seconds or uint32 nanoseconds")? {
        Some(t) => Some(t),
        None => field("t", &[6, 7, 8], "float32/float64 seconds or uint32 nanoseconds")?,
    };
    let (w, h, row) = (c.width as usize, c.height as usize, c.row_step as usize);
    if step == 0 || w.checked_mul(step).is_none_or(|n| n > row) || h.checked_mul(row).is_none_or(|n| n > c.data.0.len())
    {
        bail!(
            "{topic}: PointCloud2 of {h} × {w} points of {step} bytes, rows of {row} bytes, holds {} bytes: expected width × point_step ≤ row_step and height × row_step ≤ the data",
            c.data.0.len()
        );
    }
    let mut out = Vec::with_capacity(w * h);
    let mut inten = intensity.as_ref().map(|_| Vec::with_capacity(w * h));
    let mut times = time.as_ref().map(|_| Vec::with_capacity(w * h));
    for r in 0..h {
        for k in 0..w {
            let p = &c.data.0[r * row + k * step..r * row + (k + 1) * step];
            let v = [xyz[0].read(p, c.is_bigendian), xyz[1].read(p, c.is_bigendian), xyz[2].read(p, c.is_bigendian)];
            if !v.iter().all(|x| x.is_finite() && x.abs() < 1e7) {
                continue;
            }
            out.push(Point3::new(v[0] as f32, v[1] as f32, v[2] as f32));
            if let (Some(f), Some(i)) = (&intensity, inten.as_mut()) {
                i.push(f.read(p, c.is_bigendian) as f32);
            }
            if let (Some(f), Some(t)) = (&time, times.as_mut()) {
                let v = f.read(p, c.is_bigendian);
                t.push(if f.datatype == 6 { v * 1e-9 } else { v });
            }
        }
    }
    Ok((out, inten, times))
}

/// A cloud of the bag with its start pose.
#[derive(Debug, Clone)]
pub struct BagCloud {
    /// `BAG#TOPIC@SECONDS.NANOSECONDS`.
    pub file: String,
    /// Its points in its own frame.
    pub points: Vec<Point3<f32>>,
    /// Its start `fixed_from_cloud` at its stamp.
    pub start: Isometry3<f64>,
    /// Its points' intensities, when it has them.
    pub intensity: Option<Vec<f32>>,
    /// Its stamp, GPS seconds.
    pub gps_time_s: f64,
    /// Its points' times, GPS seconds, when it has them.
    pub time: Option<Vec<f64>>,
}

/// The clouds of `path` with their start poses (module docs).
pub fn read(path: &Path, options: &BagOptions) -> Result<Vec<BagCloud>> {
    let raw = messages(path)?;
    let what = path.display();
    let clouds_on: BTreeMap<&str, usize> =
        raw.iter().filter(|r| r.kind == POINT_CLOUD2).fold(BTreeMap::new(), |mut m, r| {
            *m.entry(r.topic.as_str()).or_default() += 1;
            m
        });
    let topic = match &options.topic {
        Some(t) if clouds_on.contains_key(t.as_str()) => t.clone(),
        Some(t) => bail!(
            "{what}: --topic {t}: no PointCloud2 messages on it; the bag's PointCloud2 topics: {}",
            if clouds_on.is_empty() {
                "none".to_string()
            } else {
                clouds_on.keys().copied().collect::<Vec<_>>().join(", ")
            }
        ),
        None => match clouds_on.keys().collect::<Vec<_>>().as_slice() {
            [one] => one.to_string(),
            [] => bail!("{what}: no sensor_msgs/msg/PointCloud2 messages in the bag"),
            many => bail!(
                "{what}: {} PointCloud2 topics ({}): choose one with --topic",
                many.len(),
                many.iter().map(|t| t.to_string()).collect::<Vec<_>>().join(", ")
            ),
        },
    };
    // The transforms: /tf and /tf_static, then the odometry's edge.
    let mut tree = Tree::default();
    let mut odom_frame = None;
    for r in &raw {
        if r.kind == TF_MESSAGE {
            let fixed = r.topic == "/tf_static" || r.topic.ends_with("/tf_static");
            for t in decode::<TfMessage>(r)?.transforms {
                let iso = isometry(&t.transform)
                    .with_context(|| format!("{what}: {} {} → {}", r.topic, t.header.frame_id, t.child_frame_id))?;
                tree.add(&t.header.frame_id, &t.child_frame_id, stamp_ns(&t.header), iso, fixed);
            }
        }
    }
    if let Some(odom) = &options.odom {
        let mut n = 0;
        for r in raw.iter().filter(|r| &r.topic == odom) {
            if r.kind != ODOMETRY {
                bail!("{what}: --odom {odom} carries {}: expected {ODOMETRY}", r.kind);
            }
            let o = decode::<OdometryHead>(r)?;
            let iso = isometry(&o.pose.pose).with_context(|| format!("{what}: {odom}"))?;
            // The odometry's edge replaces what /tf says of it.
            let child = trim(&o.child_frame_id);
            if n == 0 {
                tree.moving.remove(&child);
                tree.fixed.remove(&child);
            }
            tree.add(&o.header.frame_id, &o.child_frame_id, stamp_ns(&o.header), iso, false);
            odom_frame = Some(trim(&o.header.frame_id));
            n += 1;
        }
        if n == 0 {
            bail!("{what}: --odom {odom}: no {ODOMETRY} messages on that topic");
        }
    }
    tree.sort();
    let frames = tree.frames();
    let fixed = match (&options.frame, odom_frame) {
        (Some(f), _) => trim(f),
        (None, Some(f)) => f,
        (None, None) if frames.iter().any(|f| f == "map") => "map".into(),
        (None, None) if frames.iter().any(|f| f == "odom") => "odom".into(),
        (None, None) => bail!(
            "{what}: no map or odom frame in /tf (frames: {}): give the fixed frame with --frame, or poses with --odom TOPIC",
            if frames.is_empty() { "none".into() } else { frames.join(", ") }
        ),
    };
    if !frames.contains(&fixed) {
        bail!("{what}: --frame {fixed} is not in the bag's transforms (frames: {})", frames.join(", "));
    }
    // The clouds with their poses, then the ones kept.
    let mut scans: Vec<BagCloud> = Vec::new();
    let mut last: Option<(u64, Isometry3<f64>)> = None;
    for r in raw.iter().filter(|r| r.topic == topic) {
        let c = decode::<PointCloud2>(r)?;
        let at = stamp_ns(&c.header);
        let stamp_s = at as f64 * 1e-9;
        let frame = trim(&c.header.frame_id);
        let start = tree
            .lookup(&fixed, &frame, at)
            .with_context(|| format!("{what}: {topic} at {stamp_s:.3} s: start pose"))?;
        let keep = match (last, options.every_s, options.every_distance_m) {
            (None, _, _) => true,
            (Some((t, _)), Some(s), _) => (at - t.min(at)) as f64 * 1e-9 >= s,
            (Some((_, p)), _, Some(m)) => (start.translation.vector - p.translation.vector).norm() >= m,
            _ => true,
        };
        if !keep {
            continue;
        }
        last = Some((at, start));
        let (pts, intensity, times) =
            points(&c, &topic).with_context(|| format!("{what}: the cloud at {stamp_s:.3} s"))?;
        let gps = scanner::io::gps_time_of_unix(stamp_s);
        scans.push(BagCloud {
            file: format!("{what}#{topic}@{}.{:09}", at / 1_000_000_000, at % 1_000_000_000),
            points: pts,
            start,
            intensity,
            gps_time_s: gps,
            time: times.map(|t| t.into_iter().map(|d| gps + d).collect()),
        });
    }
    Ok(scans)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::ros2::messages::{Bytes, Header, PointField};

    fn field(name: &str, offset: u32, datatype: u8) -> PointField {
        PointField { name: name.into(), offset, datatype, count: 1 }
    }

    /// A 2 × 2 organised cloud of float64 x, y, z, a uint16 intensity and a
    /// uint32 time in ns, one point NaN, in either byte order.
    fn cloud(big: bool) -> PointCloud2 {
        let fields =
            vec![field("x", 0, 8), field("y", 8, 8), field("z", 16, 8), field("intensity", 24, 4), field("t", 28, 6)];
        let mut data = Vec::new();
        for k in 0..4u32 {
            let x = if k == 2 { f64::NAN } else { k as f64 + 0.5 };
            let (y, z, i, t) = (-(k as f64), 2.0 * k as f64, 100 * k as u16, 1_000_000 * k);
            if big {
                for v in [x, y, z] {
                    data.extend_from_slice(&v.to_be_bytes());
                }
                data.extend_from_slice(&i.to_be_bytes());
                data.extend_from_slice(&[0, 0]);
                data.extend_from_slice(&t.to_be_bytes());
            } else {
                for v in [x, y, z] {
                    data.extend_from_slice(&v.to_le_bytes());
                }
                data.extend_from_slice(&i.to_le_bytes());
                data.extend_from_slice(&[0, 0]);
                data.extend_from_slice(&t.to_le_bytes());
            }
        }
        PointCloud2 {
            header: Header::default(),
            height: 2,
            width: 2,
            fields,
            is_bigendian: big,
            point_step: 32,
            row_step: 64,
            data: Bytes(data),
            is_dense: false,
        }
    }

    #[test]
    fn common_layouts_read_and_nan_points_drop() {
        for big in [false, true] {
            let (p, i, t) = points(&cloud(big), "/points").expect("reads");
            assert_eq!(p, vec![Point3::new(0.5, 0.0, 0.0), Point3::new(1.5, -1.0, 2.0), Point3::new(3.5, -3.0, 6.0)]);
            assert_eq!(i, Some(vec![0.0, 100.0, 300.0]));
            assert_eq!(t, Some(vec![0.0, 1e-3, 3e-3]));
        }
    }

    #[test]
    fn an_unknown_compression_and_a_foreign_schema_are_named() {
        let dir = tempfile::tempdir().expect("tempdir");
        // A chunk compressed with "bz2": magic, then opcode 6 and its record.
        let mut chunk = Vec::new();
        chunk.extend_from_slice(&[0u8; 16]);
        chunk.extend_from_slice(&10u64.to_le_bytes());
        chunk.extend_from_slice(&0u32.to_le_bytes());
        chunk.extend_from_slice(&3u32.to_le_bytes());
        chunk.extend_from_slice(b"bz2");
        chunk.extend_from_slice(&4u64.to_le_bytes());
        chunk.extend_from_slice(&[1, 2, 3, 4]);
        let mut file = b"\x89MCAP0\r\n".to_vec();
        file.push(0x06);
        file.extend_from_slice(&(chunk.len() as u64).to_le_bytes());
        file.extend_from_slice(&chunk);
        let path = dir.path().join("bz2.mcap");
        std::fs::write(&path, &file).expect("write");
        let err = format!("{:#}", read(&path, &BagOptions::default()).expect_err("bz2"));
        assert!(
            err.contains("bz2.mcap") && err.contains("\"bz2\"") && err.contains("expected zstd, lz4 or none"),
            "{err}"
        );
        // A PointCloud2 channel whose schema is ROS 1's.
        let path = dir.path().join("ros1.mcap");
        let mut w =
            mcap::Writer::new(std::io::BufWriter::new(std::fs::File::create(&path).expect("create"))).expect("writer");
        let schema = w.add_schema(POINT_CLOUD2, "ros1msg", b"Header header").expect("schema");
        let channel = w.add_channel(schema, "/points", "ros1", &BTreeMap::new()).expect("channel");
        let header = mcap::records::MessageHeader { channel_id: channel, sequence: 1, log_time: 1, publish_time: 1 };
        w.write_to_known_channel(&header, &[0u8; 8]).expect("message");
        w.finish().expect("finish");
        drop(w);
        let err = format!("{:#}", read(&path, &BagOptions::default()).expect_err("ros1"));
        assert!(err.contains("/points") && err.contains("\"ros1msg\"") && err.contains("expected ROS 2's"), "{err}");
    }

    #[test]
    fn other_layouts_are_refused_naming_the_topic_and_field() {
        let mut c = cloud(false);
        c.fields[1] = field("y", 8, 5);
        let err = points(&c, "/points").expect_err("int32 y").to_string();
        assert!(
            err.contains("/points") && err.contains("field y is 1 × int32") && err.contains("float32 or float64"),
            "{err}"
        );
        let mut c = cloud(false);
        c.fields.retain(|f| f.name != "z");
        let err = points(&c, "/points").expect_err("no z").to_string();
        assert!(err.contains("without a field z"), "{err}");
        let mut c = cloud(false);
        c.row_step = 40;
        let err = points(&c, "/points").expect_err("rows too short").to_string();
        assert!(err.contains("row_step"), "{err}");
        let mut c = cloud(false);
        c.fields[0].offset = 30;
        let err = points(&c, "/points").expect_err("x past the point").to_string();
        assert!(err.contains("field x") && err.contains("inside the point"), "{err}");
    }
}
