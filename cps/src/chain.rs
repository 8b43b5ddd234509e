//! The joint covariance of the scan stations from one link per station —
//! linear in the stations, where carrying a clone of every scan station
//! in the team state ([`crate::TeamState::clone_parent`]) is quadratic.
//!
//! Placements and fixes only ever write a new state as a linear(ised)
//! function of the states before it plus fresh, independent noise; no
//! earlier state is changed. So for scan stations a < b,
//!
//! cov(p_b, p_a) = [S_b S_{b−1} ⋯ S_{a+1} · cov(X_a, p_a)]_parent,
//!
//! where X_a is the whole team state at station a (parent, children, fixed
//! points), p_a its parent, and S_b = ∂X_b/∂X_{b−1} the sensitivity the
//! team tracks from one scan station to the next
//! ([`crate::TeamState::set_anchor`], [`crate::TeamState::from_anchor`]).
//! Each station keeps cov(X, p) (m × 4) and the team rows of S (the fixed
//! points' rows are the identity: they never move): O(m²) numbers per
//! station whatever the route's length.

use nalgebra::{DMatrix, Matrix4};

use crate::error::{CpsError, Result};

/// What one scan station keeps of the team state.
#[derive(Debug, Clone, PartialEq)]
pub struct ChainLink {
    /// cov(X, p): the whole state's covariance with the parent, m × 4
    /// (order as the team state's, without clones). Rows left out at the
    /// end are zero (a start whose children are not placed yet: 4 rows).
    pub parent_columns: DMatrix<f64>,
    /// ∂(parent and children)/∂X at the previous scan station: the team's
    /// rows of S, (4 + 3N) × m_previous. `None` when this station's state
    /// is independent of the previous one's (the first scan station; a
    /// robot alone that took its pose from odometry).
    pub from_previous: Option<DMatrix<f64>>,
}

impl ChainLink {
    /// cov(p, p) of the station.
    pub fn parent_covariance(&self) -> Matrix4<f64> {
        Matrix4::from_fn(|r, c| if r < self.parent_columns.nrows() { self.parent_columns[(r, c)] } else { 0.0 })
    }

    fn check(&self, station: usize) -> Result<()> {
        let bad_shape = |what: &str, value: usize, expected: String| CpsError::OutOfRange {
            what: format!("scan station {station}'s chain link: {what}"),
            value: value as f64,
            expected,
        };
        if self.parent_columns.ncols() != 4 || self.parent_columns.nrows() < 4 {
            return Err(bad_shape("columns of cov(X, p)", self.parent_columns.ncols(), "4 columns, ≥ 4 rows".into()));
        }
        if let Some(s) = &self.from_previous
            && s.nrows() < 4
        {
            return Err(bad_shape("rows of ∂X/∂X_previous", s.nrows(), "≥ 4 (the parent's)".into()));
        }
        let values = self.parent_columns.iter().chain(self.from_previous.iter().flat_map(|s| s.iter()));
        if let Some(v) = values.copied().find(|v| !v.is_finite()) {
            return Err(CpsError::NonFinite { what: format!("scan station {station}'s chain link"), value: v });
        }
        Ok(())
    }
}

/// Calls `put(b, a, cov(p_b, p_a))` for every pair of stations a ≤ b that
/// the chain correlates (independent pairs are left out: their block is
/// zero), in O(n² · m²) for n stations of state dimension m.
pub fn for_each_cross_covariance(links: &[ChainLink], mut put: impl FnMut(usize, usize, &Matrix4<f64>)) -> Result<()> {
    for (station, link) in links.iter().enumerate() {
        link.check(station)?;
    }
    for (a, link) in links.iter().enumerate() {
        put(a, a, &link.parent_covariance());
        let mut columns = link.parent_columns.clone();
        for (b, later) in links.iter().enumerate().skip(a + 1) {
            let Some(s) = &later.from_previous else { break };
            columns =
                propagate(s, &columns, later.parent_columns.nrows()).map_err(|expected| CpsError::OutOfRange {
                    what: format!("scan station {b}'s chain link: columns of ∂X/∂X_previous"),
                    value: s.ncols() as f64,
                    expected,
                })?;
            put(b, a, &Matrix4::from_fn(|r, c| columns[(r, c)]));
        }
    }
    Ok(())
}

