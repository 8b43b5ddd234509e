//! A cloud file written part by part — a scan at a time — so that writing
//! a merged cloud needs one part in memory, not the whole: every format
//! but PCD's `binary_compressed` (one LZF block of every column) streams.
//! Like [`super::write`], it writes a temporary file and renames it when
//! finished; a writer dropped unfinished removes it.

use std::fs::File;
use std::io::{BufWriter, Seek, SeekFrom, Write};
use std::path::{Path, PathBuf};

use super::e57::E57Stream;
use super::las::{LasStream, convert_to_copc};
use super::{
    CloudHeader, Format, Hashed, PcdData, PointCloud, against, check, create_hashed, finish_hashed, finish_write, pcd,
    ply, remove_entry, temporary, text,
};
use crate::error::{Location, Result, ScannerError};

/// A cloud file being written part by part: [`CloudWriter::create`] with
/// what the cloud is ([`CloudHeader`]), [`CloudWriter::push`] each part,
/// [`CloudWriter::finish`].
#[derive(Debug)]
pub struct CloudWriter {
    path: PathBuf,
    tmp: PathBuf,
    header: CloudHeader,
    written: usize,
    sink: Option<Sink>,
}

#[derive(Debug)]
enum Sink {
    /// One byte stream after its header (hashed on the way); `header` is
    /// kept when it holds a count placeholder, to be patched.
    Stream {
        w: BufWriter<Hashed<File>>,
        kind: Kind,
        header: Option<Vec<u8>>,
    },
    /// PCD `binary_compressed`: the parts gathered, compressed at the end.
    Gathered(PointCloud),
    Las(LasStream),
    /// LAZ into `laz`, re-ordered into COPC at the end.
    Copc {
        laz: PathBuf,
        stream: LasStream,
    },
    E57(Box<E57Stream>),
}

#[derive(Debug)]
enum Kind {
    ThreeDtk,
    Xyz,
    Ply(ply_rs_bw::ply::Header),
    Pcd(PcdData),
}

impl CloudWriter {
    /// Starts writing `path` in `format` for a cloud that `header`
    /// describes.
    pub fn create(path: &Path, format: Format, header: CloudHeader) -> Result<Self> {
        if !header.origin.iter().all(|v| v.is_finite()) {
            return Err(ScannerError::file(
                path,
                Location::File,
                format!("origin {:?}: expected finite coordinates", header.origin.as_slice()),
            ));
        }
        let tmp = temporary(path);
        // COPC is written as LAZ beside it first.
        let mut name = tmp.file_name().map(|n| n.to_os_string()).unwrap_or_default();
        name.push(".laz");
        let copc_laz = tmp.with_file_name(name);
        // Whatever is at the temporary names (a link left there, a stale
        // file) is removed, not followed: every sink creates its file anew.
        for stale in [&tmp, &copc_laz] {
            remove_entry(stale)?;
        }
        let open = |kind: Kind| -> Result<Sink> {
            let mut w = create_hashed(&tmp).map_err(|e| against(path, e))?;
            let mut bytes = Vec::new();
            match &kind {
                Kind::Ply(h) => ply::write_header(&mut bytes, h),
                Kind::Pcd(data) => pcd::write_header(&mut bytes, &header, *data),
                Kind::ThreeDtk | Kind::Xyz => Ok(()),
            }
            .and_then(|()| w.write_all(&bytes))
            .map_err(|e| {
                let _ = std::fs::remove_file(&tmp);
                ScannerError::io(path, e)
            })?;
            let counted = matches!(kind, Kind::Ply(_) | Kind::Pcd(_));
            Ok(Sink::Stream { w, kind, header: (counted && header.points.is_none()).then_some(bytes) })
        };
        let sink = match format {
            Format::ThreeDtk => open(Kind::ThreeDtk)?,
            Format::Xyz => open(Kind::Xyz)?,
            Format::Ply(e) => open(Kind::Ply(ply::cloud_header(&header, e)))?,
            Format::Pcd(PcdData::BinaryCompressed) => Sink::Gathered(PointCloud {
                origin: header.origin,
                crs: header.crs.clone(),
                intensity: header.intensity.then(Vec::new),
                source: header.source.then(Vec::new),
                color: header.color.then(Vec::new),
                time: header.time.map(|_| Vec::new()),
                time_base: header.time.unwrap_or_default(),
                ..PointCloud::default()
            }),
            Format::Pcd(data) => open(Kind::Pcd(data))?,
            Format::Las => Sink::Las(LasStream::create(&tmp, &header, false).map_err(|e| against(path, e))?),
            Format::Laz => Sink::Las(LasStream::create(&tmp, &header, true).map_err(|e| against(path, e))?),
            Format::Copc => {
                if header.points == Some(0) {
                    return Err(ScannerError::file(
                        path,
                        Location::File,
                        "a COPC file needs at least one point; the cloud has none",
                    ));
                }
                let stream = LasStream::create(&copc_laz, &header, true).map_err(|e| against(path, e))?;
                Sink::Copc { laz: copc_laz, stream }
            }
            Format::E57 => Sink::E57(Box::new(E57Stream::create(&tmp, &header).map_err(|e| against(path, e))?)),
        };
        Ok(Self { path: path.to_path_buf(), tmp, header, written: 0, sink: Some(sink) })
    }

