//! `sgm run --threads N`: the robots run on threads of their own, up to N at once, and the
//! report does not depend on N — `report.json` is byte-identical on 1, 2 and more threads, with
//! each robot's registrations split over the same N threads (`sgm_model::workers`). Two
//! scenarios: eight robots on a campus (one joining late), where many pairs align and exchange
//! over the radio in the same steps, and a crash and restart from a snapshot on a lossy link
//! (the radio's random draws, which the robots' threads must not reorder).

use sgm_scenarios::report;
use sgm_scenarios::runner::{run_with, RunOutputs};
use sgm_scenarios::scenario::Scenario;
use sgm_scenarios::threads::Threads;
use std::num::NonZeroUsize;

/// `scenario`'s report.json on `threads` threads, and the report.
fn report_on(scenario: &Scenario, threads: usize) -> (Vec<u8>, report::Report) {
    let threads = Threads::exactly(NonZeroUsize::new(threads).unwrap());
    let outputs = RunOutputs { threads, ..RunOutputs::default() };
    let outcome = actix_rt::System::new().block_on(run_with(scenario, None, outputs)).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let report = report::write(&outcome, dir.path()).unwrap();
    (std::fs::read(dir.path().join("report.json")).unwrap(), report)
}

fn assert_same_on(scenario: &Scenario, counts: &[usize]) -> report::Report {
    let (one, report) = report_on(scenario, 1);
    for &n in counts {
        let (other, _) = report_on(scenario, n);
        assert!(one == other, "{}: report.json on {n} threads differs from 1 thread's", scenario.scenario.name);
    }
    report
}

#[test]
fn eight_robots_give_the_same_report_on_1_2_and_8_threads() {
    let mut scenario = Scenario::load_with_env("team_of_eight", "SGM_THREADS_TEST").unwrap();
    scenario.scenario.duration_s = 60.0;
    // Jitter: packets from different robots sent in one step arrive in an order the radio draws.
    scenario.radio.jitter_ms = 30.0;
    let report = assert_same_on(&scenario, &[2, 8]);
    // Not a trivial run: the robots aligned and talked, in the same steps.
    let aligned = report.alignments.iter().filter(|a| a.state == "Aligned").count();
    assert!(aligned >= 4, "only {aligned} alignments in 60 s");
    assert!(report.radio.delivered > 100, "{:?}", report.radio);
}

#[test]
fn a_crash_and_restart_on_a_lossy_link_gives_the_same_report_on_1_2_and_3_threads() {
    let mut scenario = Scenario::load_with_env("faults/crash_restart", "SGM_THREADS_TEST").unwrap();
    scenario.scenario.duration_s = 110.0;
    scenario.radio.loss = 0.2;
    scenario.radio.jitter_ms = 40.0;
    let report = assert_same_on(&scenario, &[2, 3]);
    assert_eq!(report.ledger.restarts.len(), 1, "{:?}", report.ledger.restarts);
    assert!(report.radio.lost > 0 && report.radio.delivered > 0, "{:?}", report.radio);
}
