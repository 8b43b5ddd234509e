//! The hall mission at full resolution (720 slices × 0.5°, 22 stations,
//! 5.7 M points), with and without `mission.rrd`:
//! `cargo bench -p missions --bench mission`.

use std::path::Path;

use criterion::{BatchSize, Criterion, criterion_group, criterion_main};
use missions::Mission;
use missions::mission::diagnostics::Source;
use missions::planning::Planned;
use missions::run::runner::{RunOptions, run};

fn hall(rerun: bool) -> Mission {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("examples/hall.toml");
    let text = std::fs::read_to_string(&path)
        .expect("hall.toml")
        .replace("slices = 180", "slices = 720")
        .replace("resolution_deg = 1", "resolution_deg = 0.5")
        .replace("formats = [\"ply\"]", &format!("formats = [\"ply\"]\nrerun = {rerun}"));
    Mission::parse(Source::new(&path, text)).expect("mission")
}

fn bench(c: &mut Criterion) {
    let options = RunOptions { quiet: true, ..RunOptions::default() };
    let mut group = c.benchmark_group("hall full resolution");
    group.sample_size(10);
    for (name, rerun) in [("without mission.rrd", false), ("with mission.rrd", true)] {
        let mission = hall(rerun);
        let planned = Planned::new(&mission).expect("plan");
        group.bench_function(name, |b| {
            b.iter_batched(
                || tempfile::tempdir().expect("tempdir"),
                |dir| run(&mission, &planned, dir.path(), &options).expect("run"),
                BatchSize::PerIteration,
            )
        });
    }
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
