//! Loading a scenario file (`Scenario::from_toml`: defaults, the file, the environment, then
//! validation), beside what every load cost before the defaults layer was built once per process:
//! - `from_toml/{quickstart,team_of_eight}`: a whole load of a library scenario;
//! - `defaults_layer_per_load`: `config::Config::try_from(&Scenario::default())`, which
//!   `from_toml` ran on every call until `b0529e1`. `config` rebuilds its tree after each key it
//!   sets, so this is quadratic in the number of keys.
//!
//! `cargo bench -p sgm-scenarios --bench scenario_load`

use criterion::{criterion_group, criterion_main, Criterion};
use sgm_scenarios::scenario::{library, Scenario};
use std::hint::black_box;

fn scenario_load(c: &mut Criterion) {
    let mut group = c.benchmark_group("scenario_load");
    for name in ["quickstart", "team_of_eight"] {
        let Some(text) = library::get(name) else { panic!("library scenario {name} is missing") };
        group.bench_function(format!("from_toml/{name}"), |b| {
            b.iter(|| black_box(Scenario::from_toml(black_box(text), name, "SGM_BENCH_UNSET")))
        });
    }
    group.bench_function("defaults_layer_per_load", |b| {
        b.iter(|| black_box(config::Config::try_from(black_box(&Scenario::default()))))
    });
    group.finish();
}

criterion_group!(benches, scenario_load);
criterion_main!(benches);
