//! The scans `match` registers, each with a start pose: a 3DTK directory
//! (`scanNNN.3d` with its `scanNNN.pose` odometry, converted to our axes
//! and metres at the boundary), a multi-scan E57 (each `data3D` in its own
//! frame, its pose the start), or single scan files (identity, or the pose
//! `--init-poses` gives), or a robot's rosbag2 ([`crate::ros2::read`]).

use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail};
use nalgebra::{Isometry3, Point3};
use serde::Deserialize;

/// One scan of the set.
#[derive(Debug, Clone)]
pub struct InputScan {
    /// What the user calls it: the file as given, or `FILE.e57#NAME`.
    pub file: String,
    /// A short name for frames and the recording (the file's stem, or the
    /// E57 scan's name).
    pub name: String,
    /// Its points in its own frame (within the range limits).
    pub points: Vec<Point3<f32>>,
    /// Its start `world_from_scan`.
    pub start: Isometry3<f64>,
    /// Its points' intensities, when the input has them (as recorded).
    pub intensity: Option<Vec<f32>>,
    /// When it was taken, GPS seconds, when the input says.
    pub gps_time_s: Option<f64>,
    /// Its points' colours (16 bits a channel), when the input has them.
    pub color: Option<Vec<[u16; 3]>>,
    /// Its points' times, when the input has them, and what they count
    /// from.
    pub time: Option<(Vec<f64>, scanner::io::TimeBase)>,
    /// Where its scanner stood in its frame, when the input says: a 3DTK
    /// scan, an E57 `data3D` and a ROS 2 cloud are in their scanner's
    /// frame (the origin), a PCD states its VIEWPOINT; PLY, XYZ and LAS do
    /// not say. The verification's free-space test needs it.
    pub viewpoint: Option<Point3<f64>>,
}

impl InputScan {
    /// A scan of no points at the identity (tests).
    #[cfg(test)]
    pub(crate) fn empty(file: &str, name: &str) -> Self {
        Self {
            file: file.into(),
            name: name.into(),
            points: Vec::new(),
            start: Isometry3::identity(),
            intensity: None,
            gps_time_s: None,
            color: None,
            time: None,
            viewpoint: None,
        }
    }
}

/// One entry of an `--init-poses` file.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct InitPose {
    file: String,
    world_from_scan: [[f64; 4]; 4],
}

