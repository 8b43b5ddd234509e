//! PCD v0.7 (Point Cloud Library), written by hand: the header, then
//! `ascii`, `binary` (point records) or `binary_compressed` (u32 compressed
//! size, u32 raw size, an LZF stream of the field-major data). Reads x, y,
//! z and an optional `intensity` of types F4/F8/I1–I8/U1–U8; other fields
//! are skipped. Reads and writes colour as PCL packs it (`rgb`, F4 or U4:
//! the bits 0x00RRGGBB, written F4 as PCL declares it; `rgba` U4) and a time field (`time`, `timestamp`
//! or `gps_time`, F8 when written; GPS time when the header's comment says
//! so). Points with a non-finite coordinate are PCL's marker for "no
//! return" in organised clouds and are left out.

use std::io::Write;
use std::path::Path;

use nalgebra::Point3;

use super::{PointCloud, read_bytes};
use crate::error::{Location, Result, ScannerError};

/// PCD data encoding.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PcdData {
    /// Text.
    Ascii,
    /// Binary point records.
    Binary,
    /// LZF-compressed, field-major.
    BinaryCompressed,
}

#[derive(Debug, Clone)]
struct Field {
    name: String,
    size: usize,
    kind: u8,
    count: usize,
}

impl Field {
    fn bytes(&self) -> usize {
        self.size * self.count
    }

    /// The first element of this field from little-endian bytes.
    fn value(&self, b: &[u8]) -> Option<f64> {
        let a = |n: usize| -> Option<[u8; 8]> {
            let mut out = [0u8; 8];
            out[..n].copy_from_slice(b.get(..n)?);
            Some(out)
        };
        Some(match (self.kind, self.size) {
            (b'F', 4) => f64::from(f32::from_le_bytes(b.get(..4)?.try_into().ok()?)),
            (b'F', 8) => f64::from_le_bytes(b.get(..8)?.try_into().ok()?),
            (b'U', n @ (1 | 2 | 4 | 8)) => u64::from_le_bytes(a(n)?) as f64,
            (b'I', n @ (1 | 2 | 4 | 8)) => {
                let shift = 64 - 8 * n as u32;
                ((i64::from_le_bytes(a(n)?) << shift) >> shift) as f64
            }
            _ => return None,
        })
    }

    /// The first element's 32 bits (PCL's packed colour), as a number.
    fn bits(&self, b: &[u8]) -> Option<f64> {
        (self.size == 4).then(|| b.get(..4).map(|b| f64::from(u32::from_le_bytes([b[0], b[1], b[2], b[3]]))))?
    }
}

/// The names PCD time fields go by.
const TIME_NAMES: [&str; 3] = ["time", "timestamp", "gps_time"];

/// Packed PCL colour bits 0x00RRGGBB as our 16-bit colour.
fn unpack_rgb(bits: u32) -> [u16; 3] {
    [16, 8, 0].map(|shift| super::color_from_8bit((bits >> shift) as u8))
}

/// Our colour as PCL's packed bits.
fn pack_rgb(rgb: [u16; 3]) -> u32 {
    rgb.iter().fold(0, |bits, &v| (bits << 8) | u32::from(super::color_to_8bit(v)))
}

/// Where each field starts when fields of `width(f)` follow each other.
fn starts(fields: &[Field], width: impl Fn(&Field) -> usize) -> Vec<usize> {
    fields
        .iter()
        .scan(0, |c, f| {
            let s = *c;
            *c += width(f);
            Some(s)
        })
        .collect()
}

struct Header {
    fields: Vec<Field>,
    points: usize,
    data: PcdData,
    /// Byte offset of the data.
    offset: usize,
    /// VIEWPOINT's translation: where the points were seen from.
    viewpoint: [f64; 3],
}

