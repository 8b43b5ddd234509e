//! What `match` writes: `poses.json`, the frames, `links.csv`, the merged
//! cloud and `match.rrd`; and the `--out` directory it may write into.

use std::path::Path;

use anyhow::{Context, Result, bail};
use fusion::scanset::SetResult;

use super::args::MatchArgs;
use crate::documents::matching::MatchReport;
use crate::scans::inputs::InputScan;
use crate::view::recording::{Recorder, Viewer};

/// poses.json, frames/NAME.frames, links.csv, the clouds and match.rrd.
pub(super) fn write_outputs(
    args: &MatchArgs,
    crs: &scanner::io::Crs,
    scans: &[InputScan],
    r: &SetResult,
    report: &MatchReport,
) -> Result<Vec<String>> {
    let dir = &args.out;
    let frames = dir.join("frames");
    remove_stale_outputs(dir, &args.formats)?;
    // A link in frames' place is replaced by match's own directory, never
    // followed.
    if std::fs::symlink_metadata(&frames).is_ok_and(|m| m.file_type().is_symlink()) {
        std::fs::remove_file(&frames).with_context(|| format!("removing the link {}", frames.display()))?;
    }
    std::fs::create_dir_all(&frames).with_context(|| format!("creating {}", frames.display()))?;
    crate::documents::write_file(&dir.join("poses.json"), report)?;
    let mut names = std::collections::HashSet::new();
    for (i, s) in scans.iter().enumerate() {
        // Unique, file-system-safe names (E57 scans may share theirs).
        let mut name: String =
            s.name.chars().map(|c| if c.is_ascii_alphanumeric() || "-_.".contains(c) { c } else { '_' }).collect();
        if !names.insert(name.clone()) {
            name = format!("{name}_{i}");
            names.insert(name.clone());
        }
        scanner::io::write_3dtk_frames(&frames.join(format!("{name}.frames")), &r.world_from_scan[i])?;
    }
    write_links(&dir.join("links.csv"), scans, report)?;
    let mut written = vec!["poses.json".to_string(), "frames/".into(), "links.csv".into()];
    let numbers: Vec<u16> = report.scans.iter().map(|s| s.number).collect();
    written.extend(write_clouds(dir, &args.formats, crs, scans, &numbers, r)?);
    let rrd = dir.join("match.rrd");
    // Recorded into a new file beside it (a link or file there removed,
    // not followed) and renamed into place when whole: a full disk leaves
    // no truncated recording, a link at match.rrd is replaced.
    let partial = dir.join("match.rrd.partial");
    scanner::io::remove_entry(&partial)?;
    let recorded = (|| -> Result<bool> {
        let mut rec = Recorder::new("match", Some(&partial), &Viewer::None, Vec::new())?;
        if !rec.enabled() {
            return Ok(false);
        }
        for (i, s) in scans.iter().enumerate() {
            rec.scan("before", &s.name, fusion::direct::transform(&s.points, &s.start))?;
            rec.scan("after", &s.name, fusion::direct::transform(&s.points, &r.world_from_scan[i]))?;
        }
        rec.finish()?;
        std::fs::rename(&partial, &rrd).with_context(|| format!("writing {}", rrd.display()))?;
        Ok(true)
    })();
    if !matches!(recorded, Ok(true)) {
        let _ = std::fs::remove_file(&partial);
    }
    if recorded.with_context(|| format!("writing {}", rrd.display()))? {
        written.push("match.rrd".into());
    }
    if let Some(bag) = &args.ros2_bag {
        let registered: Vec<crate::ros2::registered::Registered<'_>> = scans
            .iter()
            .zip(&report.scans)
            .enumerate()
            .map(|(i, (s, rs))| crate::ros2::registered::Registered {
                name: &rs.name,
                points: &s.points,
                intensity: s.intensity.as_deref(),
                world_from_scan: r.world_from_scan[i],
                covariance: r.covariance[i],
                gps_time_s: s.gps_time_s,
            })
            .collect();
        let about = r.world_from_scan.first().map_or_else(nalgebra::Vector3::zeros, |t| t.translation.vector);
        crate::ros2::registered::write(bag, &registered, &about, &format!("cps-survey match; crs {}", crs.name))?;
        written.push(bag.display().to_string());
    }
    Ok(written)
}

pub(super) fn write_links(path: &Path, scans: &[InputScan], report: &MatchReport) -> Result<()> {
    let mut text = String::from("source,targets,overlap,correspondences,rmse_m,converged,accepted,reason\n");
    let quote = |s: &str| format!("\"{}\"", s.replace('"', "\"\""));
    for l in &report.links {
        let targets: Vec<&str> = l.targets.iter().map(|&t| scans[t].file.as_str()).collect();
        let opt = |v: Option<String>| v.unwrap_or_default();
        text.push_str(&format!(
            "{},{},{},{},{},{},{},{}\n",
            quote(&scans[l.source].file),
            quote(&targets.join(";")),
            opt(l.overlap.map(|v| v.to_string())),
            opt(l.correspondences.map(|v| v.to_string())),
            opt(l.rmse_m.map(|v| format!("{v:.6}"))),
            l.converged,
            l.accepted,
            quote(l.reason.as_deref().unwrap_or("")),
        ));
    }
    scanner::io::replace_file(path, text.as_bytes()).with_context(|| format!("writing {}", path.display()))
}

