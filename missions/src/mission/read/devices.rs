//! The tables of the devices and what they do: `[instruments]`,
//! `[backend]` (with `[backend.serial]`), `[scan]`, `[fusion]` and `[pipe]`.

use std::ops::Range;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use cps::{DistanceErrorModel, Instrument, RAD_PER_ARCSEC};
use nalgebra::Vector3;

use crate::mission::reader::{At, Reader, Table};
use crate::mission::{Backend, FUSION_MODES, FusionMode, FusionPlan, PipePlan, ScanPlan, SerialPorts};

use super::fields::{Raw, non_negative, positive, positive_at_most, within};

/// `[instruments]`: the total station (none for a robot alone).
pub(super) fn read_instruments(r: &mut Reader<'_>, root: &mut Table<'_, '_>, solo: bool) -> Option<Option<Instrument>> {
    let mut instruments = root.table(r, "instruments");
    let total_station = if solo {
        if let Some(v) = instruments.get("total_station") {
            let message = "the team has no children, so the total station has nothing to measure; remove this table";
            r.problem(&v.span(), "instruments.total_station", message);
        }
        Some(None)
    } else {
        let mut ts = instruments.table(r, "total_station");
        let total_station = read_total_station(r, &mut ts);
        ts.finish(r);
        total_station.map(Some)
    };
    instruments.finish(r);
    total_station
}

pub(super) fn read_total_station(r: &mut Reader<'_>, t: &mut Table<'_, '_>) -> Option<Instrument> {
    let nonneg = non_negative;
    let sigma_distance_mm =
        t.required(r, "sigma_distance_mm", "the distance error's constant part in mm (> 0)", positive);
    let ppm = t.optional(r, "sigma_distance_ppm", nonneg);
    let model = t.optional(r, "distance_error_model", |r, v, f| {
        let s = r.choice(v, f, &["quadrature", "linear"])?;
        Some(if s.get_ref() == "linear" { DistanceErrorModel::Linear } else { DistanceErrorModel::Quadrature })
    });
    let hz = t.required(r, "sigma_hz_arcsec", "the horizontal-direction error in arc-seconds (> 0)", positive);
    let v = t.required(r, "sigma_v_arcsec", "the vertical-angle error in arc-seconds (> 0)", positive);
    let ci = t.optional(r, "centring_instrument_mm", nonneg);
    let ct = t.optional(r, "centring_target_mm", nonneg);
    let prism = t.optional(r, "prism_constant_mm", |r, v, f| r.number(v, f).map(At::into_inner));
    let min_range =
        t.optional(r, "min_range_m", |r, v, f| r.number_in(v, f, 0.0, true, None).map(|x| (*x.get_ref(), x.span())));
    let max_range =
        t.optional(r, "max_range_m", |r, v, f| r.number_in(v, f, 0.0, false, None).map(|x| (*x.get_ref(), x.span())));
    let (min_range, max_range) = (min_range?, max_range?);
    if let (Some((lo, _)), Some((hi, span))) = (&min_range, &max_range)
        && hi <= lo
    {
        let field = "instruments.total_station.max_range_m";
        r.problem(span, field, format!("value {hi} is out of range; expected > min_range_m = {lo}"));
        return None;
    }
    Some(Instrument {
        sigma_distance_m: sigma_distance_mm? * 1e-3,
        sigma_distance_ppm: ppm?.unwrap_or(0.0),
        distance_model: model?.unwrap_or_default(),
        sigma_hz_rad: hz? * RAD_PER_ARCSEC,
        sigma_v_rad: v? * RAD_PER_ARCSEC,
        centring_instrument_m: ci?.unwrap_or(0.0) * 1e-3,
        centring_target_m: ct?.unwrap_or(0.0) * 1e-3,
        prism_constant_m: prism?.unwrap_or(0.0) * 1e-3,
        min_range_m: min_range.map_or(0.0, |x| x.0),
        max_range_m: max_range.map_or(f64::INFINITY, |x| x.0),
    })
}

