//! PLY through `ply-rs-bw`: reads ascii and binary (either endianness)
//! vertices with x, y, z of any numeric type and an optional intensity
//! (`intensity`, `scalar_intensity`, `scalar_Intensity`); writes float x, y, z
//! (+ intensity) in ascii or binary little endian.

use std::io::{BufReader, Write};
use std::path::Path;

use nalgebra::Point3;
use ply_rs_bw::parser::{Parser, Reader};
use ply_rs_bw::ply::{
    Addable, ElementDef, Encoding, Ply, Property, PropertyAccess, PropertyAccessResult, PropertyDef, PropertyType,
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

#[derive(Debug, Clone, Copy, Default)]
struct Vertex {
    p: [f32; 3],
    intensity: f32,
}

impl PropertyAccess for Vertex {
    fn new() -> Self {
        Self::default()
    }

    fn set_property(&mut self, name: &str, property: Property) -> PropertyAccessResult {
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
}

fn ply_error(path: &Path, e: &ply_rs_bw::parser::ParseError) -> ScannerError {
    let location = e.line().map_or(Location::File, Location::Line);
    ScannerError::file(path, location, e.to_string())
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
    let mut reader = Reader::new(BufReader::with_capacity(1 << 20, file));
    let parser = Parser::<Vertex>::new();
    let header = parser.read_header(&mut reader).map_err(|e| ply_error(path, &e))?;
    check_counts(path, &header)?;
    let mut cloud = PointCloud::default();
    let mut found = false;
    for element in header.elements.values() {
        let items = parser.read_payload_for_element(&mut reader, element, &header).map_err(|e| ply_error(path, &e))?;
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
        cloud.points = items.iter().map(|v| Point3::from(v.p)).collect();
        if has_intensity {
            cloud.intensity = Some(items.iter().map(|v| v.intensity).collect());
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
    Ok(cloud)
}

pub(super) fn write(w: &mut impl Write, cloud: &PointCloud, encoding: PlyEncoding) -> std::io::Result<()> {
    write_scalar(w, &cloud.points, cloud.intensity.as_deref().map(|v| ("intensity", v)), encoding)
}

/// Float x, y, z and, when given, one float scalar field per vertex.
pub(super) fn write_scalar(
    w: &mut impl Write,
    points: &[Point3<f32>],
    scalar: Option<(&str, &[f32])>,
    encoding: PlyEncoding,
) -> std::io::Result<()> {
    let mut ply = Ply::<Vertex>::new();
    ply.header.encoding = match encoding {
        PlyEncoding::Ascii => Encoding::Ascii,
        PlyEncoding::BinaryLittleEndian => Encoding::BinaryLittleEndian,
    };
    ply.header.comments.push("written by cps-survey; metres, x forward, y left, z up".into());
    let mut vertex = ElementDef::new("vertex".into());
    let mut names = vec!["x", "y", "z"];
    if let Some((name, _)) = scalar {
        names.push(name);
    }
    for n in &names {
        vertex.properties.add(PropertyDef::new((*n).into(), PropertyType::Scalar(ScalarType::Float)));
    }
    ply.header.elements.add(vertex);
    let items = points
        .iter()
        .enumerate()
        .map(|(i, p)| Vertex { p: [p.x, p.y, p.z], intensity: scalar.map_or(0.0, |(_, v)| v[i]) })
        .collect();
    ply.payload.insert("vertex".into(), items);
    Writer::new().write_ply(w, &mut ply).map(|_| ()).map_err(|e| std::io::Error::other(e.to_string()))
}
