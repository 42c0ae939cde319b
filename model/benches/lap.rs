//! Our rectangular JV against the `lsap` crate (a port of scipy's solver) on the same matrices,
//! in one run, so the ratio is measured here.

use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use sgm_model::spatial::lap::{solve, CostMatrix};
use std::hint::black_box;

fn lap(c: &mut Criterion) {
    let mut group = c.benchmark_group("lap");
    for &(rows, cols) in &[(35, 32), (100, 100), (500, 500), (300, 500)] {
        let mut rng = ChaCha8Rng::seed_from_u64(5);
        let costs: Vec<f64> = (0..rows * cols).map(|_| rng.random_range(0.0..1.0)).collect();
        let matrix = CostMatrix::new(rows, cols, costs.clone()).expect("finite costs");
        group.bench_with_input(BenchmarkId::new("sgm_jv", format!("{rows}x{cols}")), &matrix, |b, m| {
            b.iter(|| solve(black_box(m)))
        });
        group.bench_with_input(BenchmarkId::new("lsap_crate", format!("{rows}x{cols}")), &costs, |b, costs| {
            b.iter(|| lsap::solve(rows, cols, black_box(costs), false))
        });
    }
    group.finish();
}

criterion_group!(benches, lap);
criterion_main!(benches);
