//! A run as a rosbag2 of standard messages, from its journal and scans
//! (finished or interrupted), for the ROS 2 tools a robotics user reviews
//! missions in (Foxglove, RViz, `rosbags`). Every topic is in frame `map`,
//! the survey's world (`[site]`'s CRS, named in the bag's metadata):
//!
//! | topic | type | what |
//! |---|---|---|
//! | `/tf_static` | `tf2_msgs/msg/TFMessage` | `parent/base_link → parent/scanner` (the scan head's mount) |
//! | `/tf` | `tf2_msgs/msg/TFMessage` | `map → parent/base_link` at each fix and scan, `map → <child>/base_link` at each placement |
//! | `/cps/parent/pose` | `geometry_msgs/msg/PoseWithCovarianceStamped` | each fix: the CPS pose and its covariance |
//! | `/cps/<child>/pose` | the same | each placement as the network adjustment puts it |
//! | `/cps/scan` | `sensor_msgs/msg/PointCloud2` | each scan in the scanner's frame `parent/scanner`, at its time |
//! | `/cps/route`, `/cps/plan` | `nav_msgs/msg/Path` | the stations fixed, the stations planned |
//! | `/cps/control`, `/cps/ellipses` | `visualization_msgs/msg/MarkerArray` | control points; 95 % ellipses of the adjusted stations |
//!
//! Covariance order (ROS): x, y, z, rotation about X, Y, Z. Ours is
//! (x, y, z, θ): θ goes to Z; X and Y (roll, pitch) get the tilt sensor's
//! σ² where a tilt was read, else [`UNKNOWN_VARIANCE`]; a child's rotation
//! is unknown alike.
//!
//! Times: on real instruments each step's UTC time as journaled (the
//! fixes at their last reading's). On the simulator the mission clock
//! (`mission.rrd`'s `sim_time`: drives at 0.3 m/s, 4 s a measurement, 1 s
//! a tilt reading, the scanner's own slice rate), anchored so that the
//! first scan lands at the UTC time the journal recorded for it (the epoch
//! when no scan recorded one).

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use anyhow::{Context, Result};
use cps::ParentPose;
use nalgebra::{Isometry3, Matrix4, Point3, Translation3, UnitQuaternion, Vector3};

use super::bag::BagWriter;
use super::messages::{
    CYLINDER, Color, Covariance6, Header, Marker, MarkerArray, Path as PathMsg, PointCloud2, Pose, PoseStamped,
    PoseWithCovariance, PoseWithCovarianceStamped, SPHERE, TEXT_VIEW_FACING, TfMessage, Time, TransformStamped,
};
use crate::journal::{Event, Phase};
use crate::products::load::RunDir;
use crate::run::observer::{DRIVE_SPEED_M_PER_S, MEASURE_S, TILT_S};

/// The variance given to a rotation nothing measured, rad².
pub const UNKNOWN_VARIANCE: f64 = 1e6;

/// The fixed frame.
pub const MAP: &str = "map";

/// What a bag was written with.
#[derive(Debug, Clone, PartialEq)]
pub struct Exported {
    /// The bag's directory.
    pub dir: PathBuf,
    /// Messages per topic.
    pub topics: BTreeMap<String, u64>,
}

/// When each step happened on the mission clock, seconds from the start.
#[derive(Debug, Default)]
struct Timeline {
    /// Station → the time of its fix.
    fixes: BTreeMap<usize, f64>,
    /// (cycle, child) → the time of its (last) placement.
    placements: BTreeMap<(usize, usize), f64>,
    /// Station → the time its scan started.
    scans: BTreeMap<usize, f64>,
    /// The clock at the end.
    end: f64,
    /// Nanoseconds since the epoch at clock 0.
    epoch_ns: f64,
}