/// `[backend]` (with `[backend.serial]`) and the span of its `scene_file`.
pub(super) fn read_backend(
    r: &mut Reader<'_>,
    root: &mut Table<'_, '_>,
    n_children: Option<usize>,
    scene_override: Option<&Path>,
) -> Option<(Backend, Option<Range<usize>>)> {
    let given = root.has("backend");
    let mut b = root.table(r, "backend");
    let kind = b.optional(r, "kind", |r, v, f| r.choice(v, f, &["sim", "serial"]));
    let serial_given = b.has("serial");
    let mut sp = b.table(r, "serial");
    let serial = if kind.as_ref().and_then(|k| k.as_ref()).is_some_and(|k| k.get_ref() == "serial") {
        let ports = read_serial(r, &mut sp, n_children);
        sp.finish(r);
        ports.map(Some)
    } else {
        if serial_given {
            r.problem(&sp.span(), "backend.serial", "[backend.serial] is used with kind = \"serial\" only");
        }
        Some(None)
    };
    let scene = b.optional(r, "scene", |r, v, f| {
        let name = r.choice(v, f, &cps::geom::BUILTIN_SCENES)?;
        match cps::geom::builtin(name.get_ref()) {
            Ok(scene) => Some((name.into_inner(), scene)),
            Err(e) => {
                r.problem(&name.span(), f, e.to_string());
                None
            }
        }
    });
    let scene_file = b.optional(r, "scene_file", |r, v, f| {
        let name = r.string(v, f)?;
        let written = PathBuf::from(name.get_ref());
        let path = match scene_override {
            Some(p) => p.to_path_buf(),
            None => r.source.file.parent().unwrap_or(Path::new("")).join(&written),
        };
        let text = match std::fs::read_to_string(&path) {
            Ok(text) => text,
            Err(e) => {
                r.problem(&name.span(), f, format!("cannot read scene file {}: {e}", path.display()));
                return None;
            }
        };
        match cps::geom::parse_scene_toml(&text) {
            Ok(scene) => {
                let span = name.span();
                Some((name.into_inner(), path, text, scene, span))
            }
            Err(e) => {
                r.problem(&name.span(), f, format!("scene file {}: {e}", path.display()));
                None
            }
        }
    });
    if b.has("scene") && b.has("scene_file") {
        let span = b.get("scene_file").map_or(b.span(), |v| v.span());
        r.problem(&span, "backend.scene_file", "give either scene or scene_file, not both");
    }
    let seed = b.optional(r, "seed", |r, v, f| r.integer_in(v, f, 0, 1 << 53));
    let retries = b.optional(r, "max_retries", |r, v, f| r.integer_in(v, f, 0, 100));
    let delay = b.optional(r, "retry_delay_s", within(0.0, 3600.0));
    let odo_scale = b.optional(r, "odometry_scale_error_percent", within(-50.0, 50.0));
    let odo_sigma_d = b.optional(r, "odometry_sigma_distance_mm_per_sqrt_m", within(0.0, 1000.0));
    let odo_drift = b.optional(r, "odometry_heading_drift_mrad_per_m", within(-1000.0, 1000.0));
    let odo_sigma_h = b.optional(r, "odometry_sigma_heading_mrad_per_sqrt_m", within(0.0, 1000.0));
    let terrain = b.optional(r, "terrain_tilt_sigma_deg", within(0.0, 10.0));
    let table_span = b.span();
    b.finish(r);

    kind?;
    let (scene, scene_file) = (scene?, scene_file?);
    let d = scanner::sim::OdometryError::default();
    let odometry = scanner::sim::OdometryError {
        scale_error: odo_scale?.map_or(d.scale_error, |p| p / 100.0),
        sigma_distance_m_per_sqrt_m: odo_sigma_d?.map_or(d.sigma_distance_m_per_sqrt_m, |v| v / 1e3),
        heading_drift_rad_per_m: odo_drift?.map_or(d.heading_drift_rad_per_m, |v| v / 1e3),
        sigma_heading_rad_per_sqrt_m: odo_sigma_h?.map_or(d.sigma_heading_rad_per_sqrt_m, |v| v / 1e3),
        terrain_tilt_sigma_rad: terrain?.map_or(d.terrain_tilt_sigma_rad, f64::to_radians),
    };
    let (name, model, file, span) = match (scene_file, scene) {
        (Some((written, path, text, model, span)), _) => (written, model, Some((path, text)), Some(span)),
        (None, Some((name, model))) => (name, model, None, None),
        (None, None) => {
            let model = match cps::geom::builtin("hall") {
                Ok(model) => model,
                Err(e) => {
                    r.problem(&table_span, "backend.scene", e.to_string());
                    return None;
                }
            };
            ("hall".to_string(), model, None, None)
        }
    };
    let backend = Backend {
        serial: serial?,
        scene: name,
        scene_model: Arc::new(model),
        scene_file: file,
        given,
        seed: seed?.unwrap_or(1),
        max_retries: retries?.map_or(2, |n| n as u32),
        retry_delay_s: delay?.unwrap_or(0.5),
        odometry,
    };
    Some((backend, span))
}