fn parse_header(path: &Path, bytes: &[u8]) -> Result<Header> {
    let err = |line: usize, msg: String| ScannerError::file(path, Location::Line(line), msg);
    let mut pos = 0;
    let mut line_no = 0;
    let (mut names, mut sizes, mut kinds, mut counts) = (Vec::new(), Vec::new(), Vec::new(), Vec::new());
    let mut points = None;
    let (mut width, mut height) = (None, None);
    let mut viewpoint = [0.0; 3];
    loop {
        let end =
            bytes[pos..].iter().position(|&b| b == b'\n').map(|e| pos + e).ok_or_else(|| {
                ScannerError::file(path, Location::Byte(pos as u64), "header ends without a DATA line")
            })?;
        line_no += 1;
        let line = std::str::from_utf8(&bytes[pos..end])
            .map_err(|_| ScannerError::file(path, Location::Byte(pos as u64), "header is not text"))?
            .trim();
        pos = end + 1;
        if line.is_empty() || line.starts_with('#') {
            continue;
        }
        let mut toks = line.split_whitespace();
        let key = toks.next().unwrap_or_default().to_ascii_uppercase();
        let rest: Vec<&str> = toks.collect();
        let usize_list = |what: &str| -> Result<Vec<usize>> {
            rest.iter()
                .map(|t| t.parse().map_err(|_| err(line_no, format!("{what}: '{t}' is not a non-negative integer"))))
                .collect()
        };
        match key.as_str() {
            "VERSION" => {}
            "VIEWPOINT" => {
                let v: Vec<f64> = rest.iter().filter_map(|t| t.parse().ok()).filter(|v: &f64| v.is_finite()).collect();
                if v.len() != 7 {
                    return Err(err(
                        line_no,
                        format!("VIEWPOINT '{}': expected 7 finite numbers (tx ty tz qw qx qy qz)", rest.join(" ")),
                    ));
                }
                viewpoint = [v[0], v[1], v[2]];
            }
            "FIELDS" => names = rest.iter().map(|s| s.to_string()).collect(),
            "SIZE" => sizes = usize_list("SIZE")?,
            "TYPE" => {
                kinds = rest
                    .iter()
                    .map(|t| match t.as_bytes() {
                        [k @ (b'F' | b'I' | b'U')] => Ok(*k),
                        _ => Err(err(line_no, format!("TYPE '{t}': expected F, I or U"))),
                    })
                    .collect::<Result<_>>()?
            }
            "COUNT" => counts = usize_list("COUNT")?,
            "WIDTH" => width = usize_list("WIDTH")?.first().copied(),
            "HEIGHT" => height = usize_list("HEIGHT")?.first().copied(),
            "POINTS" => points = usize_list("POINTS")?.first().copied(),
            "DATA" => {
                let data = match rest.first().map(|s| s.to_ascii_lowercase()).as_deref() {
                    Some("ascii") => PcdData::Ascii,
                    Some("binary") => PcdData::Binary,
                    Some("binary_compressed") => PcdData::BinaryCompressed,
                    other => {
                        return Err(err(
                            line_no,
                            format!("DATA {other:?}: expected ascii, binary or binary_compressed"),
                        ));
                    }
                };
                if counts.is_empty() {
                    counts = vec![1; names.len()];
                }
                if names.is_empty()
                    || sizes.len() != names.len()
                    || kinds.len() != names.len()
                    || counts.len() != names.len()
                {
                    return Err(err(
                        line_no,
                        format!(
                            "FIELDS ({}), SIZE ({}), TYPE ({}) and COUNT ({}) must have the same, non-zero length",
                            names.len(),
                            sizes.len(),
                            kinds.len(),
                            counts.len()
                        ),
                    ));
                }
                let fields: Vec<Field> = names
                    .into_iter()
                    .zip(sizes)
                    .zip(kinds)
                    .zip(counts)
                    .map(|(((name, size), kind), count)| Field { name, size, kind, count })
                    .collect();
                let points = match (points, width, height) {
                    (Some(n), ..) => n,
                    (None, Some(w), Some(h)) => w.checked_mul(h).ok_or_else(|| {
                        err(
                            line_no,
                            format!("WIDTH {w} × HEIGHT {h} overflows: expected a point count a file can hold"),
                        )
                    })?,
                    _ => return Err(err(line_no, "no POINTS (or WIDTH and HEIGHT) before DATA".into())),
                };
                return Ok(Header { fields, points, data, offset: pos, viewpoint });
            }
            other => return Err(err(line_no, format!("unknown header key '{other}'"))),
        }
    }
}

