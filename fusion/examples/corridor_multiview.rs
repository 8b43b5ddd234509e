//! Seed 000 Fig. 5 on the simulated corridor: 20 scans with odometry error,
//! registered pairwise, incrementally and simultaneously; prints each
//! strategy's error against ground truth as a Markdown table.
//!
//! `cargo run --release -p fusion --example corridor_multiview [SEED]`

#![allow(clippy::print_stdout)] // a program whose output is the table

#[path = "../tests/corridor/mod.rs"]
mod corridor;

use std::time::Instant;

use fusion::multiview::{Strategy, register_views};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let seed = std::env::args().nth(1).map_or(Ok(7), |s| s.parse())?;
    let c = corridor::corridor(20, 180, seed);
    let points: usize = c.scans.iter().map(Vec::len).sum();
    println!("Seed {seed}: 20 scans, {points} points. Error against ground truth: position (m) / heading (°).\n");
    println!("| | ICP runs | seconds | scan 5 | scan 10 | scan 15 | scan 20 | max | mean |");
    println!("|---|---:|---:|---:|---:|---:|---:|---:|---:|");
    let row = |name: &str, runs: usize, secs: f64, e: &[(f64, f64)]| {
        let at = |k: usize| format!("{:.3} / {:.2}", e[k - 1].0, e[k - 1].1);
        let max = e.iter().map(|x| x.0).fold(0.0, f64::max);
        let mean = e.iter().map(|x| x.0).sum::<f64>() / e.len() as f64;
        println!(
            "| {name} | {runs} | {secs:.1} | {} | {} | {} | {} | {max:.3} | {mean:.3} |",
            at(5),
            at(10),
            at(15),
            at(20)
        );
    };
    row("odometry", 0, 0.0, &corridor::errors(&c.odometry, &c.truth));
    for (name, strategy) in [
        ("pairwise", Strategy::Pairwise),
        ("incremental", Strategy::Incremental),
        ("simultaneous", Strategy::Simultaneous),
    ] {
        let config = corridor::multiview_config(strategy);
        let t = Instant::now();
        let r = register_views(&c.scans, &c.odometry, &config, &mut |_, _| {})?;
        let secs = t.elapsed().as_secs_f64();
        row(name, r.matches, secs, &corridor::errors(&r.world_from_scan, &c.truth));
    }
    Ok(())
}
