//! The end-to-end tests, one module per subject, linked into one test
//! binary: each binary links the whole CLI with Rerun, and fifteen of them
//! cost CI fifteen links and gigabytes of disk. Run one subject with
//! `cargo test -p tests --release --test e2e -- serial::`.

mod cli;
mod examples;
mod georeferenced;
mod hostile;
mod journal_v1;
mod journal_v2;
mod malformed;
mod match_covariance;
mod match_set;
mod montecarlo;
mod network;
mod odometry;
mod plan;
mod readme;
mod register;
mod ros2;
mod rrd;
mod run;
mod schemas;
mod serial;
