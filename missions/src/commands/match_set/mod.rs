//! `cps-survey match INPUT…`: registers a user's own scans into one frame
//! ([`fusion::scanset`]) and writes their poses (`poses.json`, 3DTK
//! `.frames`), the merged cloud, the link table and `match.rrd`.

mod args;
mod outputs;
mod report;
mod text;

use std::io::Write;
use std::time::Instant;

use anyhow::{Context, Result, bail};
use fusion::icp::{Kernel, Method};
use fusion::scanset::SetConfig;
use nalgebra::Isometry3;

use super::Outcome;
use super::register::MethodArg;
use crate::scans::inputs::InputScan;

use args::{GLOBAL_CELL_OF_RADIUS, bag_options, mode, output_crs};
pub use args::{InitArg, MatchArgs, ModeArg};
use outputs::{check_out, write_outputs};

use crate::documents::matching::{GlobalMatchReport, GlobalReport, PipeReport, SettingsReport, ViewpointReport};
use report::report;
use text::{unlinked, write_text};

/// Runs `match`.
pub fn run(args: &MatchArgs, out: &mut dyn Write) -> Result<Outcome> {
    crate::scans::settings::check_range(args.min_range, args.max_range)?;
    let given =
        (args.schedule.trim() != "auto").then(|| crate::scans::settings::schedule(&args.schedule)).transpose()?;
    if let Some(h) = args.huber
        && !(h.is_finite() && h >= 0.0)
    {
        bail!("--huber {h}: expected a width ≥ 0 in metres (0: least squares)");
    }
    for (k, f) in args.formats.iter().enumerate() {
        if !crate::mission::OUTPUT_FORMATS.contains(&f.as_str()) {
            bail!("--formats {f}: expected some of {}", crate::mission::OUTPUT_FORMATS.join(", "));
        }
        if args.formats[..k].contains(f) {
            bail!("--formats {}: {f} is listed twice: expected each format once", args.formats.join(","));
        }
    }
    let bag = bag_options(args)?;
    if let Some(dir) = &args.ros2_bag
        && std::fs::symlink_metadata(dir).is_ok()
    {
        bail!("--ros2-bag {}: already exists; a bag is written into a new directory", dir.display());
    }
    if args.init.is_some() && args.init_poses.is_some() {
        bail!("--init global and --init-poses: give the starts, or have them found, not both");
    }
    if args.out.exists() && !args.out.is_dir() {
        bail!("--out {}: exists and is not a directory", args.out.display());
    }
    check_out(args)?;
    crate::view::recording::available()?;
    let degeneracy_ratio = args.degeneracy_ratio.unwrap_or(fusion::links::DEFAULT_DEGENERACY_RATIO);
    if !(degeneracy_ratio.is_finite() && (0.0..0.1).contains(&degeneracy_ratio)) {
        bail!("--degeneracy-ratio {degeneracy_ratio}: expected a ratio in [0, 0.1) (0: off)");
    }
    // A threshold of the user's own comes with the line test, as a
    // mission's `[fusion] degeneracy_ratio` does (docs/match.md, Known
    // limits: at the default it held a street's weakly seen direction
    // at a start 2° off).
    let line_ratio = args.line_ratio.unwrap_or(match args.degeneracy_ratio {
        Some(r) if r > 0.0 => crate::mission::DEFAULT_LINE_RATIO,
        _ => 0.0,
    });
    if !(line_ratio.is_finite() && (0.0..1.0).contains(&line_ratio)) {
        bail!("--line-ratio {line_ratio}: expected a ratio in [0, 1) (0: off)");
    }
    if line_ratio > 0.0 && degeneracy_ratio == 0.0 {
        bail!("--line-ratio {line_ratio} judges the blind directions: it needs --degeneracy-ratio above 0");
    }
    if !(args.normal_agreement.is_finite() && (0.0..90.0).contains(&args.normal_agreement)) {
        bail!("--normal-agreement {}: expected degrees in [0, 90) (0: off)", args.normal_agreement);
    }
    if !(args.corner_ratio.is_finite() && (0.0..=1.0).contains(&args.corner_ratio)) {
        bail!("--corner-ratio {}: expected a ratio in [0, 1] (0: off)", args.corner_ratio);
    }
    if args.corner_everywhere && args.corner_ratio == 0.0 {
        bail!("--corner-everywhere widens the corner test: it needs --corner-ratio above 0");
    }
    if args.max_partners == 0 {
        bail!("--max-partners 0: expected at least 1");
    }
    if args.max_matches_per_scan == 0 {
        bail!("--max-matches-per-scan 0: expected at least 1");
    }
    let mut config = SetConfig { mode: mode(args.mode), ..SetConfig::default() };
    config.link.max_partners = args.max_partners;
    config.link.multiview.max_matches_per_scan = args.max_matches_per_scan;
    let icp = &mut config.link.multiview.icp;
    icp.degeneracy_ratio = (degeneracy_ratio > 0.0).then_some(degeneracy_ratio);
    icp.line_ratio = (line_ratio > 0.0).then_some(line_ratio);
    icp.normal_agreement_cos = (args.normal_agreement > 0.0).then(|| args.normal_agreement.to_radians().cos());
    icp.corner_ratio = (args.corner_ratio > 0.0).then_some(args.corner_ratio);
    icp.corner_everywhere = args.corner_everywhere;
    if args.method == MethodArg::PointToPoint {
        icp.method = Method::PointToPoint;
        // Back faces need the target's normals, which point-to-point does not estimate.
        icp.reject_back_faces = false;
    }
    let min_points = config.link.multiview.min_pairs;
    let crs = output_crs(args)?;
    let scans = crate::scans::inputs::read(
        &args.inputs,
        args.init_poses.as_deref(),
        (args.min_range, args.max_range),
        min_points,
        &bag,
    )?;
    if scans.len() < 2 {
        bail!("{}: one scan: expected at least two to match", scans[0].file);
    }
    let points: Vec<&[nalgebra::Point3<f32>]> = scans.iter().map(|s| s.points.as_slice()).collect();
    let viewpoints = viewpoints(args, &scans);
    let position = |v: &ViewpointReport| nalgebra::Point3::from(v.position);
    config.viewpoints = viewpoints.iter().map(|v| v.as_ref().filter(|v| v.used).map(position)).collect();
    // Stated or told (`--scanner-at-origin`), not estimated.
    let stated: Vec<Option<nalgebra::Point3<f64>>> =
        viewpoints.iter().map(|v| v.as_ref().filter(|v| !v.is_estimate()).map(position)).collect();
    config.only_covered = args.only_covered;
    // A pipe — every scan's points on a tube, all round it — holds its
    // axis and its roll by its small features alone, which the matches'
    // pull along the scans' sampling outweighs: without a threshold of the
    // user's own, the pipe's (docs/match.md, Blind directions: "A pipe is
    // found").
    let pipe = if args.degeneracy_ratio.is_none() { pipe_of(&points, &stated) } else { None };
    if pipe.is_some() {
        let icp = &mut config.link.multiview.icp;
        icp.degeneracy_ratio = Some(fusion::links::PIPE_DEGENERACY_RATIO);
        if args.line_ratio.is_none() && icp.method == Method::PointToPlane {
            icp.line_ratio = Some(fusion::links::DEFAULT_LINE_RATIO);
        }
    }
    let mut settings = scale_settings(args, given, &scans, &points, &mut config)?;
    settings.pipe = pipe;
    let starts: Vec<Isometry3<f64>> = match args.init {
        None => scans.iter().map(|s| s.start).collect(),
        Some(InitArg::Global) => {
            let voxel_m = settings.radius_m * GLOBAL_CELL_OF_RADIUS;
            let started = Instant::now();
            let global = fusion::global::GlobalConfig::new(voxel_m);
            let (starts, found) = fusion::global::starts(&points, &global).map_err(|e| named(e, &scans))?;
            settings.global = Some(GlobalReport {
                voxel_m,
                seconds: started.elapsed().as_secs_f64(),
                matches: found
                    .iter()
                    .enumerate()
                    .filter_map(|(i, f)| {
                        f.as_ref().map(|(j, m)| GlobalMatchReport {
                            source: i,
                            target: *j,
                            correspondences: m.correspondences,
                            inliers: m.inliers,
                        })
                    })
                    .collect(),
            });
            starts
        }
    };
    rayon::broadcast(|_| ());
    let started = Instant::now();
    let bar = progress_bar(args.json);
    let result = fusion::scanset::register_set(&points, &starts, &config, &mut |stage, stages, done, total| {
        bar.set_message(format!("stage {stage}/{stages}"));
        bar.set_length(total as u64);
        bar.set_position(done as u64);
    });
    bar.finish_and_clear();
    let result = result.map_err(|e| named(e, &scans))?;
    let seconds = started.elapsed().as_secs_f64();
    let mut report = report(args.mode, &crs, &scans, &result, seconds, settings, args.joint_covariance);
    for (s, v) in report.scans.iter_mut().zip(viewpoints) {
        s.viewpoint = v;
    }
    if args.init == Some(InitArg::Global) {
        // A start found from the scans' shape says nothing along what no
        // match sees: a scan blind there has no pose the data confirm.
        report.blind_without_start =
            (1..report.scans.len()).filter(|&i| !report.scans[i].degenerate_directions.is_empty()).collect();
    }
    let written = write_outputs(args, &crs, &scans, &result, &report)?;
    if args.json {
        crate::documents::write_line(out, &report)?;
    } else {
        write_text(out, &scans, &report)?;
        writeln!(out, "outputs in {}: {}", args.out.display(), written.join(", "))?;
    }
    // A scan the final matches do not hold, or that the verification
    // names, has a pose no data confirm: the outputs are written, and the
    // exit says it (1).
    Ok(Outcome::passed(
        unlinked(&report).is_empty() && report.untrusted.is_empty() && report.blind_without_start.is_empty(),
    ))
}

