//! `--plot FILE.svg` for `predict` and `plan`: σ_xy and σ_θ versus distance,
//! and a top view of the route with the scene, the stations, the children's
//! placements and the parent's 95 % error ellipses, exaggerated by a stated
//! factor.
//!
//! SVG only: the SVG backend needs no font files (the viewer renders the
//! text), so the plot works on any machine; convert it with any SVG tool
//! (`rsvg-convert -o plan.png plan.svg`) for a bitmap.

use std::path::Path;

use anyhow::{Context, Result, bail};
use cps::geom::Scene;
use cps::{CHI2_2D_95_SQRT, ErrorEllipse, RAD_PER_ARCSEC};
use nalgebra::{Point2, Point3};
use planner::{Dance, Prediction, Step, Violation};
use plotters::coord::Shift;
use plotters::prelude::*;

use super::shapes::{ellipse_scale, ellipse_scale_name};
use crate::planning::Planned;

/// One plan to plot: its schedule, its prediction and its violations.
#[derive(Debug, Clone, Copy)]
pub struct PlotPlan<'a> {
    /// Legend label ("as written", "optimized").
    pub label: &'a str,
    /// The schedule.
    pub dance: &'a Dance,
    /// Its prediction.
    pub prediction: &'a Prediction,
    /// Its steps (to place the violations).
    pub steps: &'a [Step],
    /// Constraints it breaks.
    pub violations: &'a [Violation],
}

impl<'a> PlotPlan<'a> {
    /// A mission's plan as planned, with the violations to mark.
    pub fn of(label: &'a str, planned: &'a Planned, violations: &'a [Violation]) -> Self {
        Self { label, dance: &planned.dance, prediction: &planned.prediction, steps: &planned.steps, violations }
    }
}

/// How to get a bitmap from the SVG, for error messages.
pub const SVG_HINT: &str =
    " (the plot is SVG, which needs no fonts installed; convert it with e.g. `rsvg-convert -o plot.png plot.svg`)";

/// The line a command prints after writing a plot.
pub fn plotted(out: &mut dyn std::io::Write, file: &Path, s: &PlotSummary) -> std::io::Result<()> {
    writeln!(
        out,
        "plotted {}: {} parent 95 % ellipses drawn ×{}, {} scene outline segments",
        file.display(),
        s.ellipses,
        s.ellipse_scale,
        s.scene_segments
    )
}

/// What the plot shows, for the caller's report.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PlotSummary {
    /// The ellipses' exaggeration factor.
    pub ellipse_scale: f64,
    /// Ellipses drawn (one per cycle of the chosen plan, or every n-th on
    /// long routes, always the last).
    pub ellipses: usize,
    /// Scene outline segments drawn.
    pub scene_segments: usize,
}

const WIDTH: u32 = 1200;
const CURVES_HEIGHT: u32 = 380;
const COLOURS: [RGBColor; 3] = [RGBColor(31, 119, 180), RGBColor(214, 39, 40), RGBColor(44, 160, 44)];

fn draw<T, E: std::error::Error + Send + Sync + 'static>(r: Result<T, E>) -> Result<T> {
    r.context("drawing the plot")
}

/// Writes the plot. The top view shows the last plan of `plans` (the
/// chosen one) with the violations of every plan; the curves show them all.
pub fn write_svg(path: &Path, title: &str, plans: &[PlotPlan], scene: Option<&Scene>) -> Result<PlotSummary> {
    let Some(chosen) = plans.last() else { bail!("nothing to plot") };
    let (lo, hi) = extent(chosen.dance, scene);
    let (dx, dy) = ((hi.x - lo.x).max(1.0), (hi.y - lo.y).max(1.0));
    let view_height = ((f64::from(WIDTH) - 100.0) * dy / dx + 120.0).clamp(320.0, 1400.0) as u32;
    let root = SVGBackend::new(path, (WIDTH, CURVES_HEIGHT + view_height)).into_drawing_area();
    draw(root.fill(&WHITE))?;
    let root = draw(root.titled(title, ("sans-serif", 22)))?;
    let (curves, view) = root.split_vertically(CURVES_HEIGHT - 30);
    let (left, right) = curves.split_horizontally(WIDTH / 2);
    curve(&left, plans, "√(σx² + σy²) (mm)", |c| 1e3 * c.sigma_xy2_m2().sqrt())?;
    curve(&right, plans, "σθ (″)", |c| c.sigma_heading_rad() / RAD_PER_ARCSEC)?;
    let summary = top_view(&view, plans, scene, (lo, hi))?;
    root.present().map_err(|e| {
        anyhow::anyhow!("cannot write the plot {}: {e} (does the directory exist and is it writable?)", path.display())
    })?;
    Ok(summary)
}