/// Where the points of the PCD at `path` were seen from: its header's
/// VIEWPOINT translation (PCL's "acquisition viewpoint"; the origin when
/// the header has none).
pub fn viewpoint(path: &Path) -> Result<Point3<f64>> {
    use std::io::Read;
    let mut head = Vec::new();
    std::fs::File::open(path)
        .and_then(|f| f.take(HEADER_LIMIT).read_to_end(&mut head))
        .map_err(|e| ScannerError::file(path, Location::File, e.to_string()))?;
    Ok(Point3::from(parse_header(path, &head)?.viewpoint))
}

/// The longest header [`viewpoint`] reads.
const HEADER_LIMIT: u64 = 1 << 16;

pub(super) fn read(path: &Path) -> Result<PointCloud> {
    let bytes = read_bytes(path)?;
    let h = parse_header(path, &bytes)?;
    let find = |n: &str| h.fields.iter().position(|f| f.name == n);
    let (Some(ix), Some(iy), Some(iz)) = (find("x"), find("y"), find("z")) else {
        return Err(ScannerError::file(path, Location::File, "FIELDS lacks x, y or z"));
    };
    let ii = find("intensity");
    let irgb = find("rgb").or_else(|| find("rgba")).filter(|&f| h.fields[f].size == 4);
    let itime = TIME_NAMES.iter().find_map(|n| find(n));
    // Slots: x, y, z, then intensity, colour, time as present.
    let wanted: Vec<usize> = [Some(ix), Some(iy), Some(iz), ii, irgb, itime].into_iter().flatten().collect();
    let slot_of = |f: Option<usize>| f.and_then(|f| wanted.iter().position(|&w| w == f));
    let (si, srgb, stime) = (slot_of(ii), slot_of(irgb), slot_of(itime));
    // The colour's bits, not its value as a float.
    let get = |f: usize, b: &[u8]| if Some(f) == irgb { h.fields[f].bits(b) } else { h.fields[f].value(b) };
    for &f in &wanted {
        if get(f, &[0u8; 8]).is_none() {
            let fd = &h.fields[f];
            return Err(ScannerError::file(
                path,
                Location::File,
                format!("field {} has type {}{}: unsupported", fd.name, fd.kind as char, fd.size),
            ));
        }
    }
    let record: usize = h.fields.iter().map(Field::bytes).sum();
    let n = h.points;
    let data = &bytes[h.offset..];
    // The header's count is a claim, never a buffer size: the data bytes
    // bound what is reserved (an ASCII point takes at least two bytes, a
    // binary one its record, compressed data at most ~90 times its bytes),
    // and the counts are checked against the data below.
    let room = match h.data {
        PcdData::Ascii => data.len() / 2 + 1,
        PcdData::Binary => data.len() / record.max(1),
        PcdData::BinaryCompressed => data.len().saturating_mul(100) / record.max(1),
    };
    // values[k][i]: wanted field k of point i.
    let mut values: Vec<Vec<f64>> = vec![Vec::with_capacity(n.min(room)); wanted.len()];
    match h.data {
        PcdData::Ascii => {
            let text = std::str::from_utf8(data).map_err(|e| {
                ScannerError::file(path, Location::Byte((h.offset + e.valid_up_to()) as u64), "ASCII data is not text")
            })?;
            let header_lines = bytes[..h.offset].iter().filter(|&&b| b == b'\n').count();
            let columns = starts(&h.fields, |f| f.count);
            let mut read = 0;
            for (k, line) in text.lines().enumerate() {
                if line.trim().is_empty() {
                    continue;
                }
                let toks: Vec<&str> = line.split_whitespace().collect();
                for (slot, &f) in wanted.iter().enumerate() {
                    let t = toks.get(columns[f]).ok_or_else(|| {
                        ScannerError::file(
                            path,
                            Location::Line(header_lines + k + 1),
                            format!(
                                "{} values: expected {}",
                                toks.len(),
                                columns.last().map_or(0, |c| c + h.fields[h.fields.len() - 1].count)
                            ),
                        )
                    })?;
                    let v: f64 = if t.eq_ignore_ascii_case("nan") {
                        f64::NAN
                    } else if Some(f) == irgb {
                        // PCL prints the packed colour as an integer, also
                        // when its type is F; some writers as the float of
                        // its bits.
                        let float = || t.parse::<f32>().ok().filter(|_| h.fields[f].kind == b'F').map(f32::to_bits);
                        let bits = t.parse::<u32>().ok().or_else(float);
                        bits.map(f64::from).ok_or_else(|| {
                            ScannerError::file(
                                path,
                                Location::Line(header_lines + k + 1),
                                format!("'{t}' is not a packed colour"),
                            )
                        })?
                    } else {
                        t.parse().map_err(|_| {
                            ScannerError::file(
                                path,
                                Location::Line(header_lines + k + 1),
                                format!("'{t}' is not a number"),
                            )
                        })?
                    };
                    values[slot].push(v);
                }
                read += 1;
            }
            if read != n {
                return Err(ScannerError::file(
                    path,
                    Location::File,
                    format!("{read} points in the data: the header says {n}"),
                ));
            }
        }
        PcdData::Binary => {
            if n.checked_mul(record).is_none_or(|need| data.len() < need) {
                return Err(ScannerError::file(
                    path,
                    Location::Byte(bytes.len() as u64),
                    format!(
                        "truncated: {n} points of {record} bytes need {} data bytes, found {}",
                        n as u128 * record as u128,
                        data.len()
                    ),
                ));
            }
            let offsets = starts(&h.fields, |f| f.bytes());
            for i in 0..n {
                let rec = &data[i * record..(i + 1) * record];
                for (slot, &f) in wanted.iter().enumerate() {
                    values[slot].push(get(f, &rec[offsets[f]..]).unwrap_or(f64::NAN));
                }
            }
        }
        PcdData::BinaryCompressed => {
            let word = |at: usize| -> Result<usize> {
                data.get(at..at + 4).map(|b| u32::from_le_bytes([b[0], b[1], b[2], b[3]]) as usize).ok_or_else(|| {
                    ScannerError::file(
                        path,
                        Location::Byte((h.offset + at) as u64),
                        "truncated: expected the compressed and uncompressed sizes (2 × u32)",
                    )
                })
            };
            let (compressed, raw) = (word(0)?, word(4)?);
            if n.checked_mul(record) != Some(raw) {
                return Err(ScannerError::file(
                    path,
                    Location::Byte((h.offset + 4) as u64),
                    format!(
                        "uncompressed size {raw}: expected {} ({n} points × {record} bytes)",
                        n as u128 * record as u128
                    ),
                ));
            }
            if raw > room.saturating_mul(record) {
                return Err(ScannerError::file(
                    path,
                    Location::Byte((h.offset + 4) as u64),
                    format!("uncompressed size {raw}: more than LZF can expand {} bytes to", data.len()),
                ));
            }
            let stream = data.get(8..8 + compressed).ok_or_else(|| {
                ScannerError::file(
                    path,
                    Location::Byte(bytes.len() as u64),
                    format!(
                        "truncated: {compressed} compressed bytes announced, {} present",
                        data.len().saturating_sub(8)
                    ),
                )
            })?;
            let plain = if raw == 0 {
                Vec::new()
            } else {
                lzf::decompress(stream, raw).map_err(|e| {
                    ScannerError::file(path, Location::Byte((h.offset + 8) as u64), format!("corrupt LZF data: {e}"))
                })?
            };
            if plain.len() != raw {
                return Err(ScannerError::file(
                    path,
                    Location::Byte((h.offset + 8) as u64),
                    format!("LZF data expands to {} bytes: expected {raw}", plain.len()),
                ));
            }
            // Field-major: all of field 0, then all of field 1, ...
            let field_start = starts(&h.fields, |f| f.bytes() * n);
            for (slot, &f) in wanted.iter().enumerate() {
                let fd = &h.fields[f];
                values[slot]
                    .extend((0..n).map(|i| get(f, &plain[field_start[f] + i * fd.bytes()..]).unwrap_or(f64::NAN)));
            }
        }
    }
    let comments = std::str::from_utf8(&bytes[..h.offset]).unwrap_or_default();
    let mut cloud = PointCloud {
        points: Vec::with_capacity(n),
        intensity: si.map(|_| Vec::with_capacity(n)),
        color: srgb.map(|_| Vec::with_capacity(n)),
        time: stime.map(|_| Vec::with_capacity(n)),
        time_base: stime.map_or_else(Default::default, |_| {
            super::TimeBase::from_comments(comments.lines().filter(|l| l.trim_start().starts_with('#')))
        }),
        ..PointCloud::default()
    };
    for (i, ((x, y), z)) in values[0].iter().zip(&values[1]).zip(&values[2]).enumerate() {
        if !(x.is_finite() && y.is_finite() && z.is_finite()) {
            continue;
        }
        cloud.points.push(Point3::new(*x as f32, *y as f32, *z as f32));
        if let (Some(v), Some(s)) = (cloud.intensity.as_mut(), si) {
            v.push(values[s][i] as f32);
        }
        if let (Some(v), Some(s)) = (cloud.color.as_mut(), srgb) {
            v.push(unpack_rgb(values[s][i] as u32));
        }
        if let (Some(v), Some(s)) = (cloud.time.as_mut(), stime) {
            let t = values[s][i];
            if !t.is_finite() {
                return Err(ScannerError::file(path, Location::File, format!("point {i}'s time {t} is not finite")));
            }
            v.push(t);
        }
    }
    Ok(cloud)
}