fn progress_bar(hidden: bool) -> indicatif::ProgressBar {
    if hidden {
        return indicatif::ProgressBar::hidden();
    }
    let bar = indicatif::ProgressBar::new(0);
    if let Ok(style) = indicatif::ProgressStyle::with_template("matching {msg} [{bar:30}] {pos}/{len}") {
        bar.set_style(style);
    }
    bar
}

/// A fusion error with the scans' indices turned into their files.
fn named(e: fusion::FusionError, scans: &[InputScan]) -> anyhow::Error {
    let file = |i: usize| scans.get(i).map_or_else(|| format!("scan {i}"), |s| s.file.clone());
    match e {
        fusion::FusionError::NoOverlap { scan, pairs, needed, against, partner, stage } => {
            let partner = partner.map_or(against, file);
            match stage {
                Some(k) if k > 1 => anyhow::anyhow!(
                    "{} and {partner} do not overlap at stage {k} of the schedule: {pairs} correspondences, expected at least {needed}; they did at the start, so a match of stage {} moved them apart (a symmetric fit from rough starts? try --init global, or starts nearer the truth)",
                    file(scan),
                    k - 1
                ),
                _ => anyhow::anyhow!(
                    "{} and {partner} do not overlap at their start poses: {pairs} correspondences, expected at least {needed} (are the start poses within the schedule's first distance, and do the scans overlap? --init global finds starts from the scans alone)",
                    file(scan)
                ),
            }
        }
        fusion::FusionError::InScan { scan, source } => anyhow::anyhow!("{}: {source}", file(scan)),
        e => anyhow::Error::new(e).context("matching the scans"),
    }
}

