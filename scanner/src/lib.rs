//! Instruments of the survey team.
//!
//! - [`devices`]: the traits every backend implements — [`TotalStation`],
//!   [`RangeFinder2D`], [`ScanHead`], [`TiltSensor`], [`Drive`] — and their
//!   data ([`TsMeasurement`], [`Slice`], [`Tilt`], [`Odometry`]);
//! - [`sim`]: the built-in simulator ([`sim::SimWorld`] and its devices);
//! - [`assembly`]: slices + head angles + lever arm → a 3D [`Scan`];
//! - [`reduce`]: reduced points (voxel means);
//! - [`io`]: scan files (3DTK, PLY, XYZ, PCD, LAS, E57) as [`PointCloud`]s;
//! - [`protocol`]: the real instruments' wire formats (SICK LMS-2xx
//!   telegrams, Leica GeoCOM, NMEA XDR tilt lines), without I/O;
//! - [`serial`]: drivers for the real instruments over serial ports;
//! - [`emulate`]: those instruments' protocols on pseudo-terminals,
//!   answering from the simulator.
//!
//! Frames: scanner S (the 2D scanner's plane is its x-y plane), head H,
//! body B (origin at the total-station centre, x forward, z up), world W.
#![warn(missing_docs)]

pub mod assembly;
pub mod devices;
pub mod emulate;
pub mod error;
pub mod io;
pub mod protocol;
pub mod reduce;
pub mod serial;
pub mod sim;

pub use assembly::{Scan, assemble, scan_3d};
pub use devices::{
    Drive, HeadKind, Odometry, PlanarPose, Prism, RangeFinder2D, ScanHead, Slice, Target, Tilt, TiltSensor,
    TotalStation, TsMeasurement, TsStatus,
};
pub use error::{Location, Result, ScannerError};
pub use io::PointCloud;
pub use reduce::reduced_points;
