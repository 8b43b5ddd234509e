//! The standard ROS 2 messages the bag carries, laid out field by field as
//! their definitions (`msg/`, ROS 2 Humble's, as `ros2 bag record` embeds
//! them with their dependencies) so that serde's CDR serialiser writes them
//! in order. Only the layouts are ours; CDR is `cdr-encoding`'s.

use nalgebra::{Isometry3, Point3, UnitQuaternion};
use serde::{Deserialize, Serialize};

/// A message type: its name and its `ros2msg` definition with every
/// dependency, as the bag's schema.
pub trait Message: Serialize {
    /// `package/msg/Name`.
    const TYPE: &'static str;
    /// The definition (`ros2msg`).
    const DEFINITION: &'static str;
}

/// `builtin_interfaces/msg/Time` (and `Duration`: the same layout).
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct Time {
    /// Seconds.
    pub sec: i32,
    /// Nanoseconds within the second.
    pub nanosec: u32,
}

impl Time {
    /// From nanoseconds since the epoch (clamped to what `int32` seconds hold).
    pub fn from_nanos(ns: u64) -> Self {
        let sec = (ns / 1_000_000_000).min(i32::MAX as u64) as i32;
        Self { sec, nanosec: (ns % 1_000_000_000) as u32 }
    }
}

/// `std_msgs/msg/Header`.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct Header {
    /// When.
    pub stamp: Time,
    /// In which frame.
    pub frame_id: String,
}

/// `geometry_msgs/msg/Point` and `Vector3`.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct Vector3 {
    /// x.
    pub x: f64,
    /// y.
    pub y: f64,
    /// z.
    pub z: f64,
}

impl From<Point3<f64>> for Vector3 {
    fn from(p: Point3<f64>) -> Self {
        Self { x: p.x, y: p.y, z: p.z }
    }
}

/// `geometry_msgs/msg/Quaternion`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Quaternion {
    /// x.
    pub x: f64,
    /// y.
    pub y: f64,
    /// z.
    pub z: f64,
    /// w.
    pub w: f64,
}

impl Default for Quaternion {
    fn default() -> Self {
        Self { x: 0.0, y: 0.0, z: 0.0, w: 1.0 }
    }
}

impl From<UnitQuaternion<f64>> for Quaternion {
    fn from(q: UnitQuaternion<f64>) -> Self {
        Self { x: q.i, y: q.j, z: q.k, w: q.w }
    }
}

/// `geometry_msgs/msg/Pose` (and `Transform`: translation then rotation,
/// the same layout).
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct Pose {
    /// Position (translation).
    pub position: Vector3,
    /// Orientation (rotation).
    pub orientation: Quaternion,
}

impl From<&Isometry3<f64>> for Pose {
    fn from(t: &Isometry3<f64>) -> Self {
        Self { position: Point3::from(t.translation.vector).into(), orientation: t.rotation.into() }
    }
}

/// `float64[36]`: a fixed array, no length on the wire (serde derives
/// arrays only up to 32).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Covariance6(pub [f64; 36]);

impl Serialize for Covariance6 {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        use serde::ser::SerializeTuple;
        let mut t = s.serialize_tuple(36)?;
        for v in &self.0 {
            t.serialize_element(v)?;
        }
        t.end()
    }
}

impl<'de> Deserialize<'de> for Covariance6 {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        struct Visitor;
        impl<'de> serde::de::Visitor<'de> for Visitor {
            type Value = Covariance6;
            fn expecting(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
                f.write_str("36 float64")
            }
            fn visit_seq<A: serde::de::SeqAccess<'de>>(self, mut seq: A) -> Result<Covariance6, A::Error> {
                let mut out = [0.0; 36];
                for (k, v) in out.iter_mut().enumerate() {
                    *v = seq.next_element()?.ok_or_else(|| serde::de::Error::invalid_length(k, &self))?;
                }
                Ok(Covariance6(out))
            }
        }
        d.deserialize_tuple(36, Visitor)
    }
}

/// `geometry_msgs/msg/PoseWithCovariance`: the 6×6 covariance row-major
/// over (x, y, z, rotation about X, about Y, about Z).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PoseWithCovariance {
    /// The pose.
    pub pose: Pose,
    /// Row-major 6×6.
    pub covariance: Covariance6,
}

/// `geometry_msgs/msg/PoseWithCovarianceStamped`.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct PoseWithCovarianceStamped {
    /// Stamp and frame.
    pub header: Header,
    /// The pose and its covariance.
    pub pose: PoseWithCovariance,
}

impl Message for PoseWithCovarianceStamped {
    const TYPE: &'static str = "geometry_msgs/msg/PoseWithCovarianceStamped";
    const DEFINITION: &'static str = include_str!("msg/geometry_msgs.PoseWithCovarianceStamped.msg");
}

