//! The network adjustment of a run (`cps-survey adjust`, and at the end of
//! `run`): the journal's readings as one network ([`planner::network`]),
//! adjusted by [`cps::batch`] with its tests, the misclosures at the
//! control points, and the typed report (`adjust --json`, `report.json`'s
//! `adjustment`).
//!
//! **Misclosures.** Before the adjustment ties the route to a control
//! point, the survey and the other control points say where it is: the
//! network adjusted without that point's given coordinates (its sightings
//! kept). The misclosure of a control point is that position minus its
//! given coordinates, with the covariance of the difference (the surveyed
//! position's and the given coordinates' with the prism's centring). A
//! point without which the rest cannot hold the network (one of the two a
//! start is resected on, sighted nowhere else) has none.

use anyhow::{Context, Result, bail};
use cps::batch::{AdjustOptions, Adjustment, ScalarStats, Source};
use cps::screen::{GROSS_ANGLE_RAD, GROSS_DISTANCE_M};
use cps::{CHI2_2D_95_SQRT, ErrorEllipse, ParentPose, Reading};
use nalgebra::{Matrix2, Matrix3, Matrix4, Point3};
use planner::network::{DanceNetwork, PointId, Taken};
use serde::{Deserialize, Serialize};

use super::journal::{self, Event, MeasureKey, Phase};
use crate::mission::Mission;
use crate::planning::Planned;
use crate::planning::preanalysis::{KINDS, point_name};

/// The version of the adjustment report's shape.
pub const SCHEMA_VERSION: u32 = 1;

/// `adjust --json`, nested whole as `report.json`'s `adjustment`: it
/// carries its own header.
impl crate::view::document::Document for AdjustmentReport {
    const NAME: &'static str = "adjust";
    const VERSION: u32 = SCHEMA_VERSION;
    const SELF_VERSIONED: bool = true;
}

/// The journal's readings as the dance's network: every `measure` event in
/// the dance's reading order (checked), the stations reached (their fix's
/// pose as the approximation) — a run stopped early gives the network so
/// far.
pub fn network(
    mission: &Mission,
    planned: &Planned,
    read: &journal::Read,
    path: &std::path::Path,
) -> Result<DanceNetwork> {
    let Some(instrument) = &mission.total_station else {
        bail!("mission \"{}\" is a robot alone: there is no network of total-station readings to adjust", mission.name)
    };
    let dance = &planned.dance;
    let order = planner::network::reading_order(dance);
    let mut readings = Vec::with_capacity(order.len());
    let mut stations: Vec<ParentPose> = vec![dance.station_pose(0)];
    // The readings' keys so far, with their journal lines.
    let mut seen: Vec<(usize, MeasureKey)> = Vec::new();
    for n in &read.events {
        match &n.event {
            Event::Measure(m) if m.key.attempt > 0 => {
                // A reading measured again after a fix's field test: it
                // supersedes its earlier attempt (the one before it).
                let earlier = MeasureKey { attempt: m.key.attempt - 1, ..m.key.clone() };
                let Some(k) = seen.iter().rposition(|(_, key)| *key == earlier) else {
                    bail!(
                        "{}:{}: {} without its attempt {} before it",
                        path.display(),
                        n.line,
                        key_words(&m.key),
                        earlier.attempt
                    );
                };
                readings[k] = checked_reading(m.data.measurement().to_reading(instrument), path, n)?;
                seen[k] = (n.line, m.key.clone());
            }
            Event::Measure(m) => {
                let Some(expected) = order.get(readings.len()) else {
                    bail!("{}:{}: a measurement beyond the plan's {} readings", path.display(), n.line, order.len());
                };
                let k = &m.key;
                let matches = match *expected {
                    Taken::Placement { cycle, child, .. } => {
                        k.phase == Phase::Placement && k.cycle == cycle && k.child == Some(child)
                    }
                    Taken::Fix { cycle, child, .. } => {
                        k.phase == Phase::Fix && k.cycle == cycle && k.child == Some(child)
                    }
                    Taken::Control { cycle, control, .. } => {
                        k.phase == Phase::Control
                            && k.cycle == cycle
                            && k.control.as_deref() == Some(dance.control[control].name.as_str())
                    }
                };
                if !matches {
                    // In words, not the record's JSON and a Rust value
                    // (issue 34, U7); a reading recorded twice said so.
                    let recorded = key_words(k);
                    let planned = taken_words(expected, &dance.control);
                    if let Some((line, _)) = seen.iter().find(|(_, key)| key == k) {
                        bail!(
                            "{}:{}: {recorded} again (line {line} recorded it): each reading once, the plan's next is {planned}",
                            path.display(),
                            n.line
                        );
                    }
                    bail!(
                        "{}:{}: the journal records {recorded} where the plan takes {planned}: the journal belongs to another plan",
                        path.display(),
                        n.line,
                    );
                }
                seen.push((n.line, k.clone()));
                readings.push(checked_reading(m.data.measurement().to_reading(instrument), path, n)?);
            }
            Event::Fix(f) => {
                let pose: ParentPose = (&f.data.pose).into();
                match f.key.station {
                    0 => stations[0] = pose,
                    s if s == stations.len() => stations.push(pose),
                    s => bail!(
                        "{}:{}: a fix of station {s} after station {}",
                        path.display(),
                        n.line,
                        stations.len() - 1
                    ),
                }
            }
            _ => {}
        }
    }
    let net = planner::network::build(dance, instrument, &mission.plan.start_covariance, &stations, &readings)
        .context("the journal's network")?;
    screen(&net, &seen, path)?;
    Ok(net)
}