/// One quantity versus distance, one line per plan.
fn curve(
    area: &DrawingArea<SVGBackend, Shift>,
    plans: &[PlotPlan],
    y_desc: &str,
    value: impl Fn(&planner::CyclePrediction) -> f64,
) -> Result<()> {
    let series: Vec<Vec<(f64, f64)>> = plans
        .iter()
        .map(|p| {
            let start = std::iter::once((0.0, 0.0));
            start.chain(p.prediction.cycles.iter().map(|c| (c.distance_m, value(c)))).collect()
        })
        .collect();
    let x_max = series.iter().flatten().map(|p| p.0).fold(1e-9, f64::max);
    let y_max = series.iter().flatten().map(|p| p.1).filter(|v| v.is_finite()).fold(1e-9, f64::max);
    let mut chart = draw(
        ChartBuilder::on(area)
            .margin(12)
            .x_label_area_size(40)
            .y_label_area_size(64)
            .build_cartesian_2d(0.0..x_max * 1.02, 0.0..y_max * 1.08),
    )?;
    draw(
        chart
            .configure_mesh()
            .x_desc("distance along the route (m)")
            .y_desc(y_desc)
            .light_line_style(RGBColor(240, 240, 240))
            .draw(),
    )?;
    for (k, (points, plan)) in series.into_iter().zip(plans).enumerate() {
        let colour = COLOURS[k % COLOURS.len()];
        draw(chart.draw_series(LineSeries::new(points.clone(), colour.stroke_width(2))))?
            .label(plan.label)
            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], colour.stroke_width(2)));
        draw(chart.draw_series(points.into_iter().map(|p| Circle::new(p, 3, colour.filled()))))?;
    }
    draw(chart.configure_series_labels().position(SeriesLabelPosition::UpperLeft).border_style(BLACK).draw())?;
    Ok(())
}

/// Bounding box of what the top view shows: the scene, or else the
/// stations and children, with a margin.
fn extent(dance: &Dance, scene: Option<&Scene>) -> (Point2<f64>, Point2<f64>) {
    let mut lo = Point2::new(f64::INFINITY, f64::INFINITY);
    let mut hi = Point2::new(f64::NEG_INFINITY, f64::NEG_INFINITY);
    let mut grow = |p: &Point3<f64>| {
        lo = Point2::new(lo.x.min(p.x), lo.y.min(p.y));
        hi = Point2::new(hi.x.max(p.x), hi.y.max(p.y));
    };
    dance.stations.iter().for_each(|s| grow(&s.position));
    dance.cycles.iter().flat_map(|c| &c.children).for_each(&mut grow);
    if let Some(b) = scene.map(Scene::bounds) {
        grow(&b.min);
        grow(&b.max);
    }
    let pad = 0.04 * (hi.x - lo.x).max(hi.y - lo.y).max(1.0);
    (lo - nalgebra::Vector2::repeat(pad), hi + nalgebra::Vector2::repeat(pad))
}

/// The outline of an ellipse, `n` points, centred on `c`.
pub fn ellipse_outline(c: Point2<f64>, e: &ErrorEllipse, n: usize) -> Vec<Point2<f64>> {
    let (s, co) = e.orientation_rad.sin_cos();
    (0..n)
        .map(|k| {
            let t = std::f64::consts::TAU * k as f64 / n as f64;
            let (u, v) = (e.semi_major_m * t.cos(), e.semi_minor_m * t.sin());
            Point2::new(c.x + co * u - s * v, c.y + s * u + co * v)
        })
        .collect()
}