/// `geometry_msgs/msg/TransformStamped`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TransformStamped {
    /// Stamp and the parent frame.
    pub header: Header,
    /// The child frame.
    pub child_frame_id: String,
    /// parent_from_child.
    pub transform: Pose,
}

/// `tf2_msgs/msg/TFMessage`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TfMessage {
    /// The transforms.
    pub transforms: Vec<TransformStamped>,
}

impl Message for TfMessage {
    const TYPE: &'static str = "tf2_msgs/msg/TFMessage";
    const DEFINITION: &'static str = include_str!("msg/tf2_msgs.TFMessage.msg");
}

/// The head of `nav_msgs/msg/Odometry` (its twist is not read).
#[derive(Debug, Clone, PartialEq, Deserialize)]
pub struct OdometryHead {
    /// Stamp and the fixed frame.
    pub header: Header,
    /// The robot's frame.
    pub child_frame_id: String,
    /// header.frame_id_from_child.
    pub pose: PoseWithCovariance,
}

/// `uint8[]`, serialised as one block (CDR's sequence of octets).
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Bytes(pub Vec<u8>);

impl Serialize for Bytes {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        s.serialize_bytes(&self.0)
    }
}

impl<'de> Deserialize<'de> for Bytes {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        struct Visitor;
        impl<'de> serde::de::Visitor<'de> for Visitor {
            type Value = Bytes;
            fn expecting(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
                f.write_str("a sequence of octets")
            }
            fn visit_bytes<E: serde::de::Error>(self, v: &[u8]) -> Result<Bytes, E> {
                Ok(Bytes(v.to_vec()))
            }
            fn visit_byte_buf<E: serde::de::Error>(self, v: Vec<u8>) -> Result<Bytes, E> {
                Ok(Bytes(v))
            }
        }
        d.deserialize_byte_buf(Visitor)
    }
}

/// `sensor_msgs/msg/PointField`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PointField {
    /// Field name (`x`, `intensity`, …).
    pub name: String,
    /// Byte offset in a point.
    pub offset: u32,
    /// `FLOAT32` = 7, `FLOAT64` = 8, …
    pub datatype: u8,
    /// Elements.
    pub count: u32,
}

/// `PointField.FLOAT32`.
pub const FLOAT32: u8 = 7;

/// `sensor_msgs/msg/PointCloud2`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PointCloud2 {
    /// Stamp and frame.
    pub header: Header,
    /// Rows (1: unorganised).
    pub height: u32,
    /// Points per row.
    pub width: u32,
    /// The point layout.
    pub fields: Vec<PointField>,
    /// Byte order of `data`.
    pub is_bigendian: bool,
    /// Bytes per point.
    pub point_step: u32,
    /// Bytes per row.
    pub row_step: u32,
    /// The points.
    pub data: Bytes,
    /// No invalid (NaN) points.
    pub is_dense: bool,
}

impl PointCloud2 {
    /// An unorganised, dense cloud of `points` (with `intensity`, one per
    /// point, when given) as little-endian float32 `x y z [intensity]`.
    pub fn xyz(header: Header, points: &[Point3<f32>], intensity: Option<&[f32]>) -> Self {
        let intensity = intensity.filter(|i| i.len() == points.len());
        let names: &[&str] = if intensity.is_some() { &["x", "y", "z", "intensity"] } else { &["x", "y", "z"] };
        let fields: Vec<PointField> = names
            .iter()
            .enumerate()
            .map(|(k, name)| PointField { name: (*name).into(), offset: 4 * k as u32, datatype: FLOAT32, count: 1 })
            .collect();
        let step = 4 * fields.len();
        let mut data = Vec::with_capacity(step * points.len());
        for (k, p) in points.iter().enumerate() {
            for v in [p.x, p.y, p.z] {
                data.extend_from_slice(&v.to_le_bytes());
            }
            if let Some(i) = intensity {
                data.extend_from_slice(&i[k].to_le_bytes());
            }
        }
        let width = points.len() as u32;
        Self {
            header,
            height: 1,
            width,
            fields,
            is_bigendian: false,
            point_step: step as u32,
            row_step: step as u32 * width,
            data: Bytes(data),
            is_dense: true,
        }
    }
}

impl Message for PointCloud2 {
    const TYPE: &'static str = "sensor_msgs/msg/PointCloud2";
    const DEFINITION: &'static str = include_str!("msg/sensor_msgs.PointCloud2.msg");
}

/// `geometry_msgs/msg/PoseStamped`.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct PoseStamped {
    /// Stamp and frame.
    pub header: Header,
    /// The pose.
    pub pose: Pose,
}

/// `nav_msgs/msg/Path`.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Path {
    /// Stamp and frame.
    pub header: Header,
    /// The poses in order.
    pub poses: Vec<PoseStamped>,
}

