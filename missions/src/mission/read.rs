//! Reading a mission file: TOML with spans → a validated [`Mission`], one
//! function per table, every problem collected (file:line:column) before
//! anything is refused.

use std::ops::Range;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use cps::{DistanceErrorModel, Instrument, RAD_PER_ARCSEC};
use nalgebra::{Matrix4, Point3, Vector3, Vector4};
use scanner::io::Crs;
use toml::Spanned;
use toml::de::{DeTable, DeValue};

use super::diagnostics::{Diagnostic, Diagnostics, Source};
use super::reader::{At, Reader, Table};
use super::{
    Acceptance, Backend, Control, ControlAt, FUSION_MODES, FusionMode, FusionPlan, Mission, MissionError,
    OUTPUT_FORMATS, Output, PipePlan, Plan, ScanPlan, Search, SerialPorts, Spans,
};

/// A raw TOML value with its span.
type Raw<'i> = Spanned<DeValue<'i>>;

impl Mission {
    /// Reads and validates a mission file.
    pub fn load(path: &Path) -> Result<Self, MissionError> {
        let text = std::fs::read_to_string(path)
            .map_err(|source| MissionError::Io { file: path.display().to_string(), source })?;
        Self::parse(Source::new(path, text))
    }

    /// Validates a mission from its text.
    pub fn parse(source: Source) -> Result<Self, MissionError> {
        parse(source, None)
    }

    /// Reads and validates a mission file whose `scene_file`, if it has one,
    /// is read from `scene_file` instead (a run directory's copy).
    pub fn load_with_scene(path: &Path, scene_file: &Path) -> Result<Self, MissionError> {
        let text = std::fs::read_to_string(path)
            .map_err(|source| MissionError::Io { file: path.display().to_string(), source })?;
        parse(Source::new(path, text), Some(scene_file))
    }
}

/// Validates a mission; `scene_file` overrides where its `scene_file` is read.
fn parse(source: Source, scene_file: Option<&Path>) -> Result<Mission, MissionError> {
    let invalid = |source: &Source, problems: Vec<Diagnostic>| MissionError::Invalid {
        file: source.file.display().to_string(),
        problems: Diagnostics(problems),
    };
    let doc = match DeTable::parse(&source.text) {
        Ok(doc) => doc,
        Err(e) => {
            let span = e.span().unwrap_or(0..0);
            let message = format!("invalid TOML: {}", e.message());
            let d = source.diagnostic(&span, "", message);
            return Err(invalid(&source, vec![d]));
        }
    };
    let mut r = Reader::new(&source);
    let mut root = Table::root(&doc);
    let mission = read_mission(&mut r, &mut root, scene_file);
    root.finish(&mut r);
    match mission {
        Some(mission) if r.problems.is_empty() => Ok(mission),
        _ => Err(invalid(&source, r.problems)),
    }
}