/// `reading` of the journal's line `n` when it is finite.
fn checked_reading(reading: cps::Reading, path: &std::path::Path, n: &journal::Numbered) -> Result<cps::Reading> {
    if reading.to_vector().iter().any(|v| !v.is_finite()) {
        bail!("{}:{}: a non-finite reading: {}", path.display(), n.line, n.event.describe());
    }
    Ok(reading)
}

/// Refuses a reading that disagrees grossly ([`cps::screen`]'s bounds: a
/// reading off by them cannot be adjusted; issue 34, U2: a 1000 m distance
/// gave "degenerate geometry … station 6") with the journal's own poses
/// (the fixes' stations, the points placed from them), naming its journal
/// line, what it measured and what the poses give. `lines[k]`: reading
/// k's journal line and key.
fn screen(net: &DanceNetwork, lines: &[(usize, MeasureKey)], path: &std::path::Path) -> Result<()> {
    for (k, r) in net.network.readings.iter().enumerate() {
        let (Some(station), Some(point), Some((line, key))) =
            (net.network.stations.get(r.station), net.network.points.get(r.point), lines.get(k))
        else {
            continue;
        };
        let Ok(expected) = cps::observe(&station.pose, &point.position) else { continue };
        let got = &r.reading;
        if cps::screen::Misclosure::between(got, &expected).is_gross() {
            bail!(
                "{}:{line}: {} measures {:.3} m, {:.4}°, {:.4}° where the journal's poses give {:.3} m, {:.4}°, {:.4}° \
                 (off by more than {GROSS_DISTANCE_M} m or {:.1}°): a gross error, not noise the adjustment can take",
                path.display(),
                key_words(key),
                got.slope_m,
                got.azimuth_rad.to_degrees(),
                got.elevation_rad.to_degrees(),
                expected.slope_m,
                expected.azimuth_rad.to_degrees(),
                expected.elevation_rad.to_degrees(),
                GROSS_ANGLE_RAD.to_degrees()
            );
        }
    }
    Ok(())
}

