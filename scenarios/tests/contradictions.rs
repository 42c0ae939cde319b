//! Cycles of alignments flag a wrong one (`matcher.relay.contradiction_m`): in the indoor world
//! of repeated rooms, seed 25 has alpha and bravo align each other 29–32 m off, turned by 180°
//! (the 4 × 3 grid of rooms maps onto itself under a half turn), and the other four
//! alignments, right, contradict them around the cycle; on seed 11, where every alignment is
//! right, nothing is flagged. A cycle cannot say which of its alignments is wrong, so right ones
//! on a broken cycle are flagged too. (Seed 2, which aligned alpha and bravo turned by 180°, was
//! this test's case until the matcher's crowd estimate refused that turn; then seed 13, where
//! charlie aligned alpha 19 m and 90° off, and seed 1 the right one, until the object layer was
//! kept clean and those seeds aligned fewer directions in the first 70–80 s; then seed 25 until
//! the merges were done whole, after which alpha ↔ charlie no longer aligned there; then seed
//! 32 until objects were estimated from every view and their far side, after which seed 25
//! aligned all six again, and 32 no longer wrongly.)

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

fn indoor(seed: u64, duration_s: f64) -> Report {
    let mut scenario =
        Scenario::load_with_env("indoor_three_robots", "SGM_CONTRADICTIONS_TEST").unwrap().with_seed(seed);
    scenario.scenario.duration_s = duration_s;
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

#[test]
fn a_wrong_alignment_among_repeated_rooms_is_flagged_around_its_cycle() {
    let logs = logs();
    let report = indoor(25, 70.0);
    all_aligned(&report);
    let wrong_ones: Vec<&AlignmentReport> = report.alignments.iter().filter(|a| wrong(a)).collect();
    assert!(!wrong_ones.is_empty(), "seed 25 no longer aligns wrongly: choose another case for this test");
    // The wrong alignment is flagged, and so are right ones that meet it around the cycle.
    for a in &wrong_ones {
        assert!(!a.contradicted_by.is_empty(), "{} ← {} is wrong and not flagged", a.local, a.remote);
    }
    let flagged: std::collections::BTreeSet<(String, String)> = report
        .alignments
        .iter()
        .filter(|a| !a.contradicted_by.is_empty())
        .map(|a| (a.local.clone(), a.remote.clone()))
        .collect();
    assert!(flagged.len() > wrong_ones.len(), "only the wrong ones flagged: {flagged:?}");
    // And the log said so for each of them, at most once a minute each (70 s: twice at most;
    // the other test of this file flags nothing, so every such line is this run's). A direction
    // may also have been flagged for a while and cleared (its cycle then went through the
    // wrong alignment, before a right one came in).
    let text = String::from_utf8_lossy(&logs.lock().unwrap()).into_owned();
    let warned: Vec<&str> =
        text.lines().filter(|l| l.contains("our alignment of the neighbour is contradicted")).collect();
    assert!(warned.iter().all(|l| l.contains("WARN") && l.contains("through=")), "{warned:#?}");
    let field = |line: &str, key: &str| {
        line.split_whitespace().find_map(|w| w.strip_prefix(key)).map(str::to_owned).unwrap_or_default()
    };
    let name = |robot: String| match robot.as_str() {
        "robot1" => "alpha".to_owned(),
        "robot2" => "bravo".to_owned(),
        "robot3" => "charlie".to_owned(),
        _ => robot,
    };
    let directions: std::collections::BTreeSet<(String, String)> =
        warned.iter().map(|l| (name(field(l, "robot=")), name(field(l, "neighbour=")))).collect();
    assert!(directions.is_superset(&flagged), "flagged {flagged:?}, warned {warned:#?}");
    assert!(warned.len() <= 2 * directions.len(), "{} warnings: {warned:#?}", warned.len());
}

#[test]
fn right_alignments_are_not_flagged() {
    let report = indoor(11, 80.0);
    all_aligned(&report);
    for a in &report.alignments {
        assert!(!wrong(a), "{} ← {}: {:?} m", a.local, a.remote, a.translation_error_m);
        assert!(a.contradicted_by.is_empty(), "{} ← {} flagged by {:?}", a.local, a.remote, a.contradicted_by);
    }
}
