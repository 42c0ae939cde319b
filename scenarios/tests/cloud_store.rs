//! The bounded keyframe cloud store end to end: the quickstart with 6 MiB of clouds per robot
//! (its maps make about 19 MiB each) and only the newest 5 scans spared. Both of the store's
//! stages are reached; every map stays within its budget at every observation; only clouds go
//! (every keyframe is kept); and the two robots still align and close their maps. The 1-hour
//! endurance run (`sgm run endurance/team_of_eight_1h`) is measured in the book.

use sgm_model::scene_graph::CloudStoreConfig;
use sgm_scenarios::report::compute;
use sgm_scenarios::runner::run;
use sgm_scenarios::scenario::Scenario;

#[test]
fn a_team_with_a_small_cloud_budget_stays_within_it_and_still_aligns() {
    let mut scenario = Scenario::load("quickstart").unwrap();
    let budget = CloudStoreConfig { budget_mb: 6.0, keep_recent: 5, ..CloudStoreConfig::default() };
    scenario.tracker.cloud_store = budget.clone();
    let outcome = actix_rt::System::new().block_on(run(&scenario, None)).unwrap();
    let report = compute(&outcome.record);

    let budget_bytes = budget.budget_bytes() as u64;
    for r in &report.robots {
        let c = &r.clouds;
        assert!(c.compacted > 0 && c.evicted > 0, "{}: both stages reached: {c:?}", r.name);
        assert!(c.bytes as u64 <= budget_bytes, "{}: {} bytes held, budget {budget_bytes}", r.name, c.bytes);
        // Every keyframe was given a scan, and only eviction takes one away: no keyframe lost.
        assert_eq!(c.scans as u64 + c.evicted, r.keyframes as u64, "{}", r.name);
        assert!(r.keyframes > 80, "{}: {} keyframes", r.name, r.keyframes);
    }
    let robots = report.robots.len() as u64;
    assert!(report.series.len() >= 9);
    for p in &report.series {
        assert!(p.cloud_bytes <= robots * budget_bytes, "at {} s: {} bytes", p.t, p.cloud_bytes);
    }
    // The maps as held at the end agree with the report.
    for (map, r) in outcome.maps.iter().zip(&report.robots) {
        assert_eq!(map.cloud_stats(), r.clouds);
    }
    for a in &report.alignments {
        assert_eq!(a.state, "Aligned", "{} ← {}", a.local, a.remote);
        assert!(a.translation_error_m.unwrap() < 0.3, "{} ← {}: {:?}", a.local, a.remote, a.translation_error_m);
    }
    assert!(report.team_ate_rmse_m.unwrap() < 0.15, "{:?}", report.team_ate_rmse_m);
}
