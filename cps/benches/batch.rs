//! The batch adjustment of a long network: a leapfrog chain of N stations
//! (two children placed per cycle, each sighted from two stations), a
//! control point beside every 100th station, noisy readings —
//! `cargo bench -p cps --bench batch`.

#[path = "common/chain.rs"]
mod chain;

use chain::chain;
use cps::batch::{AdjustOptions, adjust};
use criterion::{BenchmarkId, Criterion, criterion_group, criterion_main};

fn bench(c: &mut Criterion) {
    let mut group = c.benchmark_group("batch adjustment");
    group.sample_size(10);
    for n in [100, 1000] {
        let net = chain(n, 1);
        for (name, snooping) in [("with statistics", false), ("with statistics and snooping", true)] {
            let options = AdjustOptions { snooping, ..AdjustOptions::default() };
            group.bench_with_input(BenchmarkId::new(name, n), &net, |b, net| {
                b.iter(|| adjust(net, &options).expect("adjust"));
            });
        }
    }
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
