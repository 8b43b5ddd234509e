//! `cps-survey fuse RUN_DIR`: re-fuses a run's scans from its journal by a
//! `[fusion] mode` into `RUN_DIR/fusion/<mode>/` through the same output
//! stage as `run` — the cloud in the mission's formats, with `[pipe]` the
//! pipe inspection — and `fusion.json`.

use std::io::Write;
use std::path::PathBuf;

use anyhow::{Context, Result, bail};

use super::Outcome;
use crate::documents::run::{FusionReport, Timings};
use crate::mission::FusionMode;
use crate::view::recording::Recorder;

/// `fuse`'s arguments.
#[derive(Debug, Clone, clap::Args)]
pub struct FuseArgs {
    /// The run directory (holds mission.toml, journal.jsonl and scans/).
    pub run_dir: PathBuf,
    /// direct, icp or cps-icp (default: the mission's [fusion] mode).
    #[arg(long, value_parser = parse_mode)]
    pub mode: Option<FusionMode>,
    /// Print one JSON object instead of the table.
    #[arg(long)]
    pub json: bool,
}

fn parse_mode(s: &str) -> Result<FusionMode, String> {
    FusionMode::from_name(s).ok_or_else(|| {
        format!("unknown fusion mode \"{s}\"; expected one of {}", crate::mission::FUSION_MODES.join(", "))
    })
}

/// Runs `fuse`: exit 1 when a `[pipe]` fit of the re-fused cloud fails.
pub fn run(args: &FuseArgs, out: &mut dyn Write) -> Result<Outcome> {
    let dir = &args.run_dir;
    let _lock = crate::journal::directory::guard(dir, &format!("fuse {}", dir.display()))?;
    let run = crate::products::load::load(dir)?;
    let (mission, views) = (&run.mission, &run.views);
    if views.is_empty() {
        bail!("{}: the journal has no scans to fuse", dir.display());
    }
    let mode = args.mode.unwrap_or(mission.fusion.mode);
    // As the mission file says of `[fusion] mode`: a robot alone has
    // odometry, not CPS poses, to take as the priors.
    if mode == FusionMode::CpsIcp && mission.children.is_empty() {
        bail!(
            "{}: --mode cps-icp needs CPS poses, but the mission's team has no children; expected direct or icp",
            dir.display()
        );
    }
    // Where the results go, checked before the fusion runs.
    let target = dir.join("fusion").join(mode.name());
    crate::products::outputs::check_targets(mission, &target, &["fusion.json"])?;
    let frames = target.join("frames");
    crate::products::outputs::check_targets(mission, &frames, &[])?;
    std::fs::create_dir_all(&frames).with_context(|| format!("creating {}", frames.display()))?;
    let scanner = mission.scan.scanner_in_body();
    let fused = crate::products::fuse::fuse(views, mode, &mission.fusion, scanner, false, &mut |_, _| {})?;
    crate::products::fuse::write_frames(&frames, views, &fused)?;
    // The cloud's files, a scan at a time.
    let (origin, mut timings) = (mission.cloud_origin(), Timings::default());
    let points = views.iter().map(|v| v.body.len()).sum();
    let mut cloud = crate::products::outputs::CloudFiles::create(mission, &target, Some(points))?;
    for (v, f) in views.iter().zip(&fused.scans) {
        cloud.push(&crate::output::part(&v.body, &f.world_from_body, &origin, v.label()), &mut timings)?;
    }
    let written = cloud.finish(mission, &target, &mut Recorder::disabled(), &mut timings)?;
    let mut report = FusionReport::new(views, &fused);
    report.seconds = Some(fused.seconds);
    report.pipe = written.pipe.clone();
    crate::documents::write_file(&target.join("fusion.json"), &report)?;
    if args.json {
        crate::documents::write_line(out, &report)?;
    } else {
        crate::products::text::fusion(out, views, &fused)?;
        if let Some(pipe) = &report.pipe {
            crate::view::tables::pipe_summary(out, pipe)?;
        }
        writeln!(out, "outputs in {}: {}, fusion.json, frames/", target.display(), written.files.join(", "))?;
    }
    Ok(Outcome::passed(written.complete()))
}
