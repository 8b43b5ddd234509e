//! `cps::batch` against an independent dense adjustment of the same
//! network: numerical Jacobians, the dense normal matrix inverted whole,
//! the textbook formulas for redundancy numbers, w and MDB.

use cps::batch::{AdjustOptions, Network, NetworkReading, Point, Source, Station, adjust};
use cps::{Instrument, ParentPose, observe, wrap_angle};
use nalgebra::{DMatrix, DVector, Matrix3, Matrix4, Point3, Vector3, Vector4};
use rand::SeedableRng;
use rand_distr::{Distribution, StandardNormal};

/// A leapfrog-like chain of 6 stations with two children per cycle, a
/// weighted start, two control points (one fixed, one weighted in x, y and
/// fixed in z) sighted from the start and the end, noisy readings.
fn network(seed: u64) -> (Network, Vec<ParentPose>, Vec<Point3<f64>>) {
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    let mut z = || -> f64 { StandardNormal.sample(&mut rng) };
    let inst = Instrument { sigma_distance_m: 0.002, min_range_m: 0.5, ..Instrument::default() };
    let truth: Vec<ParentPose> = (0..6)
        .map(|k| ParentPose::new(8.0 * k as f64, 0.3 * (k as f64).sin(), 1.0 + 0.05 * k as f64, 0.02 * k as f64))
        .collect();
    let mut points = Vec::new();
    let mut readings = Vec::new();
    let reading = |station: usize, point: usize, at: &Point3<f64>, z: &mut dyn FnMut() -> f64| {
        let exact = observe(&truth[station], at).expect("regular");
        let r = inst.perturbed(&exact, [z(), z(), z()]);
        NetworkReading { station, point, reading: r, covariance: inst.reading_covariance(&r) }
    };
    for k in 0..5 {
        for side in [6.0, -5.0] {
            let at = Point3::new(8.0 * k as f64 + 4.0, side, 0.5);
            points.push(Point { position: at + Vector3::new(0.01, -0.02, 0.005), prior: None });
            let p = points.len() - 1;
            readings.push(reading(k, p, &at, &mut z));
            readings.push(reading(k + 1, p, &at, &mut z));
        }
    }
    let controls = [Point3::new(-6.0, 7.0, 0.0), Point3::new(46.0, -8.0, 2.0)];
    points.push(Point { position: controls[0], prior: Some(Matrix3::zeros()) });
    points.push(Point {
        position: controls[1] + Vector3::new(0.002 * z(), 0.002 * z(), 0.0),
        prior: Some(Matrix3::from_diagonal(&Vector3::new(4e-6, 4e-6, 0.0))),
    });
    let (c0, c1) = (points.len() - 2, points.len() - 1);
    for (station, point, at) in [(0, c0, controls[0]), (5, c1, controls[1]), (4, c1, controls[1]), (1, c0, controls[0])]
    {
        readings.push(reading(station, point, &at, &mut z));
    }
    let mut stations: Vec<Station> = truth
        .iter()
        .map(|t| Station {
            pose: ParentPose::new(t.position.x + 0.01, t.position.y - 0.01, t.position.z, t.heading_rad + 1e-3),
            prior: None,
        })
        .collect();
    stations[0] =
        Station { pose: truth[0], prior: Some(Matrix4::from_diagonal(&Vector4::new(1e-6, 1e-6, 1e-6, 1e-8))) };
    let truth_points = points.iter().map(|p| p.position).collect();
    (Network { stations, points, readings }, truth, truth_points)
}

/// The unknown vector of the dense reference: stations (x, y, z, θ), then
/// points — minus the fixed coordinates.
struct Dense {
    cols: Vec<(bool, usize, usize)>, // (is station, index, coordinate)
}

