//! E57 through the `e57` crate: one point cloud of f32 Cartesian
//! coordinates (f64 for a georeferenced cloud; + intensity as a unit float
//! when present); reading takes every point cloud in the file with its pose
//! applied.

use std::path::Path;

use e57::{CartesianCoordinate, E57Reader, E57Writer, Record, RecordValue};
use nalgebra::Point3;

use super::PointCloud;
use crate::error::{Result, ScannerError};

pub(super) fn read(path: &Path) -> Result<PointCloud> {
    let mut reader = E57Reader::from_file(path).map_err(|e| ScannerError::whole_file(path, e))?;
    let mut cloud = PointCloud::default();
    let mut intensity = Vec::new();
    let mut all_have_intensity = true;
    for pc in reader.pointclouds() {
        let mut points = reader.pointcloud_simple(&pc).map_err(|e| ScannerError::whole_file(path, e))?;
        points.normalize_intensity(false);
        for (i, p) in points.enumerate() {
            let p = p.map_err(|e| ScannerError::whole_file(path, format!("point {i}: {e}")))?;
            if let CartesianCoordinate::Valid { x, y, z } = p.cartesian {
                let point = Point3::new(x as f32, y as f32, z as f32);
                if !point.iter().all(|v| v.is_finite()) {
                    return Err(ScannerError::whole_file(
                        path,
                        format!("point {i}: ({x}, {y}, {z}) m: expected coordinates within ±{:e}", f32::MAX),
                    ));
                }
                cloud.points.push(point);
                match p.intensity {
                    Some(v) => intensity.push(v),
                    None => all_have_intensity = false,
                }
            }
        }
    }
    if all_have_intensity && !cloud.points.is_empty() {
        cloud.intensity = Some(intensity);
    }
    Ok(cloud)
}

pub(super) fn write(path: &Path, cloud: &PointCloud) -> Result<()> {
    let mut writer = E57Writer::from_file(path, "cps-survey-e57").map_err(|e| ScannerError::whole_file(path, e))?;
    // Georeferenced: 64-bit coordinates (origin + p).
    let georeferenced = cloud.georeferenced();
    let mut prototype = if georeferenced {
        vec![Record::CARTESIAN_X_F64, Record::CARTESIAN_Y_F64, Record::CARTESIAN_Z_F64]
    } else {
        vec![Record::CARTESIAN_X_F32, Record::CARTESIAN_Y_F32, Record::CARTESIAN_Z_F32]
    };
    if cloud.intensity.is_some() {
        prototype.push(Record::INTENSITY_UNIT_F32);
    }
    {
        let mut pc =
            writer.add_pointcloud("cps-survey-cloud", prototype).map_err(|e| ScannerError::whole_file(path, e))?;
        for (i, p) in cloud.points.iter().enumerate() {
            let mut values = if georeferenced {
                cloud.coordinates(i).map(RecordValue::Double).to_vec()
            } else {
                vec![RecordValue::Single(p.x), RecordValue::Single(p.y), RecordValue::Single(p.z)]
            };
            if let Some(v) = &cloud.intensity {
                values.push(RecordValue::Single(v[i]));
            }
            pc.add_point(values).map_err(|e| ScannerError::whole_file(path, format!("point {i}: {e}")))?;
        }
        pc.finalize().map_err(|e| ScannerError::whole_file(path, e))?;
    }
    writer.finalize().map_err(|e| ScannerError::whole_file(path, e))
}