/// Occupied voxel cells a scan needs at every stage of a given schedule:
/// fewer and ICP has nothing to fit (the coarsest stage of a 0.5 m
/// schedule holds a 0.27 m object in 3 cells).
const MIN_CELLS: usize = 50;

/// The scans' length scales, and the schedule and metre-valued settings
/// they call for, set into `config`: the schedule given or derived
/// ([`fusion::scale::SetScale::schedule`]), each stage checked to leave
/// every scan at least [`MIN_CELLS`] voxel cells (else refused naming the
/// stage, the scan and the spacing found, before any match); the Huber
/// width given or scaled, the step σ and the convergence tolerance scaled
/// to the schedule ([`fusion::scale::ScaledSettings`]).
fn scale_settings(
    args: &MatchArgs,
    given: Option<Vec<fusion::icp::Stage>>,
    scans: &[InputScan],
    points: &[&[nalgebra::Point3<f32>]],
    config: &mut SetConfig,
) -> Result<SettingsReport> {
    use fusion::scale::{ScaledSettings, SetScale, occupied_cells};
    check_distinct(scans)?;
    let Some(scale) = SetScale::of(points) else {
        bail!("{}: no two distinct points in any scan: nothing to measure or match", scans[0].file);
    };
    let auto = given.is_none();
    let stages = given.unwrap_or_else(|| scale.schedule());
    for stage in &stages {
        for (s, p) in scans.iter().zip(points) {
            let cells = occupied_cells(p, stage.voxel_m);
            if cells < MIN_CELLS {
                bail!(
                    "--schedule {}: stage {}/{} leaves {} in {cells} voxel cells (its points lie {:.3e} m apart over the surface, the scans' radius is {:.3e} m): expected at least {MIN_CELLS}; give stages whose voxels suit the scans (the finest near the spacing), or --schedule auto",
                    args.schedule,
                    stage.voxel_m,
                    stage.max_correspondence_m,
                    s.file,
                    scale.spacing_m,
                    scale.radius_m
                );
            }
        }
    }
    let scaled = ScaledSettings::of(&stages).context("an empty schedule")?;
    let huber_m = args.huber.unwrap_or(scaled.huber_m);
    let icp = &mut config.link.multiview.icp;
    icp.kernel = if huber_m > 0.0 { Kernel::Huber { width_m: huber_m } } else { Kernel::None };
    icp.translation_tolerance_m = scaled.translation_tolerance_m;
    config.link.step_sigma_m = scaled.step_sigma_m;
    config.link.multiview.moved_translation_m = scaled.moved_translation_m;
    config.stages = stages;
    Ok(SettingsReport {
        spacing_m: scale.spacing_m,
        radius_m: scale.radius_m,
        auto_schedule: auto,
        schedule: config.stages.iter().map(|s| [s.voxel_m, s.max_correspondence_m]).collect(),
        huber_m,
        step_sigma_m: scaled.step_sigma_m,
        translation_tolerance_m: scaled.translation_tolerance_m,
        moved_translation_m: scaled.moved_translation_m,
        only_covered: config.only_covered,
        degeneracy_ratio: config.link.multiview.icp.degeneracy_ratio.unwrap_or(0.0),
        line_ratio: config.link.multiview.icp.line_ratio.unwrap_or(0.0),
        normal_agreement_deg: args.normal_agreement,
        corner_ratio: args.corner_ratio,
        corner_everywhere: args.corner_everywhere,
        pipe: None,
        global: None,
    })
}

