//! The team passphrase KDF (argon2id, m = 19 456 KiB, t = 2, p = 1; `wire::team_key`): one
//! first derivation (a passphrase not seen before in the process: the cost a robot pays once at
//! start, and an attacker pays per guess), and a later one (the per-process cache).

use criterion::{criterion_group, criterion_main, BatchSize, Criterion};
use sgm_model::wire::TeamKey;
use std::hint::black_box;

fn team_key(c: &mut Criterion) {
    let mut group = c.benchmark_group("team_key");
    group.sample_size(20);
    let mut fresh = 0u64;
    group.bench_function("derive_first", |b| {
        b.iter_batched(
            || {
                fresh += 1;
                format!("a passphrase never derived before {fresh}")
            },
            |passphrase| TeamKey::from_passphrase(black_box(&passphrase), "sgm team"),
            BatchSize::PerIteration,
        )
    });
    let _ = TeamKey::from_passphrase("a passphrase derived before", "sgm team");
    group.bench_function("derive_again", |b| {
        b.iter(|| TeamKey::from_passphrase(black_box("a passphrase derived before"), "sgm team"))
    });
    group.finish();
}

criterion_group!(benches, team_key);
criterion_main!(benches);