/// Reads `inputs` in order, every scan's points between `min_m` and
/// `max_m` from its origin; each needs more than `min_points` of them.
pub fn read(
    inputs: &[PathBuf],
    init_poses: Option<&Path>,
    (min_m, max_m): (f64, f64),
    min_points: usize,
    bag: &crate::ros2::read::BagOptions,
) -> Result<Vec<InputScan>> {
    let mut scans = Vec::new();
    for input in inputs {
        if crate::ros2::read::is_bag(input) {
            scans.extend(crate::ros2::read::read(input, bag)?.into_iter().enumerate().map(|(k, c)| InputScan {
                file: c.file,
                name: format!("scan{k:03}"),
                points: c.points,
                start: c.start,
                intensity: c.intensity,
                gps_time_s: Some(c.gps_time_s),
                color: None,
                time: c.time.map(|t| (t, scanner::io::TimeBase::Gps)),
                viewpoint: Some(Point3::origin()),
            }));
        } else if input.is_dir() {
            scans.extend(threedtk_directory(input)?);
        } else if scanner::io::Format::from_path(input).ok() == Some(scanner::io::Format::E57) {
            let found = scanner::io::read_e57_scans(input)?;
            if found.is_empty() {
                bail!("{}: no scans (data3D) in the file", input.display());
            }
            scans.extend(found.into_iter().map(|s| InputScan {
                file: format!("{}#{}", input.display(), s.name),
                name: s.name,
                points: s.points,
                start: s.world_from_scan,
                intensity: s.intensity,
                gps_time_s: s.gps_time_s,
                color: s.color,
                time: s.time.map(|t| (t, s.time_base)),
                viewpoint: s.posed.then(Point3::origin),
            }));
        } else {
            let cloud = scanner::io::read(input)?;
            let viewpoint = match scanner::io::Format::from_path(input).ok() {
                Some(scanner::io::Format::ThreeDtk) => Some(Point3::origin()),
                Some(scanner::io::Format::Pcd(_)) => Some(scanner::io::pcd_viewpoint(input)?),
                _ => None,
            };
            if cloud.origin != nalgebra::Vector3::zeros() {
                bail!("{}: a georeferenced cloud: expected a scan in its own frame", input.display());
            }
            let gps_time_s = match cloud.scans.as_slice() {
                [one] => one.gps_time_s,
                _ => None,
            };
            scans.push(InputScan {
                file: input.display().to_string(),
                name: stem(input),
                points: cloud.points,
                start: Isometry3::identity(),
                intensity: cloud.intensity,
                gps_time_s,
                color: cloud.color,
                time: cloud.time.map(|t| (t, cloud.time_base)),
                viewpoint,
            });
        }
    }
    if scans.is_empty() {
        bail!("no scans given: expected scan files, a 3DTK directory or an E57 file");
    }
    if let Some(path) = init_poses {
        apply_init_poses(path, &mut scans)?;
    }
    for s in &mut scans {
        let all = s.points.len();
        // One mask for the points and everything they carry.
        let keep = super::settings::in_range(&s.points, min_m, max_m);
        s.intensity = s.intensity.take().and_then(|v| kept(v, &keep));
        s.color = s.color.take().and_then(|v| kept(v, &keep));
        s.time = s.time.take().and_then(|(t, base)| kept(t, &keep).map(|t| (t, base)));
        s.points = kept(std::mem::take(&mut s.points), &keep).unwrap_or_default();
        if s.points.len() <= min_points {
            bail!(
                "{}: {} points between {min_m} m and {max_m} m from its origin ({all} in the file): expected more than {min_points} to match",
                s.file,
                s.points.len()
            );
        }
    }
    Ok(scans)
}

/// The values whose `keep` is true, when there is one value per flag.
fn kept<T>(values: Vec<T>, keep: &[bool]) -> Option<Vec<T>> {
    (values.len() == keep.len()).then(|| values.into_iter().zip(keep).filter_map(|(v, &k)| k.then_some(v)).collect())
}

/// A 3DTK directory: every `scanNNN.3d` in order, each with its `.pose`.
fn threedtk_directory(dir: &Path) -> Result<Vec<InputScan>> {
    let entries = std::fs::read_dir(dir).with_context(|| format!("reading the directory {}", dir.display()))?;
    let mut scans = Vec::new();
    let mut poses = Vec::new();
    for entry in entries {
        let path = entry.with_context(|| format!("reading the directory {}", dir.display()))?.path();
        let name = path.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
        let number = |ext: &str| {
            name.strip_prefix("scan")
                .and_then(|n| n.strip_suffix(ext))
                .filter(|n| !n.is_empty() && n.bytes().all(|b| b.is_ascii_digit()))
                .map(str::to_owned)
        };
        if let Some(n) = number(".3d") {
            scans.push((n, path));
        } else if let Some(n) = number(".pose") {
            poses.push(n);
        }
    }
    if scans.is_empty() {
        bail!("{}: no 3DTK scans (scanNNN.3d) in the directory", dir.display());
    }
    scans.sort_by(|a, b| (a.0.len(), &a.0).cmp(&(b.0.len(), &b.0)));
    let without: Vec<String> =
        scans.iter().filter(|(n, _)| !poses.contains(n)).map(|(n, _)| format!("scan{n}.3d")).collect();
    let orphans: Vec<String> =
        poses.iter().filter(|n| !scans.iter().any(|(s, _)| s == *n)).map(|n| format!("scan{n}.pose")).collect();
    if !without.is_empty() || !orphans.is_empty() {
        bail!(
            "{}: the scans and .pose files do not match ({}{}{}): expected a scanNNN.pose beside every scanNNN.3d",
            dir.display(),
            if without.is_empty() { String::new() } else { format!("no pose for {}", without.join(", ")) },
            if without.is_empty() || orphans.is_empty() { "" } else { "; " },
            if orphans.is_empty() { String::new() } else { format!("no scan for {}", orphans.join(", ")) },
        );
    }
    scans
        .into_iter()
        .map(|(_, path)| {
            let start = scanner::io::read_3dtk_pose(&path.with_extension("pose"))?;
            let cloud = scanner::io::read(&path)?;
            Ok(InputScan {
                file: path.display().to_string(),
                name: stem(&path),
                points: cloud.points,
                start,
                intensity: cloud.intensity,
                gps_time_s: None,
                color: None,
                time: None,
                viewpoint: Some(Point3::origin()),
            })
        })
        .collect()
}

