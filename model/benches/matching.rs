//! Matching time against graph size (issue [core] §6). Graphs keep the paper's object density
//! (50 objects per 60 m × 60 m), noisy, half overlapping.

use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion};
use sgm_model::eval::matching_protocol::{generate_pair, PairSpec, SyntheticWorld};
use sgm_model::matching::{match_graphs, LabelSimilarity, MatcherConfig};
use std::hint::black_box;

fn matching(c: &mut Criterion) {
    let config = MatcherConfig::default();
    let mut group = c.benchmark_group("match_graphs");
    for &(local, remote) in &[(8, 8), (15, 15), (35, 32), (150, 150), (400, 400)] {
        let overlap = local.min(remote) / 2;
        let world = SyntheticWorld::with_density_for((local + remote - overlap).max(50));
        let spec = PairSpec { local, remote, overlap, noisy: true, mislabels: 0 };
        let pair = generate_pair(&world, &spec, 1);
        let labels = LabelSimilarity::uniform(world.classes as usize, config.mislabel_similarity);
        if local >= 150 {
            group.sample_size(20);
        }
        group.bench_with_input(BenchmarkId::from_parameter(format!("{local}x{remote}")), &pair, |b, pair| {
            b.iter(|| match_graphs(black_box(&pair.local), black_box(&pair.remote), &labels, &config))
        });
    }
    group.finish();
}

criterion_group!(benches, matching);
criterion_main!(benches);