pub(super) fn write(w: &mut impl Write, cloud: &PointCloud, data: PcdData) -> std::io::Result<()> {
    write_header(w, &super::CloudHeader::of(cloud), data)?;
    match data {
        PcdData::Ascii | PcdData::Binary => write_points(w, cloud, data),
        PcdData::BinaryCompressed => write_compressed(w, cloud),
    }
}

/// The header of a cloud of `header.points` points (unknown: the
/// placeholder [`COUNT_PLACEHOLDER`] in WIDTH and POINTS, see
/// [`patch_count`]).
pub(super) fn write_header(w: &mut impl Write, header: &super::CloudHeader, data: PcdData) -> std::io::Result<()> {
    let n = header.points.map_or_else(|| COUNT_PLACEHOLDER.to_string(), |n| n.to_string());
    // Georeferenced: x, y, z as 8-byte doubles (origin + p).
    let xyz_size = if header.georeferenced() { 8 } else { 4 };
    let columns = columns(header.intensity, header.color, header.time.is_some());
    let names: Vec<&str> = columns.iter().map(|c| c.name()).collect();
    let sizes: Vec<String> = columns.iter().map(|c| if c.is_xyz() { xyz_size } else { c.size() }.to_string()).collect();
    let types = vec!["F"; columns.len()];
    let (fields, sizes, types, counts) =
        (names.join(" "), sizes.join(" "), types.join(" "), vec!["1"; columns.len()].join(" "));
    let comment = header.time.map(|b| format!("# {}\n", b.comment())).unwrap_or_default();
    let encoding = match data {
        PcdData::Ascii => "ascii",
        PcdData::Binary => "binary",
        PcdData::BinaryCompressed => "binary_compressed",
    };
    write!(
        w,
        "# .PCD v0.7 - Point Cloud Data file format\n{comment}VERSION 0.7\nFIELDS {fields}\nSIZE {sizes}\nTYPE {types}\nCOUNT {counts}\nWIDTH {n}\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS {n}\nDATA {encoding}\n"
    )
}