/// S·V for the team's rows, the fixed points' rows of V carried over
/// unchanged (zero for a point the previous state did not hold); `rows`
/// is the new state's dimension.
fn propagate(
    team_rows: &DMatrix<f64>,
    columns: &DMatrix<f64>,
    rows: usize,
) -> std::result::Result<DMatrix<f64>, String> {
    let (t, m_previous) = team_rows.shape();
    if columns.nrows() > m_previous {
        return Err(format!("{} (the previous station's state dimension)", columns.nrows()));
    }
    let rows = rows.max(t);
    let mut next = DMatrix::zeros(rows, 4);
    let held = columns.nrows();
    next.rows_mut(0, t).copy_from(&(team_rows.columns(0, held) * columns));
    for r in t..rows.min(held) {
        next.row_mut(r).copy_from(&columns.row(r));
    }
    Ok(next)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::instrument::Instrument;
    use crate::observation::{ParentPose, observe};
    use crate::{FixOptions, TeamState};
    use nalgebra::{Matrix3, Point3, Vector4};

    fn instrument() -> Instrument {
        Instrument { centring_target_m: 0.001, min_range_m: 0.5, ..Instrument::default() }
    }

    /// A leapfrog team with a control point (a fixed point sighted in some
    /// fixes), driven both ways at once: one copy clones every scan
    /// station (the quadratic reference), the other keeps chain links.
    #[test]
    fn the_chain_gives_the_clones_joint_covariance() {
        let inst = instrument();
        let start = ParentPose::new(0.0, 0.0, 0.0, 0.05);
        let cov0 = Matrix4::from_diagonal(&Vector4::new(1e-4, 2e-4, 5e-5, 1e-7));
        let mut cloned = TeamState::new(start, cov0, 2).expect("team");
        let control = Point3::new(25.0, 30.0, 1.0);
        let k = cloned.add_fixed_point(control, Matrix3::from_diagonal_element(4e-6)).expect("control");
        let mut chained = cloned.clone();
        let mut links = Vec::new();
        let mut parent = start;
        for station in 0..7 {
            // Scan stations: 0, 1, 3, 4, 6 (2 and 5 only fix).
            if station != 2 && station != 5 {
                cloned.clone_parent();
                links.push(ChainLink {
                    parent_columns: chained.covariance().columns(0, 4).into_owned(),
                    from_previous: chained.from_anchor().cloned(),
                });
                chained.set_anchor();
            }
            let x = 10.0 * (station + 1) as f64;
            let children = [Point3::new(x + 4.0, 6.0, 0.2), Point3::new(x + 5.0, -7.0, -0.1)];
            for (j, c) in children.iter().enumerate() {
                let reading = observe(&parent, c).expect("reading");
                cloned.place_child(j, &reading, &inst).expect("place");
                chained.place_child(j, &reading, &inst).expect("place");
            }
            parent = ParentPose::new(x + 9.0, 0.5, 0.1, 0.05 - 0.01 * station as f64);
            let mut readings: Vec<_> =
                children.iter().enumerate().map(|(j, c)| (j, observe(&parent, c).expect("reading"), &inst)).collect();
            if station % 2 == 1 {
                readings.push((k, observe(&parent, &control).expect("reading"), &inst));
            }
            cloned.fix_parent_mixed(&readings, &FixOptions::default()).expect("fix");
            chained.fix_parent_mixed(&readings, &FixOptions::default()).expect("fix");
        }
        let n = links.len();
        let mut seen = vec![vec![false; n]; n];
        for_each_cross_covariance(&links, |b, a, block| {
            let expected = cloned.clone_covariance(b, a).expect("clone");
            let err = (block - expected).amax() / expected.amax();
            assert!(err < 1e-10, "stations {b}, {a}: relative error {err:e}\n{block}\n{expected}");
            seen[b][a] = true;
        })
        .expect("chain");
        assert!((0..n).all(|b| (0..=b).all(|a| seen[b][a])), "every pair correlated: {seen:?}");
        // The chain's covariances are not trivially equal: they decay.
        let near = cloned.clone_covariance(1, 0).expect("clone")[(0, 0)];
        assert!(near.abs() > 1e-8, "{near}");
    }

    #[test]
    fn an_independent_station_cuts_the_chain_and_bad_links_are_refused() {
        let link = |rows: usize, previous: Option<(usize, usize)>| ChainLink {
            parent_columns: DMatrix::from_fn(rows, 4, |r, c| if r == c { 1.0 } else { 0.0 }),
            from_previous: previous.map(|(t, m)| DMatrix::from_element(t, m, 0.5)),
        };
        let links = [link(4, None), link(10, Some((10, 4))), link(4, None), link(4, Some((4, 4)))];
        let mut pairs = Vec::new();
        for_each_cross_covariance(&links, |b, a, _| pairs.push((b, a))).expect("chain");
        assert_eq!(pairs, vec![(0, 0), (1, 0), (1, 1), (2, 2), (3, 2), (3, 3)]);
        let wide = [link(10, None), link(10, Some((10, 4)))];
        let err = for_each_cross_covariance(&wide, |_, _, _| {}).expect_err("10 rows into 4 columns");
        assert!(err.to_string().contains("scan station 1"), "{err}");
        let mut nan = link(4, None);
        nan.parent_columns[(0, 0)] = f64::NAN;
        let err = for_each_cross_covariance(&[nan], |_, _, _| {}).expect_err("NaN");
        assert!(err.to_string().contains("scan station 0"), "{err}");
    }
}
