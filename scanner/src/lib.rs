//! Instruments of the survey team: device traits, simulated devices, serial
//! drivers, scan assembly and scan files.
//!
//! This crate is built up by the simulator and serial-driver issues; the CPS
//! model it feeds lives in [`cps`]. Nothing here is exposed yet.
#![warn(missing_docs)]