/// WIDTH and POINTS of a header written before its count was known.
const COUNT_PLACEHOLDER: &str = "00000000000000000000";

/// The header bytes `header` (written with the placeholder) with the
/// count `n`, zero-padded to the placeholder's width: the same length.
pub(super) fn patch_count(header: &[u8], n: usize) -> Option<Vec<u8>> {
    let text = std::str::from_utf8(header).ok()?;
    let count = format!("{n:020}");
    let mut out = text.to_string();
    for key in ["WIDTH", "POINTS"] {
        let old = format!("\n{key} {COUNT_PLACEHOLDER}\n");
        out = out.contains(&old).then(|| out.replacen(&old, &format!("\n{key} {count}\n"), 1))?;
    }
    (out.len() == header.len()).then(|| out.into_bytes())
}

/// A field we write.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Column {
    X,
    Y,
    Z,
    Intensity,
    /// PCL's packed colour: F4 as PCL declares it (the bits 0x00RRGGBB),
    /// an integer in ASCII as PCL writes it.
    Rgb,
    /// F8 seconds.
    Time,
}

impl Column {
    fn name(self) -> &'static str {
        match self {
            Column::X => "x",
            Column::Y => "y",
            Column::Z => "z",
            Column::Intensity => "intensity",
            Column::Rgb => "rgb",
            Column::Time => "time",
        }
    }

    fn is_xyz(self) -> bool {
        matches!(self, Column::X | Column::Y | Column::Z)
    }

    /// Bytes (x, y, z: 4, or 8 when georeferenced).
    fn size(self) -> usize {
        if self == Column::Time { 8 } else { 4 }
    }
}