/// `[backend.serial]`: the instruments' ports and line settings.
pub(super) fn read_serial(r: &mut Reader<'_>, t: &mut Table<'_, '_>, children: Option<usize>) -> Option<SerialPorts> {
    let port = |r: &mut Reader<'_>, v: &Raw<'_>, f: &str| {
        let p = r.string(v, f)?;
        if p.get_ref().trim().is_empty() {
            r.problem(&p.span(), f, "an empty port path; expected e.g. \"/dev/ttyUSB0\"");
            return None;
        }
        Some(p.into_inner())
    };
    let baud = |choices: &'static [u64]| {
        move |r: &mut Reader<'_>, v: &Raw<'_>, f: &str| {
            let b = r.integer_in(v, f, 1, 4_000_000)?;
            if !choices.is_empty() && !choices.contains(&b) {
                r.problem(&v.span(), f, format!("{b} Bd; expected one of {choices:?}"));
                return None;
            }
            Some(b as u32)
        }
    };
    let expected_ts = "the total station's port, e.g. \"/dev/ttyUSB0\"";
    let total_station = match children {
        Some(n) if n > 0 => t.required(r, "total_station", expected_ts, port).map(Some),
        _ => t.optional(r, "total_station", port),
    };
    let total_station_baud = t.optional(r, "total_station_baud", baud(&[]));
    let ts_timeout = t.optional(r, "total_station_timeout_s", |r, v, f| {
        r.number_in(v, f, 0.0, false, Some(600.0)).map(At::into_inner)
    });
    let tilt = t.required(r, "tilt", "the tilt sensor's port", port);
    let tilt_baud = t.optional(r, "tilt_baud", baud(&[]));
    let tilt_rate =
        t.optional(r, "tilt_rate_hz", |r, v, f| r.number_in(v, f, 0.0, false, Some(1000.0)).map(At::into_inner));
    let scanner = t.required(r, "scanner", "the LMS-2xx's port", port);
    let scanner_baud = t.optional(r, "scanner_baud", baud(&[9600, 19200, 38400, 500_000]));
    let continuous = t.optional(r, "scanner_continuous", |r, v, f| r.boolean(v, f));
    let head = t.required(r, "head", "the scan head's port", port);
    let drives = t.required(r, "drives", "the drives' ports, the parent's first", |r, v, f| {
        let list = r.array(v, f, port)?;
        let n = 1 + children.unwrap_or(0);
        if list.len() != n {
            let got = list.len();
            r.problem(&v.span(), f, format!("{got} ports; expected {n}: the parent's, then one per child in order"));
            return None;
        }
        Some(list)
    });
    let robot_baud = t.optional(r, "robot_baud", baud(&[]));
    let move_timeout =
        t.optional(r, "move_timeout_s", |r, v, f| r.number_in(v, f, 0.0, false, Some(3600.0)).map(At::into_inner));
    Some(SerialPorts {
        total_station: total_station?,
        total_station_baud: total_station_baud?.unwrap_or(9600),
        total_station_timeout_s: ts_timeout?.unwrap_or(5.0),
        tilt: tilt?,
        tilt_baud: tilt_baud?.unwrap_or(9600),
        tilt_rate_hz: tilt_rate?.unwrap_or(10.0),
        scanner: scanner?,
        scanner_baud: scanner_baud?.unwrap_or(38400),
        scanner_continuous: continuous?.unwrap_or(false),
        head: head?,
        drives: drives?,
        robot_baud: robot_baud?.unwrap_or(115_200),
        move_timeout_s: move_timeout?.unwrap_or(120.0),
    })
}

