//! A user's own scans, outside a mission: reading them — files of any
//! supported format, a 3DTK directory with its `.pose` odometry, a
//! multi-scan E57 with its registration — with their start poses
//! ([`inputs`]), and the settings `register` and `match` share: the
//! coarse-to-fine schedule and rigid transforms given as matrices
//! ([`settings`]).

pub mod inputs;
pub mod settings;
