//! Cycles of alignments flag a wrong one (`matcher.relay.contradiction_m`): in the indoor world
//! whose room grid a half turn maps onto itself, seed 2 aligns alpha and bravo turned by 180°,
//! and charlie's right alignments contradict that around the cycle; on seed 1, where every
//! alignment is right, nothing is flagged. A cycle cannot say which of its alignments is wrong,
//! so the right ones on a broken cycle are flagged too.

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
fn a_wrong_alignment_among_symmetric_rooms_is_flagged_around_its_cycle() {
    let logs = logs();
    let report = indoor(2, 70.0);
    all_aligned(&report);
    let wrong_ones: Vec<&AlignmentReport> = report.alignments.iter().filter(|a| wrong(a)).collect();
    assert!(!wrong_ones.is_empty(), "seed 2 no longer aligns wrongly: choose another case for this test");
    // Three robots make one cycle: a wrong alignment on it breaks it for every direction.
    for a in &report.alignments {
        assert!(!a.contradicted_by.is_empty(), "{} ← {} is not flagged", a.local, a.remote);
    }
    // And the log said so for every direction, at most once a minute each (70 s: twice at
    // most; the other test of this file flags nothing, so every such line is this run's).
    let text = String::from_utf8_lossy(&logs.lock().unwrap()).into_owned();
    let warned: Vec<&str> =
        text.lines().filter(|l| l.contains("our alignment of the neighbour is contradicted")).collect();
    assert!(warned.iter().all(|l| l.contains("WARN") && l.contains("through=")), "{warned:#?}");
    let field = |line: &str, key: &str| {
        line.split_whitespace().find_map(|w| w.strip_prefix(key)).map(str::to_owned).unwrap_or_default()
    };
    let directions: std::collections::BTreeSet<(String, String)> =
        warned.iter().map(|l| (field(l, "robot="), field(l, "neighbour="))).collect();
    assert_eq!(directions.len(), 6, "{warned:#?}");
    assert!(warned.len() <= 12, "{} warnings: {warned:#?}", warned.len());
}

#[test]
fn right_alignments_are_not_flagged() {
    let report = indoor(1, 80.0);
    all_aligned(&report);
    for a in &report.alignments {
        assert!(!wrong(a), "{} ← {}: {:?} m", a.local, a.remote, a.translation_error_m);
        assert!(a.contradicted_by.is_empty(), "{} ← {} flagged by {:?}", a.local, a.remote, a.contradicted_by);
    }
}