impl Dense {
    fn new(net: &Network) -> Self {
        let mut cols = Vec::new();
        for (k, s) in net.stations.iter().enumerate() {
            for c in 0..4 {
                if s.prior.is_none_or(|p| p[(c, c)] > 0.0) {
                    cols.push((true, k, c));
                }
            }
        }
        for (k, p) in net.points.iter().enumerate() {
            for c in 0..3 {
                if p.prior.is_none_or(|q| q[(c, c)] > 0.0) {
                    cols.push((false, k, c));
                }
            }
        }
        Self { cols }
    }

    fn apply(&self, net: &Network, x: &DVector<f64>) -> (Vec<ParentPose>, Vec<Point3<f64>>) {
        let mut st: Vec<ParentPose> = net.stations.iter().map(|s| s.pose).collect();
        let mut pt: Vec<Point3<f64>> = net.points.iter().map(|p| p.position).collect();
        for (i, &(is_station, k, c)) in self.cols.iter().enumerate() {
            if is_station {
                let mut v = st[k].to_vector();
                v[c] += x[i];
                st[k] = ParentPose::from_vector(&v);
            } else {
                pt[k][c] += x[i];
            }
        }
        (st, pt)
    }

    /// Observed − computed for every scalar (readings, then priors) at the
    /// offset x from the approximations, and their variances.
    fn residual(&self, net: &Network, x: &DVector<f64>) -> (DVector<f64>, Vec<f64>) {
        let (st, pt) = self.apply(net, x);
        let mut v = Vec::new();
        let mut var = Vec::new();
        for r in &net.readings {
            let c = observe(&st[r.station], &pt[r.point]).expect("regular");
            v.extend([
                r.reading.slope_m - c.slope_m,
                wrap_angle(r.reading.azimuth_rad - c.azimuth_rad),
                r.reading.elevation_rad - c.elevation_rad,
            ]);
            var.extend((0..3).map(|i| r.covariance[(i, i)]));
        }
        for (k, s) in net.stations.iter().enumerate() {
            if let Some(p) = s.prior {
                let mut d = s.pose.to_vector() - st[k].to_vector();
                d[3] = wrap_angle(d[3]);
                for c in (0..4).filter(|&c| p[(c, c)] > 0.0) {
                    v.push(d[c]);
                    var.push(p[(c, c)]);
                }
            }
        }
        for (k, q) in net.points.iter().enumerate() {
            if let Some(p) = q.prior {
                let d = q.position - pt[k];
                for c in (0..3).filter(|&c| p[(c, c)] > 0.0) {
                    v.push(d[c]);
                    var.push(p[(c, c)]);
                }
            }
        }
        (DVector::from_vec(v), var)
    }

    /// Gauss–Newton with central-difference Jacobians to 1e-10; returns x, the
    /// design matrix at x, the weights and the residuals there.
    fn adjust(&self, net: &Network) -> (DVector<f64>, DMatrix<f64>, Vec<f64>, DVector<f64>) {
        let n = self.cols.len();
        let mut x = DVector::zeros(n);
        for _ in 0..20 {
            let (l, var) = self.residual(net, &x);
            let mut a = DMatrix::zeros(l.len(), n);
            for j in 0..n {
                let h = if self.cols[j].0 && self.cols[j].2 == 3 { 1e-8 } else { 1e-6 };
                let (mut xp, mut xm) = (x.clone(), x.clone());
                xp[j] += h;
                xm[j] -= h;
                // ∂(computed)/∂x = −∂(observed − computed)/∂x.
                let col = (self.residual(net, &xm).0 - self.residual(net, &xp).0) / (2.0 * h);
                a.set_column(j, &col);
            }
            let p = DMatrix::from_diagonal(&DVector::from_iterator(var.len(), var.iter().map(|v| 1.0 / v)));
            let n_mat = a.transpose() * &p * &a;
            let dx = n_mat.clone().cholesky().expect("SPD").solve(&(a.transpose() * &p * &l));
            x += &dx;
            // Central differences leave a floor of a few 1e-11 on the steps.
            if dx.amax() < 1e-10 {
                let (l, var) = self.residual(net, &x);
                return (x, a, var, l);
            }
        }
        panic!("the dense reference did not converge");
    }
}

