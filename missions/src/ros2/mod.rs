//! ROS 2 interop (issue 37): a run as a rosbag2 (MCAP) of standard
//! messages — [`messages`] (the layouts, CDR by `cdr-encoding`), [`bag`]
//! (the rosbag2 directory, MCAP by the `mcap` crate) and [`export`] (what
//! a run puts on which topic), and a robot's bag read as `match`'s scans
//! ([`read`]).

pub mod bag;
pub mod export;
pub mod messages;
pub mod read;
pub mod registered;