impl Timeline {
    fn of(run: &RunDir) -> Self {
        let scan_s = run.mission.scan.slices as f64 / (75.0 * run.mission.scan.resolution.degrees());
        let mut t = Self::default();
        let mut clock = 0.0;
        let mut anchor = None;
        for n in &run.journal.events {
            // A step of real instruments carries its UTC time: the clock
            // jumps to it (the first one anchors the clock).
            if let Some(u) = real_time(&n.event) {
                let offset = *anchor.get_or_insert(u - clock);
                clock = u - offset;
            }
            match &n.event {
                Event::Drive(d) if d.unix_time_s.is_none() => clock += d.data.distance_m.max(0.0) / DRIVE_SPEED_M_PER_S,
                Event::Measure(m) => {
                    if m.unix_time_s.is_none() {
                        clock += MEASURE_S;
                    }
                    if let (Phase::Placement, Some(child)) = (m.key.phase, m.key.child) {
                        t.placements.insert((m.key.cycle, child), clock);
                    }
                }
                Event::Tilt(t) if t.unix_time_s.is_none() => clock += TILT_S,
                Event::Scan(s) => {
                    t.scans.insert(s.key.station, clock);
                    if anchor.is_none() {
                        anchor = s.data.unix_time_s.map(|u| u - clock);
                    }
                    if s.unix_time_s.is_none() {
                        clock += scan_s;
                    }
                }
                Event::Fix(f) => {
                    t.fixes.insert(f.key.station, clock);
                }
                _ => {}
            }
        }
        t.end = clock;
        t.epoch_ns = anchor.unwrap_or(0.0).max(0.0) * 1e9;
        t
    }

    fn ns(&self, clock_s: f64) -> u64 {
        (self.epoch_ns + clock_s * 1e9).round().max(0.0) as u64
    }
}

/// The parent at `world` with its ROS `covariance`: on `/tf` and
/// `/cps/parent/pose`.
fn parent_at(bag: &mut BagWriter, stamp: u64, world: &Isometry3<f64>, covariance: [f64; 36]) -> Result<()> {
    bag.write("/tf", stamp, &TfMessage { transforms: vec![transform(stamp, MAP, "parent/base_link", world)] })?;
    bag.write(
        "/cps/parent/pose",
        stamp,
        &PoseWithCovarianceStamped {
            header: header(stamp, MAP),
            pose: PoseWithCovariance { pose: Pose::from(world), covariance: Covariance6(covariance) },
        },
    )
}

/// A step's journaled UTC time (real instruments').
fn real_time(event: &Event) -> Option<f64> {
    match event {
        Event::Drive(r) => r.unix_time_s,
        Event::Measure(r) => r.unix_time_s,
        Event::Tilt(r) => r.unix_time_s,
        Event::Scan(r) => r.unix_time_s,
        _ => None,
    }
}

fn header(stamp_ns: u64, frame: &str) -> Header {
    Header { stamp: Time::from_nanos(stamp_ns), frame_id: frame.into() }
}

/// The 6×6 ROS covariance of a pose with our 4×4 (x, y, z, θ) and the
/// roll and pitch variance.
fn covariance6(c: &Matrix4<f64>, tilt_variance: f64) -> [f64; 36] {
    // Ours → ROS index: x, y, z, θ → 0, 1, 2, 5.
    let at = [0usize, 1, 2, 5];
    let mut out = [0.0; 36];
    for (r, &i) in at.iter().enumerate() {
        for (k, &j) in at.iter().enumerate() {
            out[6 * i + j] = c[(r, k)];
        }
    }
    out[6 * 3 + 3] = tilt_variance;
    out[6 * 4 + 4] = tilt_variance;
    out
}

fn transform(stamp_ns: u64, parent: &str, child: &str, t: &Isometry3<f64>) -> TransformStamped {
    TransformStamped { header: header(stamp_ns, parent), child_frame_id: child.into(), transform: Pose::from(t) }
}

fn planar(pose: &ParentPose) -> Isometry3<f64> {
    Isometry3::from_parts(
        Translation3::from(pose.position.coords),
        UnitQuaternion::from_axis_angle(&Vector3::z_axis(), pose.heading_rad),
    )
}