#[test]
fn the_sparse_adjustment_equals_a_dense_one() {
    for seed in [1, 2, 3] {
        let (net, _, _) = network(seed);
        let options = AdjustOptions { snooping: false, ..AdjustOptions::default() };
        let adj = adjust(&net, &options).expect("adjust");
        assert!(adj.converged);
        let dense = Dense::new(&net);
        let (x, a, var, l) = dense.adjust(&net);
        let (st, pt) = dense.apply(&net, &x);
        for (k, s) in st.iter().enumerate() {
            let d = (s.position - adj.stations[k].position).norm();
            assert!(d < 1e-9, "seed {seed} station {k}: {d:e} m");
            assert!(wrap_angle(s.heading_rad - adj.stations[k].heading_rad).abs() < 1e-11);
        }
        for (k, p) in pt.iter().enumerate() {
            assert!((p - adj.points[k]).norm() < 1e-9, "seed {seed} point {k}");
        }
        // Covariances: the dense inverse of the normal matrix.
        let p = DMatrix::from_diagonal(&DVector::from_iterator(var.len(), var.iter().map(|v| 1.0 / v)));
        let q = (a.transpose() * &p * &a).try_inverse().expect("invertible");
        let col = |is_station: bool, k: usize, c: usize| dense.cols.iter().position(|&x| x == (is_station, k, c));
        for k in 0..net.stations.len() {
            let cov = adj.station_covariance(k);
            for i in 0..4 {
                for j in 0..4 {
                    let expected = match (col(true, k, i), col(true, k, j)) {
                        (Some(a), Some(b)) => q[(a, b)],
                        _ => 0.0,
                    };
                    assert!(
                        (cov[(i, j)] - expected).abs() <= 1e-7 * cov[(i, i)].abs().max(cov[(j, j)].abs()).max(1e-30)
                    );
                }
            }
        }
        let last = net.points.len() - 1;
        let cov = adj.point_covariance(last);
        let (ax, ay) = (col(false, last, 0).expect("x free"), col(false, last, 1).expect("y free"));
        assert!((cov[(0, 1)] - q[(ax, ay)]).abs() < 1e-7 * cov[(0, 0)]);
        assert_eq!(cov[(2, 2)], 0.0, "z is held fixed");
        // σ0², redundancy numbers, w and MDB by the textbook formulas.
        let dof = l.len() - dense.cols.len();
        assert_eq!(adj.redundancy, dof);
        let vtpv = (l.transpose() * &p * &l)[(0, 0)];
        assert!((adj.sigma0_squared - vtpv / dof as f64).abs() < 1e-6 * adj.sigma0_squared);
        let qvv = DMatrix::from_diagonal(&DVector::from_vec(var.clone())) - &a * &q * a.transpose();
        let r_sum: f64 = adj.observations.iter().map(|o| o.redundancy).sum();
        assert!((r_sum - dof as f64).abs() < 1e-6, "Σr = {r_sum}, redundancy {dof}");
        let lambda0 = cps::stats::noncentrality(cps::stats::ALPHA0, cps::stats::BETA0);
        for o in &adj.observations {
            let Source::Reading(k) = o.source else { continue };
            let i = 3 * k + o.component;
            let r = qvv[(i, i)] / var[i];
            assert!((o.redundancy - r).abs() < 1e-7, "reading {k}.{}: r {} vs {r}", o.component, o.redundancy);
            if let (Some(w), true) = (o.w, r > 1e-6) {
                // v = adjusted − observed = −l.
                let expected = -l[i] / (var[i].sqrt() * r.sqrt());
                assert!((w - expected).abs() < 1e-5 * expected.abs().max(1.0), "w {w} vs {expected}");
                let mdb = o.mdb.expect("checked");
                assert!((mdb - var[i].sqrt() * (lambda0 / r).sqrt()).abs() < 1e-6 * mdb);
            }
        }
    }
}