/// `--init-poses FILE`: JSON `[{"file", "world_from_scan"}]`, each entry
/// naming a scan by the file as given, its file name or (E57) its
/// `FILE#NAME`; every entry must match a scan and be rigid.
fn apply_init_poses(path: &Path, scans: &mut [InputScan]) -> Result<()> {
    let text = std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
    let entries: Vec<InitPose> = serde_json::from_str(&text).with_context(|| {
        format!("{}: expected JSON [{{\"file\": \"…\", \"world_from_scan\": [[4×4 row-major]]}}, …]", path.display())
    })?;
    let mut given: Vec<(usize, usize)> = Vec::new(); // (scan, entry)
    for (k, e) in entries.iter().enumerate() {
        let m = nalgebra::Matrix4::from_fn(|r, c| e.world_from_scan[r][c]);
        let pose = super::settings::rigid(&m)
            .with_context(|| format!("{}: entry {k} (\"{}\"): world_from_scan", path.display(), e.file))?;
        if let Some(t) = pose.translation.vector.iter().find(|t| t.abs() > cps::MAX_COORDINATE_M) {
            bail!(
                "{}: entry {k} (\"{}\"): world_from_scan's translation {t} m is beyond ±{:e} m: expected a position on Earth",
                path.display(),
                e.file,
                cps::MAX_COORDINATE_M
            );
        }
        let matches = |s: &InputScan| {
            s.file == e.file || Path::new(&s.file).file_name().is_some_and(|n| n.to_string_lossy() == e.file)
        };
        let found = scans.iter().position(matches);
        if let Some(i) = found
            && let Some((_, first)) = given.iter().find(|(scan, _)| *scan == i)
        {
            bail!(
                "{}: entries {first} and {k} both give the pose of \"{}\": expected one entry per scan",
                path.display(),
                scans[i].file
            );
        }
        let Some(i) = found else {
            bail!(
                "{}: entry {k} names \"{}\", which is not among the scans: expected one of {}",
                path.display(),
                e.file,
                scans.iter().map(|s| format!("\"{}\"", s.file)).collect::<Vec<_>>().join(", ")
            );
        };
        scans[i].start = pose;
        given.push((i, k));
    }
    Ok(())
}

/// Each scan's number in the outputs (LAS `point_source_id`,
/// `poses.json`): the input's own — the trailing digits of its name (a
/// 3DTK `scanNNN`, an E57 `data3D` named `scan002`, a file `room_scan2`) —
/// when every scan has one and no two share it; else its place in the
/// input order (then, as the numbers cannot tell them apart, all of them).
pub fn scan_numbers(scans: &[InputScan]) -> Vec<u16> {
    let own: Option<Vec<u16>> = scans
        .iter()
        .map(|s| {
            let digits = s.name.len() - s.name.trim_end_matches(|c: char| c.is_ascii_digit()).len();
            s.name[s.name.len() - digits..].parse().ok()
        })
        .collect();
    match own {
        Some(numbers) if numbers.iter().collect::<std::collections::HashSet<_>>().len() == numbers.len() => numbers,
        _ => (0..scans.len()).map(|i| u16::try_from(i).unwrap_or(u16::MAX)).collect(),
    }
}