impl Message for Path {
    const TYPE: &'static str = "nav_msgs/msg/Path";
    const DEFINITION: &'static str = include_str!("msg/nav_msgs.Path.msg");
}

/// `std_msgs/msg/ColorRGBA`.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize)]
pub struct Color {
    /// Red, 0–1.
    pub r: f32,
    /// Green.
    pub g: f32,
    /// Blue.
    pub b: f32,
    /// Opacity.
    pub a: f32,
}

/// `sensor_msgs/msg/CompressedImage` (a marker's unused texture).
#[derive(Debug, Clone, PartialEq, Default, Serialize)]
pub struct CompressedImage {
    /// Stamp and frame.
    pub header: Header,
    /// Image format.
    pub format: String,
    /// The image.
    pub data: Bytes,
}

/// `visualization_msgs/msg/MeshFile` (a marker's unused mesh).
#[derive(Debug, Clone, PartialEq, Default, Serialize)]
pub struct MeshFile {
    /// File name.
    pub filename: String,
    /// Its bytes.
    pub data: Bytes,
}

/// `visualization_msgs/msg/UVCoordinate`.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize)]
pub struct UvCoordinate {
    /// u.
    pub u: f32,
    /// v.
    pub v: f32,
}

/// `visualization_msgs/msg/Marker`.
#[derive(Debug, Clone, PartialEq, Default, Serialize)]
pub struct Marker {
    /// Stamp and frame.
    pub header: Header,
    /// Namespace.
    pub ns: String,
    /// Id within the namespace.
    pub id: i32,
    /// `SPHERE` = 2, `CYLINDER` = 3, `TEXT_VIEW_FACING` = 9, …
    #[serde(rename = "type")]
    pub kind: i32,
    /// `ADD` = 0.
    pub action: i32,
    /// Where.
    pub pose: Pose,
    /// Size per axis, metres.
    pub scale: Vector3,
    /// Colour.
    pub color: Color,
    /// 0: forever.
    pub lifetime: Time,
    /// Re-transformed every frame.
    pub frame_locked: bool,
    /// For list types.
    pub points: Vec<Vector3>,
    /// Per point colours.
    pub colors: Vec<Color>,
    /// Texture (unused).
    pub texture_resource: String,
    /// Texture (unused).
    pub texture: CompressedImage,
    /// Texture coordinates (unused).
    pub uv_coordinates: Vec<UvCoordinate>,
    /// For `TEXT_VIEW_FACING`.
    pub text: String,
    /// Mesh (unused).
    pub mesh_resource: String,
    /// Mesh (unused).
    pub mesh_file: MeshFile,
    /// Mesh (unused).
    pub mesh_use_embedded_materials: bool,
}

/// `Marker.SPHERE`.
pub const SPHERE: i32 = 2;
/// `Marker.CYLINDER`.
pub const CYLINDER: i32 = 3;
/// `Marker.TEXT_VIEW_FACING`.
pub const TEXT_VIEW_FACING: i32 = 9;

/// `visualization_msgs/msg/MarkerArray`.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct MarkerArray {
    /// The markers.
    pub markers: Vec<Marker>,
}

impl Message for MarkerArray {
    const TYPE: &'static str = "visualization_msgs/msg/MarkerArray";
    const DEFINITION: &'static str = include_str!("msg/visualization_msgs.MarkerArray.msg");
}

/// A message as CDR: the little-endian encapsulation header, then the
/// fields (aligned from after the header, as CDR counts).
pub fn cdr<M: Message>(message: &M) -> Result<Vec<u8>, cdr_encoding::Error> {
    let body = cdr_encoding::to_vec::<M, byteorder::LittleEndian>(message)?;
    let mut out = Vec::with_capacity(body.len() + 4);
    out.extend_from_slice(&[0, 1, 0, 0]);
    out.extend_from_slice(&body);
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The bytes rosbags 0.11.9 (`serialize_cdr`, an independent
    /// serialiser) writes for the same message.
    #[test]
    fn a_header_serialises_as_rosbags_does() {
        let m = PoseWithCovarianceStamped {
            header: Header { stamp: Time { sec: 1, nanosec: 2 }, frame_id: "map".into() },
            pose: PoseWithCovariance { pose: Pose::default(), covariance: Covariance6([0.0; 36]) },
        };
        let bytes = cdr(&m).expect("cdr");
        assert_eq!(&bytes[..20], &[0, 1, 0, 0, 1, 0, 0, 0, 2, 0, 0, 0, 4, 0, 0, 0, b'm', b'a', b'p', 0]);
        // The pose's f64s align to 8 from after the encapsulation header:
        // 16 bytes of header then the position, w = 1 at 16 + 48.
        assert_eq!(bytes.len(), 4 + 16 + 56 + 288);
        assert_eq!(f64::from_le_bytes(bytes[4 + 16 + 48..4 + 16 + 56].try_into().expect("8")), 1.0);
    }
}
