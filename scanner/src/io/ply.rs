//! PLY through `ply-rs-bw`: reads ascii and binary (either endianness)
//! vertices with x, y, z of any numeric type, an optional intensity
//! (`intensity`, `scalar_intensity`, `scalar_Intensity`), colour (`red`,
//! `green`, `blue` as uchar or ushort) and time (`time`, `gps_time`,
//! `timestamp`, `scalar_time`, `scalar_gps_time`, `scalar_GpsTime`; GPS
//! time when the header's comment says so); writes float x, y, z
//! (+ intensity, uchar colour, double `time`) in ascii or binary little
//! endian.

use std::io::{BufReader, Write};
use std::path::Path;

use nalgebra::Point3;
use ply_rs_bw::parser::{Parser, Reader};
use ply_rs_bw::ply::{
    Addable, ElementDef, Encoding, Header, Property, PropertyAccess, PropertyAccessResult, PropertyDef, PropertyType,
    ScalarType,
};
use ply_rs_bw::writer::Writer;

use super::PointCloud;
use crate::error::{Location, Result, ScannerError};

/// PLY encoding for writing.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PlyEncoding {
    /// ASCII.
    Ascii,
    /// Binary little endian.
    BinaryLittleEndian,
}

const INTENSITY_NAMES: [&str; 3] = ["intensity", "scalar_intensity", "scalar_Intensity"];
const COLOR_NAMES: [&str; 3] = ["red", "green", "blue"];
const TIME_NAMES: [&str; 6] = ["time", "gps_time", "timestamp", "scalar_time", "scalar_gps_time", "scalar_GpsTime"];

#[derive(Debug, Clone, Copy, Default)]
struct Vertex {
    p: [f32; 3],
    intensity: f32,
    /// Colour, 16 bits a channel.
    rgb: [u16; 3],
    time: f64,
}

/// A vertex of a georeferenced cloud: double x, y, z (origin + p).
#[derive(Debug, Clone, Copy, Default)]
struct GeoVertex {
    c: [f64; 3],
    intensity: f32,
    rgb: [u16; 3],
    time: f64,
}

/// A colour channel's 8 bits, by its property name.
fn channel(rgb: &[u16; 3], name: &str) -> Option<u8> {
    COLOR_NAMES.iter().position(|n| *n == name).map(|k| super::color_to_8bit(rgb[k]))
}

impl PropertyAccess for GeoVertex {
    fn new() -> Self {
        Self::default()
    }

    fn get_double(&self, name: &str) -> Option<f64> {
        match name {
            "x" => Some(self.c[0]),
            "y" => Some(self.c[1]),
            "z" => Some(self.c[2]),
            "time" => Some(self.time),
            _ => None,
        }
    }

    fn get_float(&self, _name: &str) -> Option<f32> {
        // The one float field, under whatever name the header gives it.
        Some(self.intensity)
    }

    fn get_uchar(&self, name: &str) -> Option<u8> {
        channel(&self.rgb, name)
    }
}

impl PropertyAccess for Vertex {
    fn new() -> Self {
        Self::default()
    }

    fn set_property(&mut self, name: &str, property: Property) -> PropertyAccessResult {
        if let Some(k) = COLOR_NAMES.iter().position(|n| *n == name) {
            self.rgb[k] = match property {
                Property::UChar(v) => super::color_from_8bit(v),
                Property::UShort(v) => v,
                _ => return PropertyAccessResult::Ignored,
            };
            return PropertyAccessResult::Set;
        }
        if TIME_NAMES.contains(&name) {
            self.time = match property {
                Property::Double(v) => v,
                other => match other.to_f32_lossy() {
                    Some(v) => f64::from(v),
                    None => return PropertyAccessResult::Ignored,
                },
            };
            return PropertyAccessResult::Set;
        }
        let slot = match name {
            "x" => &mut self.p[0],
            "y" => &mut self.p[1],
            "z" => &mut self.p[2],
            n if INTENSITY_NAMES.contains(&n) => &mut self.intensity,
            _ => return PropertyAccessResult::Ignored,
        };
        match property.to_f32_lossy() {
            Some(v) => {
                *slot = v;
                PropertyAccessResult::Set
            }
            None => PropertyAccessResult::Ignored,
        }
    }

    fn get_float(&self, name: &str) -> Option<f32> {
        match name {
            "x" => Some(self.p[0]),
            "y" => Some(self.p[1]),
            "z" => Some(self.p[2]),
            // The one scalar field, under whatever name the header gives it.
            _ => Some(self.intensity),
        }
    }