/// Where each scan's scanner stood, for the free-space test: as its input
/// states, at its frame's origin with `--scanner-at-origin`, else
/// estimated from its point spacing (unless `--no-viewpoint-estimate`)
/// and used where the range, or a scanner turning about an axis,
/// explains the spacing.
fn viewpoints(args: &MatchArgs, scans: &[InputScan]) -> Vec<Option<ViewpointReport>> {
    use rayon::prelude::*;
    scans
        .par_iter()
        .map(|s| {
            let known = |p: nalgebra::Point3<f64>, source: &str| ViewpointReport {
                position: p.coords.into(),
                source: source.into(),
                explained: None,
                used: true,
                axis: None,
            };
            if let Some(p) = s.viewpoint {
                return Some(known(p, "stated"));
            }
            if args.scanner_at_origin {
                return Some(known(nalgebra::Point3::origin(), "origin"));
            }
            if args.no_viewpoint_estimate {
                return None;
            }
            fusion::viewpoint::estimate(&s.points).map(|e| ViewpointReport {
                position: e.viewpoint.coords.into(),
                source: crate::documents::matching::ESTIMATED.into(),
                explained: Some(e.explained),
                used: e.taken(),
                axis: e.axis.map(Into::into),
            })
        })
        .collect()
}

/// The pipe the scans are, when every one's points lie on a tube all round
/// it ([`fusion::pipe::Tube::is_pipe`]) — with its scanner inside, where
/// the scan says where it stood (`viewpoints`: a cylinder scanned all round
/// from outside is not a pipe) —: the median radius, the least share on
/// the tube and the least share of the way round.
fn pipe_of(points: &[&[nalgebra::Point3<f32>]], viewpoints: &[Option<nalgebra::Point3<f64>>]) -> Option<PipeReport> {
    use rayon::prelude::*;
    let tubes: Vec<Option<fusion::pipe::Tube>> = points.par_iter().map(|p| fusion::pipe::tube_of(p)).collect();
    let tubes: Vec<fusion::pipe::Tube> = tubes.into_iter().collect::<Option<Vec<_>>>()?;
    let pipe = tubes
        .iter()
        .enumerate()
        .all(|(i, t)| t.is_pipe() && viewpoints.get(i).copied().flatten().is_none_or(|v| t.pipe.deviation_m(&v) < 0.0));
    if !pipe {
        return None;
    }
    let mut radii: Vec<f64> = tubes.iter().map(|t| t.pipe.radius_m).collect();
    radii.sort_by(f64::total_cmp);
    Some(PipeReport {
        radius_m: radii[radii.len() / 2],
        share: tubes.iter().map(|t| t.share).fold(1.0, f64::min),
        around: tubes.iter().map(|t| t.around).fold(1.0, f64::min),
    })
}

