//! Directions ICP cannot see (degeneracy-aware ICP, Zhang, Kaess & Singh
//! 2016): the eigen-analysis of the point-to-plane normal matrix. Rotation
//! and translation are made comparable by a lever arm L — ξ = (ω, v) as
//! u = (L·ω, v), metres both — and a direction whose eigenvalue is below
//! `min_ratio` times the largest is unobservable: a straight corridor's
//! axis, a pipe's axis and the roll about it. The solve then leaves those
//! directions where the estimate (or a prior, which is part of the normal
//! matrix) holds them, instead of letting them slide on noise.
//!
//! Noise in the normals couples a blind direction weakly between rotation
//! and translation (a corridor's axis comes out as the axis and a
//! hundredth of a degree of yaw per metre): a blind direction's rotation
//! or translation part below [`SNAP`] (of the unit vector in u) is taken
//! as that noise and dropped, so that the information a match keeps
//! ([`Observability::observed_part`]) says nothing along the axis itself —
//! otherwise the coupling, times the large eigenvalues, leaves
//! centimetre-level "information" along the axis that a pose graph then
//! believes. (A pipe's roll about an axis well off the frame's origin keeps
//! its translation part: that coupling is geometry.)

use nalgebra::{Matrix6, Point3, SymmetricEigen, Vector3, Vector6};

/// The centroid of a point set (the origin for none).
pub fn centroid(points: &[Point3<f32>]) -> Point3<f64> {
    let n = points.len().max(1) as f64;
    Point3::from(points.iter().fold(Vector3::zeros(), |a, p| a + p.coords.cast::<f64>()) / n)
}

/// The lever arm of a point set: its RMS distance from its centroid (at
/// least 1 mm).
pub fn lever_arm(points: &[Point3<f32>]) -> f64 {
    centroid_and_lever_arm(points).1
}

/// A point set's [`centroid`] and [`lever_arm`], what an analysis about
/// the centroid needs.
pub fn centroid_and_lever_arm(points: &[Point3<f32>]) -> (Point3<f64>, f64) {
    let n = points.len().max(1) as f64;
    let c = centroid(points);
    let rms = (points.iter().map(|p| (p.coords.cast::<f64>() - c.coords).norm_squared()).sum::<f64>() / n).sqrt();
    (c, rms.max(1e-3))
}

/// A blind direction's rotation or translation part (of its unit vector in
/// u) below this is noise.
pub const SNAP: f64 = 0.05;

/// An orthonormal basis of the span of `directions` (Gram–Schmidt, in
/// order; a direction within 1e-6 of the others' span adds nothing).
/// [`Observability::unobservable`] comes back normalised but not
/// orthogonal in ξ (the analysis is orthonormal in u about the centroid):
/// whatever projects off the blind directions goes through this.
pub fn orthonormal(directions: &[Vector6<f64>]) -> Vec<Vector6<f64>> {
    let mut basis: Vec<Vector6<f64>> = Vec::with_capacity(directions.len());
    for d in directions {
        let mut b = *d;
        for q in &basis {
            b -= q * q.dot(&b);
        }
        if b.norm() > 1e-6 {
            basis.push(b.normalize());
        }
    }
    basis
}

/// I − Q·Qᵀ, Q an [`orthonormal`] basis of `directions`: the projector
/// off their span (the identity for none).
pub fn projector_off(directions: &[Vector6<f64>]) -> Matrix6<f64> {
    orthonormal(directions).iter().fold(Matrix6::identity(), |p, q| p - q * q.transpose())
}

/// The normal equations' eigen-analysis in u = (L·ω, v_c), the twist
/// about a centre c (v_c the motion of the point at c).
#[derive(Debug, Clone)]
pub struct Observability {
    hu: Matrix6<f64>,
    eigen: SymmetricEigen<f64, nalgebra::U6>,
    lever_arm_m: f64,
    min_ratio: f64,
    /// ξ = A·ξ_c: v = v_c + c × ω.
    about: Matrix6<f64>,
    /// Blind directions in u found by another analysis
    /// ([`judged`](Self::judged)): `hu` is projected off them.
    judged: Vec<Vector6<f64>>,
}