/// The report of an adjustment (`adjust --json`, `report.json`'s
/// `adjustment`). Covariances and w use the a-priori variance factor.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
pub struct AdjustmentReport {
    /// The version of this document's schema.
    pub schema_version: u32,
    /// The cps-survey version that wrote it.
    #[serde(default)]
    pub tool_version: String,
    /// vᵀPv / redundancy.
    pub sigma0_squared: f64,
    /// Observations minus unknowns.
    pub redundancy: usize,
    /// Unknowns.
    pub unknowns: usize,
    /// Gauss–Newton iterations.
    pub iterations: usize,
    /// Whether they converged.
    pub converged: bool,
    /// The global model test of every observation, before data snooping.
    pub global_test: GlobalTestReport,
    /// The same test after snooping's removals (none when nothing was
    /// removed; only its upper bound means something).
    #[serde(default)]
    pub global_test_after_snooping: Option<GlobalTestReport>,
    /// Whether the model holds: the global test passes, or snooping found
    /// the cause and what is left stays below the upper bound.
    #[serde(default)]
    pub model_accepted: bool,
    /// The tests' settings.
    pub testing: TestingReport,
    /// Every station.
    pub stations: Vec<StationAdjusted>,
    /// Every point: child placements and control points.
    pub points: Vec<PointAdjusted>,
    /// Every reading's (r, φ, ψ), removed ones included.
    pub observations: Vec<ObservationReport>,
    /// The weighted prior coordinates (the start's, the control points').
    pub coordinate_observations: Vec<CoordinateReport>,
    /// Data snooping's removals of readings, in order (indices into
    /// `observations`).
    pub removed: Vec<usize>,
    /// Data snooping's removals of weighted prior coordinates, in order
    /// (indices into `coordinate_observations`).
    #[serde(default)]
    pub removed_coordinates: Vec<usize>,
    /// Why snooping stopped early, if it did.
    pub snooping_stopped: Option<String>,
    /// The misclosure at each control point the others can check (module docs).
    pub misclosures: Vec<Misclosure>,
    /// The largest MDB's effect: the observation and the station it moves most.
    pub worst_mdb: Option<WorstMdb>,
}

/// The global test as reported.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
pub struct GlobalTestReport {
    /// vᵀPv.
    pub statistic: f64,
    /// Degrees of freedom.
    pub dof: usize,
    /// Significance level, two-sided.
    pub alpha: f64,
    /// χ²_dof(α/2).
    pub lower: Option<f64>,
    /// χ²_dof(1 − α/2).
    pub upper: Option<f64>,
    /// lower ≤ statistic ≤ upper.
    pub passed: bool,
}

impl From<&cps::batch::GlobalTest> for GlobalTestReport {
    fn from(g: &cps::batch::GlobalTest) -> Self {
        Self { statistic: g.statistic, dof: g.dof, alpha: g.alpha, lower: g.lower, upper: g.upper, passed: g.passed }
    }
}

/// The tests' settings.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
pub struct TestingReport {
    /// Global test level.
    pub alpha: f64,
    /// w-test level.
    pub alpha0: f64,
    /// w-test power.
    pub beta0: f64,
    /// Non-centrality λ0.
    pub lambda0: f64,
    /// Critical |w|.
    pub w_critical: f64,
    /// Whether data snooping ran.
    pub snooping: bool,
}

/// A horizontal error ellipse, metres, orientation counter-clockwise from +x.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
pub struct EllipseReport {
    /// Semi-major axis.
    pub semi_major_m: f64,
    /// Semi-minor axis.
    pub semi_minor_m: f64,
    /// Direction of the major axis, radians.
    pub orientation_rad: f64,
}

impl EllipseReport {
    /// The 95 % ellipse of a covariance's (x, y) block.
    pub fn of(cov: &Matrix2<f64>) -> Self {
        let e = ErrorEllipse::from_covariance(cov).scaled(CHI2_2D_95_SQRT);
        Self { semi_major_m: e.semi_major_m, semi_minor_m: e.semi_minor_m, orientation_rad: e.orientation_rad }
    }
}

/// An adjusted station.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
pub struct StationAdjusted {
    /// Station index.
    pub index: usize,
    /// x, metres.
    pub x_m: f64,
    /// y, metres.
    pub y_m: f64,
    /// z, metres.
    pub z_m: f64,
    /// Heading, radians.
    pub heading_rad: f64,
    /// 4×4 (x, y, z, θ), m², m·rad, rad².
    pub covariance: [[f64; 4]; 4],
    /// √(σx² + σy²), metres.
    pub sigma_xy_m: f64,
    /// The absolute 95 % ellipse.
    pub ellipse_95: EllipseReport,
    /// The 95 % ellipse relative to the previous station (none for the first).
    pub relative_ellipse_95: Option<EllipseReport>,
}