/// `[scan]` and the span of its `stations`.
pub(super) fn read_scan(r: &mut Reader<'_>, root: &mut Table<'_, '_>) -> Option<(ScanPlan, Option<Range<usize>>)> {
    let mut sc = root.table(r, "scan");
    let every = sc.optional(r, "every_n_stations", |r, v, f| r.integer_in(v, f, 0, 1_000_000));
    let slices = sc.optional(r, "slices", |r, v, f| r.integer_in(v, f, 2, 100_000));
    let resolution = sc.optional(r, "resolution_deg", |r, v, f| {
        let x = r.number(v, f)?;
        use scanner::sim::LmsResolution::{Half, One, Quarter};
        match *x.get_ref() {
            1.0 => Some(One),
            0.5 => Some(Half),
            0.25 => Some(Quarter),
            other => {
                r.problem(&x.span(), f, format!("value {other} is not an LMS resolution; expected 1, 0.5 or 0.25"));
                None
            }
        }
    });
    let lever = sc.optional(r, "body_from_head_m", |r, v, f| r.point3(v, f).map(|p| Vector3::from(*p.get_ref())));
    let head = sc.optional(r, "head", |r, v, f| {
        let h = r.choice(v, f, &["rotating-table", "pitching"])?;
        Some(if h.get_ref() == "pitching" {
            scanner::HeadKind::PitchingMount
        } else {
            scanner::HeadKind::RotatingTable
        })
    });
    let listed = sc.optional(r, "stations", |r, v, f| {
        let list = r.array(v, f, |r, e, f| r.integer_in(e, f, 0, 1_000_000).map(|k| k as usize))?;
        if list.windows(2).any(|w| w[1] <= w[0]) {
            r.problem(&v.span(), f, "expected station indices in ascending order, each once");
            return None;
        }
        Some((list, v.span()))
    });
    if sc.has("stations") && sc.has("every_n_stations") {
        let span = sc.get("stations").map_or(sc.span(), |v| v.span());
        r.problem(&span, "scan.stations", "give either stations or every_n_stations, not both");
    }
    sc.finish(r);
    let d = ScanPlan::default();
    let listed = listed?;
    let span = listed.as_ref().map(|(_, span)| span.clone());
    let scan = ScanPlan {
        every_n_stations: every?.map_or(d.every_n_stations, |n| n as usize),
        stations: listed.map(|(list, _)| list),
        slices: slices?.map_or(d.slices, |n| n as usize),
        resolution: resolution?.unwrap_or(d.resolution),
        body_from_head_m: lever?.unwrap_or(d.body_from_head_m),
        head: head?.unwrap_or(d.head),
    };
    Some((scan, span))
}