/// With the whole chain's readings exact, every residual vanishes; a 2 cm
/// distance blunder is found by data snooping and removed.
#[test]
fn data_snooping_removes_a_planted_blunder() {
    let (mut net, _, _) = network(9);
    net.readings[7].reading.slope_m += 0.02;
    let adj = adjust(&net, &AdjustOptions::default()).expect("adjust");
    assert_eq!(adj.removed.len(), 1, "{:?}", adj.removed);
    assert_eq!(adj.removed[0].source, Source::Reading(7));
    assert_eq!(adj.removed[0].component, 0);
    assert!(adj.removed[0].w.abs() > adj.w_critical);
    // Detected by the global test, found by snooping: what is left passes.
    assert!(adj.model_accepted(), "{:?}", adj.after_snooping);
    let clean = adjust(&net, &AdjustOptions { snooping: false, ..AdjustOptions::default() }).expect("adjust");
    assert!(!clean.global_test.passed || clean.sigma0_squared > adj.sigma0_squared);
}

/// Several blunders: snooping's removals, found by rank-one downdates of
/// one adjustment and confirmed by one adjustment without them all, are
/// the ones Baarda's iteration finds re-adjusting after each removal (the
/// reference here: `adjust_without` the removals so far, no snooping, the
/// largest |w| of what others check), in the same order, with the same w
/// to the linearisation's second order, and the adjustment is the same.
#[test]
fn data_snooping_by_downdates_removes_what_re_adjusting_removes() {
    for seed in [9u64, 21, 33] {
        let (mut net, _, _) = network(seed);
        net.readings[3].reading.slope_m += 0.03;
        net.readings[11].reading.azimuth_rad += 0.004;
        net.readings[16].reading.slope_m -= 0.025;
        net.readings[18].reading.elevation_rad += 0.003;
        let options = AdjustOptions::default();
        let fast = adjust(&net, &options).expect("adjust");
        // The reference: one removal, one adjustment.
        let plain = AdjustOptions { snooping: false, ..options };
        let mut left: Vec<(Source, usize)> = Vec::new();
        let mut ws = Vec::new();
        let reference = loop {
            let adj = cps::batch::adjust_without(&net, &plain, &left).expect("adjust");
            let worst = adj
                .observations
                .iter()
                .filter(|o| o.redundancy >= cps::batch::statistics::WEAKLY_CHECKED)
                .filter_map(|o| o.w.map(|w| (o, w)))
                .max_by(|a, b| a.1.abs().total_cmp(&b.1.abs()));
            match worst {
                Some((o, w)) if w.abs() > adj.w_critical && adj.redundancy > 1 => {
                    left.push((o.source, o.component));
                    ws.push(w);
                }
                _ => break adj,
            }
        };
        assert!(left.len() >= 3, "seed {seed}: the test wants several removals: {left:?}");
        let found: Vec<(Source, usize)> = fast.removed.iter().map(|r| (r.source, r.component)).collect();
        assert_eq!(found, left, "seed {seed}");
        // The first removal's w is the adjustment's own; the later ones'
        // are linearised at it (a re-adjustment moves the stations by
        // centimetres here: 0.14 % at most on these seeds).
        assert_eq!(fast.removed[0].w, ws[0], "seed {seed}");
        for (r, w) in fast.removed.iter().zip(&ws) {
            assert!((r.w - w).abs() < 3e-3 * w.abs(), "seed {seed}: w {} against {w}", r.w);
        }
        for (a, b) in fast.stations.iter().zip(&reference.stations) {
            assert!((a.to_vector() - b.to_vector()).norm() < 1e-9, "seed {seed}");
        }
        assert!((fast.sigma0_squared - reference.sigma0_squared).abs() < 1e-9 * reference.sigma0_squared);
    }
}