/// An adjusted point.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
pub struct PointAdjusted {
    /// Its name: a control point's, or `child@cycle` for a placement.
    pub id: String,
    /// Whether it is a control point.
    pub control: bool,
    /// x, metres.
    pub x_m: f64,
    /// y, metres.
    pub y_m: f64,
    /// z, metres.
    pub z_m: f64,
    /// 3×3 (x, y, z), m².
    pub covariance: [[f64; 3]; 3],
}

/// One scalar observation's statistics.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
pub struct ObservationReport {
    /// Its index in this list.
    pub index: usize,
    /// The station it was measured from.
    pub station: usize,
    /// The point it was measured to (an `id` of `points`).
    pub target: String,
    /// `slope_distance`, `azimuth` or `elevation`.
    pub kind: String,
    /// The observation as adjusted (prism constant applied), m or rad.
    pub value: f64,
    /// Its a-priori σ.
    pub sigma: f64,
    /// Adjusted minus observed.
    pub residual: f64,
    /// Redundancy number.
    pub redundancy: f64,
    /// Baarda's w (at its removal for a removed one); null unchecked.
    pub w: Option<f64>,
    /// Minimal detectable bias; null unchecked.
    pub mdb: Option<f64>,
    /// Bias-to-noise ratio: an undetected MDB's largest effect on any
    /// unknown, in its σ.
    pub bnr: Option<f64>,
    /// How far an error of MDB moves its station horizontally, metres.
    pub station_shift_m: Option<f64>,
    /// Removed by data snooping.
    pub removed: bool,
}

/// A weighted prior coordinate's statistics.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
pub struct CoordinateReport {
    /// `station N` or the control point's name.
    pub of: String,
    /// `x`, `y`, `z` or `heading`.
    pub coordinate: String,
    /// Its σ.
    pub sigma: f64,
    /// Adjusted minus given.
    pub residual: f64,
    /// Redundancy number.
    pub redundancy: f64,
    /// Baarda's w.
    pub w: Option<f64>,
    /// Minimal detectable bias.
    pub mdb: Option<f64>,
    /// Removed by data snooping (its w then, its residual at the final
    /// estimate; no redundancy or MDB).
    #[serde(default)]
    pub removed: bool,
}

/// A misclosure at a control point.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
pub struct Misclosure {
    /// The control point.
    pub control: String,
    /// Surveyed minus given, x, metres.
    pub dx_m: f64,
    /// … y.
    pub dy_m: f64,
    /// … z.
    pub dz_m: f64,
    /// √(dx² + dy²).
    pub horizontal_m: f64,
    /// Its σ: √(σx² + σy²) of the difference.
    pub sigma_horizontal_m: f64,
    /// σ of dz.
    pub sigma_z_m: f64,
    /// dᵀ Σ⁻¹ d of the horizontal part (χ²₂ without a blunder).
    pub chi2_horizontal: Option<f64>,
}

/// The observation whose MDB moves its station the most.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
pub struct WorstMdb {
    /// Index into `observations`.
    pub observation: usize,
    /// The station it moves.
    pub station: usize,
    /// By how much, metres.
    pub shift_m: f64,
}

fn rows<const R: usize>(m: &nalgebra::SMatrix<f64, R, R>) -> [[f64; R]; R] {
    std::array::from_fn(|i| std::array::from_fn(|j| m[(i, j)]))
}