/// The merged cloud in every format, a scan at a time, relative to the
/// first pose's position rounded to the kilometre (64-bit coordinates when
/// that is not zero) — [`crate::output`].
pub(super) fn write_clouds(
    dir: &Path,
    formats: &[String],
    crs: &scanner::io::Crs,
    scans: &[InputScan],
    numbers: &[u16],
    r: &SetResult,
) -> Result<Vec<String>> {
    let origin = crate::output::cloud_origin(&r.world_from_scan[0].translation.vector);
    let header = scanner::io::CloudHeader {
        origin,
        crs: Some(crs.clone()),
        points: Some(scans.iter().map(|s| s.points.len()).sum()),
        // What every input scan carries (intensity, colour, point times
        // of one base) or any (its time).
        intensity: scans.iter().all(|s| s.intensity.is_some()),
        source: true,
        timed: scans.iter().any(|s| s.gps_time_s.is_some()),
        color: scans.iter().all(|s| s.color.is_some()),
        time: point_time_base(scans),
    };
    let mut clouds = crate::output::CloudFiles::create(dir, formats, &header)?;
    // Each scan moved into the world once, into every file.
    for (i, s) in scans.iter().enumerate() {
        let label = crate::output::ScanLabel { name: s.name.clone(), number: numbers[i], gps_time_s: s.gps_time_s };
        let mut part = crate::output::part(&s.points, &r.world_from_scan[i], &origin, label);
        part.intensity = s.intensity.clone().filter(|_| header.intensity);
        part.color = s.color.clone().filter(|_| header.color);
        part.time = s.time.as_ref().filter(|_| header.time.is_some()).map(|(t, _)| t.clone());
        part.time_base = header.time.unwrap_or_default();
        clouds.push(&part)?;
    }
    clouds.finish()
}

/// The base of the scans' point times, when every scan has times and all
/// count from the same epoch (else the merged cloud carries none).
pub(super) fn point_time_base(scans: &[InputScan]) -> Option<scanner::io::TimeBase> {
    let bases: Option<Vec<_>> = scans.iter().map(|s| s.time.as_ref().map(|(_, b)| *b)).collect();
    let bases = bases?;
    bases.first().copied().filter(|b| bases.iter().all(|c| c == b))
}

/// Refuses, before any work, an `--out` that is not `match`'s to write
/// into: a run directory (its cloud is the run's, under the run's lock),
/// or a directory that holds one of the inputs (an input named like an
/// output would be overwritten).
pub(super) fn check_out(args: &MatchArgs) -> Result<()> {
    let out = &args.out;
    if out.join("journal.jsonl").exists() {
        bail!(
            "--out {}: a run directory (it holds journal.jsonl): match writes its outputs into a directory of its own",
            out.display()
        );
    }
    // An output's name taken by something match cannot replace (a
    // directory where a file goes, a file where frames/ goes) is refused
    // now, not after the registration (with a `.partial` left).
    let files = ["poses.json", "links.csv", "match.rrd"].map(String::from);
    let clouds = args.formats.iter().map(|f| crate::output::cloud_file(f));
    if let Some((name, meta)) = crate::output::taken(out, files.into_iter().chain(clouds)) {
        bail!(
            "--out {}: {name} is {}: expected match's output file there (or nothing)",
            out.display(),
            if meta.is_dir() { "a directory" } else { "not a file" }
        );
    }
    let frames = out.join("frames");
    if std::fs::symlink_metadata(&frames).is_ok_and(|m| !m.is_dir() && !m.file_type().is_symlink()) {
        bail!("--out {}: frames is a file: expected match's frames/ directory there (or nothing)", out.display());
    }
    let Ok(out_real) = out.canonicalize() else { return Ok(()) }; // not there yet: nothing in it
    for input in &args.inputs {
        let Ok(real) = input.canonicalize() else { continue }; // reading names it
        let holds = if real.is_dir() { real == out_real } else { real.parent() == Some(out_real.as_path()) };
        if holds {
            bail!(
                "--out {}: holds the input {}: expected a directory apart from the scans (its outputs would \
                 overwrite what they were made from)",
                out.display(),
                input.display()
            );
        }
    }
    Ok(())
}

/// A previous `match`'s outputs in `dir` that this one will not rewrite
/// — clouds of other formats, frames of other scans — are removed, so no
/// stale result stands beside the new ones. Only `match`'s own names.
pub(super) fn remove_stale_outputs(dir: &Path, formats: &[String]) -> Result<()> {
    for format in crate::mission::OUTPUT_FORMATS.iter().filter(|f| !formats.iter().any(|g| g == *f)) {
        let path = dir.join(crate::output::cloud_file(format));
        if std::fs::symlink_metadata(&path).is_ok_and(|m| m.is_file() || m.file_type().is_symlink()) {
            std::fs::remove_file(&path).with_context(|| format!("removing the stale {}", path.display()))?;
        }
    }
    let frames = dir.join("frames");
    if std::fs::symlink_metadata(&frames).is_ok_and(|m| m.is_dir()) {
        for entry in std::fs::read_dir(&frames).with_context(|| format!("reading {}", frames.display()))? {
            let path = entry.with_context(|| format!("reading {}", frames.display()))?.path();
            if path.extension().is_some_and(|e| e == "frames") {
                std::fs::remove_file(&path).with_context(|| format!("removing the stale {}", path.display()))?;
            }
        }
    }
    Ok(())
}