    fn get_double(&self, name: &str) -> Option<f64> {
        (name == "time").then_some(self.time)
    }

    fn get_uchar(&self, name: &str) -> Option<u8> {
        channel(&self.rgb, name)
    }
}

/// A `ply-rs` error as ours: a line only where there are lines (the header,
/// ASCII data); for a row that does not parse, the row and what the
/// element's properties expect, else the parser's message on one line
/// (without its own "Line N:" prefix and nested dump).
fn ply_error(path: &Path, e: &ply_rs_bw::parser::ParseError, data: Option<(&ElementDef, Encoding)>) -> ScannerError {
    let binary = data.is_some_and(|(_, encoding)| encoding != Encoding::Ascii);
    let location = e.line().filter(|_| !binary).map_or(Location::File, Location::Line);
    let text = e.to_string();
    let row = text.split_once("String: '").and_then(|(_, rest)| rest.split_once('\'')).map(|(row, _)| row.trim());
    if let (Some(row), Some((element, Encoding::Ascii))) = (row, data) {
        // A NaN or an infinity is a number the parser does not take (issue
        // 34, U6 called the row malformed).
        if let Some(t) = row.split_whitespace().find(|t| t.parse::<f64>().is_ok_and(|v| !v.is_finite())) {
            let message = format!("'{row}': the value {t} is not finite: expected finite numbers");
            return ScannerError::file(path, location, message);
        }
        let names: Vec<&str> = element.properties.keys().map(String::as_str).collect();
        let message = format!("'{row}' is not a row of element '{}': expected {}", element.name, names.join(" "));
        return ScannerError::file(path, location, message);
    }
    let text = match e.line() {
        Some(n) => text.strip_prefix(&format!("Line {n}: ")).unwrap_or(&text).to_string(),
        None => text,
    };
    let parts: Vec<&str> = text
        .lines()
        .map(|l| l.trim().trim_start_matches("Error: ").trim_end_matches('.'))
        .filter(|l| !l.is_empty())
        .collect();
    ScannerError::file(path, location, parts.join(": "))
}

/// Refuses a file that does not begin as a PLY file must (`ply` and a line
/// end), before the header parser reads it as text.
fn check_magic(path: &Path, reader: &mut impl std::io::BufRead) -> Result<()> {
    let head = reader.fill_buf().map_err(|e| ScannerError::io(path, e))?;
    if !(head.starts_with(b"ply\n") || head.starts_with(b"ply\r")) {
        return Err(ScannerError::file(path, Location::File, "not a PLY file: expected it to begin with 'ply'"));
    }
    Ok(())
}

/// Bytes of one scalar.
fn scalar_bytes(t: &ScalarType) -> u64 {
    match t {
        ScalarType::Char | ScalarType::UChar => 1,
        ScalarType::Short | ScalarType::UShort => 2,
        ScalarType::Int | ScalarType::UInt | ScalarType::Float => 4,
        ScalarType::Double => 8,
    }
}

/// The header's element counts are claims: an element without properties
/// holds nothing, and all items together need at least so many bytes (a
/// binary scalar its size, a list its count; an ASCII value a character and
/// a separator) — more than the file has is refused before anything is read.
fn check_counts(path: &Path, header: &ply_rs_bw::ply::Header) -> Result<()> {
    let len = std::fs::metadata(path).map_err(|e| ScannerError::io(path, e))?.len();
    let mut need = 0u64;
    for element in header.elements.values() {
        if element.count > 0 && element.properties.is_empty() {
            return Err(ScannerError::file(
                path,
                Location::File,
                format!(
                    "element '{}' has {} items and no properties: expected properties",
                    element.name, element.count
                ),
            ));
        }
        let per_item: u64 = match header.encoding {
            Encoding::Ascii => 2 * element.properties.len() as u64,
            _ => element
                .properties
                .values()
                .map(|p| match &p.data_type {
                    PropertyType::Scalar(t) => scalar_bytes(t),
                    PropertyType::List(count, _) => scalar_bytes(count),
                })
                .sum(),
        };
        need = need.saturating_add(per_item.saturating_mul(element.count as u64));
    }
    if need > len {
        return Err(ScannerError::file(
            path,
            Location::File,
            format!("the header announces at least {need} bytes of items; the file has {len} bytes in all"),
        ));
    }
    Ok(())
}