/// The fields of a cloud with these attributes, in order.
fn columns(intensity: bool, color: bool, time: bool) -> Vec<Column> {
    let mut c = vec![Column::X, Column::Y, Column::Z];
    c.extend(intensity.then_some(Column::Intensity));
    c.extend(color.then_some(Column::Rgb));
    c.extend(time.then_some(Column::Time));
    c
}

fn columns_of(cloud: &PointCloud) -> Vec<Column> {
    columns(cloud.intensity.is_some(), cloud.color.is_some(), cloud.time.is_some())
}

/// Field `c` of point `i` of `cloud`: its little-endian bytes (appended to
/// `bytes`) and its text.
fn value(cloud: &PointCloud, i: usize, c: Column, bytes: &mut Vec<u8>) -> String {
    let axis = match c {
        Column::X => 0,
        Column::Y => 1,
        Column::Z => 2,
        Column::Intensity => {
            let v = cloud.intensity.as_ref().map_or(0.0, |v| v[i]);
            bytes.extend_from_slice(&v.to_le_bytes());
            return v.to_string();
        }
        Column::Rgb => {
            let v = pack_rgb(cloud.color.as_ref().map_or([0; 3], |c| c[i]));
            bytes.extend_from_slice(&v.to_le_bytes());
            return v.to_string();
        }
        Column::Time => {
            let v = cloud.time.as_ref().map_or(0.0, |t| t[i]);
            bytes.extend_from_slice(&v.to_le_bytes());
            return v.to_string();
        }
    };
    if cloud.georeferenced() {
        let v = cloud.coordinates(i)[axis];
        bytes.extend_from_slice(&v.to_le_bytes());
        format!("{v:.4}")
    } else {
        let v = cloud.points[i][axis];
        bytes.extend_from_slice(&v.to_le_bytes());
        v.to_string()
    }
}

