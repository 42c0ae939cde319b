//! Fault scenarios of `library/faults/` end to end: the team converges (every robot aligned
//! with every other), and the report's ledger shows that nothing was lost — every robot holds
//! every other's latest ObjectData, no keyframe request is left pending, and a robot that
//! crashed and came back from its snapshot still holds every keyframe of that snapshot; and
//! the back end rejects every false inter-robot factor injected and the team ATE holds. The
//! other fault scenarios (30 % and 60 % loss, duplication and reordering, late join) are run
//! with `sgm run faults/NAME`; their figures are in the book's scenario chapter.

use sgm_scenarios::report::{compute, Report};
use sgm_scenarios::runner::run;
use sgm_scenarios::scenario::{FalseFactorSpec, Scenario};

fn run_fault(name: &str) -> Report {
    let scenario = Scenario::load_with_env(&format!("faults/{name}"), "SGM_FAULTS_TEST").unwrap();
    let outcome = actix_rt::System::new().block_on(run(&scenario, None)).unwrap();
    compute(&outcome.record)
}

fn assert_converged_and_nothing_lost(report: &Report) {
    let robots = report.robots.len();
    assert_eq!(report.alignments.len(), robots * (robots - 1));
    for a in &report.alignments {
        assert_eq!(a.state, "Aligned", "{} ← {}", a.local, a.remote);
        assert!(a.translation_error_m.unwrap() < 0.5, "{} ← {}: {:?}", a.local, a.remote, a.translation_error_m);
        // Right alignments close their cycles (`matcher.relay.contradiction_m`).
        assert!(a.contradicted_by.is_empty(), "{} ← {} flagged by {:?}", a.local, a.remote, a.contradicted_by);
    }
    assert_eq!(report.ledger.pairs.len(), robots * (robots - 1));
    for p in &report.ledger.pairs {
        assert!(
            p.object_data_current,
            "{} ← {}: ObjectData {:?} is not the latest",
            p.local, p.remote, p.object_data_revision
        );
        assert_eq!(p.keyframes_pending, 0, "{} ← {}", p.local, p.remote);
        assert_eq!(
            p.keyframes_received + p.keyframes_refused + p.keyframes_given_up,
            p.keyframes_wanted,
            "{} ← {}",
            p.local,
            p.remote
        );
    }
    assert!(report.team_ate_rmse_m.unwrap() < 0.3, "{:?}", report.team_ate_rmse_m);
}

#[test]
fn a_partition_heals_and_the_team_converges() {
    let report = run_fault("partition");
    assert!(report.radio.partitioned > 0);
    assert_converged_and_nothing_lost(&report);
    // charlie could not align before the partition healed at 80 s.
    for a in report.alignments.iter().filter(|a| a.local == "charlie" || a.remote == "charlie") {
        assert!(a.first_aligned_s.unwrap() >= 80.0, "{} ← {} at {:?}", a.local, a.remote, a.first_aligned_s);
    }
}

#[test]
fn a_robot_restarts_from_its_snapshot_with_nothing_lost() {
    let report = run_fault("crash_restart");
    assert_converged_and_nothing_lost(&report);
    let [restart] = &report.ledger.restarts[..] else { panic!("{:?}", report.ledger.restarts) };
    assert_eq!((restart.robot.as_str(), restart.crashed_at_s, restart.restarted_at_s), ("bravo", 75.0, 95.0));
    // Snapshots every 20 s: the last before the crash.
    let taken = restart.snapshot_taken_at_s.unwrap();
    assert!((55.0..75.0).contains(&taken), "{taken}");
    assert!(restart.keyframes_in_snapshot > 0 && restart.keyframes_in_snapshot <= restart.keyframes_at_crash);
    assert_eq!(restart.snapshot_keyframes_kept, restart.keyframes_in_snapshot, "a restored keyframe was lost");
    assert!(restart.objects_in_snapshot > 0);
    let bravo = report.robots.iter().find(|r| r.name == "bravo").unwrap();
    assert!(bravo.keyframes > restart.keyframes_in_snapshot, "bravo went on mapping after the restart");
}

