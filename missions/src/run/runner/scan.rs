//! A station's scan: the tilt read, the scan taken (or replayed) and
//! written, fused directly with the CPS pose, and joined to the scan
//! stations whose joint covariance the team carries.

use anyhow::{Result, bail};
use nalgebra::Point3;
use scanner::Tilt;
use scanner::io::{Format, PointCloud};

use super::Run;
use crate::journal::{ChainRecord, Scanned, StationKey, StepKey, Tilted};
use crate::mission::FusionMode;
use crate::products::fuse::{Correlation, ScanView};
use crate::run::backend::DeviceKind;

/// A scan as taken at a station: the tilt, the CPS pose they give the
/// scanner's body, the journal's record and the points (body frame).
struct Taken {
    tilt: Tilt,
    world_from_body: nalgebra::Isometry3<f64>,
    scanned: Scanned,
    cloud: PointCloud,
}

impl Run<'_> {
    /// The scan at station `index`: taken (or replayed), fused directly
    /// with the CPS pose into the recording and (direct fusion) the
    /// cloud's files, and joined to the scan stations; returns its file.
    pub(super) fn scan(&mut self, index: usize) -> Result<String> {
        let Taken { tilt, world_from_body, scanned, cloud } = self.take_scan(index)?;
        let mut view = self.scan_view(index, tilt, &scanned, cloud.points)?;
        let origin = self.origin;
        let part = self.obs.fusing(|| crate::output::part(&view.body, &world_from_body, &origin, view.label()));
        self.obs.scan("direct", &format!("scan{index:03}"), None, || {
            crate::output::viewed(&part, &view.body, &world_from_body)
        })?;
        if self.mission.fusion.mode == FusionMode::Direct {
            // Merged as it goes; the ICP modes need every scan's points at the end.
            view.body = Vec::new();
            let cloud = self.cloud.as_mut().ok_or_else(|| anyhow::anyhow!("the cloud's files are already finished"))?;
            cloud.push(&part, &mut self.obs.timings)?;
        }
        self.views.push(view);
        self.scan_times.push(self.obs.now());
        Ok(scanned.file)
    }

    /// Reads the tilt and takes a 3D scan at station `index`, written to
    /// `scans/` with its CPS pose — or, replayed, read back from there.
    fn take_scan(&mut self, index: usize) -> Result<Taken> {
        let key = StationKey { station: index };
        let tilted: Tilted = self.dispatch.step(&mut self.obs, key, StepKey::Tilt, DeviceKind::Tilt, |team, _| {
            team.tilt().map(|t| Tilted { roll_rad: t.roll_rad, pitch_rad: t.pitch_rad })
        })?;
        self.obs.tilted();
        let tilt = Tilt { roll_rad: tilted.roll_rad, pitch_rad: tilted.pitch_rad };
        let world_from_body = tilt.world_from_body(&self.team.parent());
        let name = format!("scans/scan{index:03}");
        let (dir, slices) = (&self.dir, self.mission.scan.slices);
        let mut taken = None;
        let scanned: Scanned =
            self.dispatch.step(&mut self.obs, key, StepKey::Scan, DeviceKind::Scanner, |team, obs| {
                let scan = obs.scanning(index, |on_slice| team.scan(slices, on_slice))?;
                let cloud = PointCloud::from_points(scan.points);
                let file = format!("{name}.3d");
                // The checksum of the bytes as they are written (no read-back).
                let crc = obs.scan_files(|| -> scanner::Result<u32> {
                    let crc = scanner::io::write_with_crc32(&dir.join(&file), &cloud, Format::ThreeDtk)?;
                    scanner::io::write_3dtk_pose(&dir.join(format!("{name}.pose")), &world_from_body)?;
                    Ok(crc)
                })?;
                let points = cloud.len();
                taken = Some(cloud);
                let crc32 = Some(crate::journal::crc32_hex(crc));
                Ok(Scanned { file, points, crc32, unix_time_s: Some(crate::journal::unix_now()) })
            })?;
        let cloud = match taken {
            Some(cloud) => cloud,
            None => {
                // Replayed: the file must be the one the journal names, and
                // its pose file (derived from the journal) is rewritten if
                // it went missing.
                crate::journal::check_scan_file(&self.dir, &scanned)?;
                let pose = self.dir.join(format!("{name}.pose"));
                if !pose.exists() {
                    scanner::io::write_3dtk_pose(&pose, &world_from_body)?;
                }
                self.obs.scan_files(|| scanner::io::read(&self.dir.join(&scanned.file)))?
            }
        };
        if cloud.len() != scanned.points {
            bail!("{}: {} points, but the journal recorded {}", scanned.file, cloud.len(), scanned.points);
        }
        self.obs.scanned(slices, self.mission.scan.resolution.degrees());
        Ok(Taken { tilt, world_from_body, scanned, cloud })
    }

    /// The scan at station `index` as the fusion sees it: its poses, its
    /// covariance and its correlation with the earlier scan stations (the
    /// station joins them: a robot alone, by odometry, carries none).
    fn scan_view(&mut self, index: usize, tilt: Tilt, scanned: &Scanned, body: Vec<Point3<f32>>) -> Result<ScanView> {
        let correlation = if self.clones_scan_stations() {
            let cross = (0..self.team.clones().min(self.views.len()))
                .map(|a| self.team.parent_clone_covariance(a))
                .collect::<cps::Result<Vec<_>>>()?;
            self.team.clone_parent();
            Correlation::Earlier(cross)
        } else {
            let link = ChainRecord::of(&self.team).link(&format!("scan station {index}"))?;
            self.team.set_anchor();
            Correlation::Chain(link)
        };
        let estimate = (self.team.parent(), self.team.parent_covariance(), correlation);
        let believed = Some(self.dispatch.team.parent_believed());
        let nominal = self.planned.dance.station_pose(index);
        let truth = self.dispatch.team.truth();
        let truth = truth.as_ref().map(|t| (&t.parent, &t.tilt));
        Ok(ScanView::new(index, scanned, body, estimate, tilt, (believed, &nominal), truth))
    }
}
