//! Scan assembly: 2D slices taken at known head angles, plus the
//! `body_from_head` lever arm, become one 3D scan in the body frame.

use nalgebra::{Isometry3, Point3};

use crate::devices::{HeadKind, RangeFinder2D, ScanHead, Slice};
use crate::error::Result;

/// A 3D scan: points (f32, metres) in the frame named by its producer (the
/// body frame after [`assemble`]), with each point's measured range and its
/// slice and beam index.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Scan {
    /// Points, metres.
    pub points: Vec<Point3<f32>>,
    /// Measured range of each point, metres.
    pub range_m: Vec<f32>,
    /// Slice (head step) index of each point.
    pub slice: Vec<u32>,
    /// Beam index within its slice.
    pub beam: Vec<u16>,
}

impl Scan {
    /// Number of points.
    pub fn len(&self) -> usize {
        self.points.len()
    }

    /// True when the scan has no points.
    pub fn is_empty(&self) -> bool {
        self.points.is_empty()
    }
}

/// Assembles slices `(head angle, slice)` taken on a head of kind `head`
/// into a scan in the body frame:
/// `p_body = body_from_head · head_from_scanner(angle) · (r cos α, r sin α, 0)`.
/// No-return values are skipped.
pub fn assemble(slices: &[(f64, Slice)], head: HeadKind, body_from_head: &Isometry3<f64>) -> Scan {
    let total: usize = slices.iter().map(|(_, s)| s.values.len()).sum();
    let mut scan = Scan {
        points: Vec::with_capacity(total),
        range_m: Vec::with_capacity(total),
        slice: Vec::with_capacity(total),
        beam: Vec::with_capacity(total),
    };
    for (k, (angle, slice)) in slices.iter().enumerate() {
        let body_from_scanner = body_from_head * head.head_from_scanner(*angle);
        for i in 0..slice.values.len() {
            let Some(r) = slice.range_m(i) else { continue };
            let a = slice.angle_rad(i);
            let p = body_from_scanner * Point3::new(r * a.cos(), r * a.sin(), 0.0);
            scan.points.push(p.cast());
            scan.range_m.push(r as f32);
            scan.slice.push(k as u32);
            scan.beam.push(i as u16);
        }
    }
    scan
}

/// Takes a full 3D scan: for each head angle, turn the head, take a slice;
/// then [`assemble`]. `progress(done, total)` is called after each slice.
pub fn scan_3d(
    head: &mut dyn ScanHead,
    scanner: &mut dyn RangeFinder2D,
    slices: usize,
    body_from_head: &Isometry3<f64>,
    progress: &mut dyn FnMut(usize, usize),
) -> Result<Scan> {
    let kind = head.kind();
    let angles = kind.slice_angles(slices);
    let mut taken = Vec::with_capacity(angles.len());
    for (k, angle) in angles.iter().enumerate() {
        let reached = head.move_to(*angle)?;
        taken.push((reached, scanner.scan()?));
        progress(k + 1, angles.len());
    }
    Ok(assemble(&taken, kind, body_from_head))
}
