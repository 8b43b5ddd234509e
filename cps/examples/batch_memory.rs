//! Peak memory of the batch adjustment: builds the benchmark's chain of N
//! stations, adjusts it with every statistic, and prints the process's
//! peak resident set (Linux `VmHWM`) before and after —
//! `cargo run --release -p cps --example batch_memory -- 1000`.

#![allow(clippy::print_stdout)] // a program whose output is the measurement

#[path = "../benches/common/chain.rs"]
mod chain;

use cps::batch::{AdjustOptions, adjust};

fn peak_kib() -> Option<u64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with("VmHWM:"))?;
    line.split_whitespace().nth(1)?.parse().ok()
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let n: usize = std::env::args().nth(1).ok_or("usage: batch_memory STATIONS")?.parse()?;
    if n < 2 {
        return Err("expected at least 2 stations".into());
    }
    let before = peak_kib().ok_or("no /proc/self/status (Linux only)")?;
    let net = chain::chain(n, 1);
    let built = peak_kib().unwrap_or(0);
    let started = std::time::Instant::now();
    let options = AdjustOptions { snooping: false, ..AdjustOptions::default() };
    let a = adjust(&net, &options)?;
    let seconds = started.elapsed().as_secs_f64();
    let after = peak_kib().unwrap_or(0);
    println!(
        "{n} stations, {} readings, {} unknowns: adjusted in {seconds:.3} s; peak RSS {after} KiB \
         (at start {before} KiB, with the network {built} KiB); factor {} non-zeros",
        net.readings.len(),
        a.unknowns,
        a.factor_nnz
    );
    Ok(())
}
