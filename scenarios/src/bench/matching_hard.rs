//! The matcher's hard cases in `sgm bench matching` (issue 33): repeated layouts
//! (`eval::repeated_layouts`: a parking lot, an office, a lecture hall, a bare grid of lamp
//! posts), each with both robots in the same place and in two different places of the same
//! layout; and graphs of hundreds of objects at the paper's density. A claim is wrong when its
//! transform is off by 2 m or 20° (or when the robots share nothing): the target is at most 1%
//! wrong claims in every family — refusing is allowed, answering wrongly is not.

use indicatif::ProgressBar;
use serde::Serialize;
use sgm_model::eval::matching_protocol::{generate_pair, score_trial, PairSpec, SyntheticWorld, TrialPair, TrialScore};
use sgm_model::eval::repeated_layouts::{generate_layout_pair, Layout, LayoutPairSpec, CLASSES};
use sgm_model::matching::{match_graphs, LabelSimilarity, MatchOutcome, MatcherConfig};
use std::fmt::Write;
use std::time::Instant;

/// Sizes of the hundreds-of-objects family (local = remote, half shared).
const LARGE: [usize; 2] = [150, 400];

/// Outcomes of one cell.
#[derive(Clone, Copy, Default, Serialize)]
pub struct HardCell {
    pub success_pct: f64,
    pub wrong_pct: f64,
    pub recall_pct: f64,
    pub median_ms: f64,
    pub mean_objects: f64,
    pub mean_shared: f64,
}

fn run_cell(
    reps: usize,
    progress: &ProgressBar,
    labels: &LabelSimilarity,
    config: &MatcherConfig,
    pair_of: impl Fn(u64) -> TrialPair,
) -> HardCell {
    let (mut scores, mut times, mut objects, mut shared) = (Vec::<TrialScore>::new(), Vec::new(), 0usize, 0usize);
    for rep in 0..reps as u64 {
        let pair = pair_of(rep);
        objects += pair.local.len();
        shared += pair.true_pairs.len();
        let start = Instant::now();
        let report = match_graphs(&pair.local, &pair.remote, labels, config);
        times.push(start.elapsed().as_secs_f64() * 1e3);
        let (pose, matches) = match &report.outcome {
            MatchOutcome::Aligned(a) => {
                (Some(a.local_from_remote), a.matches.iter().map(|m| (m.local, m.remote)).collect())
            }
            MatchOutcome::Refused(_) => (None, Vec::new()),
        };
        scores.push(score_trial(&pair, pose.as_ref(), &matches));
        progress.inc(1);
    }
    times.sort_by(f64::total_cmp);
    let n = reps.max(1) as f64;
    let true_pairs: usize = scores.iter().map(|s| s.true_pairs).sum();
    let correct: usize = scores.iter().map(|s| s.correct_matches).sum();
    HardCell {
        success_pct: 100.0 * scores.iter().filter(|s| s.success).count() as f64 / n,
        wrong_pct: 100.0 * scores.iter().filter(|s| s.claimed && !s.success).count() as f64 / n,
        recall_pct: if true_pairs == 0 { 0.0 } else { 100.0 * correct as f64 / true_pairs as f64 },
        median_ms: times.get(times.len() / 2).copied().unwrap_or(0.0),
        mean_objects: objects as f64 / n,
        mean_shared: shared as f64 / n,
    }
}

#[derive(Serialize)]
pub struct LayoutRow {
    pub layout: &'static str,
    /// [NoErr, Err], robots in the same place.
    pub same_place: [HardCell; 2],
    /// [NoErr, Err], two places of the same layout.
    pub different_places: [HardCell; 2],
}

#[derive(Serialize)]
pub struct LargeRow {
    pub objects: usize,
    /// [NoErr, Err], half the objects shared.
    pub shared_half: [HardCell; 2],
    /// [NoErr, Err], nothing shared.
    pub disjoint: [HardCell; 2],
}

#[derive(Serialize)]
pub struct HardFamilies {
    pub reps: usize,
    pub layouts: Vec<LayoutRow>,
    pub large: Vec<LargeRow>,
}

/// Trials the hard families will run (for the progress bar).
pub fn trials(reps: usize) -> u64 {
    ((Layout::ALL.len() + LARGE.len()) * 4 * reps) as u64
}