/// Where the scene crosses the horizontal plane at `z`: one segment per
/// facet that crosses it (cylinders and spheres as the recording's facets).
pub fn scene_slice(scene: &Scene, z: f64) -> Vec<[Point2<f64>; 2]> {
    let (vertices, triangles) = super::shapes::scene_mesh(scene);
    let v = |i: u32| {
        let p = vertices[i as usize];
        Point3::new(f64::from(p[0]), f64::from(p[1]), f64::from(p[2]))
    };
    let mut out = Vec::new();
    for t in triangles {
        let [a, b, c] = t.map(v);
        let mut crossing = Vec::with_capacity(2);
        for (p, q) in [(a, b), (b, c), (c, a)] {
            let (dp, dq) = (p.z - z, q.z - z);
            if (dp < 0.0) != (dq < 0.0) {
                let s = dp / (dp - dq);
                crossing.push(Point2::new(p.x + s * (q.x - p.x), p.y + s * (q.y - p.y)));
            }
        }
        if let [p, q] = crossing[..]
            && (p - q).norm() > 1e-9
        {
            out.push([p, q]);
        }
    }
    out
}

/// The heights of the top view's scene slices: 0.25 m and 1 m above the
/// scene's lowest point (obstacles a robot drives into) and the stations'
/// mean height (what blocks sight lines).
pub fn slice_heights(scene: &Scene, dance: &Dance) -> Vec<f64> {
    let b = scene.bounds();
    let n = dance.stations.len().max(1) as f64;
    let stations = dance.stations.iter().map(|s| s.position.z).sum::<f64>() / n;
    // A hair off round heights, so that a face lying exactly in a slice
    // plane does not count as crossing it.
    [b.min.z + 0.25, b.min.z + 1.0, stations].into_iter().map(|z| z + 1e-6).filter(|z| *z < b.max.z).collect()
}