/// Adjusts the run's network: the statistics with `options`, the
/// misclosures, the report.
pub fn adjust(
    mission: &Mission,
    planned: &Planned,
    net: &DanceNetwork,
    options: &AdjustOptions,
) -> Result<AdjustmentReport> {
    let a = cps::batch::adjust(&net.network, options).context("adjusting the network")?;
    let name =
        |p: usize| net.points.get(p).map_or_else(|| format!("point {p}"), |id| point_name(mission, &planned.dance, id));
    let lambda0 = cps::stats::noncentrality(options.alpha0, options.beta0);
    let stations = (0..a.stations.len())
        .map(|k| {
            let p = &a.stations[k];
            let cov = a.station_covariance(k);
            StationAdjusted {
                index: k,
                x_m: p.position.x,
                y_m: p.position.y,
                z_m: p.position.z,
                heading_rad: p.heading_rad,
                covariance: rows(&cov),
                sigma_xy_m: cps::sigma_xy2(&cov).sqrt(),
                ellipse_95: EllipseReport::of(&cov.fixed_view::<2, 2>(0, 0).into_owned()),
                relative_ellipse_95: k
                    .checked_sub(1)
                    .map(|j| EllipseReport::of(&a.relative_covariance(j).fixed_view::<2, 2>(0, 0).into_owned())),
            }
        })
        .collect();
    let points = (0..a.points.len())
        .map(|p| {
            let x = &a.points[p];
            PointAdjusted {
                id: name(p),
                control: matches!(net.points.get(p), Some(PointId::Control(_))),
                x_m: x.x,
                y_m: x.y,
                z_m: x.z,
                covariance: rows(&a.point_covariance(p)),
            }
        })
        .collect();
    let (observations, removed) = observation_reports(&a, net, &name);
    let (coordinate_observations, removed_coordinates) = coordinate_reports(&a, net, &name);
    let worst_mdb = observations
        .iter()
        .filter(|o: &&ObservationReport| o.redundancy >= cps::batch::statistics::WEAKLY_CHECKED)
        .filter_map(|o| o.station_shift_m.map(|s| (o.index, o.station, s)))
        .max_by(|x, y| x.2.total_cmp(&y.2))
        .map(|(observation, station, shift_m)| WorstMdb { observation, station, shift_m });
    Ok(AdjustmentReport {
        schema_version: SCHEMA_VERSION,
        tool_version: crate::view::document::TOOL_VERSION.into(),
        sigma0_squared: a.sigma0_squared,
        redundancy: a.redundancy,
        unknowns: a.unknowns,
        iterations: a.iterations,
        converged: a.converged,
        global_test: (&a.global_test).into(),
        global_test_after_snooping: a.after_snooping.as_ref().map(Into::into),
        model_accepted: a.model_accepted(),
        testing: TestingReport {
            alpha: options.alpha,
            alpha0: options.alpha0,
            beta0: options.beta0,
            lambda0,
            w_critical: a.w_critical,
            snooping: options.snooping,
        },
        stations,
        points,
        observations,
        coordinate_observations,
        removed_coordinates,
        removed,
        snooping_stopped: a.snooping_stopped.clone(),
        misclosures: misclosures(net, &name, &a),
        worst_mdb,
    })
}