impl Observability {
    /// Analyses the normal matrix `h` (of ξ = (ω, v)) about the frame's
    /// origin, with lever arm `lever_arm_m` (> 0) and eigenvalue ratio
    /// `min_ratio`.
    pub fn new(h: &Matrix6<f64>, lever_arm_m: f64, min_ratio: f64) -> Self {
        Self::about(h, &Point3::origin(), lever_arm_m, min_ratio)
    }

    /// [`Observability::new`] about `centre` (the matched points'
    /// centroid, in the frame of `h`): the verdict is then the same in
    /// every frame — a turn about a far origin no longer weighs as a slide
    /// (issue 38: a façade scanned from 50 m had 2–5 directions flagged
    /// blind about its scanner). Directions and information come back in
    /// the frame of `h`.
    pub fn about(h: &Matrix6<f64>, centre: &Point3<f64>, lever_arm_m: f64, min_ratio: f64) -> Self {
        let mut about = Matrix6::identity();
        about.fixed_view_mut::<3, 3>(3, 0).copy_from(&centre.coords.cross_matrix());
        let s = scale(lever_arm_m);
        let hu = s * about.transpose() * h * about * s;
        let hu = (hu + hu.transpose()) * 0.5;
        let eigen = SymmetricEigen::new(hu);
        Self { hu, eigen, lever_arm_m, min_ratio, about, judged: Vec::new() }
    }

    /// [`about`](Self::about) `h`, blind also where `surface` is — the same
    /// normal matrix without the pairs whose partner lies on one scan line
    /// ([`IcpConfig::line_ratio`](crate::icp::IcpConfig::line_ratio)):
    /// their PCA normal is the line's own plane, not the surface's, and on
    /// sparse scan lines of a pipe it lies along the axis and makes the
    /// axis look seen (the sewer at 60 slices: BENCHMARKS.md, "Sparse scan
    /// lines"). The solve and the information keep every pair, projected
    /// off those directions. With `surface` equal to `h`, exactly
    /// [`about`](Self::about).
    pub fn judged(
        h: &Matrix6<f64>,
        surface: &Matrix6<f64>,
        centre: &Point3<f64>,
        lever_arm_m: f64,
        min_ratio: f64,
    ) -> Self {
        let own = Self::about(h, centre, lever_arm_m, min_ratio);
        if surface == h {
            return own;
        }
        let judged = Self::about(surface, centre, lever_arm_m, min_ratio).blind();
        if judged.is_empty() {
            return own;
        }
        let p = projector_off(&judged);
        let hu = p * own.hu * p;
        let hu = (hu + hu.transpose()) * 0.5;
        Self { eigen: SymmetricEigen::new(hu), hu, judged, ..own }
    }

    /// A⁻¹: ξ_c = A⁻¹·ξ.
    fn about_inverse(&self) -> Matrix6<f64> {
        let mut inverse = self.about;
        inverse.fixed_view_mut::<3, 3>(3, 0).scale_mut(-1.0);
        inverse
    }

    fn observed(&self, i: usize) -> bool {
        let max = self.eigen.eigenvalues.max();
        max > 0.0 && self.eigen.eigenvalues[i] > self.min_ratio * max
    }

    /// The blind directions in u: the eigenvectors below the ratio, a
    /// rotation or translation part under [`SNAP`] dropped, orthonormalised.
    fn blind(&self) -> Vec<Vector6<f64>> {
        // (`judged` is another analysis' `blind()`: orthonormal already.)
        let judged = &self.judged;
        let snapped = (0..6).filter(|&i| !self.observed(i)).filter_map(|i| {
            let mut b: Vector6<f64> = self.eigen.eigenvectors.column(i).into_owned();
            // What is left outside the directions already judged blind
            // (their own eigenvalues are zero here).
            for q in judged {
                b -= q * q.dot(&b);
            }
            if b.norm() < 0.5 {
                return None;
            }
            b.normalize_mut();
            for part in [0, 3] {
                if b.fixed_rows::<3>(part).norm() < SNAP {
                    b.fixed_rows_mut::<3>(part).fill(0.0);
                }
            }
            Some(b)
        });
        orthonormal(&judged.iter().copied().chain(snapped).collect::<Vec<_>>())
    }

    /// The unobservable directions, each a unit vector of u = (L·ω, v)
    /// (noise components dropped) turned back into ξ = (ω, v) and
    /// normalised.
    pub fn unobservable(&self) -> Vec<Vector6<f64>> {
        let s = self.about * scale(self.lever_arm_m);
        self.blind().into_iter().map(|b| (s * b).normalize()).collect()
    }