/// A topic name for a robot (`[a-zA-Z0-9_/]`; anything else becomes `_`,
/// and a leading digit gets one before it).
pub fn topic_name(robot: &str) -> String {
    let mut s: String = robot.chars().map(|c| if c.is_ascii_alphanumeric() || c == '_' { c } else { '_' }).collect();
    if s.is_empty() || s.starts_with(|c: char| c.is_ascii_digit()) {
        s.insert(0, '_');
    }
    s
}

/// Writes the run in `run_dir` (`run`, as [`crate::products::load::load`]
/// read it) into the new rosbag2 directory `dir`.
pub fn write(run: &RunDir, run_dir: &Path, dir: &Path) -> Result<Exported> {
    let time = Timeline::of(run);
    let crs = &run.mission.crs;
    let note = format!("mission {}; crs {}", run.mission.name, crs.name);
    let mut bag = BagWriter::create(dir, &note)?;
    let t0 = time.ns(0.0);
    let tilt_variance = crate::products::fuse::TILT_SIGMA_RAD.powi(2);

    // The scan head's mount.
    let mount = run.mission.scan.body_from_head();
    bag.write(
        "/tf_static",
        t0,
        &TfMessage { transforms: vec![transform(t0, "parent/base_link", "parent/scanner", &mount)] },
    )?;

    // The plan and the control points, at the start.
    let dance = &run.planned.dance;
    let plan = PathMsg {
        header: header(t0, MAP),
        poses: (0..dance.stations.len())
            .map(|k| PoseStamped { header: header(t0, MAP), pose: Pose::from(&planar(&dance.station_pose(k))) })
            .collect(),
    };
    bag.write("/cps/plan", t0, &plan)?;
    if !dance.control.is_empty() {
        let mut markers = Vec::new();
        for (k, c) in dance.control.iter().enumerate() {
            let at = Pose { position: c.position.into(), ..Pose::default() };
            let green = Color { r: 0.1, g: 0.8, b: 0.2, a: 1.0 };
            markers.push(Marker {
                header: header(t0, MAP),
                ns: "control".into(),
                id: k as i32,
                kind: SPHERE,
                pose: at,
                scale: super::messages::Vector3 { x: 0.2, y: 0.2, z: 0.2 },
                color: green,
                ..Marker::default()
            });
            let mut label = at;
            label.position.z += 0.3;
            markers.push(Marker {
                header: header(t0, MAP),
                ns: "control_names".into(),
                id: k as i32,
                kind: TEXT_VIEW_FACING,
                pose: label,
                scale: super::messages::Vector3 { x: 0.0, y: 0.0, z: 0.25 },
                color: green,
                text: c.name.clone(),
                ..Marker::default()
            });
        }
        bag.write("/cps/control", t0, &MarkerArray { markers })?;
    }

    // The parent at each fix, and with its measured tilt at each scan.
    let mut route = Vec::new();
    for n in &run.journal.events {
        let Event::Fix(f) = &n.event else { continue };
        let station = f.key.station;
        let Some(&at) = time.fixes.get(&station) else { continue };
        let stamp = time.ns(at);
        let pose: ParentPose = (&f.data.pose).into();
        let covariance = crate::documents::records::matrix4(&f.data.covariance);
        let world = planar(&pose);
        parent_at(&mut bag, stamp, &world, covariance6(&covariance, UNKNOWN_VARIANCE))?;
        route.push(PoseStamped { header: header(stamp, MAP), pose: Pose::from(&world) });
    }
    for view in &run.views {
        let Some(&at) = time.scans.get(&view.station) else { continue };
        let stamp = time.ns(at);
        let world = view.direct();
        parent_at(&mut bag, stamp, &world, covariance6(&view.covariance, tilt_variance))?;
        bag.write("/cps/scan", stamp, &cloud(run_dir, view, &mount, stamp)?)?;
    }

    // The children where the adjustment puts each placement, and the
    // stations' ellipses (when the journal's network adjusts).
    let adjusted = adjustment(run, run_dir);
    let end = time.ns(time.end);
    if let Some(a) = &adjusted {
        for p in a.points.iter().filter(|p| !p.control) {
            let Some((name, cycle)) = p.id.rsplit_once('@') else { continue };
            let Ok(cycle) = cycle.parse::<usize>() else { continue };
            let Some(child) = run.mission.children.iter().position(|c| c == name) else { continue };
            let Some(&at) = time.placements.get(&(cycle, child)) else { continue };
            let stamp = time.ns(at);
            let frame = format!("{}/base_link", topic_name(name));
            let world = Isometry3::translation(p.x_m, p.y_m, p.z_m);
            let mut c = [0.0; 36];
            for r in 0..3 {
                for k in 0..3 {
                    c[6 * r + k] = p.covariance[r][k];
                }
            }
            for r in 3..6 {
                c[6 * r + r] = UNKNOWN_VARIANCE;
            }
            bag.write("/tf", stamp, &TfMessage { transforms: vec![transform(stamp, MAP, &frame, &world)] })?;
            bag.write(
                &format!("/cps/{}/pose", topic_name(name)),
                stamp,
                &PoseWithCovarianceStamped {
                    header: header(stamp, MAP),
                    pose: PoseWithCovariance { pose: Pose::from(&world), covariance: Covariance6(c) },
                },
            )?;
        }
        let markers = a
            .stations
            .iter()
            .map(|s| {
                let e = &s.ellipse_95;
                let rotation = UnitQuaternion::from_axis_angle(&Vector3::z_axis(), e.orientation_rad);
                Marker {
                    header: header(end, MAP),
                    ns: "ellipse_95".into(),
                    id: s.index as i32,
                    kind: CYLINDER,
                    pose: Pose { position: Point3::new(s.x_m, s.y_m, s.z_m).into(), orientation: rotation.into() },
                    scale: super::messages::Vector3 { x: 2.0 * e.semi_major_m, y: 2.0 * e.semi_minor_m, z: 0.001 },
                    color: Color { r: 1.0, g: 0.6, b: 0.1, a: 0.6 },
                    ..Marker::default()
                }
            })
            .collect();
        bag.write("/cps/ellipses", end, &MarkerArray { markers })?;
    }
    bag.write("/cps/route", end, &PathMsg { header: header(end, MAP), poses: route })?;
    let topics = bag.counts();
    let dir = bag.finish()?;
    Ok(Exported { dir, topics })
}

