//! Repeated layouts (issue 33): the matcher refuses or solves them, never answers wrongly.
//! `sgm bench matching` measures the same families over many more pairs, with the office and
//! the lecture hall (too slow for a debug-build test).

use sgm_model::eval::matching_protocol::score_trial;
use sgm_model::eval::repeated_layouts::{generate_layout_pair, Layout, LayoutPairSpec, CLASSES};
use sgm_model::matching::{match_graphs, LabelSimilarity, MatchOutcome, MatcherConfig, RefusalReason};

/// (successes, wrong claims, refusals as repeated) over `seeds` pairs of `spec`.
fn outcomes(spec: LayoutPairSpec, seeds: u64) -> (usize, usize, usize) {
    let config = MatcherConfig::default();
    let labels = LabelSimilarity::uniform(CLASSES as usize, config.mislabel_similarity);
    let (mut success, mut wrong, mut repeated) = (0, 0, 0);
    for seed in 0..seeds {
        let pair = generate_layout_pair(&spec, seed);
        let report = match_graphs(&pair.local, &pair.remote, &labels, &config);
        let (pose, matches) = match &report.outcome {
            MatchOutcome::Aligned(a) => {
                (Some(a.local_from_remote), a.matches.iter().map(|m| (m.local, m.remote)).collect())
            }
            MatchOutcome::Refused(r) => {
                repeated += matches!(r.reason, RefusalReason::Repeated { .. }) as usize;
                (None, Vec::new())
            }
        };
        let score = score_trial(&pair, pose.as_ref(), &matches);
        success += score.success as usize;
        wrong += (score.claimed && !score.success) as usize;
    }
    (success, wrong, repeated)
}

#[test]
fn a_bare_grid_of_lamp_posts_is_never_claimed() {
    for same_place in [true, false] {
        for noisy in [false, true] {
            let (success, wrong, repeated) =
                outcomes(LayoutPairSpec { layout: Layout::LampGrid, same_place, noisy }, 20);
            assert_eq!((success, wrong), (0, 0), "same place {same_place}, noisy {noisy}");
            assert!(repeated > 0, "same place {same_place}, noisy {noisy}: the refusals should name the repetition");
        }
    }
}

#[test]
fn a_parking_lot_is_solved_or_refused_never_wrong() {
    // Without the agreement index and the period runner-ups, 4 and 3 of 100 same-place pairs
    // and 10 and 13 of 100 different-place pairs were answered wrongly (turned by 180° or
    // shifted by a period onto a wider overlap).
    for noisy in [false, true] {
        let (success, wrong, _) = outcomes(LayoutPairSpec { layout: Layout::ParkingLot, same_place: true, noisy }, 20);
        assert_eq!(wrong, 0, "same place, noisy {noisy}");
        assert!(success >= 3, "same place, noisy {noisy}: only {success} of 20 solved");
        let (success, wrong, _) = outcomes(LayoutPairSpec { layout: Layout::ParkingLot, same_place: false, noisy }, 20);
        assert_eq!((success, wrong), (0, 0), "different places, noisy {noisy}");
    }
}

/// The seed `sgm bench matching --seed 1` gives pair `rep` of the parking lot between different
/// places (`scenarios/src/bench/matching_hard.rs`: family 1000 without error, 1001 with).
fn bench_seed(noisy: bool, rep: u64) -> u64 {
    let family = 1000 + noisy as u64;
    1_000_003 + family * 100_003 + rep
}

#[test]
fn two_parking_lots_of_one_layout_are_not_told_apart_by_a_sampling_fluke() {
    // The 11 (without error) and 7 (with) of 1000 bench pairs between different parking lots
    // that were claimed while ω was compared with a fixed 0.05 margin: each best won over a
    // period copy by 0.05–0.11, within two standard errors of the difference.
    let config = MatcherConfig::default();
    let labels = LabelSimilarity::uniform(CLASSES as usize, config.mislabel_similarity);
    let flukes = [
        (false, [152, 210, 277, 433, 521, 556, 674, 728, 767, 804, 930].as_slice()),
        (true, [104, 423, 516, 616, 622, 644, 752].as_slice()),
    ];
    for (noisy, reps) in flukes {
        for &rep in reps {
            let spec = LayoutPairSpec { layout: Layout::ParkingLot, same_place: false, noisy };
            let pair = generate_layout_pair(&spec, bench_seed(noisy, rep));
            let report = match_graphs(&pair.local, &pair.remote, &labels, &config);
            match &report.outcome {
                MatchOutcome::Refused(r) => assert!(
                    matches!(r.reason, RefusalReason::Repeated { .. }),
                    "noisy {noisy}, pair {rep}: refused, but as {}",
                    r.reason
                ),
                MatchOutcome::Aligned(a) => {
                    panic!("noisy {noisy}, pair {rep}: claimed between different places ({} matches)", a.matches.len())
                }
            }
        }
    }
}
