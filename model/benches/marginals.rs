//! Marginal covariances of the newest 200 poses, as the Optimiser asks for them after every solve,
//! on sphere2500 (2 500 poses, 4 949 factors; `../shared/data/posegraph/3d`).

use criterion::{criterion_group, criterion_main, Criterion};
use sgm_model::optim::g2o::{read_g2o, G2oGraph};
use sgm_model::optim::graph::GTSAM_PRIOR_SIGMAS_3D;
use sgm_model::optim::marginals::marginal_covariances;
use sgm_model::optim::solver::Structure;
use std::hint::black_box;

fn marginals(c: &mut Criterion) {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../shared/data/posegraph/3d/sphere2500.g2o");
    let Ok(text) = std::fs::read_to_string(&path) else {
        eprintln!("marginals: {} not found, skipped", path.display());
        return;
    };
    let Ok(G2oGraph::Spatial(mut graph)) = read_g2o(&[&text]) else {
        eprintln!("marginals: {} is not a 3-D pose graph, skipped", path.display());
        return;
    };
    graph.add_prior_at_current(0, GTSAM_PRIOR_SIGMAS_3D);
    let Ok(structure) = Structure::new(&graph) else { return };
    let Some(first) = graph.values.len().checked_sub(200) else { return };
    let newest: Vec<usize> = (first..graph.values.len()).collect();
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