/// The whole file, table by table.
fn read_mission(r: &mut Reader<'_>, root: &mut Table<'_, '_>, scene_override: Option<&Path>) -> Option<Mission> {
    let name = read_name(r, root);
    let team = read_team(r, root);
    let n_children = team.as_ref().map(|(children, _)| children.len());
    let solo = n_children == Some(0);
    let total_station = read_instruments(r, root, solo);
    let plan = read_plan_table(r, root, n_children);
    let acceptance = read_acceptance(r, root);
    let backend = read_backend(r, root, n_children, scene_override);
    let scan = read_scan(r, root);
    let fusion = read_fusion(r, root, solo);
    let output = read_output(r, root);
    let crs = read_site(r, root, name.as_deref());
    let pipe = read_pipe_table(r, root);
    let control = read_control(r, root);

    let (children, footprint) = team?;
    let (mut plan, mut spans) = plan?;
    plan.footprint_radius_m = footprint.unwrap_or(plan.footprint_radius_m);
    let (backend, scene_file_span) = backend?;
    let (scan, scan_stations_span) = scan?;
    spans.scene_file = scene_file_span;
    spans.scan_stations = scan_stations_span;
    let control = control?;
    if !control.is_empty() && total_station.as_ref().is_some_and(Option::is_none) {
        r.problem(
            &control[0].1,
            "control[0]",
            "control points are sighted by the total station, and a robot alone has none",
        );
        return None;
    }
    // A control prism stands in the free space the team works in (where
    // the route starts), not inside an object.
    let start = plan.route_m.first().copied().unwrap_or_else(Point3::origin);
    let free = backend.scene_model.enclosing(&start);
    // (Without a [backend] table the plan is checked in open space.)
    for (k, (c, span)) in control.iter().enumerate().filter(|_| backend.given) {
        let around = backend.scene_model.enclosing(&c.position_m);
        let at = c.position_m.coords.as_slice();
        let message = if let Some(&o) = around.iter().find(|o| !free.contains(o)) {
            let object = backend.scene_model.object_name(o);
            format!(
                "control point \"{}\" at {at:?} lies inside \"{object}\"; expected it in the free space of the route",
                c.name
            )
        } else if let Some(&o) = free.iter().find(|o| !around.contains(o)) {
            let object = backend.scene_model.object_name(o);
            format!(
                "control point \"{}\" at {at:?} lies outside \"{object}\", where the route starts; expected it in the free space of the route",
                c.name
            )
        } else {
            continue;
        };
        r.problem(span, &format!("control[{k}].position_m"), message);
    }
    spans.control = control.iter().map(|(_, span)| span.clone()).collect();
    Some(Mission {
        source: r.source.clone(),
        name: name?,
        children,
        total_station: total_station?,
        plan,
        acceptance: acceptance?,
        backend,
        scan,
        fusion: fusion?,
        output: output?,
        crs: crs?,
        pipe: pipe?,
        control: control.into_iter().map(|(c, _)| c).collect(),
        spans,
    })
}

/// The most children a team may have (each adds three unknowns to every
/// fix's state).
pub const MAX_CHILDREN: usize = 32;

/// The most control points a mission may list (each adds three unknowns
/// to every fix's state, which is dense: 1,000 take 1.5 s to validate and
/// 350 MB).
pub const MAX_CONTROL: usize = 1000;

/// The longest mission name, bytes (it names the run directory).
pub const MAX_NAME_BYTES: usize = 100;

/// `[mission]`.
fn read_name(r: &mut Reader<'_>, root: &mut Table<'_, '_>) -> Option<String> {
    let mut t = root.table(r, "mission");
    let name = t.required(r, "name", "a mission name (string)", |r, v, f| {
        let s = r.string(v, f)?;
        if s.get_ref().trim().is_empty() {
            r.problem(&s.span(), f, "expected a non-empty name");
            return None;
        }
        // The name is the default run directory's (`runs/<name>/`): a name,
        // never a path.
        let n = s.get_ref();
        let problem = if n.len() > MAX_NAME_BYTES {
            Some(format!("{} bytes long; expected at most {MAX_NAME_BYTES}", n.len()))
        } else if let Some(c) =
            n.chars().find(|c| matches!(c, '/' | '\\') || c.is_control() || scanner::io::is_bidi_control(*c))
        {
            // (Bidirectional controls: issue 34, S13 — a name that reads
            // as another names `runs/<name>/`.)
            Some(format!(
                "\"{}\" holds {c:?}; expected a name without path separators, control or bidirectional characters",
                n.escape_debug()
            ))
        } else if n == "." || n == ".." || n != n.trim() {
            Some(format!("\"{n}\"; expected a name, not a path (no \".\" or \"..\", no leading or trailing spaces)"))
        } else {
            None
        };
        if let Some(message) = problem {
            r.problem(&s.span(), f, message);
            return None;
        }
        Some(s.into_inner())
    });
    t.finish(r);
    name
}