/// Runs both families; `seed` seeds every pair.
pub fn run(reps: usize, seed: u64, config: &MatcherConfig, progress: &ProgressBar) -> HardFamilies {
    let layout_labels = LabelSimilarity::uniform(CLASSES as usize, config.mislabel_similarity);
    let pair_seed = |family: u64, rep: u64| seed.wrapping_mul(1_000_003).wrapping_add(family * 100_003 + rep);
    let layouts = Layout::ALL
        .iter()
        .enumerate()
        .map(|(k, &layout)| {
            let cell = |same_place: bool, noisy: bool| {
                let family = 1000 + 4 * k as u64 + 2 * same_place as u64 + noisy as u64;
                let spec = LayoutPairSpec { layout, same_place, noisy };
                run_cell(reps, progress, &layout_labels, config, |rep| {
                    generate_layout_pair(&spec, pair_seed(family, rep))
                })
            };
            LayoutRow {
                layout: layout.name(),
                same_place: [cell(true, false), cell(true, true)],
                different_places: [cell(false, false), cell(false, true)],
            }
        })
        .collect();
    let large = LARGE
        .iter()
        .enumerate()
        .map(|(k, &n)| {
            let cell = |overlap: usize, noisy: bool| {
                let world = SyntheticWorld::with_density_for((2 * n - overlap).max(50));
                let labels = LabelSimilarity::uniform(world.classes as usize, config.mislabel_similarity);
                let family = 2000 + 4 * k as u64 + 2 * (overlap > 0) as u64 + noisy as u64;
                let spec = PairSpec { local: n, remote: n, overlap, noisy, mislabels: 0 };
                run_cell(reps, progress, &labels, config, |rep| generate_pair(&world, &spec, pair_seed(family, rep)))
            };
            LargeRow {
                objects: n,
                shared_half: [cell(n / 2, false), cell(n / 2, true)],
                disjoint: [cell(0, false), cell(0, true)],
            }
        })
        .collect();
    HardFamilies { reps, layouts, large }
}

/// The two tables.
pub fn markdown(families: &HardFamilies) -> String {
    let mut s = String::new();
    let _ = writeln!(
        s,
        "\n## Repeated layouts ({} pairs per cell; a transform off by 2 m or 20°, or claimed between different places, is wrong)\n",
        families.reps
    );
    let _ = writeln!(
        s,
        "| layout | objects per robot | shared | success NoErr % | success Err % | wrong NoErr % | wrong Err % | wrong, different places NoErr % | wrong, different places Err % | time ms |"
    );
    let _ = writeln!(s, "|---|---|---|---|---|---|---|---|---|---|");
    for r in &families.layouts {
        let (a, b) = (&r.same_place, &r.different_places);
        let _ = writeln!(
            s,
            "| {} | {:.0} | {:.0} | {:.1} | {:.1} | **{:.1}** | **{:.1}** | **{:.1}** | **{:.1}** | {:.1} |",
            r.layout,
            a[0].mean_objects,
            a[0].mean_shared,
            a[0].success_pct,
            a[1].success_pct,
            a[0].wrong_pct,
            a[1].wrong_pct,
            b[0].wrong_pct,
            b[1].wrong_pct,
            a[1].median_ms
        );
    }
    let _ = writeln!(
        s,
        "\n## Hundreds of objects ({} pairs per cell; the paper's density, half shared or none)\n",
        families.reps
    );
    let _ = writeln!(
        s,
        "| objects | success NoErr % | success Err % | recall Err % | wrong NoErr % | wrong Err % | claims, nothing shared NoErr % | claims, nothing shared Err % | time ms (Err) |"
    );
    let _ = writeln!(s, "|---|---|---|---|---|---|---|---|---|");
    for r in &families.large {
        let (a, b) = (&r.shared_half, &r.disjoint);
        let _ = writeln!(
            s,
            "| {n} / {n} | {:.1} | {:.1} | {:.1} | **{:.1}** | **{:.1}** | **{:.1}** | **{:.1}** | {:.1} |",
            a[0].success_pct,
            a[1].success_pct,
            a[1].recall_pct,
            a[0].wrong_pct,
            a[1].wrong_pct,
            b[0].wrong_pct,
            b[1].wrong_pct,
            a[1].median_ms,
            n = r.objects,
        );
    }
    s
}