fn stem(path: &Path) -> String {
    path.file_stem().map_or_else(|| path.display().to_string(), |s| s.to_string_lossy().into_owned())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn named(names: &[&str]) -> Vec<InputScan> {
        names.iter().map(|n| InputScan::empty(&format!("{n}.3d"), n)).collect()
    }

    /// Mutation fuzzing of `--init-poses` (issue 34): a valid file mutated
    /// 3,000 times — bytes flipped or replaced with JSON's delimiters and
    /// extremes, the text cut — never panics; an accepted file gives every
    /// scan a finite rigid pose. Deterministic (seeded).
    #[test]
    fn init_poses_survive_mutated_files() {
        use rand::{Rng, SeedableRng};
        let dir = tempfile::tempdir().expect("temp dir");
        let path = dir.path().join("init.json");
        let valid = r#"[{"file": "a.3d", "world_from_scan": [[1,0,0,1.5],[0,1,0,-2],[0,0,1,0.25],[0,0,0,1]]},
 {"file": "b.3d", "world_from_scan": [[0,-1,0,3],[1,0,0,4],[0,0,1,0],[0,0,0,1]]}]"#;
        let pieces: [&[u8]; 9] = [b"1e308", b"-1e308", b"NaN", b"\"", b"[", b"]", b"{", b"}", b"18446744073709551616"];
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(34);
        for _ in 0..3000 {
            let mut m = valid.as_bytes().to_vec();
            match rng.random_range(0..3) {
                0 => (0..rng.random_range(1..6)).for_each(|_| {
                    let at = rng.random_range(0..m.len());
                    m[at] = rng.random();
                }),
                1 => {
                    let at = rng.random_range(0..m.len());
                    let piece = pieces[rng.random_range(0..pieces.len())];
                    m.splice(at..(at + rng.random_range(0..4)).min(m.len()), piece.iter().copied());
                }
                _ => m.truncate(rng.random_range(0..m.len())),
            }
            std::fs::write(&path, &m).expect("mutated");
            let mut scans = named(&["a", "b"]);
            if apply_init_poses(&path, &mut scans).is_ok() {
                for s in &scans {
                    let pose = s.start.to_homogeneous();
                    assert!(pose.iter().all(|v| v.is_finite()), "{}: {pose}", String::from_utf8_lossy(&m));
                }
            }
        }
    }

    /// A start 3e14 m out (issue 34, U1) is refused, naming the entry.
    #[test]
    fn an_init_pose_beyond_the_earth_is_refused() {
        let dir = tempfile::tempdir().expect("temp dir");
        let path = dir.path().join("init.json");
        std::fs::write(&path, r#"[{"file": "b.3d", "world_from_scan": [[1,0,0,3e14],[0,1,0,0],[0,0,1,0],[0,0,0,1]]}]"#)
            .expect("init");
        let e = apply_init_poses(&path, &mut named(&["a", "b"])).expect_err("refused").to_string();
        assert!(e.contains("entry 0 (\"b.3d\"): world_from_scan's translation 300000000000000 m"), "{e}");
    }

    #[test]
    fn scans_keep_their_own_numbers_when_these_tell_them_apart() {
        assert_eq!(scan_numbers(&named(&["scan000", "scan002", "scan004"])), [0, 2, 4]);
        assert_eq!(scan_numbers(&named(&["room_scan1", "room_scan2"])), [1, 2]);
        // Shared, missing or too large: the input order for all.
        assert_eq!(scan_numbers(&named(&["a/scan000", "b/scan000"])), [0, 1]);
        assert_eq!(scan_numbers(&named(&["scan7", "north"])), [0, 1]);
        assert_eq!(scan_numbers(&named(&["scan70000", "scan1"])), [0, 1]);
    }
}