/// The network adjustment of the run's journal, if it adjusts (a robot
/// alone, or a journal without readings, does not).
fn adjustment(run: &RunDir, run_dir: &Path) -> Option<crate::documents::adjustment::AdjustmentReport> {
    let path = run_dir.join("journal.jsonl");
    let net = crate::products::adjust::network(&run.mission, &run.planned, &run.journal, &path).ok()?;
    crate::products::adjust::adjust(&run.mission, &run.planned, &net, &cps::batch::AdjustOptions::default()).ok()
}

/// A scan as a `PointCloud2` in the scanner's frame (`body_from_scanner`
/// = `mount`, no rotation: the rotating head's slices are assembled in
/// it): x, y, z (and intensity when its file has one) as float32, read
/// from its file (in the body frame).
fn cloud(
    run_dir: &Path,
    view: &crate::products::fuse::ScanView,
    mount: &Isometry3<f64>,
    stamp: u64,
) -> Result<PointCloud2> {
    let scan = scanner::io::read(&run_dir.join(&view.file)).with_context(|| format!("reading {}", view.file))?;
    if scan.points != view.body {
        anyhow::bail!("{}: the file changed since the journal named it", view.file);
    }
    if u32::try_from(scan.points.len()).is_err() {
        anyhow::bail!("{}: too many points for one PointCloud2", view.file);
    }
    let scanner_from_body = mount.inverse().cast::<f32>();
    let points: Vec<Point3<f32>> = scan.points.iter().map(|p| scanner_from_body * p).collect();
    Ok(PointCloud2::xyz(header(stamp, "parent/scanner"), &points, scan.intensity.as_deref()))
}