    /// Appends `part`: its points (relative to the header's origin), their
    /// intensities, scans, colours and times as the header says, and its
    /// scans (their point ranges within the part).
    pub fn push(&mut self, part: &PointCloud) -> Result<()> {
        let path = self.path.clone();
        let refuse = |message: String| ScannerError::file(&path, Location::File, message);
        check(part).map_err(&refuse)?;
        let h = &self.header;
        if part.origin != h.origin {
            return Err(refuse(format!(
                "a part at origin {:?}: expected the cloud's origin {:?}",
                part.origin.as_slice(),
                h.origin.as_slice()
            )));
        }
        if part.intensity.is_some() != h.intensity || part.source.is_some() != h.source {
            return Err(refuse(format!(
                "a part with{} intensities and with{} scan indices: expected the cloud's fields (intensity {}, scan {})",
                if part.intensity.is_some() { "" } else { "out" },
                if part.source.is_some() { "" } else { "out" },
                h.intensity,
                h.source
            )));
        }
        let part_time = part.time.as_ref().map(|_| part.time_base);
        if part.color.is_some() != h.color || part_time != h.time {
            return Err(refuse(format!(
                "a part with colours {} and times {:?}: expected the cloud's (colours {}, times {:?})",
                part.color.is_some(),
                part_time,
                h.color,
                h.time
            )));
        }
        if let Some(n) = h.points
            && self.written + part.len() > n
        {
            return Err(refuse(format!(
                "{} points after this part: expected {n} in all (the header's count)",
                self.written + part.len(),
            )));
        }
        match self.sink.as_mut() {
            None => return Err(refuse("the file is already finished".into())),
            Some(Sink::Stream { w, kind, .. }) => match kind {
                Kind::ThreeDtk => text::write_3dtk(w, part),
                Kind::Xyz => text::write_xyz(w, part),
                Kind::Ply(h) => ply::write_points(w, part, h),
                Kind::Pcd(data) => pcd::write_points(w, part, *data),
            }
            .map_err(|e| ScannerError::io(&path, e))?,
            Some(Sink::Gathered(cloud)) => append(cloud, part),
            Some(Sink::Las(stream) | Sink::Copc { stream, .. }) => stream.push(part).map_err(|e| against(&path, e))?,
            Some(Sink::E57(stream)) => stream.push(part).map_err(|e| against(&path, e))?,
        }
        self.written += part.len();
        Ok(())
    }