#[test]
fn false_inter_robot_factors_are_rejected_and_team_ate_holds() {
    let clean = run_fault("clean");
    let load = || Scenario::load_with_env("faults/false_factors", "SGM_FAULTS_TEST").unwrap();
    let attacked = compute(&actix_rt::System::new().block_on(run(&load(), None)).unwrap().record);
    // The back end alone: without outlier rejection, without the Matchers settling the
    // contradicted cycles that the false factors' pull on the anchors opens (see below), and
    // without their matching the graphs again, which puts a pulled anchor's neighbour back
    // where the objects say (`matcher.relay.rematch`: 0.041 m against 0.032 m clean).
    let mut plain = load();
    plain.optimiser.reject_outliers = false;
    plain.matcher.relay.settle = false;
    plain.matcher.relay.rematch = false;
    let plain = compute(&actix_rt::System::new().block_on(run(&plain, None)).unwrap().record);

    assert_eq!(clean.back_end.rejected_factors, 0, "a correct factor was rejected: {:?}", clean.back_end);
    let b = &attacked.back_end;
    assert_eq!((b.false_factors_injected, b.false_factors_rejected), (15, 15), "{b:?}");
    assert!(b.rejected_factors <= b.false_factors_rejected + 2, "{b:?}");
    let (clean_ate, attacked_ate, plain_ate) =
        (clean.team_ate_rmse_m.unwrap(), attacked.team_ate_rmse_m.unwrap(), plain.team_ate_rmse_m.unwrap());
    assert!(attacked_ate <= 1.1 * clean_ate, "team ATE {attacked_ate} m against {clean_ate} m clean");
    // Not silently outvoted: each direction given false factors holds its neighbour suspect,
    // naming the count outside the consistent set; the clean run holds none suspect.
    let suspect = |r: &Report| r.alignments.iter().filter(|a| !a.suspect.is_empty()).count();
    assert_eq!(suspect(&clean), 0, "{:?}", clean.alignments.iter().map(|a| &a.suspect).collect::<Vec<_>>());
    assert_eq!(suspect(&attacked), 3);
    for a in attacked.alignments.iter().filter(|a| !a.suspect.is_empty()) {
        let counts = format!("{} of its {} inter-robot factors", a.inconsistent_factors, a.inter_robot_factors);
        assert!(a.inconsistent_factors >= 3 && a.suspect[0].starts_with(&counts), "{:?}", a.suspect);
    }
    // The factors are harmful: least squares without outlier rejection is far off.
    assert!(plain_ate > 5.0 * clean_ate, "least squares reached {plain_ate} m against {clean_ate} m clean");
    assert_eq!(plain.back_end.false_factors_rejected, 0);
    assert!(plain.alignments.iter().all(|a| a.withdrawals == 0));
    // Defence in depth: with settling on, least squares still keeps every false factor, but the
    // anchors they pull away (bravo's) contradict the cycles through charlie, the
    // object evidence names them, and bravo withdraws them — the false factors go with them
    // — and aligns again through the relay: within 2× of the clean run (1.73 m without).
    let mut settled = load();
    settled.optimiser.reject_outliers = false;
    // Settling alone: with the graphs matched again as well, the pulled anchors are also
    // withdrawn on stronger matches, three directions are still waiting for a new round at the
    // end, and the team ATE is 0.098 m against 0.032 m clean (measured; the defaults, with
    // outlier rejection, are the first run above).
    settled.matcher.relay.rematch = false;
    let settled = compute(&actix_rt::System::new().block_on(run(&settled, None)).unwrap().record);
    let settled_ate = settled.team_ate_rmse_m.unwrap();
    assert!(settled_ate < 2.0 * clean_ate, "settled least squares {settled_ate} m against {clean_ate} m clean");
    assert!(settled.alignments.iter().any(|a| a.withdrawals > 0), "{:?}", settled.alignments);
    assert!(settled.alignments.iter().all(|a| a.state == "Aligned"));

    // Early on, as `sgm bench outliers` injects them: two per direction 5 s after it first
    // aligned, when the pair holds only its first round's factors. Rejected, they leave the
    // estimate the clean run's: the graphs differ only by factors that weigh nothing (a false
    // factor's claim on its neighbour keyframe is vague, and the keyframe's own prior replaces
    // it when it arrives). Runs are deterministic, so the two missions differ only by that, and
    // by the solves keyframe pose updates then trigger: with the matcher's crowd estimate the
    // two end 0.07 mm apart (0.030881 m against 0.030811 m); with `comms.pose_updates` off,
    // `faults/false_factors` and `faults/clean` agree to 5e-9 m, with them on 0.09 mm apart
    // (not traced further). 0.2 mm is far below what one kept false factor moves (centimetres;
    // with the injection's earlier σ = 0.1 m claim the team ATE was 20 % off on the bench).
    let mut early = load();
    early.false_factors = clean
        .alignments
        .iter()
        .map(|a| FalseFactorSpec {
            robot: a.local.clone(),
            neighbour: a.remote.clone(),
            at_s: a.first_aligned_s.unwrap() + 5.0,
            count: 2,
            translation_m: 5.0,
            rotation_deg: 30.0,
        })
        .collect();
    let early = compute(&actix_rt::System::new().block_on(run(&early, None)).unwrap().record);
    let b = &early.back_end;
    assert_eq!((b.false_factors_injected, b.false_factors_rejected), (12, 12), "{b:?}");
    let early_ate = early.team_ate_rmse_m.unwrap();
    assert!((early_ate - clean_ate).abs() < 2e-4, "team ATE {early_ate} m against {clean_ate} m clean");
}