/// Every reading's (r, φ, ψ), in network order, with its statistics — a
/// removed one with its residual at the final estimate and its w when
/// removed; and the removed ones' indices in the order removed.
fn observation_reports(
    a: &Adjustment,
    net: &DanceNetwork,
    name: &dyn Fn(usize) -> String,
) -> (Vec<ObservationReport>, Vec<usize>) {
    // Indexed once: a search per observation made the report quadratic
    // (a 40 km run's 48,000 readings: 2 s of 5).
    let by_reading: std::collections::HashMap<(usize, usize), &ScalarStats> = a
        .observations
        .iter()
        .filter_map(|o| match o.source {
            Source::Reading(k) => Some(((k, o.component), o)),
            _ => None,
        })
        .collect();
    let stat = |k: usize, c: usize| -> Option<&ScalarStats> { by_reading.get(&(k, c)).copied() };
    let mut out = Vec::with_capacity(3 * net.network.readings.len());
    for (k, r) in net.network.readings.iter().enumerate() {
        let value = r.reading.to_vector();
        let adjusted: Option<Reading> = cps::observe(&a.stations[r.station], &a.points[r.point]).ok();
        for c in 0..3 {
            let index = out.len();
            let base = ObservationReport {
                index,
                station: r.station,
                target: name(r.point),
                kind: KINDS[c].into(),
                value: value[c],
                sigma: r.covariance[(c, c)].sqrt(),
                residual: f64::NAN,
                redundancy: 0.0,
                w: None,
                mdb: None,
                bnr: None,
                station_shift_m: None,
                removed: false,
            };
            out.push(match stat(k, c) {
                Some(o) => ObservationReport {
                    residual: o.residual,
                    redundancy: o.redundancy,
                    w: o.w,
                    mdb: o.mdb,
                    bnr: o.bnr,
                    station_shift_m: o.station_shift_m,
                    ..base
                },
                None => {
                    let at = a.removed.iter().find(|x| x.source == Source::Reading(k) && x.component == c);
                    let residual = adjusted.map_or(f64::NAN, |adj| {
                        let d = adj.to_vector()[c] - value[c];
                        if c == 1 { cps::wrap_angle(d) } else { d }
                    });
                    ObservationReport { residual, w: at.map(|x| x.w), removed: true, ..base }
                }
            });
        }
    }
    let removed = a
        .removed
        .iter()
        .filter_map(|x| match x.source {
            Source::Reading(k) => Some(3 * k + x.component),
            _ => None,
        })
        .collect();
    (out, removed)
}

/// The weighted prior coordinates with their statistics, and after them
/// those data snooping removed (issue 34, S1: they were left out, and "0
/// removal(s)" reported) with their w then and their residual at the final
/// estimate; and the removed ones' indices in the order removed.
fn coordinate_reports(
    a: &Adjustment,
    net: &DanceNetwork,
    name: &dyn Fn(usize) -> String,
) -> (Vec<CoordinateReport>, Vec<usize>) {
    let label = |source: Source, component: usize| -> Option<(String, String)> {
        let (of, names): (String, &[&str]) = match source {
            Source::StationPrior(k) => (format!("station {k}"), &["x", "y", "z", "heading"]),
            Source::PointPrior(p) => (name(p), &["x", "y", "z"]),
            Source::Reading(_) => return None,
        };
        Some((of, names.get(component).copied().unwrap_or("?").into()))
    };
    let mut out: Vec<CoordinateReport> = a
        .observations
        .iter()
        .filter_map(|o| {
            let (of, coordinate) = label(o.source, o.component)?;
            Some(CoordinateReport {
                of,
                coordinate,
                sigma: o.sigma,
                residual: o.residual,
                redundancy: o.redundancy,
                w: o.w,
                mdb: o.mdb,
                removed: false,
            })
        })
        .collect();
    let mut removed = Vec::new();
    for x in &a.removed {
        let Some((of, coordinate)) = label(x.source, x.component) else { continue };
        // Adjusted − given, and the given coordinate's σ.
        let (residual, sigma) = match x.source {
            Source::StationPrior(k) => {
                let st = &net.network.stations[k];
                let v = |p: &cps::ParentPose| [p.position.x, p.position.y, p.position.z, p.heading_rad];
                let d = v(&a.stations[k])[x.component] - v(&st.pose)[x.component];
                let d = if x.component == 3 { cps::wrap_angle(d) } else { d };
                (d, st.prior.map_or(f64::NAN, |c| c[(x.component, x.component)].sqrt()))
            }
            Source::PointPrior(p) => {
                let pt = &net.network.points[p];
                let d = a.points[p][x.component] - pt.position[x.component];
                (d, pt.prior.map_or(f64::NAN, |c| c[(x.component, x.component)].sqrt()))
            }
            Source::Reading(_) => continue,
        };
        removed.push(out.len());
        out.push(CoordinateReport {
            of,
            coordinate,
            sigma,
            residual,
            redundancy: 0.0,
            w: Some(x.w),
            mdb: None,
            removed: true,
        });
    }
    (out, removed)
}

