//! The end of a run: the scans fused, the output stage, the network
//! adjustment, the acceptance, the reports, the recording's end and the
//! journal's.

use std::time::Instant;

use anyhow::{Context, Result};
use nalgebra::Point3;

use super::{Run, RunSummary};
use crate::documents::adjustment::{AdjustmentOutcome, AdjustmentReport};
use crate::documents::run::{FusionReport, RunReport};
use crate::journal::{Derived, EndKey, EndRecord, Event};
use crate::mission::{FusionMode, Mission};
use crate::products::fuse::{Fused, ScanView};
use crate::products::outputs::Written;
use crate::products::report::StationRecord;

impl Run<'_> {
    /// Fuses the scans by the mission's `[fusion] mode` (direct fusion has
    /// merged them already), logs the refined scans and their ICP RMSE.
    fn fuse(&mut self) -> Result<Fused> {
        let (views, mode, obs) = (&self.views, self.mission.fusion.mode, &mut self.obs);
        let trace = obs.traces_icp();
        let scanner = self.mission.scan.scanner_in_body();
        let fused = obs.fusion(mode != FusionMode::Direct, |progress| {
            crate::products::fuse::fuse(views, mode, &self.mission.fusion, scanner, trace, progress)
        })?;
        if mode == FusionMode::Direct {
            return Ok(fused);
        }
        // Each scan moved once, into the cloud's files and the recording.
        if !fused.traces.is_empty() {
            let names: Vec<String> = views.iter().map(|v| format!("scan{:03}", v.station)).collect();
            let bodies: Vec<&[Point3<f32>]> = views.iter().map(|v| v.body.as_slice()).collect();
            obs.icp_iterations(&fused.traces, &names, &bodies)?;
        }
        let origin = self.origin;
        let cloud = self.cloud.as_mut().ok_or_else(|| anyhow::anyhow!("the cloud's files are already finished"))?;
        for ((view, at), f) in views.iter().zip(&self.scan_times).zip(&fused.scans) {
            let part = obs.fusing(|| crate::output::part(&view.body, &f.world_from_body, &origin, view.label()));
            obs.scan("icp", &format!("scan{:03}", view.station), Some(*at), || {
                crate::output::viewed(&part, &view.body, &f.world_from_body)
            })?;
            if let Some(rmse) = f.rmse_m {
                obs.icp_residual(at.0, rmse);
            }
            cloud.push(&part, &mut obs.timings)?;
        }
        Ok(fused)
    }

    /// The network adjustment of the journal's readings (with a total
    /// station): its listing `adjustment.txt` and its place in the
    /// recording; a network that cannot be adjusted is reported, not raised.
    fn adjust(&mut self) -> Result<Option<AdjustmentOutcome>> {
        if self.mission.total_station.is_none() {
            return Ok(None);
        }
        let path = self.dir.join("journal.jsonl");
        let read = crate::journal::read_without_cross_covariances(&path)?;
        let report = crate::products::adjust::network(self.mission, self.planned, &read, &path).and_then(|net| {
            crate::products::adjust::adjust(self.mission, self.planned, &net, &cps::batch::AdjustOptions::default())
        });
        Ok(Some(match report {
            Ok(report) => {
                let listing = self.dir.join("adjustment.txt");
                scanner::io::replace_file(&listing, crate::view::listing::listing(self.mission, &report).as_bytes())
                    .with_context(|| format!("writing {}", listing.display()))?;
                self.obs.adjusted(self.mission, &report)?;
                AdjustmentOutcome::Adjusted(Box::new(report))
            }
            Err(e) => {
                let error = format!("{e:#}");
                self.obs.warn(format!("network adjustment failed: {error}"))?;
                AdjustmentOutcome::Failed { error }
            }
        }))
    }

    /// The fusion, the output stage, the reports, the recording's end and
    /// the end of the journal.
    pub(super) fn finish(mut self, started: Instant) -> Result<RunSummary> {
        self.obs.dance_done();
        let fused = self.fuse()?;
        crate::products::fuse::write_frames(&self.dir.join("scans"), &self.views, &fused)?;
        self.obs.fusion_done();
        let fusion = FusionReport::new(&self.views, &fused);
        let cloud = self.cloud.take().ok_or_else(|| anyhow::anyhow!("the cloud's files are already finished"))?;
        let written: Written = cloud.finish(self.mission, &self.dir, &mut self.obs.rec, &mut self.obs.timings)?;
        let adjustment = self.adjust()?;
        let adjusted = adjustment.as_ref().and_then(AdjustmentOutcome::report);
        let accepted = mission_accepted(self.mission, &self.stations, &self.views, &fused, adjusted)
            && written.complete()
            && !matches!(adjustment, Some(AdjustmentOutcome::Failed { .. }));
        self.obs.info(format!("mission ends: acceptance {}", if accepted { "passed" } else { "FAILED" }))?;
        // The recording's end is not allowed to cost the reports: they are
        // written whatever it says, and its error (a full disk) comes after.
        let (recorded, recording_end) = self.obs.finish(started);
        let mut report = RunReport::new(
            self.mission,
            &self.stations,
            fusion,
            written.pipe.clone(),
            accepted,
            self.obs.timings,
            self.remeasured,
        )?;
        report.adjustment = adjustment;
        crate::documents::write_file(&self.dir.join("report.json"), &report)?;
        let adjusted = report.adjustment.as_ref().and_then(AdjustmentOutcome::report);
        crate::products::report::write_stations_csv(&self.dir.join("stations.csv"), &self.stations, adjusted)?;
        let viewer_warning = recording_end.map_err(|e| {
            anyhow::anyhow!(
                "{e:#}; report.json and stations.csv are written, `run --resume` writes the recording again"
            )
        })?;
        self.dispatch.note(Event::End(Derived { key: EndKey {}, data: EndRecord { accepted } }))?;
        let mut files: Vec<String> =
            ["mission.toml", "journal.jsonl", "scans/", "report.json", "stations.csv"].map(String::from).to_vec();
        if adjusted.is_some() {
            files.push("adjustment.txt".into());
        }
        files.extend(written.files);
        if recorded {
            files.push("mission.rrd".into());
        }
        Ok(RunSummary {
            dir: self.dir,
            stations: self.stations,
            accepted,
            replayed: self.dispatch.replayed,
            report,
            files,
            points: written.points,
            viewer_warning,
        })
    }
}

