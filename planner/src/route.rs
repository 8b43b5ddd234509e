//! A route is a polyline of parent waypoints; stations are placed along it.

use nalgebra::Point3;

use crate::error::PlanError;

/// One parent station of a route.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Station {
    /// Position of the total station's centre, world frame, metres.
    pub position: Point3<f64>,
    /// Heading at the station: the horizontal direction of travel to the next
    /// station, radians counter-clockwise from world +x (the last station
    /// keeps the previous heading).
    pub heading_rad: f64,
    /// Path length travelled from the start to this station, metres.
    pub distance_m: f64,
}

/// The most stations a route may have (a 1,000 km traverse at 10 m strides).
pub const MAX_STATIONS: usize = 100_001;

/// Places stations every `stride_m` along each segment, starting at its first
/// point; every corner is a station; a segment whose length is not a multiple
/// of the stride ends with one shorter step.
pub fn stations(route_m: &[Point3<f64>], stride_m: f64) -> Result<Vec<Station>, PlanError> {
    if !(stride_m.is_finite() && stride_m > 0.0) {
        return Err(PlanError::BadStride { value: stride_m });
    }
    if route_m.len() < 2 {
        return Err(PlanError::RouteTooShort { got: route_m.len() });
    }
    // Count before placing: a route is refused, not allocated, beyond the
    // limit.
    let mut count = 1.0;
    for (k, pair) in route_m.windows(2).enumerate() {
        let (a, b) = (pair[0], pair[1]);
        let length = (b - a).norm();
        if length.is_nan() || length <= 1e-9 {
            return Err(PlanError::ZeroLengthSegment { waypoint: k + 1 });
        }
        if (b - a).xy().norm() < 1e-3 {
            return Err(PlanError::VerticalSegment { waypoint: k + 1, rise_m: b.z - a.z });
        }
        count += (length / stride_m * (1.0 - 1e-12)).ceil();
    }
    if count.is_nan() || count > MAX_STATIONS as f64 {
        return Err(PlanError::TooManyStations { count, limit: MAX_STATIONS });
    }
    let mut positions = Vec::new();
    let mut distances = Vec::new();
    let mut travelled = 0.0;
    for pair in route_m.windows(2) {
        let (a, b) = (pair[0], pair[1]);
        let length = (b - a).norm();
        let dir = (b - a) / length;
        let steps = (length / stride_m * (1.0 - 1e-12)).ceil() as usize;
        for s in 0..steps {
            let along = s as f64 * stride_m;
            positions.push(a + along * dir);
            distances.push(travelled + along);
        }
        travelled += length;
    }
    positions.push(route_m[route_m.len() - 1]);
    distances.push(travelled);

    let mut headings = vec![0.0; positions.len()];
    // Headings point to the next station; where a step is vertical only, the
    // previous heading is kept (the first such steps take the first defined one).
    let mut previous: Option<f64> = None;
    for k in 0..positions.len() {
        let next = positions.get(k + 1).map(|n| n - positions[k]).filter(|d| d.xy().norm() > 1e-9);
        headings[k] = match next {
            Some(d) => d.y.atan2(d.x),
            None => previous.unwrap_or(f64::NAN),
        };
        if next.is_some() {
            previous = Some(headings[k]);
        }
    }
    let first_defined = headings.iter().copied().find(|h| h.is_finite()).unwrap_or(0.0);
    for h in &mut headings {
        if h.is_nan() {
            *h = first_defined;
        }
    }
    Ok(positions
        .into_iter()
        .zip(headings)
        .zip(distances)
        .map(|((position, heading_rad), distance_m)| Station { position, heading_rad, distance_m })
        .collect())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn stations_every_stride_with_corners_and_a_short_last_step() {
        let route = [Point3::new(0.0, 0.0, 0.0), Point3::new(25.0, 0.0, 0.0), Point3::new(25.0, 10.0, 1.0)];
        let s = stations(&route, 10.0).expect("valid");
        let xs: Vec<(f64, f64)> = s.iter().map(|s| (s.position.x, s.position.y)).collect();
        assert_eq!(xs.len(), 6);
        assert_eq!(&xs[..4], &[(0.0, 0.0), (10.0, 0.0), (20.0, 0.0), (25.0, 0.0)]);
        assert!((s[4].position.y - 10.0 / 101f64.sqrt() * 10.0).abs() < 1e-12);
        assert_eq!((s[5].position.x, s[5].position.y, s[5].position.z), (25.0, 10.0, 1.0));
        assert!((s[5].distance_m - (25.0 + 101f64.sqrt())).abs() < 1e-12);
        assert_eq!(s[0].heading_rad, 0.0);
        assert!((s[3].heading_rad - std::f64::consts::FRAC_PI_2).abs() < 1e-12);
        assert_eq!(s[5].heading_rad, s[4].heading_rad);
    }

    #[test]
    fn exact_multiples_do_not_add_a_tiny_step() {
        let route = [Point3::new(0.0, 0.0, 0.0), Point3::new(1000.0, 0.0, 0.0)];
        assert_eq!(stations(&route, 10.0).expect("valid").len(), 101);
        let route = [Point3::new(0.0, 0.0, 0.0), Point3::new(0.3, 0.0, 0.0)];
        assert_eq!(stations(&route, 0.1).expect("valid").len(), 4);
    }

    #[test]
    fn bad_routes_are_errors() {
        let p = Point3::new(1.0, 2.0, 3.0);
        assert!(matches!(stations(&[p, p + nalgebra::Vector3::x()], 0.0), Err(PlanError::BadStride { .. })));
        assert!(matches!(stations(&[p, p + nalgebra::Vector3::x()], f64::NAN), Err(PlanError::BadStride { .. })));
        assert!(matches!(stations(&[p], 1.0), Err(PlanError::RouteTooShort { got: 1 })));
        assert!(matches!(stations(&[p, p], 1.0), Err(PlanError::ZeroLengthSegment { waypoint: 1 })));
    }
}