/// `[team]`: the children's names and the footprint radius.
fn read_team(r: &mut Reader<'_>, root: &mut Table<'_, '_>) -> Option<(Vec<String>, Option<f64>)> {
    let mut t = root.table(r, "team");
    let children = t.required(r, "children", "the child robots' names, e.g. [\"c1\", \"c2\"]", read_children);
    let footprint =
        t.optional(r, "footprint_radius_m", |r, v, f| r.number_in(v, f, 0.0, false, Some(10.0)).map(At::into_inner));
    t.finish(r);
    Some((children?, footprint?))
}

/// `[instruments]`: the total station (none for a robot alone).
fn read_instruments(r: &mut Reader<'_>, root: &mut Table<'_, '_>, solo: bool) -> Option<Option<Instrument>> {
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

/// `[plan]` (with `[plan.search]`).
fn read_plan_table(r: &mut Reader<'_>, root: &mut Table<'_, '_>, n_children: Option<usize>) -> Option<(Plan, Spans)> {
    let mut t = root.table(r, "plan");
    let plan = read_plan(r, &mut t, n_children);
    t.finish(r);
    plan
}

/// `[acceptance]`.
fn read_acceptance(r: &mut Reader<'_>, root: &mut Table<'_, '_>) -> Option<Acceptance> {
    let mut t = root.table(r, "acceptance");
    let max_xy = t.optional(r, "max_final_sigma_xy_m", positive);
    let max_err = t.optional(r, "max_station_error_m", positive);
    let max_station = t.optional(r, "max_station_sigma_xy_m", positive);
    t.finish(r);
    Some(Acceptance {
        max_final_sigma_xy_m: max_xy?,
        max_station_error_m: max_err?,
        max_station_sigma_xy_m: max_station?,
    })
}

/// `[backend]` (with `[backend.serial]`) and the span of its `scene_file`.
fn read_backend(
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

/// `[scan]` and the span of its `stations`.
fn read_scan(r: &mut Reader<'_>, root: &mut Table<'_, '_>) -> Option<(ScanPlan, Option<Range<usize>>)> {
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
fn read_fusion(r: &mut Reader<'_>, root: &mut Table<'_, '_>, solo: bool) -> Option<FusionPlan> {
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
    let fd = FusionPlan::default();
    let (max_corr, fine_corr) = (max_corr?, fine_corr?);
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
    })
}

/// `[output]`.
fn read_output(r: &mut Reader<'_>, root: &mut Table<'_, '_>) -> Option<Output> {
    let mut o = root.table(r, "output");
    let formats = o.optional(r, "formats", |r, v, f| {
        let mut seen = Vec::new();
        r.array(v, f, |r, e, f| {
            let format = r.choice(e, f, &OUTPUT_FORMATS)?.into_inner();
            // Two writers of one file: the survey ran, then no report.
            if seen.contains(&format) {
                r.problem(&e.span(), f, format!("\"{format}\" is listed twice: expected each format once"));
                return None;
            }
            seen.push(format.clone());
            Some(format)
        })
    });
    let rerun = o.optional(r, "rerun", |r, v, f| r.boolean(v, f));
    let ros2_bag = o.optional(r, "ros2_bag", |r, v, f| r.boolean(v, f));
    o.finish(r);
    Some(Output {
        formats: formats?.unwrap_or_else(|| vec!["ply".into()]),
        rerun: rerun?.unwrap_or(true),
        ros2_bag: ros2_bag?.unwrap_or(false),
    })
}

/// `[site]`: the coordinate reference system of the mission's coordinates
/// — `crs` (`EPSG:NNNN` or a WKT definition) or `local_frame` (the name of
/// a local engineering frame); without either, a local frame named after
/// the mission.
fn read_site(r: &mut Reader<'_>, root: &mut Table<'_, '_>, mission: Option<&str>) -> Option<Crs> {
    let default = || Crs::local(&format!("{} local frame", mission.unwrap_or("cps-survey")));
    if !root.has("site") {
        return Some(default());
    }
    let mut t = root.table(r, "site");
    let crs = t.optional(r, "crs", |r, v, f| {
        let s = r.string(v, f)?;
        Crs::parse(s.get_ref()).map_err(|message| r.problem(&s.span(), f, message)).ok().map(|c| (c, s.span()))
    });
    let local = t.optional(r, "local_frame", |r, v, f| {
        let s = r.string(v, f)?;
        if s.get_ref().trim().is_empty() {
            r.problem(&s.span(), f, "expected the local frame's name, found an empty string");
            return None;
        }
        // It goes into file headers (a newline ended a PLY header early).
        Crs::check_local_name(s.get_ref().trim()).map_err(|message| r.problem(&s.span(), f, message)).ok()?;
        Some(Crs::local(s.get_ref().trim()))
    });
    t.finish(r);
    match (crs?, local?) {
        (Some((_, span)), Some(_)) => {
            r.problem(&span, "site.crs", "both `crs` and `local_frame` given: expected one (a local frame has no CRS)");
            None
        }
        (Some((crs, _)), None) => Some(crs),
        (None, Some(local)) => Some(local),
        (None, None) => Some(default()),
    }
}

/// `[pipe]`, when given.
fn read_pipe_table(r: &mut Reader<'_>, root: &mut Table<'_, '_>) -> Option<Option<PipePlan>> {
    if !root.has("pipe") {
        return Some(None);
    }
    let mut t = root.table(r, "pipe");
    let pipe = read_pipe(r, &mut t);
    t.finish(r);
    pipe.map(Some)
}

/// A number > 0.
fn positive(r: &mut Reader<'_>, v: &Raw<'_>, f: &str) -> Option<f64> {
    r.number_in(v, f, 0.0, false, None).map(At::into_inner)
}

/// Any finite number.
fn number(r: &mut Reader<'_>, v: &Raw<'_>, f: &str) -> Option<f64> {
    r.number(v, f).map(At::into_inner)
}

/// A number ≥ 0.
fn non_negative(r: &mut Reader<'_>, v: &Raw<'_>, f: &str) -> Option<f64> {
    r.number_in(v, f, 0.0, true, None).map(At::into_inner)
}

/// A number in [min, max].
fn within(min: f64, max: f64) -> impl Fn(&mut Reader<'_>, &Raw<'_>, &str) -> Option<f64> {
    move |r, v, f| r.number_in(v, f, min, true, Some(max)).map(At::into_inner)
}

/// A number in (0, max].
fn positive_at_most(max: f64) -> impl Fn(&mut Reader<'_>, &Raw<'_>, &str) -> Option<f64> {
    move |r, v, f| r.number_in(v, f, 0.0, false, Some(max)).map(At::into_inner)
}

fn read_pipe(r: &mut Reader<'_>, t: &mut Table<'_, '_>) -> Option<PipePlan> {
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

fn read_children(r: &mut Reader<'_>, v: &Raw<'_>, field: &str) -> Option<Vec<String>> {
    let names = r.array(v, field, |r, e, f| r.string(e, f))?;
    if names.len() > MAX_CHILDREN {
        let message = format!("{} children; expected at most {MAX_CHILDREN}", names.len());
        r.problem(&v.span(), field, message);
        return None;
    }
    if names.len() == 1 {
        let message = "the team has 1 child; a parent fix needs at least 2 (or none: a robot alone, by odometry)";
        r.problem(&v.span(), field, message);
        return None;
    }
    let mut ok = true;
    for (k, n) in names.iter().enumerate() {
        if n.get_ref().trim().is_empty() {
            r.problem(&n.span(), &format!("{field}[{k}]"), "expected a non-empty name");
            ok = false;
        } else if names[..k].iter().any(|o| o.get_ref() == n.get_ref()) {
            r.problem(&n.span(), &format!("{field}[{k}]"), format!("duplicate child name \"{}\"", n.get_ref()));
            ok = false;
        }
    }
    ok.then(|| names.into_iter().map(At::into_inner).collect())
}

fn read_total_station(r: &mut Reader<'_>, t: &mut Table<'_, '_>) -> Option<Instrument> {
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

fn read_plan(r: &mut Reader<'_>, t: &mut Table<'_, '_>, n_children: Option<usize>) -> Option<(Plan, Spans)> {
    let route = t.required(r, "route_m", "parent waypoints [[x, y, z], ...] in metres (at least 2)", |r, v, f| {
        let pts = r.array(v, f, |r, e, f| r.point3(e, f))?;
        if pts.len() < 2 {
            r.problem(&v.span(), f, format!("route_m has {} waypoint(s); expected at least 2", pts.len()));
            return None;
        }
        let mut ok = true;
        for k in 1..pts.len() {
            let (a, b) = (pts[k - 1].get_ref(), pts[k].get_ref());
            if (0..3).map(|i| (a[i] - b[i]).powi(2)).sum::<f64>().sqrt() <= 1e-9 {
                r.problem(
                    &pts[k].span(),
                    &format!("{f}[{k}]"),
                    "repeats the previous waypoint; expected a segment of non-zero length",
                );
                ok = false;
            }
        }
        ok.then_some(pts)
    });
    let stride = t.required(r, "stride_m", "the distance between parent stations in metres (> 0)", |r, v, f| {
        r.number_in(v, f, 0.0, false, None).map(|x| (*x.get_ref(), x.span()))
    });
    let read_formation = |r: &mut Reader<'_>, v: &Raw<'_>, f: &str| {
        let offsets = r.array(v, f, |r, e, f| r.point3(e, f))?;
        if let Some(n) = n_children
            && offsets.len() != n
        {
            r.problem(
                &v.span(),
                f,
                format!("{} offsets given; expected one per child ({n}, as in team.children)", offsets.len()),
            );
            return None;
        }
        for (k, o) in offsets.iter().enumerate() {
            if o.get_ref()[0].hypot(o.get_ref()[1]) < 1e-6 {
                r.problem(
                    &o.span(),
                    &format!("{f}[{k}]"),
                    "the child stands vertically above or below the parent; expected a horizontal offset",
                );
                return None;
            }
        }
        Some(offsets)
    };
    let n = n_children.unwrap_or(0);
    let formation = if n_children == Some(0) {
        for key in ["formation_m", "formation"] {
            if let Some(v) = t.get(key) {
                r.problem(&v.span(), &format!("plan.{key}"), "the team has no children to place; remove it");
            }
        }
        Some(Formation::Listed(Vec::new(), 0..0))
    } else if t.has("formation") {
        if let Some(v) = t.get("formation_m") {
            r.problem(&v.span(), "plan.formation_m", "give either formation_m or formation, not both");
        }
        let span = t.get("formation").map_or(t.span(), |v| v.span());
        let mut g = t.table(r, "formation");
        let kind = read_formation_kind(r, &mut g);
        g.finish(r);
        kind.map(|(kind, up)| Formation::Generated(kind, up, span))
    } else {
        t.required(
            r,
            "formation_m",
            "one offset [forward, left, up] in metres per child (or a generated formation = { kind = ... })",
            |r, v, f| read_formation(r, v, f).map(|o| Formation::Listed(o, v.span())),
        )
    };
    let start_sigma = t.optional(r, "start_sigma_m", |r, v, f| {
        let p = r.point3(v, f)?;
        let mut ok = true;
        for (i, x) in p.get_ref().iter().enumerate() {
            if *x < 0.0 {
                r.problem(&p.span(), &format!("{f}[{i}]"), format!("value {x} is out of range; expected ≥ 0"));
                ok = false;
            }
        }
        ok.then(|| *p.get_ref())
    });
    let start_heading =
        t.optional(r, "start_sigma_heading_arcsec", |r, v, f| r.number_in(v, f, 0.0, true, None).map(At::into_inner));
    let strategy_v =
        t.optional(r, "strategy", |r, v, f| r.choice(v, f, &planner::STRATEGIES).map(|s| (s.into_inner(), v.span())));
    let hops_v = t.optional(r, "hops", |r, v, f| r.integer_in(v, f, 1, 1000).map(|h| (h as usize, v.span())));
    let track = t.optional(r, "track", |r, v, f| r.boolean(v, f));
    let slope = t.optional(r, "max_slope_deg", |r, v, f| r.number_in(v, f, 0.0, false, Some(90.0)).map(At::into_inner));
    let control_at = t.optional(r, "control_at", read_control_at);
    let mut st = t.table(r, "search");
    let strategies = st.optional(r, "strategies", |r, v, f| {
        let list = r.array(v, f, |r, e, f| r.choice(e, f, &planner::STRATEGIES).map(At::into_inner))?;
        if list.is_empty() {
            r.problem(&v.span(), f, format!("expected at least one of {}", planner::STRATEGIES.join(", ")));
            return None;
        }
        Some(list)
    });
    let max_hops = st.optional(r, "max_hops", |r, v, f| r.integer_in(v, f, 2, 100).map(|h| h as usize));
    let strides = st.optional(r, "strides_m", |r, v, f| {
        let list = r.array(v, f, |r, e, f| r.number_in(e, f, 0.0, false, None).map(At::into_inner))?;
        if list.is_empty() {
            r.problem(&v.span(), f, "expected at least one stride");
            return None;
        }
        Some(list)
    });
    let sight = st.optional(r, "max_sight_line_m", |r, v, f| r.number_in(v, f, 0.0, false, None).map(At::into_inner));
    st.finish(r);
    let (strategy_v, hops_v) = (strategy_v?, hops_v?);
    let strategy = match (strategy_v.as_ref().map(|(s, _)| s.as_str()), &hops_v) {
        (Some("parent-hops"), hops) => Some(planner::Strategy::ParentHops { hops: hops.as_ref().map_or(2, |h| h.0) }),
        (_, Some((_, span))) => {
            r.problem(
                span,
                "plan.hops",
                "hops applies to strategy = \"parent-hops\" only; remove it or set the strategy",
            );
            None
        }
        _ => Some(planner::Strategy::Leapfrog),
    };
    let (route, stride, formation) = (route?, stride?, formation?);
    let (strategy, track, slope, control_at) = (strategy?, track?, slope?, control_at?);
    let s = start_sigma?.unwrap_or([0.0; 3]);
    let h = start_heading?.unwrap_or(0.0) * RAD_PER_ARCSEC;
    let (offsets, generated, offset_spans, formation_value) = match formation {
        Formation::Listed(o, span) => {
            let spans = o.iter().map(|p| p.span()).collect();
            (o.iter().map(|p| Vector3::from(*p.get_ref())).collect(), None, spans, span)
        }
        Formation::Generated(kind, up, span) => (kind.offsets(n, up), Some((kind, up)), vec![span.clone(); n], span),
    };
    let spans = Spans {
        plan: t.span(),
        route_m: route.iter().map(|p| p.span()).collect(),
        stride_m: stride.1.clone(),
        formation_m: offset_spans,
        formation_value,
        strategy: strategy_v.map(|(_, span)| span),
        hops: hops_v.map(|(_, span)| span),
        scan_stations: None,
        scene_file: None,
        control: Vec::new(),
        control_at: control_at.as_ref().map(|(_, span)| span.clone()),
    };
    let stride_m = stride.0;
    let plan = Plan {
        route_m: route.iter().map(|p| Point3::from(*p.get_ref())).collect(),
        stride_m,
        formation_m: offsets,
        formation: generated,
        start_covariance: Matrix4::from_diagonal(&Vector4::new(s[0] * s[0], s[1] * s[1], s[2] * s[2], h * h)),
        strategy,
        track: track.unwrap_or(false),
        max_slope_rad: slope.map(f64::to_radians),
        footprint_radius_m: 0.3,
        search: Search {
            strategies: strategies?.unwrap_or_else(|| planner::STRATEGIES.iter().map(|s| s.to_string()).collect()),
            max_hops: max_hops?.unwrap_or(4),
            strides_m: strides?.unwrap_or_else(|| [0.5, 0.75, 1.0, 1.25, 1.5, 2.0].map(|f| f * stride_m).to_vec()),
            max_sight_line_m: sight?.unwrap_or(f64::INFINITY),
        },
        control_at: control_at.map(|(c, _)| c).unwrap_or_default(),
    };
    Some((plan, spans))
}

/// `control_at = "every" | "start-end" | [station indices]`.
fn read_control_at(r: &mut Reader<'_>, v: &Raw<'_>, f: &str) -> Option<(ControlAt, Range<usize>)> {
    let at = match v.get_ref() {
        DeValue::Array(_) => {
            let list = r.array(v, f, |r, e, f| r.integer_in(e, f, 0, 1_000_000).map(|k| k as usize))?;
            if list.windows(2).any(|w| w[1] <= w[0]) || list.is_empty() {
                r.problem(&v.span(), f, "expected station indices in ascending order, each once, at least one");
                return None;
            }
            ControlAt::Stations(list)
        }
        DeValue::String(_) => match r.choice(v, f, &["every", "start-end"])?.get_ref().as_str() {
            "every" => ControlAt::Every,
            _ => ControlAt::StartEnd,
        },
        _ => {
            r.problem(&v.span(), f, "expected \"every\", \"start-end\" or a list of station indices");
            return None;
        }
    };
    Some((at, v.span()))
}

/// Every `[[control]]` table: name, position, σ; with the span of each
/// position.
fn read_control(r: &mut Reader<'_>, root: &mut Table<'_, '_>) -> Option<Vec<(Control, Range<usize>)>> {
    let Some(v) = root.get("control") else { return Some(Vec::new()) };
    let DeValue::Array(items) = v.get_ref() else {
        r.problem(&v.span(), "control", "expected [[control]] tables, one per control point");
        return None;
    };
    if items.len() > MAX_CONTROL {
        let message = format!("{} control points; expected at most {MAX_CONTROL}", items.len());
        r.problem(&v.span(), "control", message);
        return None;
    }
    let mut out = Vec::with_capacity(items.len());
    let mut ok = true;
    for (k, item) in items.iter().enumerate() {
        let path = format!("control[{k}]");
        let DeValue::Table(table) = item.get_ref() else {
            r.problem(&item.span(), &path, "expected a table with name, position_m and sigma_m");
            ok = false;
            continue;
        };
        let mut t = Table::element(table, item.span(), path);
        let name = t.required(r, "name", "the control point's name (string)", |r, v, f| {
            let s = r.string(v, f)?;
            if s.get_ref().trim().is_empty() {
                r.problem(&s.span(), f, "expected a non-empty name");
                return None;
            }
            Some(s.into_inner())
        });
        let position =
            t.required(r, "position_m", "its coordinates [x, y, z] in metres, the mission's frame", |r, v, f| {
                r.point3(v, f).map(|p| (Point3::from(*p.get_ref()), p.span()))
            });
        let sigma = t.optional(r, "sigma_m", |r, v, f| {
            let s = match v.get_ref() {
                DeValue::Array(_) => *r.point3(v, f)?.get_ref(),
                _ => [r.number(v, f)?.into_inner(); 3],
            };
            if s.iter().any(|x| *x < 0.0) {
                r.problem(
                    &v.span(),
                    f,
                    format!("{s:?}: expected standard deviations ≥ 0 (0 holds a coordinate fixed)"),
                );
                return None;
            }
            Some(s)
        });
        t.finish(r);
        match (name, position, sigma) {
            (Some(name), Some((position_m, span)), Some(sigma)) => {
                let s = sigma.unwrap_or([0.0; 3]);
                let covariance = nalgebra::Matrix3::from_diagonal(&Vector3::new(s[0] * s[0], s[1] * s[1], s[2] * s[2]));
                out.push((Control { name, position_m, covariance }, span));
            }
            _ => ok = false,
        }
    }
    for (k, (c, span)) in out.iter().enumerate() {
        if let Some((j, _)) = out[..k].iter().enumerate().find(|(_, (o, _))| o.name == c.name) {
            r.problem(
                span,
                &format!("control[{k}].name"),
                format!("duplicate control point name \"{}\" (also control[{j}]); expected unique names", c.name),
            );
            ok = false;
        } else if let Some((o, _)) = out[..k].iter().find(|(o, _)| (o.position_m - c.position_m).norm() < 1e-3) {
            let message =
                format!("control point \"{}\" coincides with \"{}\"; expected points ≥ 1 mm apart", c.name, o.name);
            r.problem(span, &format!("control[{k}].position_m"), message);
            ok = false;
        }
    }
    ok.then_some(out)
}

enum Formation {
    Listed(Vec<At<[f64; 3]>>, Range<usize>),
    Generated(planner::FormationKind, f64, Range<usize>),
}

/// `formation = { kind = "symmetric" | "fan" | "line", ..., up_m }`.
fn read_formation_kind(r: &mut Reader<'_>, g: &mut Table<'_, '_>) -> Option<(planner::FormationKind, f64)> {
    use planner::FormationKind;
    let kind = g.required(r, "kind", "one of \"symmetric\", \"fan\", \"line\"", |r, v, f| {
        r.choice(v, f, &["symmetric", "fan", "line"]).map(At::into_inner)
    })?;
    let num = number;
    let up = g.optional(r, "up_m", num);
    let kind = match kind.as_str() {
        "symmetric" => {
            let forward = g.required(r, "forward_m", "the children's forward offset in metres", num);
            let lateral = g.required(r, "lateral_m", "the first pair's lateral offset in metres (> 0)", positive);
            FormationKind::Symmetric { forward_m: forward?, lateral_m: lateral? }
        }
        "fan" => {
            let radius = g.required(r, "radius_m", "the children's distance from the parent in metres (> 0)", positive);
            let spread = g.required(
                r,
                "spread_deg",
                "the angle from the first to the last child in degrees (0 to 359)",
                |r, v, f| r.number_in(v, f, 0.0, false, Some(359.0)).map(At::into_inner),
            );
            FormationKind::Fan { radius_m: radius?, spread_deg: spread? }
        }
        _ => {
            let ahead = g.required(r, "ahead_m", "the first child's forward offset in metres (≠ 0)", num);
            let spacing =
                g.required(r, "spacing_m", "the distance between children along the line in metres (≠ 0)", num);
            let (ahead, spacing) = (ahead?, spacing?);
            if ahead == 0.0 || spacing == 0.0 {
                r.problem(
                    &g.span(),
                    "plan.formation",
                    "a line needs ahead_m ≠ 0 and spacing_m ≠ 0 (a child on the parent)",
                );
                return None;
            }
            FormationKind::Line { ahead_m: ahead, spacing_m: spacing }
        }
    };
    Some((kind, up?.unwrap_or(0.0)))
}

/// `[backend.serial]`: the instruments' ports and line settings.
fn read_serial(r: &mut Reader<'_>, t: &mut Table<'_, '_>, children: Option<usize>) -> Option<SerialPorts> {
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
