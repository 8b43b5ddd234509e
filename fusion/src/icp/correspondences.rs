//! One pass of correspondences: every source point's nearest target point
//! within the distance (back faces left out on request), summed into what
//! both metrics' normal equations need.

use nalgebra::{Isometry3, Matrix3, Matrix6, Point3, Vector3, Vector6};
use rayon::prelude::*;

use super::config::{IcpConfig, Method};
use super::target::{Target, point};
use crate::se3::skew;

/// Sums over the correspondences of one iteration.
#[derive(Clone, Copy, Default)]
pub(crate) struct Sums {
    pub(crate) n: usize,
    /// Σ w (point-to-point; equals n without a kernel).
    pub(crate) sw: f64,
    pub(crate) sq: f64,
    pub(crate) h: Matrix6<f64>,
    pub(crate) b: Vector6<f64>,
    pub(crate) sp: Vector3<f64>,
    pub(crate) sq_t: Vector3<f64>,
    pub(crate) spq: Matrix3<f64>,
    pub(crate) spp: Matrix3<f64>,
}

impl Sums {
    pub(crate) fn merge(mut self, o: Sums) -> Sums {
        self.n += o.n;
        self.sw += o.sw;
        self.sq += o.sq;
        self.h += o.h;
        self.b += o.b;
        self.sp += o.sp;
        self.sq_t += o.sq_t;
        self.spq += o.spq;
        self.spp += o.spp;
        self
    }

    /// Σ w JᵀJ of the pairs, with J = [−[p]×, I] for point-to-point (derived
    /// from Σw, Σwp and Σwppᵀ: [p]×ᵀ[p]× = |p|²I − ppᵀ) and the accumulated
    /// `h` for point-to-plane.
    pub(crate) fn normal_matrix(&self, method: Method) -> Matrix6<f64> {
        match method {
            Method::PointToPlane => self.h,
            Method::PointToPoint => {
                let k = skew(&self.sp);
                let mut h = Matrix6::zeros();
                h.fixed_view_mut::<3, 3>(0, 0).copy_from(&(Matrix3::identity() * self.spp.trace() - self.spp));
                h.fixed_view_mut::<3, 3>(0, 3).copy_from(&k);
                h.fixed_view_mut::<3, 3>(3, 0).copy_from(&(-k));
                h.fixed_view_mut::<3, 3>(3, 3).copy_from(&(Matrix3::identity() * self.sw));
                h
            }
        }
    }
}

/// One pass over the source: nearest neighbours within the distance and
/// the sums both metrics need. `partners` holds each source point's
/// nearest target point of the last pass (`u32::MAX` before the first),
/// where its search starts, and is updated.
pub(crate) fn accumulate(
    source: &[Point3<f32>],
    target: &Target,
    estimate: &Isometry3<f64>,
    max_sq: f64,
    config: &IcpConfig,
    partners: &mut [u32],
) -> Sums {
    let r: Matrix3<f64> = estimate.rotation.to_rotation_matrix().into_inner();
    let t = estimate.translation.vector;
    // The source scanner in the target frame.
    let back_faces = config.reject_back_faces.then(|| r * config.source_viewpoint.coords + t);
    source
        .par_chunks(4096)
        .zip(partners.par_chunks_mut(4096))
        .map(|(chunk, partners)| {
            let mut s = Sums::default();
            for (p, partner) in chunk.iter().zip(partners) {
                let pt = r * p.coords.cast::<f64>() + t;
                let (i, d2) = target.nearest_from(&[pt.x as f32, pt.y as f32, pt.z as f32], *partner);
                *partner = i as u32;
                if d2 > max_sq {
                    continue;
                }
                let q = point(&target.points[i]);
                if let Some(eye) = back_faces
                    && target.normals[i].dot(&(eye - q)) < 0.0
                {
                    continue;
                }
                s.n += 1;
                match config.method {
                    Method::PointToPlane => {
                        let n = target.normals[i];
                        let res = n.dot(&(pt - q));
                        let w = config.kernel.weight(res);
                        // r = nᵀ(T̂p + ω × T̂p + v − q): ∂r/∂ω = T̂p × n, ∂r/∂v = n.
                        let c = pt.cross(&n);
                        let j = Vector6::new(c.x, c.y, c.z, n.x, n.y, n.z);
                        s.h += w * j * j.transpose();
                        s.b += w * res * j;
                        s.sq += res * res;
                    }
                    Method::PointToPoint => {
                        let e2 = (pt - q).norm_squared();
                        let w = config.kernel.weight(e2.sqrt());
                        s.sq += e2;
                        s.sw += w;
                        s.sp += w * pt;
                        s.sq_t += w * q;
                        s.spq += w * pt * q.transpose();
                        s.spp += w * pt * pt.transpose();
                    }
                }
            }
            s
        })
        .reduce(Sums::default, Sums::merge)
}

#[cfg(test)]
mod tests {
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    use super::*;

    /// The point-to-point normal matrix derived from the sums equals Σ JᵀJ
    /// with J = [−[p]×, I] built point by point.
    #[test]
    fn point_to_point_normal_matrix() {
        let mut rng = ChaCha8Rng::seed_from_u64(2);
        let mut sums = Sums::default();
        let mut explicit = Matrix6::zeros();
        for _ in 0..20 {
            let p = Vector3::new(rng.random_range(-5.0..5.0), rng.random_range(-5.0..5.0), rng.random_range(-5.0..5.0));
            let mut j = nalgebra::Matrix3x6::zeros();
            j.fixed_view_mut::<3, 3>(0, 0).copy_from(&(-skew(&p)));
            j.fixed_view_mut::<3, 3>(0, 3).copy_from(&Matrix3::identity());
            explicit += j.transpose() * j;
            sums.n += 1;
            sums.sw += 1.0;
            sums.sp += p;
            sums.spp += p * p.transpose();
        }
        assert!((sums.normal_matrix(Method::PointToPoint) - explicit).amax() < 1e-9);
    }
}
