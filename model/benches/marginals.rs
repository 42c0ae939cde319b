//! Marginal covariances of the newest 200 poses, as the Optimiser asks for them after every solve,
//! on sphere2500 (2 500 poses, 4 949 factors; `../shared/data/posegraph/3d`).

#[path = "common/sphere2500.rs"]
mod common;

use common::sphere2500;
use criterion::{criterion_group, criterion_main, Criterion};
use sgm_model::optim::marginals::marginal_covariances;
use sgm_model::optim::solver::Structure;
use std::hint::black_box;

fn marginals(c: &mut Criterion) {
    let Some(graph) = sphere2500("marginals") else { return };
    let Ok(structure) = Structure::new(&graph) else { return };
    let Some(first) = graph.values.len().checked_sub(200) else { return };
    let newest: Vec<usize> = (first..graph.values.len()).collect();
    c.bench_function("structure/sphere2500", |b| b.iter(|| Structure::new(black_box(&graph))));
    c.bench_function("marginals/sphere2500_newest_200", |b| {
        b.iter(|| marginal_covariances(black_box(&graph), &structure, &newest))
    });
}

criterion_group! {
    name = benches;
    config = Criterion::default().sample_size(10);
    targets = marginals
}
criterion_main!(benches);