pub(super) fn read(path: &Path) -> Result<PointCloud> {
    let file = std::fs::File::open(path).map_err(|e| ScannerError::io(path, e))?;
    let mut buffered = BufReader::with_capacity(1 << 20, file);
    check_magic(path, &mut buffered)?;
    let mut reader = Reader::new(buffered);
    let parser = Parser::<Vertex>::new();
    let header = parser.read_header(&mut reader).map_err(|e| ply_error(path, &e, None))?;
    check_counts(path, &header)?;
    let mut cloud = PointCloud::default();
    let mut found = false;
    for element in header.elements.values() {
        let items = parser
            .read_payload_for_element(&mut reader, element, &header)
            .map_err(|e| ply_error(path, &e, Some((element, header.encoding))))?;
        if element.name != "vertex" {
            continue;
        }
        for axis in ["x", "y", "z"] {
            if !element.properties.contains_key(axis) {
                return Err(ScannerError::file(
                    path,
                    Location::File,
                    format!("vertex element has no '{axis}' property"),
                ));
            }
        }
        found = true;
        let has_intensity = INTENSITY_NAMES.iter().any(|n| element.properties.contains_key(*n));
        let has_color = COLOR_NAMES.iter().all(|n| {
            element
                .properties
                .get(*n)
                .is_some_and(|p| matches!(p.data_type, PropertyType::Scalar(ScalarType::UChar | ScalarType::UShort)))
        });
        let has_time = TIME_NAMES.iter().any(|n| element.properties.contains_key(*n));
        cloud.points = items.iter().map(|v| Point3::from(v.p)).collect();
        if has_intensity {
            cloud.intensity = Some(items.iter().map(|v| v.intensity).collect());
        }
        if has_color {
            cloud.color = Some(items.iter().map(|v| v.rgb).collect());
        }
        if has_time {
            cloud.time = Some(items.iter().map(|v| v.time).collect());
            cloud.time_base = super::TimeBase::from_comments(header.comments.iter().map(String::as_str));
        }
    }
    if !found {
        return Err(ScannerError::file(path, Location::File, "no 'vertex' element: expected a point cloud"));
    }
    if let Some(i) = cloud.points.iter().position(|p| !p.coords.iter().all(|c| c.is_finite())) {
        return Err(ScannerError::file(
            path,
            Location::File,
            format!("vertex {i} is not finite: {:?}", cloud.points[i]),
        ));
    }
    if let Some(i) = cloud.time.as_ref().and_then(|t| t.iter().position(|v| !v.is_finite())) {
        return Err(ScannerError::file(path, Location::File, format!("vertex {i}'s time is not finite")));
    }
    Ok(cloud)
}

/// The PLY header of a cloud: x, y, z (double when georeferenced: the
/// coordinates, origin + p), `intensity` if it has one, uchar `red`,
/// `green`, `blue` if it has colours, double `time` (with a comment on its
/// base) if it has times, its CRS in two comments (its name, then its WKT
/// on one line), its point count.
pub(super) fn cloud_header(cloud: &super::CloudHeader, encoding: PlyEncoding) -> Header {
    let mut comments: Vec<String> =
        cloud.crs.iter().flat_map(|c| [format!("crs {}", c.name), format!("crs_wkt {}", c.wkt)]).collect();
    let xyz = if cloud.georeferenced() {
        let o = cloud.origin;
        comments.insert(0, format!("georeferenced: x, y, z are coordinates (origin {} {} {})", o.x, o.y, o.z));
        ScalarType::Double
    } else {
        ScalarType::Float
    };
    let names: &[&str] = if cloud.intensity { &["intensity"] } else { &[] };
    let mut extra: Vec<(&str, ScalarType)> = Vec::new();
    if cloud.color {
        extra.extend(COLOR_NAMES.map(|n| (n, ScalarType::UChar)));
    }
    if let Some(base) = cloud.time {
        extra.push(("time", ScalarType::Double));
        comments.push(base.comment().to_string());
    }
    // A cloud with a CRS is in the world (its axes east, north, up); one
    // without is in a body's frame (a scan in its scanner's).
    let axes = if cloud.crs.is_some() { WORLD_AXES } else { BODY_AXES };
    let mut h = header(xyz, axes, comments, names, encoding, cloud.points.unwrap_or(COUNT_PLACEHOLDER));
    if let Some(vertex) = h.elements.get_mut("vertex") {
        for (name, t) in extra {
            vertex.properties.add(PropertyDef::new(name.to_string(), PropertyType::Scalar(t)));
        }
    }
    h
}

/// The vertex count of a header written before it was known (20 digits).
const COUNT_PLACEHOLDER: usize = 10_000_000_000_000_000_000;

