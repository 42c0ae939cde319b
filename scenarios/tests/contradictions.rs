//! Cycles of alignments flag a wrong one (`matcher.relay.contradiction_m`), and the object
//! evidence settles it (`matcher.relay.settle`): in the indoor world of repeated rooms, seed 25
//! has alpha and bravo align each other 29–32 m off, turned by 180° (the 4 × 3 grid of rooms
//! maps onto itself under a half turn), and the other four alignments, right, contradict them
//! around the cycle. A cycle alone cannot say which of its alignments is wrong, so with settling
//! off right ones on a broken cycle are flagged too; with it on, each alignment is scored by the
//! object pairs it explains against the product of the others, the half turn loses least, and
//! alpha and bravo withdraw it. On seed 11, where every alignment is right, nothing is flagged.
//! (Seed 2, which aligned alpha and bravo turned by 180°, was this test's case until the
//! matcher's crowd estimate refused that turn; then seed 13, where charlie aligned alpha 19 m
//! and 90° off, and seed 1 the right one, until the object layer was kept clean and those seeds
//! aligned fewer directions in the first 70–80 s; then seed 25 until the merges were done whole,
//! after which alpha ↔ charlie no longer aligned there; then seed 32 until objects were
//! estimated from every view and their far side, after which seed 25 aligned all six again, and
//! 32 no longer wrongly.)

use sgm_scenarios::report::{compute, AlignmentReport, Report};
use sgm_scenarios::runner::run;
use sgm_scenarios::scenario::Scenario;
use std::sync::{Arc, Mutex, OnceLock};

/// Everything logged at info and above by any test of this file (the robots run on threads of
/// their own, so the subscriber is the process's).
fn logs() -> Arc<Mutex<Vec<u8>>> {
    static LOGS: OnceLock<Arc<Mutex<Vec<u8>>>> = OnceLock::new();
    LOGS.get_or_init(|| {
        let buffer = Arc::new(Mutex::new(Vec::new()));
        let writer = buffer.clone();
        let subscriber = tracing_subscriber::fmt()
            .with_max_level(tracing::Level::INFO)
            .with_ansi(false)
            .with_writer(move || Captured(writer.clone()))
            .finish();
        tracing::subscriber::set_global_default(subscriber).expect("no other subscriber in this test binary");
        buffer
    })
    .clone()
}

struct Captured(Arc<Mutex<Vec<u8>>>);

impl std::io::Write for Captured {
    fn write(&mut self, bytes: &[u8]) -> std::io::Result<usize> {
        self.0.lock().expect("log buffer").extend_from_slice(bytes);
        Ok(bytes.len())
    }
    fn flush(&mut self) -> std::io::Result<()> {
        Ok(())
    }
}

fn indoor(seed: u64, duration_s: f64, settle: bool) -> Report {
    let mut scenario =
        Scenario::load_with_env("indoor_three_robots", "SGM_CONTRADICTIONS_TEST").unwrap().with_seed(seed);
    scenario.scenario.duration_s = duration_s;
    scenario.matcher.relay.settle = settle;
    // This file is about cycles: no alignment is withdrawn on a stronger match (tests/rematch.rs).
    scenario.matcher.relay.rematch = false;
    let outcome = actix_rt::System::new().block_on(run(&scenario, None)).unwrap();
    compute(&outcome.record)
}

fn wrong(a: &AlignmentReport) -> bool {
    a.translation_error_m.unwrap() > 2.0 || a.rotation_error_deg.unwrap() > 5.0
}

/// Every direction aligned, and no robot's flag names itself (a flag names the third robot of
/// a cycle, or the remote when its own alignment of us disagrees).
fn all_aligned(report: &Report) {
    assert_eq!(report.alignments.len(), 6);
    for a in &report.alignments {
        assert_eq!(a.state, "Aligned", "{} ← {}", a.local, a.remote);
        assert!(!a.contradicted_by.contains(&a.local), "{} ← {}: {:?}", a.local, a.remote, a.contradicted_by);
    }
}

/// The lines logged while `body` ran that contain `text` (the other test of this file logs
/// neither contradictions nor withdrawals, so every such line is this run's).
fn logged_during(text: &str, body: impl FnOnce() -> Report) -> (Report, Vec<String>) {
    let logs = logs();
    let before = logs.lock().unwrap().len();
    let report = body();
    let all = logs.lock().unwrap()[before..].to_vec();
    let lines = String::from_utf8_lossy(&all).lines().filter(|l| l.contains(text)).map(str::to_owned).collect();
    (report, lines)
}

