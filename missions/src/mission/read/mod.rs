//! Reading a mission file: TOML with spans → a validated [`Mission`], one
//! function per table, every problem collected (file:line:column) before
//! anything is refused.

use std::path::Path;

use nalgebra::Point3;
use scanner::io::Crs;
use toml::de::DeTable;

use crate::mission::diagnostics::{Diagnostic, Diagnostics, Source};
use crate::mission::reader::{At, Reader, Table};
use crate::mission::{Acceptance, Mission, MissionError, OUTPUT_FORMATS, Output};

use devices::{read_backend, read_fusion, read_instruments, read_pipe_table, read_scan};
use fields::{Raw, positive};
use plan::{read_control, read_plan_table};

mod devices;
mod fields;
mod plan;

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
