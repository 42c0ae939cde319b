//! One cycle of a robot's Optimiser on sphere2500 (2 500 poses, 4 949 factors;
//! `../shared/data/posegraph/3d`), as `actors/src/optimiser.rs` runs it after every tenth
//! keyframe: the graph is at its GNC-TLS solution but for the newest 10 poses, which start where
//! odometry puts them (with every factor that reaches them); the solve keeps the previous
//! decision, then the marginal covariances of the newest 200 poses, all on one symbolic
//! factorisation.

#[path = "common/sphere2500.rs"]
mod common;

use common::sphere2500;
use criterion::{criterion_group, criterion_main, BatchSize, Criterion};
use sgm_model::optim::graph::Graph3;
use sgm_model::optim::marginals::marginal_covariances_with;
use sgm_model::optim::robust::{optimize_gnc_incremental, optimize_gnc_incremental_with, rejection_weights, weighted};
use sgm_model::optim::solver::{LmParams, Structure};

/// Poses left to the cycle, as a robot's Optimiser solves every 10 keyframes.
const NEW_POSES: usize = 10;

fn optimiser_cycle(c: &mut Criterion) {
    let Some(mut graph) = sphere2500("optimiser_cycle") else { return };
    let candidate =
        |g: &Graph3| -> Vec<bool> { g.betweens.iter().map(|f| g.keys[f.from].abs_diff(g.keys[f.to]) != 1).collect() };
    let params = LmParams::default();
    // The graph before the newest poses (sphere2500's poses are in key order), solved.
    let old = graph.values.len() - NEW_POSES;
    let mut before = graph.clone();
    before.keys.truncate(old);
    before.values.truncate(old);
    before.fixed.truncate(old);
    before.betweens.retain(|f| f.from < old && f.to < old);
    let before_candidates = candidate(&before);
    let Ok((_, rejected_before)) = optimize_gnc_incremental(&mut before, &params, &before_candidates, &[]) else {
        return;
    };
    // The newest poses chained on by their odometry from the last solved one.
    let mut values = before.values.clone();
    for k in old..graph.values.len() {
        let Some(odometry) = graph.betweens.iter().find(|f| f.from == k - 1 && f.to == k) else { return };
        values.push(values[k - 1] * odometry.measured);
    }
    graph.values = values;
    // Indices of `before`'s factors in `graph` (the new ones are interleaved in file order).
    let kept: Vec<usize> =
        (0..graph.betweens.len()).filter(|k| graph.betweens[*k].from < old && graph.betweens[*k].to < old).collect();
    let rejected: Vec<usize> = rejected_before.iter().map(|k| kept[*k]).collect();
    let candidates = candidate(&graph);
    let newest: Vec<usize> = (graph.values.len() - 200..graph.values.len()).collect();
    let mut once = graph.clone();
    if let Ok(structure) = Structure::new(&once) {
        if let Ok((summary, decided)) =
            optimize_gnc_incremental_with(&mut once, &params, &structure, &candidates, &rejected)
        {
            eprintln!(
                "optimiser_cycle: {} rejected before, {} after; {} linearisations",
                rejected.len(),
                decided.len(),
                summary.iterations
            );
        }
    }
    c.bench_function("optimiser_cycle/sphere2500", |b| {
        b.iter_batched(
            || graph.clone(),
            |mut g| {
                let structure = Structure::new(&g).ok()?;
                let (_, decided) =
                    optimize_gnc_incremental_with(&mut g, &params, &structure, &candidates, &rejected).ok()?;
                let weights = rejection_weights(g.betweens.len(), &decided);
                let covariances = marginal_covariances_with(&g, &structure, &newest, &weighted(&weights)).ok();
                covariances
            },
            BatchSize::LargeInput,
        )
    });
}

criterion_group! {
    name = benches;
    config = Criterion::default().sample_size(10);
    targets = optimiser_cycle
}
criterion_main!(benches);