/// Refuses a scan whose points all lie at one position (nothing to match:
/// issue 34, U5 blamed its reduced count) and two scans that hold the same
/// points (the same file or E57 scan given twice: U3), naming them.
fn check_distinct(scans: &[InputScan]) -> Result<()> {
    use std::hash::{Hash, Hasher};
    let mut seen: std::collections::HashMap<u64, usize> = std::collections::HashMap::new();
    for (i, s) in scans.iter().enumerate() {
        if s.points.iter().all(|p| *p == s.points[0]) {
            bail!("{}: its {} points all lie at one position: expected a scan of surfaces", s.file, s.points.len());
        }
        let mut h = std::collections::hash_map::DefaultHasher::new();
        s.points.len().hash(&mut h);
        s.points.iter().for_each(|p| [p.x, p.y, p.z].map(f32::to_bits).hash(&mut h));
        let key = h.finish();
        if let Some(&j) = seen.get(&key)
            && scans[j].points == s.points
        {
            bail!("{} and {} hold the same points: expected each scan once", scans[j].file, s.file);
        }
        seen.insert(key, i);
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn scan(file: &str) -> InputScan {
        InputScan::empty(file, file)
    }

    /// A pipe is every scan on a tube all round it with its scanner inside
    /// where known: a column scanned all round from outside is not one,
    /// nor a set with one scan that is not a pipe's.
    #[test]
    fn a_pipe_is_every_scan_on_its_tube_with_the_scanner_inside() {
        use nalgebra::Point3;
        let tube = |radius: f64, seed: usize| -> Vec<Point3<f32>> {
            (0..20_000)
                .map(|k| {
                    let t = (k * 7919 + seed) as f64 * 0.618_033_988_7 * std::f64::consts::TAU;
                    let x = ((k * 104_729 + seed) % 20_000) as f64 / 20_000.0 * 8.0 - 4.0;
                    Point3::new(x, radius * t.cos(), radius * t.sin()).cast::<f32>()
                })
                .collect()
        };
        let (a, b) = (tube(0.5, 1), tube(0.5, 2));
        let found = pipe_of(&[&a, &b], &[Some(Point3::new(0.0, 0.1, -0.2)), None]).expect("a pipe");
        assert!((found.radius_m - 0.5).abs() < 0.005 && found.share > 0.99 && found.around == 1.0, "{found:?}");
        // Scanned from outside (the scanner 2 m from the axis): a column.
        assert!(pipe_of(&[&a, &b], &[Some(Point3::new(0.0, 2.0, 0.0)), None]).is_none());
        // One scan of a floor among them: not a pipe.
        let floor: Vec<Point3<f32>> =
            (0..20_000).map(|k| Point3::new((k % 200) as f32 * 0.05, (k / 200) as f32 * 0.05, 0.0)).collect();
        assert!(pipe_of(&[&a, &floor], &[None, None]).is_none());
    }

    #[test]
    fn no_overlap_blames_the_starts_only_at_the_first_stage() {
        let scans = [scan("a.ply"), scan("b.ply")];
        let error = |stage| fusion::FusionError::NoOverlap {
            scan: 1,
            pairs: 12,
            needed: 251,
            against: "the best earlier scan (0)".into(),
            partner: Some(0),
            stage,
        };
        let first = named(error(Some(1)), &scans).to_string();
        assert!(
            first.starts_with("b.ply and a.ply do not overlap at their start poses: 12 correspondences"),
            "{first}"
        );
        let later = named(error(Some(3)), &scans).to_string();
        assert!(
            later.starts_with("b.ply and a.ply do not overlap at stage 3 of the schedule")
                && later.contains("a match of stage 2 moved them apart")
                && !later.contains("start poses:"),
            "{later}"
        );
    }
}