    /// The normal matrix with its unobservable directions taken out (the
    /// information a match actually carries): P·H·P in u, P the projector
    /// off the blind directions, mapped back to ξ.
    pub fn observed_part(&self) -> Matrix6<f64> {
        self.projected(&self.hu)
    }

    /// `m` (an information of the same ξ) with this analysis' blind
    /// directions taken out, as [`observed_part`](Self::observed_part)
    /// takes them out of its own.
    pub fn project(&self, m: &Matrix6<f64>) -> Matrix6<f64> {
        let s = scale(self.lever_arm_m);
        self.projected(&(s * self.about.transpose() * m * self.about * s))
    }

    /// P·M_u·P in u, P the projector off the blind directions, mapped back
    /// to ξ: H = A⁻ᵀ·S⁻¹·H_u·S⁻¹·A⁻¹, S⁻¹ = scale(1/L).
    fn projected(&self, mu: &Matrix6<f64>) -> Matrix6<f64> {
        let p = projector_off(&self.blind());
        let inv = scale(1.0 / self.lever_arm_m) * self.about_inverse();
        let h = inv.transpose() * (p * mu * p) * inv;
        0.5 * (h + h.transpose())
    }

    /// How far a motion ξ = (ω, v) (about the frame's origin, in the frame
    /// of `h`) goes along the directions whose eigenvalue is at least
    /// `ratio` of the largest: its length in u = (L·ω, v_c), metres of
    /// motion the matches see well. A pair matched alone slides along a
    /// corridor's axis (with the slight yaw noise couples to it), which the
    /// set's other links hold: that slide is not a disagreement with the
    /// set's poses.
    pub fn seen_motion(&self, xi: &Vector6<f64>, ratio: f64) -> f64 {
        let u = scale(1.0 / self.lever_arm_m) * self.about_inverse() * xi;
        let max = self.eigen.eigenvalues.max();
        (0..6)
            .filter(|&i| max > 0.0 && self.eigen.eigenvalues[i] >= ratio * max)
            .map(|i| self.eigen.eigenvectors.column(i).dot(&u).powi(2))
            .sum::<f64>()
            .sqrt()
    }

    /// The solution of `h ξ = rhs` within the observed directions only
    /// (zero along the others): Zhang et al.'s remapped update.
    pub fn solve(&self, rhs: &Vector6<f64>) -> Vector6<f64> {
        let s = self.about * scale(self.lever_arm_m);
        let ru = s.transpose() * rhs;
        let mut u = Vector6::zeros();
        for i in (0..6).filter(|&i| self.observed(i)) {
            let e = self.eigen.eigenvectors.column(i);
            u += e * (e.dot(&ru) / self.eigen.eigenvalues[i]);
        }
        s * u
    }
}

