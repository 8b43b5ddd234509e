//! What a run directory's readings make, at the end of `run` and again by
//! `fuse`, `adjust` and `export`: the run read back ([`load`]), the scans
//! fused ([`fuse`]), the output stage of the run's cloud with its pipe
//! inspection ([`outputs`]), the network adjustment of the journal's
//! readings ([`adjust`]), the reports ([`report`]: `report.json`,
//! `fusion.json`, `stations.csv`) and `fuse`'s terminal text ([`text`]).
//! Nothing here runs a mission or imports [`crate::run`].

pub mod adjust;
pub mod fuse;
pub mod load;
pub mod outputs;
pub mod report;
pub mod text;
