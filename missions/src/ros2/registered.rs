//! `match --ros2-bag DIR`: the registered scans as a rosbag2, the same way
//! a run's are ([`super::export`]): in frame `map` (the registration's
//! world),
//!
//! | topic | type | what |
//! |---|---|---|
//! | `/tf` | `tf2_msgs/msg/TFMessage` | `map → <scan>` (its registered pose) at the scan's stamp |
//! | `/cps/scan` | `sensor_msgs/msg/PointCloud2` | each scan in its own frame `<scan>` (x, y, z, and intensity when it has one) |
//! | `/cps/pose` | `geometry_msgs/msg/PoseWithCovarianceStamped` | each scan's registered pose and covariance |
//! | `/cps/route` | `nav_msgs/msg/Path` | the scans' poses in order, once, at the last stamp |
//!
//! Stamps: each scan's own time when every scan has one (its GPS time as
//! UTC), else one second apart from the epoch in input order.

use std::collections::BTreeMap;
use std::path::Path;

use anyhow::Result;
use nalgebra::{Isometry3, Matrix3, Matrix6, Point3, Vector3};

use super::bag::BagWriter;
use super::export::{MAP, topic_name};
use super::messages::{
    Covariance6, Header, Path as PathMsg, PointCloud2, Pose, PoseStamped, PoseWithCovariance,
    PoseWithCovarianceStamped, TfMessage, Time, TransformStamped,
};

/// One registered scan.
#[derive(Debug, Clone, Copy)]
pub struct Registered<'a> {
    /// Its name (the frame's, made ROS-safe).
    pub name: &'a str,
    /// Its points in its own frame.
    pub points: &'a [Point3<f32>],
    /// Their intensities, if any.
    pub intensity: Option<&'a [f32]>,
    /// Its registered pose.
    pub world_from_scan: Isometry3<f64>,
    /// 6×6 over (ωx, ωy, ωz, x, y, z), left perturbation in the world's
    /// axes about `about` (`match`'s covariance).
    pub covariance: Matrix6<f64>,
    /// When it was taken, GPS seconds.
    pub gps_time_s: Option<f64>,
}

/// The ROS covariance — (x, y, z, rotation about X, Y, Z) of the scan's
/// origin p and attitude in the world's axes — of a left perturbation
/// (ω, v) about `about`: δp = v + ω × (p − about), δθ = ω.
pub fn ros_covariance(c: &Matrix6<f64>, p: &Vector3<f64>, about: &Vector3<f64>) -> [f64; 36] {
    let r = p - about;
    let skew = Matrix3::new(0.0, -r.z, r.y, r.z, 0.0, -r.x, -r.y, r.x, 0.0);
    let mut j = Matrix6::zeros();
    j.fixed_view_mut::<3, 3>(0, 0).copy_from(&(-skew));
    j.fixed_view_mut::<3, 3>(0, 3).copy_from(&Matrix3::identity());
    j.fixed_view_mut::<3, 3>(3, 0).copy_from(&Matrix3::identity());
    let out = j * c * j.transpose();
    std::array::from_fn(|k| out[(k / 6, k % 6)])
}

/// Writes `scans` into the new rosbag2 directory `dir`; their covariances
/// are about `about`. Returns the messages per topic.
pub fn write(dir: &Path, scans: &[Registered<'_>], about: &Vector3<f64>, note: &str) -> Result<BTreeMap<String, u64>> {
    let mut bag = BagWriter::create(dir, note)?;
    let timed = scans.iter().all(|s| s.gps_time_s.is_some());
    let stamp = |k: usize, s: &Registered<'_>| -> u64 {
        match (timed, s.gps_time_s) {
            // GPS → UNIX: the epochs' 315,964,800 s less the 18 leap seconds.
            (true, Some(g)) => ((g + 315_964_800.0 - 18.0).max(0.0) * 1e9).round() as u64,
            _ => k as u64 * 1_000_000_000,
        }
    };
    let header = |ns: u64, frame: &str| Header { stamp: Time::from_nanos(ns), frame_id: frame.into() };
    let mut route = Vec::new();
    let mut last = 0;
    for (k, s) in scans.iter().enumerate() {
        let ns = stamp(k, s);
        last = last.max(ns);
        let frame = topic_name(s.name);
        let pose = Pose::from(&s.world_from_scan);
        bag.write(
            "/tf",
            ns,
            &TfMessage {
                transforms: vec![TransformStamped {
                    header: header(ns, MAP),
                    child_frame_id: frame.clone(),
                    transform: pose,
                }],
            },
        )?;
        bag.write("/cps/scan", ns, &PointCloud2::xyz(header(ns, &frame), s.points, s.intensity))?;
        let covariance = ros_covariance(&s.covariance, &s.world_from_scan.translation.vector, about);
        bag.write(
            "/cps/pose",
            ns,
            &PoseWithCovarianceStamped {
                header: header(ns, MAP),
                pose: PoseWithCovariance { pose, covariance: Covariance6(covariance) },
            },
        )?;
        route.push(PoseStamped { header: header(ns, MAP), pose });
    }
    bag.write("/cps/route", last, &PathMsg { header: header(last, MAP), poses: route })?;
    let counts = bag.counts();
    bag.finish()?;
    Ok(counts)
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Translation3, UnitQuaternion, Vector6};

    /// The mapping against finite differences: perturb by a left (ω, v)
    /// about `about`, read off the origin's move and the rotation.
    #[test]
    fn the_covariance_maps_like_the_perturbation() {
        let about = Vector3::new(10.0, -4.0, 1.0);
        let pose =
            Isometry3::from_parts(Translation3::new(13.0, 2.0, 0.5), UnitQuaternion::from_euler_angles(0.1, -0.2, 0.7));
        let xi = Vector6::new(1e-7, -2e-7, 3e-7, 4e-7, 5e-7, -6e-7);
        let (w, v) = (xi.fixed_rows::<3>(0).into_owned(), xi.fixed_rows::<3>(3).into_owned());
        // T' = [exp(ω) | v + about − exp(ω)·about] · T (left, about `about`).
        let rot = UnitQuaternion::from_scaled_axis(w);
        let moved = Isometry3::from_parts(Translation3::from(v + about - rot * about), rot) * pose;
        let dp = moved.translation.vector - pose.translation.vector;
        let dtheta = (moved.rotation * pose.rotation.inverse()).scaled_axis();
        // A covariance that is xi·xiᵀ maps to J·xi·(J·xi)ᵀ.
        let c = xi * xi.transpose();
        let got = ros_covariance(&c, &pose.translation.vector, &about);
        let expected = Vector6::new(dp.x, dp.y, dp.z, dtheta.x, dtheta.y, dtheta.z);
        for r in 0..6 {
            for k in 0..6 {
                let e = expected[r] * expected[k];
                assert!((got[6 * r + k] - e).abs() < 1e-5 * e.abs() + 1e-26, "({r}, {k}): {} vs {e}", got[6 * r + k]);
            }
        }
    }
}