/// The records of `cloud`'s points (ascii or binary: one point after the
/// other, so a cloud can be written part by part).
pub(super) fn write_points(w: &mut impl Write, cloud: &PointCloud, data: PcdData) -> std::io::Result<()> {
    let columns = columns_of(cloud);
    let mut scratch = Vec::with_capacity(8);
    for i in 0..cloud.points.len() {
        if data == PcdData::Ascii {
            let row: Vec<String> = columns.iter().map(|&c| value(cloud, i, c, &mut scratch)).collect();
            writeln!(w, "{}", row.join(" "))?;
        } else {
            for &c in &columns {
                scratch.clear();
                value(cloud, i, c, &mut scratch);
                w.write_all(&scratch)?;
            }
        }
    }
    Ok(())
}

/// binary_compressed: every field's column, LZF-compressed as one block
/// (the whole cloud at once).
fn write_compressed(w: &mut impl Write, cloud: &PointCloud) -> std::io::Result<()> {
    let n = cloud.points.len();
    let columns = columns_of(cloud);
    let xyz = if cloud.georeferenced() { 8 } else { 4 };
    let record: usize = columns.iter().map(|c| if c.is_xyz() { xyz } else { c.size() }).sum();
    let mut plain = Vec::with_capacity(n * record);
    for &c in &columns {
        for i in 0..n {
            value(cloud, i, c, &mut plain);
        }
    }
    let packed =
        if plain.is_empty() { Vec::new() } else { lzf::compress(&plain).unwrap_or_else(|_| literal_lzf(&plain)) };
    w.write_all(&(packed.len() as u32).to_le_bytes())?;
    w.write_all(&(plain.len() as u32).to_le_bytes())?;
    w.write_all(&packed)
}

/// An LZF stream of literal runs only (for data LZF cannot shrink).
fn literal_lzf(plain: &[u8]) -> Vec<u8> {
    let mut out = Vec::with_capacity(plain.len() + plain.len() / 32 + 1);
    for chunk in plain.chunks(32) {
        out.push((chunk.len() - 1) as u8);
        out.extend_from_slice(chunk);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn literal_stream_decodes() {
        let plain: Vec<u8> = (0..1000u32).map(|i| (i.wrapping_mul(2_654_435_761) >> 24) as u8).collect();
        assert_eq!(lzf::decompress(&literal_lzf(&plain), plain.len()).expect("valid LZF"), plain);
    }

    #[test]
    fn signed_and_unsigned_fields() {
        let i2 = Field { name: "i".into(), size: 2, kind: b'I', count: 1 };
        assert_eq!(i2.value(&(-3i16).to_le_bytes()), Some(-3.0));
        let u1 = Field { name: "u".into(), size: 1, kind: b'U', count: 1 };
        assert_eq!(u1.value(&[200]), Some(200.0));
        let f8 = Field { name: "f".into(), size: 8, kind: b'F', count: 1 };
        assert_eq!(f8.value(&1.25f64.to_le_bytes()), Some(1.25));
    }

    #[test]
    fn the_viewpoint_is_read_from_the_header_and_a_malformed_one_is_named() {
        let dir = tempfile::tempdir().expect("temp dir");
        let file = |name: &str, viewpoint: &str| {
            let path = dir.path().join(name);
            let text = format!(
                "VERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\nWIDTH 1\nHEIGHT 1\n{viewpoint}POINTS 1\nDATA ascii\n1 2 3\n"
            );
            std::fs::write(&path, text).expect("write");
            path
        };
        let at = viewpoint(&file("at.pcd", "VIEWPOINT 1.5 -2 0.25 1 0 0 0\n")).expect("viewpoint");
        assert_eq!(at, Point3::new(1.5, -2.0, 0.25));
        assert_eq!(viewpoint(&file("none.pcd", "")).expect("no VIEWPOINT"), Point3::origin());
        let bad = file("bad.pcd", "VIEWPOINT 1 2 nan 1 0 0 0\n");
        let e = viewpoint(&bad).expect_err("a NaN viewpoint").to_string();
        assert!(e.contains("bad.pcd") && e.contains("VIEWPOINT '1 2 nan 1 0 0 0'") && e.contains("line 8"), "{e}");
        assert!(super::read(&bad).is_err(), "the whole file's read refuses it too");
    }
}