#[test]
fn an_undetermined_point_is_named() {
    let (mut net, _, _) = network(4);
    // A point nobody sights.
    net.points.push(Point { position: Point3::new(1.0, 2.0, 3.0), prior: None });
    let e = adjust(&net, &AdjustOptions::default()).expect_err("undetermined");
    assert!(e.to_string().contains(&format!("point {}", net.points.len() - 1)), "{e}");
    // A non-finite reading.
    let (mut net, _, _) = network(4);
    net.readings[3].reading.azimuth_rad = f64::NAN;
    assert!(adjust(&net, &AdjustOptions::default()).expect_err("NaN").to_string().contains("reading 3"));
}

/// `freed_points` (one adjustment and an update a point) against the
/// network adjusted again without the point's prior, for a fixed control
/// point, a weighted one, a partly fixed one (adjusted again either way),
/// a free point, and with a scalar left out as snooping leaves it.
#[test]
fn freed_points_agree_with_an_adjustment_without_the_prior() {
    use cps::batch::freed::freed_points;
    for seed in [3, 4, 5] {
        let (net, _, _) = network(seed);
        let c0 = net.points.len() - 2;
        let c1 = net.points.len() - 1;
        let mut weighted = net.clone();
        weighted.points[c0].prior = Some(Matrix3::from_diagonal(&Vector3::new(1e-6, 2e-6, 4e-6)));
        weighted.points[c1].prior = Some(Matrix3::from_diagonal(&Vector3::new(4e-6, 4e-6, 9e-6)));
        let left_out = [(Source::Reading(3), 1)];
        for (what, n) in [("as given", &net), ("weighted", &weighted)] {
            for left in [&[][..], &left_out[..]] {
                let options = AdjustOptions { snooping: false, ..AdjustOptions::default() };
                let freed = freed_points(n, &options, left, &[c0, c1, 0], None).expect("freed");
                for (k, &p) in [c0, c1, 0].iter().enumerate() {
                    let mut without = n.clone();
                    without.points[p].prior = None;
                    let a = cps::batch::adjust_without(&without, &options, left).expect("adjusts");
                    let f = freed[k].expect("the rest holds the network");
                    let d = (f.position - a.points[p]).norm();
                    // Second order in the point's move over its sight lines
                    // (a centimetre over 10 m: 10 µm).
                    assert!(d < 2e-5, "seed {seed} {what} point {p}: {d} m from the re-adjustment");
                    let c = a.point_covariance(p);
                    let e = (f.covariance - c).amax() / c.amax();
                    // (The re-adjustment's covariance is at the point's new
                    // place: first order in its move over its sight lines,
                    // millimetres over metres.)
                    assert!(e < 1e-3, "seed {seed} {what} point {p}: covariance off by {e} relative");
                }
            }
        }
    }
}

/// The normal matrix's pattern is counted from `columns_into` before any
/// group is linearised: it must give every group's columns exactly as the
/// linearisation does (readings, station priors, point priors; a removed
/// scalar left out).
#[test]
fn the_counted_columns_are_the_linearised_ones() {
    use cps::batch::{Layout, Source};
    for seed in [1, 2, 3] {
        let (network, stations, points) = network(seed);
        let layout = Layout::new(&network);
        let mut groups = network.groups();
        if let Some(g) = groups.iter_mut().find(|g| matches!(g.source, Source::PointPrior(_))) {
            g.set_active(0, false);
        }
        let mut columns = Vec::new();
        let mut kinds = [0usize; 3];
        for g in &groups {
            network.columns_into(g, &layout, &mut columns);
            let lin = network.linearise(g, &layout, &stations, &points).expect("linearises");
            assert_eq!(columns, lin.columns, "{:?}", g.source);
            kinds[match g.source {
                Source::Reading(_) => 0,
                Source::StationPrior(_) => 1,
                Source::PointPrior(_) => 2,
            }] += 1;
        }
        assert!(kinds[0] > 0 && kinds[2] > 0, "seed {seed}: {kinds:?}");
    }
}
