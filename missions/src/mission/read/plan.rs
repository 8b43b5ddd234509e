//! `[plan]` (route, stride, formation, strategy, control sightings,
//! `[plan.search]`) and `[[control]]`.

use std::ops::Range;

use cps::RAD_PER_ARCSEC;
use nalgebra::{Matrix4, Point3, Vector3, Vector4};
use toml::de::DeValue;

use crate::mission::reader::{At, Reader, Table};
use crate::mission::{Control, ControlAt, Plan, Search, Spans};

use super::fields::{Raw, number, positive};

/// `[plan]` (with `[plan.search]`).
pub(super) fn read_plan_table(
    r: &mut Reader<'_>,
    root: &mut Table<'_, '_>,
    n_children: Option<usize>,
) -> Option<(Plan, Spans)> {
    let mut t = root.table(r, "plan");
    let plan = read_plan(r, &mut t, n_children);
    t.finish(r);
    plan
}

/// `[plan]`'s keys: each read (every problem reported), then the plan
/// with the spans its later checks point at.
pub(super) fn read_plan(r: &mut Reader<'_>, t: &mut Table<'_, '_>, n_children: Option<usize>) -> Option<(Plan, Spans)> {
    let route = t.required(r, "route_m", "parent waypoints [[x, y, z], ...] in metres (at least 2)", read_route);
    let stride = t.required(r, "stride_m", "the distance between parent stations in metres (> 0)", |r, v, f| {
        r.number_in(v, f, 0.0, false, None).map(|x| (*x.get_ref(), x.span()))
    });
    let formation = read_formation(r, t, n_children);
    let start_sigma = t.optional(r, "start_sigma_m", read_start_sigma);
    let start_heading =
        t.optional(r, "start_sigma_heading_arcsec", |r, v, f| r.number_in(v, f, 0.0, true, None).map(At::into_inner));
    let strategy_v =
        t.optional(r, "strategy", |r, v, f| r.choice(v, f, &planner::STRATEGIES).map(|s| (s.into_inner(), v.span())));
    let hops_v = t.optional(r, "hops", |r, v, f| r.integer_in(v, f, 1, 1000).map(|h| (h as usize, v.span())));
    let track = t.optional(r, "track", |r, v, f| r.boolean(v, f));
    let slope = t.optional(r, "max_slope_deg", |r, v, f| r.number_in(v, f, 0.0, false, Some(90.0)).map(At::into_inner));
    let control_at = t.optional(r, "control_at", read_control_at);
    let search = read_search(r, t);
    let (strategy_v, hops_v) = (strategy_v?, hops_v?);
    let strategy = strategy_of(r, strategy_v.as_ref().map(|(s, _)| s.as_str()), hops_v.as_ref());
    let (route, stride, formation) = (route?, stride?, formation?);
    let (strategy, track, slope, control_at) = (strategy?, track?, slope?, control_at?);
    let s = start_sigma?.unwrap_or([0.0; 3]);
    let h = start_heading?.unwrap_or(0.0) * RAD_PER_ARCSEC;
    let n = n_children.unwrap_or(0);
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
        search: search?.with_defaults(stride_m),
        control_at: control_at.map(|(c, _)| c).unwrap_or_default(),
    };
    Some((plan, spans))
}

/// `route_m`: two or more waypoints, no segment of zero length.
fn read_route(r: &mut Reader<'_>, v: &Raw<'_>, f: &str) -> Option<Vec<At<[f64; 3]>>> {
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
}

/// The formation: none for a team without children, `formation = { … }`
/// generated, or `formation_m` listed (one horizontal offset per child).
fn read_formation(r: &mut Reader<'_>, t: &mut Table<'_, '_>, n_children: Option<usize>) -> Option<Formation> {
    let listed = |r: &mut Reader<'_>, v: &Raw<'_>, f: &str| {
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
    if n_children == Some(0) {
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
            |r, v, f| listed(r, v, f).map(|o| Formation::Listed(o, v.span())),
        )
    }
}

/// `start_sigma_m`: three σ ≥ 0.
fn read_start_sigma(r: &mut Reader<'_>, v: &Raw<'_>, f: &str) -> Option<[f64; 3]> {
    let p = r.point3(v, f)?;
    let mut ok = true;
    for (i, x) in p.get_ref().iter().enumerate() {
        if *x < 0.0 {
            r.problem(&p.span(), &format!("{f}[{i}]"), format!("value {x} is out of range; expected ≥ 0"));
            ok = false;
        }
    }
    ok.then(|| *p.get_ref())
}

/// The strategy of `strategy` and `hops` (which only parent hops take).
fn strategy_of(
    r: &mut Reader<'_>,
    strategy: Option<&str>,
    hops: Option<&(usize, Range<usize>)>,
) -> Option<planner::Strategy> {
    match (strategy, hops) {
        (Some("parent-hops"), hops) => Some(planner::Strategy::ParentHops { hops: hops.map_or(2, |h| h.0) }),
        (_, Some((_, span))) => {
            r.problem(
                span,
                "plan.hops",
                "hops applies to strategy = \"parent-hops\" only; remove it or set the strategy",
            );
            None
        }
        _ => Some(planner::Strategy::Leapfrog),
    }
}

/// `[plan.search]` as given (defaults applied once the stride is known).
struct SearchKeys {
    strategies: Option<Vec<String>>,
    max_hops: Option<usize>,
    strides_m: Option<Vec<f64>>,
    max_sight_line_m: Option<f64>,
}

impl SearchKeys {
    /// The search, with the defaults: every strategy, up to 4 hops,
    /// strides from half to twice `stride_m`, sight lines of any length.
    fn with_defaults(self, stride_m: f64) -> Search {
        Search {
            strategies: self.strategies.unwrap_or_else(|| planner::STRATEGIES.iter().map(|s| s.to_string()).collect()),
            max_hops: self.max_hops.unwrap_or(4),
            strides_m: self
                .strides_m
                .unwrap_or_else(|| [0.5, 0.75, 1.0, 1.25, 1.5, 2.0].map(|f| f * stride_m).to_vec()),
            max_sight_line_m: self.max_sight_line_m.unwrap_or(f64::INFINITY),
        }
    }
}

/// `[plan.search]`.
fn read_search(r: &mut Reader<'_>, t: &mut Table<'_, '_>) -> Option<SearchKeys> {
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
    Some(SearchKeys { strategies: strategies?, max_hops: max_hops?, strides_m: strides?, max_sight_line_m: sight? })
}

/// `control_at = "every" | "start-end" | [station indices]`.
pub(super) fn read_control_at(r: &mut Reader<'_>, v: &Raw<'_>, f: &str) -> Option<(ControlAt, Range<usize>)> {
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

/// The most control points a mission may list (each adds three unknowns
/// to every fix's state, which is dense: 1,000 take 1.5 s to validate and
/// 350 MB).
pub const MAX_CONTROL: usize = 1000;

/// Every `[[control]]` table: name, position, σ; with the span of each
/// position.
pub(super) fn read_control(r: &mut Reader<'_>, root: &mut Table<'_, '_>) -> Option<Vec<(Control, Range<usize>)>> {
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

pub(super) enum Formation {
    Listed(Vec<At<[f64; 3]>>, Range<usize>),
    Generated(planner::FormationKind, f64, Range<usize>),
}

/// `formation = { kind = "symmetric" | "fan" | "line", ..., up_m }`.
pub(super) fn read_formation_kind(r: &mut Reader<'_>, g: &mut Table<'_, '_>) -> Option<(planner::FormationKind, f64)> {
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