fn top_view(
    area: &DrawingArea<SVGBackend, Shift>,
    plans: &[PlotPlan],
    scene: Option<&Scene>,
    (lo, hi): (Point2<f64>, Point2<f64>),
) -> Result<PlotSummary> {
    let Some(plan) = plans.last() else { bail!("nothing to plot") };
    let dance = plan.dance;
    let ellipses: Vec<(Point2<f64>, ErrorEllipse)> = plan
        .prediction
        .cycles
        .iter()
        .map(|c| (c.parent.position.xy(), c.ellipse_1sigma().scaled(CHI2_2D_95_SQRT)))
        .collect();
    let largest = ellipses.iter().map(|(_, e)| e.semi_major_m).fold(0.0, f64::max);
    let mut gaps: Vec<f64> = dance.stations.windows(2).map(|w| (w[1].position - w[0].position).xy().norm()).collect();
    gaps.sort_by(f64::total_cmp);
    // Room for the largest ellipse: half a station gap, or 4 % of the view
    // on long routes (then only every n-th station's ellipse is drawn, so
    // that they do not pile up).
    let gap = gaps.get(gaps.len() / 2).copied().unwrap_or(1.0).max(1e-3);
    let room = (0.45 * gap).max(0.04 * (hi.x - lo.x).max(hi.y - lo.y));
    let scale = ellipse_scale(largest, room);
    let every = ((2.0 * largest * scale / gap).ceil() as usize).clamp(1, ellipses.len().max(1));
    let n = ellipses.len();
    let ellipses: Vec<(Point2<f64>, ErrorEllipse)> =
        ellipses.into_iter().enumerate().filter(|(k, _)| (k + 1) % every == 0 || k + 1 == n).map(|(_, e)| e).collect();
    let which = if every > 1 { format!(", one station in {every}") } else { String::new() };
    let caption =
        format!("top view — {}: 95 % error ellipses of the parent ×{}{which}", plan.label, ellipse_scale_name(scale));
    let mut chart = draw(
        ChartBuilder::on(area)
            .caption(caption, ("sans-serif", 18))
            .margin(12)
            .x_label_area_size(40)
            .y_label_area_size(64)
            .build_cartesian_2d(lo.x..hi.x, lo.y..hi.y),
    )?;
    draw(chart.configure_mesh().x_desc("x (m)").y_desc("y (m)").light_line_style(WHITE).draw())?;
    let mut scene_segments = 0;
    if let Some(scene) = scene {
        let grey = RGBColor(90, 90, 90);
        let segments: Vec<[Point2<f64>; 2]> =
            slice_heights(scene, dance).into_iter().flat_map(|z| scene_slice(scene, z)).collect();
        scene_segments = segments.len();
        draw(chart.draw_series(
            segments.into_iter().map(|[p, q]| PathElement::new(vec![(p.x, p.y), (q.x, q.y)], grey.stroke_width(1))),
        ))?
        .label(format!("scene \"{}\" (horizontal slices)", scene.name()))
        .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], grey));
    }
    let route: Vec<(f64, f64)> = dance.stations.iter().map(|s| (s.position.x, s.position.y)).collect();
    let blue = COLOURS[0];
    draw(chart.draw_series(LineSeries::new(route.clone(), blue.stroke_width(1))))?
        .label("route and parent stations")
        .legend(move |(x, y)| Circle::new((x + 10, y), 3, blue.filled()));
    draw(chart.draw_series(route.into_iter().map(|p| Circle::new(p, 3, blue.filled()))))?;
    let green = COLOURS[2];
    let placed: Vec<(f64, f64)> =
        dance.cycles.iter().flat_map(|c| c.moved.iter().map(|&j| (c.children[j].x, c.children[j].y))).collect();
    draw(chart.draw_series(placed.into_iter().map(|p| TriangleMarker::new(p, 4, green.filled()))))?
        .label("children placed")
        .legend(move |(x, y)| TriangleMarker::new((x + 10, y), 4, green.filled()));
    let purple = RGBColor(148, 103, 189);
    draw(chart.draw_series(ellipses.iter().map(|(c, e)| {
        let outline = ellipse_outline(*c, &e.scaled(scale), 64);
        Polygon::new(outline.into_iter().map(|p| (p.x, p.y)).collect::<Vec<_>>(), purple.mix(0.35).filled())
    })))?
    .label(format!("parent 95 % ellipse ×{}", ellipse_scale_name(scale)))
    .legend(move |(x, y)| Rectangle::new([(x, y - 4), (x + 20, y + 4)], purple.mix(0.35).filled()));
    let red = COLOURS[1];
    let crosses: Vec<(f64, f64)> = plans
        .iter()
        .flat_map(|p| p.violations.iter().map(move |v| v.position(p.dance, p.steps)))
        .map(|q| (q.x, q.y))
        .collect();
    if !crosses.is_empty() {
        draw(chart.draw_series(crosses.into_iter().map(|p| Cross::new(p, 6, red.stroke_width(2)))))?
            .label("constraint violated")
            .legend(move |(x, y)| Cross::new((x + 10, y), 5, red.stroke_width(2)));
    }
    draw(
        chart
            .configure_series_labels()
            .position(SeriesLabelPosition::UpperRight)
            .background_style(WHITE.mix(0.85))
            .border_style(BLACK)
            .draw(),
    )?;
    Ok(PlotSummary { ellipse_scale: scale, ellipses: ellipses.len(), scene_segments })
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Matrix2;

    #[test]
    fn the_outline_lies_on_the_covariance_ellipse() {
        // Every outline point p of the k-σ ellipse satisfies
        // (p − c)ᵀ Σ⁻¹ (p − c) = k², independently of the eigen decomposition.
        let cov = Matrix2::new(4e-4, 1.5e-4, 1.5e-4, 1e-4);
        let e = ErrorEllipse::from_covariance(&cov).scaled(CHI2_2D_95_SQRT);
        let c = Point2::new(3.0, -2.0);
        let inv = cov.try_inverse().expect("positive definite");
        for p in ellipse_outline(c, &e, 37) {
            let d = p - c;
            let m = (d.transpose() * inv * d)[(0, 0)];
            assert!((m - CHI2_2D_95_SQRT.powi(2)).abs() < 1e-9, "{m}");
        }
    }

    #[test]
    fn a_box_sliced_through_the_middle_is_its_outline() {
        let mut b = cps::geom::SceneBuilder::new();
        b.cuboid("crate", Point3::new(2.0, 3.5, 0.5), nalgebra::Vector3::new(2.0, 3.0, 1.0), 0.0).expect("cuboid");
        let scene = b.build("box");
        let segments = scene_slice(&scene, 0.5);
        let length: f64 = segments.iter().map(|[p, q]| (q - p).norm()).sum();
        assert!((length - 10.0).abs() < 1e-5, "perimeter {length}");
        for [p, q] in &segments {
            for r in [p, q] {
                let on_x = (r.x - 1.0).abs() < 1e-6 || (r.x - 3.0).abs() < 1e-6;
                let on_y = (r.y - 2.0).abs() < 1e-6 || (r.y - 5.0).abs() < 1e-6;
                assert!(on_x || on_y, "{r}");
            }
        }
        assert!(scene_slice(&scene, 1.5).is_empty());
    }
}