/// The header bytes `header` (written with the placeholder) with the
/// count `n`, zero-padded to the placeholder's width: the same length.
pub(super) fn patch_count(header: &[u8], n: usize) -> Option<Vec<u8>> {
    let text = std::str::from_utf8(header).ok()?;
    let old = format!("\nelement vertex {COUNT_PLACEHOLDER}\n");
    let out = text.contains(&old).then(|| text.replacen(&old, &format!("\nelement vertex {n:020}\n"), 1))?;
    (out.len() == header.len()).then(|| out.into_bytes())
}

/// Writes the header.
pub(super) fn write_header(w: &mut impl Write, header: &Header) -> std::io::Result<()> {
    Writer::<Vertex>::new().write_header(w, header).map(|_| ()).map_err(|e| std::io::Error::other(e.to_string()))
}

/// Writes `cloud`'s vertices as `header` (of [`cloud_header`]) declares
/// them: one vertex after the other, so a cloud can be written part by
/// part.
pub(super) fn write_points(w: &mut impl Write, cloud: &PointCloud, header: &Header) -> std::io::Result<()> {
    let scalar_at = |i: usize| cloud.intensity.as_ref().map_or(0.0, |v| v[i]);
    let rgb_at = |i: usize| cloud.color.as_ref().map_or([0; 3], |c| c[i]);
    let time_at = |i: usize| cloud.time.as_ref().map_or(0.0, |t| t[i]);
    if cloud.georeferenced() {
        let items = (0..cloud.len()).map(|i| GeoVertex {
            c: cloud.coordinates(i),
            intensity: scalar_at(i),
            rgb: rgb_at(i),
            time: time_at(i),
        });
        write_vertices(w, header, &items.collect())
    } else {
        let items = cloud.points.iter().enumerate().map(|(i, p)| Vertex {
            p: [p.x, p.y, p.z],
            intensity: scalar_at(i),
            rgb: rgb_at(i),
            time: time_at(i),
        });
        write_vertices(w, header, &items.collect())
    }
}

/// Float x, y, z and, when given, one float value per vertex under each
/// of the scalar's names.
pub(super) fn write_scalar(
    w: &mut impl Write,
    points: &[Point3<f32>],
    scalar: Option<(&[&str], &[f32])>,
    encoding: PlyEncoding,
) -> std::io::Result<()> {
    let names = scalar.map_or(&[][..], |(names, _)| names);
    let header = header(ScalarType::Float, WORLD_AXES, Vec::new(), names, encoding, points.len());
    write_header(w, &header)?;
    let scalar_at = |i: usize| scalar.map_or(0.0, |(_, v)| v[i]);
    let items = points.iter().enumerate().map(|(i, p)| Vertex {
        p: [p.x, p.y, p.z],
        intensity: scalar_at(i),
        ..Vertex::default()
    });
    write_vertices(w, &header, &items.collect())
}

/// The axes a header comment names: a world cloud's, a body's.
const WORLD_AXES: &str = "x east, y north, z up";
const BODY_AXES: &str = "x forward, y left, z up";

/// A header of `count` vertices: x, y, z of type `xyz` along `axes`, one
/// float under each of `names`, `comments` after ours.
fn header(
    xyz: ScalarType,
    axes: &str,
    comments: Vec<String>,
    names: &[&str],
    encoding: PlyEncoding,
    count: usize,
) -> Header {
    let mut header = Header::new();
    header.encoding = match encoding {
        PlyEncoding::Ascii => Encoding::Ascii,
        PlyEncoding::BinaryLittleEndian => Encoding::BinaryLittleEndian,
    };
    header.comments.push(format!("written by cps-survey; metres, {axes}"));
    header.comments.extend(comments);
    let mut vertex = ElementDef::new("vertex".into());
    vertex.count = count;
    for n in ["x", "y", "z"] {
        vertex.properties.add(PropertyDef::new(n.into(), PropertyType::Scalar(xyz.clone())));
    }
    for name in names {
        vertex.properties.add(PropertyDef::new(name.to_string(), PropertyType::Scalar(ScalarType::Float)));
    }
    header.elements.add(vertex);
    header
}

/// Writes `items` as the header's vertices.
fn write_vertices<V: PropertyAccess>(w: &mut impl Write, header: &Header, items: &Vec<V>) -> std::io::Result<()> {
    let vertex = &header.elements["vertex"];
    Writer::new()
        .write_payload_of_element(w, items, vertex, header)
        .map(|_| ())
        .map_err(|e| std::io::Error::other(e.to_string()))
}