/// Whether the mission's acceptance tolerances hold. A station's error is
/// that of the mission's result: the fused scan pose where an ICP mode
/// refined it, else the station's CPS (or odometry) pose. Every station's
/// σxy is the network adjustment's where there is one, else the filter's.
fn mission_accepted(
    mission: &Mission,
    stations: &[StationRecord],
    views: &[ScanView],
    fused: &Fused,
    adjusted: Option<&AdjustmentReport>,
) -> bool {
    let sigma_xy = stations.last().map_or(0.0, |s| cps::sigma_xy2(&s.covariance).sqrt());
    let worst_station = match adjusted {
        Some(a) => a.stations.iter().map(|s| s.sigma_xy_m).fold(0.0, f64::max),
        None => stations.iter().map(|s| cps::sigma_xy2(&s.covariance).sqrt()).fold(0.0, f64::max),
    };
    let refined = |index: usize| -> Option<f64> {
        if fused.mode == FusionMode::Direct {
            return None;
        }
        let (view, f) = views.iter().zip(&fused.scans).find(|(v, _)| v.station == index)?;
        view.truth.map(|truth| crate::products::fuse::error_xy(&f.world_from_body, &truth))
    };
    // Without a truth (serial ports) there is no station error to check.
    let max_error = stations.iter().filter_map(|s| refined(s.index).or(s.error_xy_m)).fold(0.0, f64::max);
    mission.acceptance.max_final_sigma_xy_m.is_none_or(|m| sigma_xy <= m)
        && mission.acceptance.max_station_error_m.is_none_or(|m| max_error <= m)
        && mission.acceptance.max_station_sigma_xy_m.is_none_or(|m| worst_station <= m)
}