    /// Finishes the file and renames it into place; returns the CRC-32 of
    /// its bytes where they were hashed on the way (3DTK, PLY, XYZ, PCD).
    pub fn finish(mut self) -> Result<Option<u32>> {
        let (path, tmp) = (self.path.clone(), self.tmp.clone());
        if let Some(n) = self.header.points
            && self.written != n
        {
            // Dropped unfinished: its files go.
            return Err(ScannerError::file(
                &path,
                Location::File,
                format!("{} points written: expected {n} (the header's count)", self.written),
            ));
        }
        let Some(sink) = self.sink.take() else {
            return Err(ScannerError::file(&path, Location::File, "the file is already finished"));
        };
        let written = self.written;
        let result = match sink {
            Sink::Stream { w, kind, header } => finish_stream(&tmp, w, &kind, header, written),
            Sink::Gathered(cloud) => {
                super::with_writer(&tmp, |w| pcd::write(w, &cloud, PcdData::BinaryCompressed)).map(Some)
            }
            Sink::Las(stream) => stream.finish().map(|()| None),
            Sink::Copc { laz, stream } => {
                let result = stream.finish().and_then(|()| convert_to_copc(&laz, &tmp)).map(|()| None);
                let _ = std::fs::remove_file(&laz);
                result
            }
            Sink::E57(stream) => stream.finish(&self.header).map(|()| None),
        };
        finish_write(&path, &tmp, result)
    }
}

impl Drop for CloudWriter {
    /// An unfinished file is removed (with COPC's LAZ).
    fn drop(&mut self) {
        if let Some(sink) = self.sink.take() {
            if let Sink::Copc { laz, .. } = &sink {
                let _ = std::fs::remove_file(laz);
            }
            drop(sink);
            let _ = std::fs::remove_file(&self.tmp);
        }
    }
}

/// Flushes and syncs a byte stream; its header's count placeholder, if
/// any, overwritten with the count (then the bytes' CRC no longer holds).
fn finish_stream(
    tmp: &Path,
    mut w: BufWriter<Hashed<File>>,
    kind: &Kind,
    header: Option<Vec<u8>>,
    written: usize,
) -> Result<Option<u32>> {
    let Some(header) = header else {
        return finish_hashed(tmp, w).map(Some);
    };
    w.flush().map_err(|e| ScannerError::io(tmp, e))?;
    let patched = match kind {
        Kind::Ply(_) => ply::patch_count(&header, written),
        Kind::Pcd(_) => pcd::patch_count(&header, written),
        Kind::ThreeDtk | Kind::Xyz => None,
    }
    .ok_or_else(|| {
        ScannerError::file(tmp, Location::File, "the header's count placeholder is not where it was written")
    })?;
    let mut file = w.into_inner().map_err(|e| ScannerError::io(tmp, e.into_error()))?.inner;
    file.seek(SeekFrom::Start(0))
        .and_then(|_| file.write_all(&patched))
        .and_then(|()| file.sync_all())
        .map_err(|e| ScannerError::io(tmp, e))?;
    Ok(None)
}

/// Appends `part` to `cloud` (same origin and fields).
fn append(cloud: &mut PointCloud, part: &PointCloud) {
    let start = cloud.points.len();
    cloud.points.extend_from_slice(&part.points);
    if let (Some(all), Some(more)) = (cloud.intensity.as_mut(), part.intensity.as_ref()) {
        all.extend_from_slice(more);
    }
    if let (Some(all), Some(more)) = (cloud.source.as_mut(), part.source.as_ref()) {
        all.extend_from_slice(more);
    }
    if let (Some(all), Some(more)) = (cloud.color.as_mut(), part.color.as_ref()) {
        all.extend_from_slice(more);
    }
    if let (Some(all), Some(more)) = (cloud.time.as_mut(), part.time.as_ref()) {
        all.extend_from_slice(more);
    }
    cloud.scans.extend(
        part.scans
            .iter()
            .map(|s| super::ScanInfo { points: s.points.start + start..s.points.end + start, ..s.clone() }),
    );
}