/// `[fusion]`.
pub(super) fn read_fusion(r: &mut Reader<'_>, root: &mut Table<'_, '_>, solo: bool) -> Option<FusionPlan> {
    let mut fu = root.table(r, "fusion");
    let mode = fu.optional(r, "mode", |r, v, f| {
        let m = r.choice(v, f, &FUSION_MODES)?;
        let mode = FusionMode::from_name(m.get_ref())?;
        if mode == FusionMode::CpsIcp && solo {
            r.problem(&m.span(), f, "cps-icp needs CPS poses, but the team has no children; expected direct or icp");
            return None;
        }
        Some(mode)
    });
    let voxel = fu.optional(r, "voxel_m", positive_at_most(10.0));
    let max_corr = fu.optional(r, "max_correspondence_m", positive_at_most(100.0));
    let fine_corr = fu.optional(r, "fine_correspondence_m", |r, v, f| {
        r.number_in(v, f, 0.0, false, Some(100.0)).map(|x| (*x.get_ref(), x.span()))
    });
    let icp_iterations = fu.optional(r, "max_iterations", |r, v, f| r.integer_in(v, f, 1, 10_000));
    let huber = fu.optional(r, "huber_m", within(0.0, 10.0));
    let min_pairs = fu.optional(r, "min_pairs", |r, v, f| r.integer_in(v, f, 6, 100_000_000));
    let partners = fu.optional(r, "max_partners", |r, v, f| r.integer_in(v, f, 1, 1000));
    let variance_factor = fu.optional(r, "icp_variance_factor", positive_at_most(1e6));
    let degeneracy = fu.optional(r, "degeneracy_ratio", within(0.0, 0.1));
    let line = fu.optional(r, "line_ratio", |r, v, f| {
        r.number_in(v, f, 0.0, true, Some(0.99)).map(|x| (*x.get_ref(), x.span()))
    });
    let corner = fu.optional(r, "corner_ratio", within(0.0, 1.0));
    let queue = fu.optional(r, "max_matches_per_scan", |r, v, f| r.integer_in(v, f, 1, 1_000_000));
    let fd = FusionPlan::default();
    let (max_corr, fine_corr) = (max_corr?, fine_corr?);
    // (A degeneracy_ratio that did not read is reported as such, and
    // line_ratio is not checked against it.)
    let no_degeneracy = degeneracy.is_some_and(|d| d.unwrap_or(fd.degeneracy_ratio) == 0.0);
    let line = line.and_then(|line| match line {
        Some((line, span)) if line > 0.0 && no_degeneracy => {
            let message =
                format!("value {line} judges the blind directions; expected degeneracy_ratio above 0 with it");
            r.problem(&span, "fusion.line_ratio", message);
            None
        }
        Some((line, _)) => Some(line),
        None if no_degeneracy => Some(fd.line_ratio),
        None => Some(crate::mission::DEFAULT_LINE_RATIO),
    });
    let coarse = max_corr.unwrap_or(fd.max_correspondence_m);
    let fine = match fine_corr {
        Some((fine, span)) if fine > coarse => {
            let message = format!("value {fine} is out of range; expected ≤ max_correspondence_m = {coarse}");
            r.problem(&span, "fusion.fine_correspondence_m", message);
            None
        }
        Some((fine, _)) => Some(fine),
        None => Some(fd.fine_correspondence_m.min(coarse)),
    };
    fu.finish(r);
    Some(FusionPlan {
        mode: mode?.unwrap_or(fd.mode),
        voxel_m: voxel?.unwrap_or(fd.voxel_m),
        max_correspondence_m: coarse,
        fine_correspondence_m: fine?,
        max_iterations: icp_iterations?.map_or(fd.max_iterations, |n| n as usize),
        huber_m: huber?.unwrap_or(fd.huber_m),
        min_pairs: min_pairs?.map_or(fd.min_pairs, |n| n as usize),
        max_partners: partners?.map_or(fd.max_partners, |n| n as usize),
        icp_variance_factor: variance_factor?.unwrap_or(fd.icp_variance_factor),
        degeneracy_ratio: degeneracy?.unwrap_or(fd.degeneracy_ratio),
        line_ratio: line?,
        corner_ratio: corner?.unwrap_or(fd.corner_ratio),
        max_matches_per_scan: queue?.map_or(fd.max_matches_per_scan, |n| n as usize),
    })
}

/// `[pipe]`, when given.
pub(super) fn read_pipe_table(r: &mut Reader<'_>, root: &mut Table<'_, '_>) -> Option<Option<PipePlan>> {
    if !root.has("pipe") {
        return Some(None);
    }
    let mut t = root.table(r, "pipe");
    let pipe = read_pipe(r, &mut t);
    t.finish(r);
    pipe.map(Some)
}

pub(super) fn read_pipe(r: &mut Reader<'_>, t: &mut Table<'_, '_>) -> Option<PipePlan> {
    let end = |r: &mut Reader<'_>, v: &Raw<'_>, f: &str| {
        r.point3(v, f).map(|p| (nalgebra::Point3::from(*p.get_ref()), p.span()))
    };
    let from = t.required(r, "axis_from_m", "one end of the nominal pipe axis, [x, y, z] in the world frame", end);
    let to = t.required(r, "axis_to_m", "the other end of the nominal pipe axis, [x, y, z]", end);
    let radius = t.required(r, "radius_m", "the nominal inner radius (m)", positive_at_most(100.0));
    let threshold = t.optional(r, "threshold_m", positive_at_most(10.0));
    let link = t.optional(r, "link_m", positive_at_most(10.0));
    let min_points = t.optional(r, "min_points", |r, v, f| r.integer_in(v, f, 1, 100_000_000));
    let (from, to) = (from?, to?);
    if (to.0 - from.0).norm() < 1e-3 {
        let message = format!("the axis ends {} and {} coincide; expected two points ≥ 1 mm apart", from.0, to.0);
        r.problem(&to.1, "pipe.axis_to_m", message);
        return None;
    }
    Some(PipePlan {
        nominal: fusion::pipe::Pipe { a: from.0, b: to.0, radius_m: radius? },
        threshold_m: threshold?.unwrap_or(0.02),
        link_m: link?.unwrap_or(0.05),
        min_points: min_points?.map_or(20, |n| n as usize),
    })
}