/// diag(1/L, 1/L, 1/L, 1, 1, 1): ξ = S u.
fn scale(lever_arm_m: f64) -> Matrix6<f64> {
    let inv = 1.0 / lever_arm_m;
    Matrix6::from_diagonal(&Vector6::new(inv, inv, inv, 1.0, 1.0, 1.0))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_full_rank_matrix_solves_as_cholesky_does() {
        let a = Matrix6::from_fn(|i, j| ((i * 7 + j * 3) % 5) as f64 + if i == j { 6.0 } else { 0.0 });
        let h = a.transpose() * a;
        let rhs = Vector6::new(1.0, -2.0, 0.5, 3.0, 0.0, -1.0);
        let o = Observability::new(&h, 4.0, 1e-6);
        assert!(o.unobservable().is_empty());
        let want = h.cholesky().expect("positive definite").solve(&rhs);
        assert!((o.solve(&rhs) - want).norm() < 1e-9 * want.norm());
    }

    /// A direction seen only through the pairs on scan lines (a pipe's axis
    /// through rings' normals) is blind when judged on the surfaces, and
    /// held: the solve moves nothing along it, the rest as `h` has it, and
    /// the information keeps nothing of it. Judged on `h` itself, it is
    /// exactly [`Observability::about`].
    #[test]
    fn a_direction_seen_only_through_scan_lines_is_judged_blind() {
        let surface = Matrix6::from_diagonal(&Vector6::new(50.0, 40.0, 30.0, 1e-6, 20.0, 10.0));
        let mut lines = Matrix6::zeros();
        // The rings' normals along x, coupled to y a little.
        lines[(3, 3)] = 5.0;
        lines[(3, 4)] = 0.5;
        lines[(4, 3)] = 0.5;
        let h = surface + lines;
        let centre = Point3::origin();
        let own = Observability::about(&h, &centre, 3.0, 1e-2);
        assert!(own.unobservable().is_empty(), "h sees x: {:?}", own.unobservable());
        let o = Observability::judged(&h, &surface, &centre, 3.0, 1e-2);
        let dirs = o.unobservable();
        assert_eq!(dirs.len(), 1, "{dirs:?}");
        assert!((dirs[0].abs() - Vector6::new(0.0, 0.0, 0.0, 1.0, 0.0, 0.0)).norm() < 1e-9, "{dirs:?}");
        let rhs = Vector6::new(5.0, 4.0, 3.0, 7.0, 2.0, 1.0);
        let x = o.solve(&rhs);
        assert!(x[3].abs() < 1e-12, "moved along the blind x: {x}");
        // The rest solves h with x held (about the origin, x in u is x in ξ).
        assert!((x[4] - 2.0 / h[(4, 4)]).abs() < 1e-12 && (x[0] - 0.1).abs() < 1e-12, "{x}");
        assert!(o.observed_part().row(3).amax() < 1e-9, "{}", o.observed_part());
        let same = Observability::judged(&h, &h, &centre, 3.0, 1e-2);
        assert_eq!(same.solve(&rhs), own.solve(&rhs));
        assert_eq!(same.observed_part(), own.observed_part());
    }

    #[test]
    fn a_missing_direction_is_found_and_left_alone() {
        // Information about everything but translation along x.
        let h = Matrix6::from_diagonal(&Vector6::new(50.0, 40.0, 30.0, 0.0, 20.0, 10.0));
        let o = Observability::new(&h, 3.0, 1e-4);
        let dirs = o.unobservable();
        assert_eq!(dirs.len(), 1);
        assert!((dirs[0].abs() - Vector6::new(0.0, 0.0, 0.0, 1.0, 0.0, 0.0)).norm() < 1e-12);
        let x = o.solve(&Vector6::new(5.0, 4.0, 3.0, 7.0, 2.0, 1.0));
        assert!((x - Vector6::new(0.1, 0.1, 0.1, 0.0, 0.1, 0.1)).norm() < 1e-12, "{x}");
        let kept = o.observed_part();
        assert!((kept - h).amax() < 1e-9, "nothing observed is lost: {kept}");
        // A little information along the blind axis (noise) is taken out.
        let mut noisy = h;
        noisy[(3, 3)] = 1e-3;
        let o = Observability::new(&noisy, 3.0, 1e-4);
        assert_eq!(o.unobservable().len(), 1);
        assert!((o.observed_part() - h).amax() < 1e-12, "{}", o.observed_part());
    }

    /// A corridor along x (floor, ceiling, two walls) `offset` from the
    /// frame's origin: its normal matrix for point-to-plane pairs.
    fn corridor(offset: Vector3<f64>) -> (Matrix6<f64>, Vec<Point3<f32>>) {
        let mut h = Matrix6::zeros();
        let mut points = Vec::new();
        for i in 0..200 {
            let x = -10.0 + 0.1 * i as f64;
            for (p, n) in [
                (Vector3::new(x, 0.0, -1.2), Vector3::z()),
                (Vector3::new(x, 0.0, 1.3), -Vector3::z()),
                (Vector3::new(x, -1.0, 0.1), Vector3::y()),
                (Vector3::new(x, 1.1, -0.2), -Vector3::y()),
                (Vector3::new(x, 0.5, 0.6), -Vector3::y()),
            ] {
                let q = p + offset;
                // r = n·(ω × q + v): J = (q × n, n).
                let j = Vector6::new(0.0, 0.0, 0.0, n.x, n.y, n.z);
                let mut j = j;
                j.fixed_rows_mut::<3>(0).copy_from(&q.cross(&n));
                h += j * j.transpose();
                points.push(Point3::from(q.cast::<f32>()));
            }
        }
        (h, points)
    }

    #[test]
    fn the_verdict_does_not_depend_on_where_the_frame_is() {
        // At the origin the corridor is blind along its axis only; 50 m
        // away the analysis about the origin flags more (a turn about the
        // far origin weighs as a slide), about the centroid the same one.
        let (h0, p0) = corridor(Vector3::zeros());
        let o0 = Observability::about(&h0, &centroid(&p0), lever_arm(&p0), 1e-3);
        let blind0 = o0.unobservable();
        assert_eq!(blind0.len(), 1, "{blind0:?}");
        assert!((blind0[0].abs() - Vector6::new(0.0, 0.0, 0.0, 1.0, 0.0, 0.0)).norm() < 1e-9, "{}", blind0[0]);
        for offset in [Vector3::new(0.0, 50.0, 0.0), Vector3::new(30.0, -40.0, 20.0), Vector3::new(0.0, 0.0, 500.0)] {
            let (h, p) = corridor(offset);
            let far = Observability::new(&h, lever_arm(&p), 1e-3).unobservable();
            assert!(far.len() > 1, "{offset}: about the far origin {far:?}");
            let o = Observability::about(&h, &centroid(&p), lever_arm(&p), 1e-3);
            let blind = o.unobservable();
            assert_eq!(blind.len(), 1, "{offset}: {blind:?}");
            // The axis is a pure slide wherever the frame is.
            assert!((blind[0].abs() - Vector6::new(0.0, 0.0, 0.0, 1.0, 0.0, 0.0)).norm() < 1e-9, "{}", blind[0]);
            // The observed part keeps everything but the axis: H along any
            // direction orthogonal to it is unchanged.
            let kept = o.observed_part();
            let e = Vector6::new(0.3, -0.2, 0.1, 0.0, 1.0, -0.5);
            let ratio = (e.transpose() * kept * e)[(0, 0)] / (e.transpose() * h * e)[(0, 0)];
            assert!((ratio - 1.0).abs() < 1e-6, "{offset}: {ratio}");
            // Solving about the centroid is solving in the frame.
            let rhs = h * Vector6::new(0.01, -0.02, 0.005, 0.0, 0.3, -0.1);
            let x = o.solve(&rhs);
            assert!((h * x - rhs).norm() < 1e-6 * rhs.norm(), "{offset}: {x}");
        }
    }

    #[test]
    fn the_observed_part_drops_a_coupled_blind_direction() {
        // Blind along d = (ω, v) mixing a turn about z with a slide in y
        // (a pipe's roll about an axis off the origin).
        let d = Vector6::new(0.0, 0.0, 0.5, 0.0, 2.0, 0.0).normalize();
        let a = Matrix6::from_fn(|i, j| ((i * 5 + j * 11) % 7) as f64 + if i == j { 4.0 } else { 0.0 });
        let p = Matrix6::identity() - d * d.transpose();
        let h = p * a.transpose() * a * p;
        let o = Observability::new(&h, 2.0, 1e-8);
        assert_eq!(o.unobservable().len(), 1);
        assert!((o.unobservable()[0].dot(&d)).abs() > 1.0 - 1e-9);
        assert!((o.observed_part() - h).amax() < 1e-9 * h.amax());
    }

    #[test]
    fn the_projector_takes_out_the_span_of_directions_that_are_not_orthogonal() {
        // Two unit directions 60° apart (as a pipe's axis and roll come back
        // about its centroid), and one that repeats the first's span.
        let a = Vector6::new(0.0, 0.0, 0.0, 1.0, 0.0, 0.0);
        let b = Vector6::new(0.0, 0.0, 0.0, 0.5, 0.75f64.sqrt(), 0.0);
        let p = projector_off(&[a, b, -a]);
        assert_eq!(orthonormal(&[a, b, -a]).len(), 2);
        assert!((p * p - p).amax() < 1e-12 && (p - p.transpose()).amax() < 1e-12);
        assert!((p * a).norm() < 1e-12 && (p * b).norm() < 1e-12);
        // What lies outside the span is kept whole.
        let c = Vector6::new(1.0, -2.0, 0.5, 0.0, 0.0, 3.0);
        assert!((p * c - c).norm() < 1e-12);
        // Projecting one by one as if orthonormal leaves some of b.
        let naive = (Matrix6::identity() - a * a.transpose()) * (Matrix6::identity() - b * b.transpose());
        assert!((naive * b).norm() > 0.1 || (naive * a).norm() > 0.1);
        assert_eq!(projector_off(&[]), Matrix6::identity());
    }
}