/// The misclosures at the control points outside the datum (module docs),
/// without what data snooping removed (`removed`; issue 34, S2: a 0.5 m
/// blunder, removed, still gave 21–55 mm misclosures beside "model
/// accepted").
fn misclosures(net: &DanceNetwork, name: &dyn Fn(usize) -> String, a: &Adjustment) -> Vec<Misclosure> {
    let removed: Vec<(Source, usize)> = a.removed.iter().map(|x| (x.source, x.component)).collect();
    let options = AdjustOptions { snooping: false, ..AdjustOptions::default() };
    let control: Vec<usize> =
        net.points.iter().enumerate().filter(|(_, id)| matches!(id, PointId::Control(_))).map(|(p, _)| p).collect();
    // One adjustment and an update a point (`cps::batch::freed`; issue 35:
    // an adjustment a point took 2.96 s for 41 control points). Without
    // this point's coordinates the rest may not hold the network (a start
    // resected on two points): no misclosure then.
    let Ok(freed) = cps::batch::freed::freed_points(&net.network, &options, &removed, &control, Some(a)) else {
        return Vec::new();
    };
    control
        .iter()
        .zip(freed)
        .filter_map(|(&p, freed)| {
            let freed = freed?;
            let given_cov = net.network.points[p].prior.unwrap_or_else(Matrix3::zeros);
            let given = net.network.points[p].position;
            let d: Point3<f64> = Point3::from(freed.position - given);
            let cov: Matrix3<f64> = freed.covariance + given_cov;
            let xy = cov.fixed_view::<2, 2>(0, 0).into_owned();
            Some(Misclosure {
                control: name(p),
                dx_m: d.x,
                dy_m: d.y,
                dz_m: d.z,
                horizontal_m: d.x.hypot(d.y),
                sigma_horizontal_m: xy.trace().sqrt(),
                sigma_z_m: cov[(2, 2)].sqrt(),
                chi2_horizontal: xy.try_inverse().map(|inv| (d.coords.xy().transpose() * inv * d.coords.xy())[(0, 0)]),
            })
        })
        .collect()
}

/// The adjustment at the end of a run, as `report.json` has it: the report,
/// or why the network could not be adjusted.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(untagged)]
pub enum AdjustmentOutcome {
    /// The adjustment.
    Adjusted(Box<AdjustmentReport>),
    /// Why there is none.
    Failed {
        /// The reason.
        error: String,
    },
}

impl AdjustmentOutcome {
    /// The report, if the network was adjusted.
    pub fn report(&self) -> Option<&AdjustmentReport> {
        match self {
            AdjustmentOutcome::Adjusted(r) => Some(r),
            AdjustmentOutcome::Failed { .. } => None,
        }
    }
}

/// The adjusted covariance of station `k` from a report.
pub fn station_covariance(report: &AdjustmentReport, k: usize) -> Option<Matrix4<f64>> {
    report.stations.get(k).map(|s| Matrix4::from_fn(|i, j| s.covariance[i][j]))
}

/// A journal reading's key in words: "the fix reading of child 1 in cycle 2".
fn key_words(k: &MeasureKey) -> String {
    use crate::run::journal::Phase;
    let phase = match k.phase {
        Phase::Placement => "placement",
        Phase::Fix => "fix",
        Phase::Control => "control",
    };
    match (&k.control, k.child) {
        (Some(name), _) => format!("the {phase} reading of control point {name} in cycle {}", k.cycle),
        (None, Some(child)) => format!("the {phase} reading of child {child} in cycle {}", k.cycle),
        (None, None) => format!("a {phase} reading in cycle {}", k.cycle),
    }
}

/// A planned reading in words, as [`key_words`] says a recorded one.
fn taken_words(t: &Taken, control: &[planner::control::ControlPoint]) -> String {
    match *t {
        Taken::Placement { cycle, child, .. } => format!("the placement reading of child {child} in cycle {cycle}"),
        Taken::Fix { cycle, child, .. } => format!("the fix reading of child {child} in cycle {cycle}"),
        Taken::Control { cycle, control: c, .. } => {
            let name = control.get(c).map_or_else(|| format!("#{c}"), |p| p.name.clone());
            format!("the control reading of control point {name} in cycle {cycle}")
        }
    }
}