fn field(line: &str, key: &str) -> String {
    let robot = line.split_whitespace().find_map(|w| w.strip_prefix(key)).unwrap_or_default();
    match robot {
        "robot1" => "alpha",
        "robot2" => "bravo",
        "robot3" => "charlie",
        other => other,
    }
    .to_owned()
}

type Directions = std::collections::BTreeSet<(String, String)>;

/// Seed 25 at 70 s, twice: with settling off, the wrong pair is flagged around its cycle and
/// stays wrong; with it on (the default), the cycle's object evidence names the wrong pair and
/// both of its robots withdraw it, and the relay places each again through charlie, right.
#[test]
fn a_wrong_alignment_among_repeated_rooms_is_flagged_then_settled_by_the_object_evidence() {
    let contradicted = "our alignment of the neighbour is contradicted";
    let (report, warned) = logged_during(contradicted, || indoor(25, 70.0, false));
    all_aligned(&report);
    let wrong_ones: Vec<&AlignmentReport> = report.alignments.iter().filter(|a| wrong(a)).collect();
    assert!(!wrong_ones.is_empty(), "seed 25 no longer aligns wrongly: choose another case for this test");
    // The wrong alignment is flagged, and so are right ones that meet it around the cycle.
    for a in &wrong_ones {
        assert!(!a.contradicted_by.is_empty(), "{} ← {} is wrong and not flagged", a.local, a.remote);
        assert_eq!(a.withdrawals, 0, "settling is off");
    }
    let flagged: Directions = report
        .alignments
        .iter()
        .filter(|a| !a.contradicted_by.is_empty())
        .map(|a| (a.local.clone(), a.remote.clone()))
        .collect();
    assert!(flagged.len() > wrong_ones.len(), "only the wrong ones flagged: {flagged:?}");
    // And the log said so for each of them, at most once a minute each (70 s: twice at most). A
    // direction may also have been flagged for a while and cleared (its cycle then went through
    // the wrong alignment, before a right one came in).
    assert!(warned.iter().all(|l| l.contains("WARN") && l.contains("through=")), "{warned:#?}");
    let directions: Directions = warned.iter().map(|l| (field(l, "robot="), field(l, "neighbour="))).collect();
    assert!(directions.is_superset(&flagged), "flagged {flagged:?}, warned {warned:#?}");
    assert!(warned.len() <= 2 * directions.len(), "{} warnings: {warned:#?}", warned.len());
    let wrong_directions: Directions = wrong_ones.iter().map(|a| (a.local.clone(), a.remote.clone())).collect();

    let (report, withdrawn) = logged_during("our alignment of the neighbour withdrawn", || indoor(25, 70.0, true));
    all_aligned(&report);
    for a in &report.alignments {
        assert!(!wrong(a), "{} ← {} still wrong: {:?} m", a.local, a.remote, a.translation_error_m);
        assert!(a.contradicted_by.is_empty(), "{} ← {} flagged by {:?}", a.local, a.remote, a.contradicted_by);
        let direction = (a.local.clone(), a.remote.clone());
        let expected = u32::from(wrong_directions.contains(&direction));
        assert_eq!(a.withdrawals, expected, "{} ← {}", a.local, a.remote);
    }
    // Each withdrawal was logged once, as a warning naming the cycle and its evidence.
    assert_eq!(withdrawn.len(), wrong_directions.len(), "{withdrawn:#?}");
    assert!(withdrawn.iter().all(|l| l.contains("WARN") && l.contains("contradicted cycle") && l.contains("losses:")));
    let directions: Directions = withdrawn.iter().map(|l| (field(l, "robot="), field(l, "neighbour="))).collect();
    assert_eq!(directions, wrong_directions);
}

#[test]
fn right_alignments_are_not_flagged() {
    let report = indoor(11, 80.0, true);
    all_aligned(&report);
    for a in &report.alignments {
        assert!(!wrong(a), "{} ← {}: {:?} m", a.local, a.remote, a.translation_error_m);
        assert!(a.contradicted_by.is_empty(), "{} ← {} flagged by {:?}", a.local, a.remote, a.contradicted_by);
        assert_eq!(a.withdrawals, 0, "{} ← {}: a right alignment withdrawn", a.local, a.remote);
    }
}
