//! `sgm bench sweeps`: how SGM degrades, and what it costs as the team grows.
//!
//! - **Mislabel rate** (whole missions): `quickstart` with `camera.mislabel_rate` from 0 to
//!   0.4 (each object given a wrong class in that share of frames), over several seeds.
//! - **Trajectory overlap** (whole missions): `quickstart` on a 140 m campus with bravo's loop
//!   moved east step by step; the overlap is the share of bravo's path within 10 m of alpha's.
//!   The same missions again with the Swarm-SC baseline's association (Scan Context), the
//!   fair version of Table 3's outdoor comparison: low overlap is where the paper's Swarm-SC
//!   failed.
//! - **Centroid noise** (the matcher alone, paper §V-A protocol): 35 / 32 objects, 17 shared,
//!   every centroid off by up to ±σ in x and y (±σ/2 in z, yaw ±10°·σ), 20 pairs per σ.
//! - **Team size** (whole missions): 2 to 16 robots with generated routes on a 120 m campus;
//!   bytes sent by the team against raw point-cloud sharing.
//!
//! Success of a mission: every directed pair aligned and none more than 2 m from the truth.
//! Team ATE as in Table 3 (`Report::team_ate_all_start_guess_m`).

use super::{aligned_right, duration_arg, load_cut, or_dash, radio_bytes, run_report, Section, WRONG_M};
use serde::Serialize;
use sgm_actors::config::Association;
use sgm_model::eval::matching_protocol::{generate_pair, score_trial, PairSpec, SyntheticWorld};
use sgm_model::geometry::pose_error;
use sgm_model::matching::{match_graphs, LabelSimilarity, MatchOutcome, MatcherConfig};
use sgm_scenarios::report::plots::{lines, Series};
use sgm_scenarios::report::Report;
use sgm_scenarios::scenario::{RobotSpec, RouteSpec, Scenario};
use std::fmt::Write;
use std::path::Path;

/// What a sweep point measured.
#[derive(Clone, Debug, Serialize)]
pub struct Point {
    /// The swept value (rate, overlap share, σ in m, robots).
    pub x: f64,
    pub runs: usize,
    pub success_pct: f64,
    /// Mean over runs (missions: team ATE; matcher: translation error of the claimed ones), m.
    pub error_m: Option<f64>,
    /// Missions: mean bytes sent by the team, and the same missions' raw point-cloud bytes.
    pub bytes_total: Option<f64>,
    pub raw_bytes: Option<f64>,
}

#[derive(Serialize)]
struct Json {
    command: String,
    mislabel_rate: Vec<Point>,
    overlap: Vec<Point>,
    overlap_scan_context: Vec<Point>,
    centroid_noise: Vec<Point>,
    team_size: Vec<Point>,
}

pub struct Options {
    /// Cut every mission to this many seconds, and sweep fewer values (the test suite's
    /// reduced mode).
    pub duration: Option<f64>,
    /// Where the plots go (PNG); none when `None`.
    pub plots: Option<std::path::PathBuf>,
}

/// Success and mean figures of the missions of one sweep value.
fn mission_point(x: f64, reports: &[Report]) -> Point {
    let n = reports.len().max(1) as f64;
    let success = reports.iter().filter(|r| !r.alignments.is_empty() && r.alignments.iter().all(aligned_right)).count();
    let errors: Vec<f64> = reports.iter().filter_map(|r| r.team_ate_all_start_guess_m).collect();
    let bytes: f64 = reports.iter().map(|r| radio_bytes(r) as f64).sum();
    let raw: f64 = reports.iter().map(|r| r.point_cloud_raw.bytes_total as f64).sum();
    Point {
        x,
        runs: reports.len(),
        success_pct: 100.0 * success as f64 / n,
        error_m: (!errors.is_empty()).then(|| errors.iter().sum::<f64>() / errors.len() as f64),
        bytes_total: Some(bytes / n),
        raw_bytes: Some(raw / n),
    }
}

/// One point per value: the missions `build` makes for it with each seed (`build` returns the
/// measured x, e.g. the overlap share, and the scenario).
fn sweep_missions(
    what: &str,
    values: &[f64],
    seeds: &[u64],
    build: impl Fn(f64, u64) -> anyhow::Result<(f64, Scenario)>,
) -> anyhow::Result<Vec<Point>> {
    let mut points = Vec::new();
    for &v in values {
        let mut reports = Vec::new();
        let mut x = v;
        for &seed in seeds {
            let (measured_x, scenario) = build(v, seed)?;
            x = measured_x;
            reports.push(run_report(&scenario, &format!("{what} {v}, seed {seed}"))?);
        }
        points.push(mission_point(x, &reports));
    }
    Ok(points)
}

/// Samples of a polyline every `step` m.
fn samples(waypoints: &[[f64; 2]], step: f64) -> Vec<[f64; 2]> {
    let mut out = Vec::new();
    for w in waypoints.windows(2) {
        let (a, b) = (w[0], w[1]);
        let length = (b[0] - a[0]).hypot(b[1] - a[1]);
        let n = (length / step).ceil().max(1.0) as usize;
        out.extend((0..n).map(|k| {
            let t = k as f64 / n as f64;
            [a[0] + t * (b[0] - a[0]), a[1] + t * (b[1] - a[1])]
        }));
    }
    out.extend(waypoints.last().copied());
    out
}

/// Share of `b`'s path within `radius` m of `a`'s path.
fn overlap(a: &[[f64; 2]], b: &[[f64; 2]], radius: f64) -> f64 {
    let (sa, sb) = (samples(a, 0.5), samples(b, 0.5));
    let near = sb.iter().filter(|p| sa.iter().any(|q| (p[0] - q[0]).hypot(p[1] - q[1]) <= radius)).count();
    near as f64 / sb.len().max(1) as f64
}

/// Quickstart on a 140 m campus (object density kept), bravo's loop moved east by `shift` m.
fn overlap_scenario(shift: f64, seed: u64, duration: Option<f64>) -> anyhow::Result<(f64, Scenario)> {
    let mut s = load_cut("quickstart", duration)?;
    let area_scale = (140.0 * 140.0) / (s.world.size_m[0] * s.world.size_m[1]);
    s.world.size_m = [140.0, 140.0];
    s.world.buildings = 6;
    for n in s.world.objects.values_mut() {
        *n = (*n as f64 * area_scale / 2.0).round() as usize;
    }
    s.scenario.seed = seed;
    for w in &mut s.robots[1].waypoints {
        w[0] += shift;
    }
    let share = overlap(&s.robots[0].waypoints, &s.robots[1].waypoints, 10.0);
    Ok((share, s))
}

/// `robots` robots on team_of_eight's campus, each on a generated route over a 60 m square
/// region, the regions spread over the campus.
fn team_scenario(robots: usize, duration: Option<f64>) -> anyhow::Result<Scenario> {
    let mut s = load_cut("team_of_eight", duration)?;
    let template = s.robots.first().cloned().unwrap_or_default();
    let side = (robots as f64).sqrt().ceil() as usize;
    s.robots = (0..robots)
        .map(|k| {
            let (i, j) = ((k % side) as f64, (k / side) as f64);
            let step = if side > 1 { 50.0 / (side - 1) as f64 } else { 0.0 };
            let (cx, cy) = (-25.0 + i * step, -25.0 + j * step);
            RobotSpec {
                name: format!("r{}", k + 1),
                waypoints: Vec::new(),
                route: Some(RouteSpec { region_m: [cx - 30.0, cy - 30.0, cx + 30.0, cy + 30.0], legs: 6 }),
                ..template.clone()
            }
        })
        .collect();
    Ok(s)
}

/// Matcher-only sweep: success and mean translation error of the claims against σ.
fn centroid_noise(values: &[f64], reps: usize) -> Vec<Point> {
    let config = MatcherConfig::default();
    values
        .iter()
        .enumerate()
        .map(|(cell, &sigma)| {
            let world = SyntheticWorld { noise_scale: sigma, ..SyntheticWorld::default() };
            let labels = LabelSimilarity::uniform(world.classes as usize, config.mislabel_similarity);
            let spec = PairSpec { local: 35, remote: 32, overlap: 17, noisy: sigma > 0.0, mislabels: 0 };
            let (mut success, mut errors) = (0, Vec::new());
            for rep in 0..reps as u64 {
                let pair = generate_pair(&world, &spec, 7_000_003 * (cell as u64 + 1) + rep);
                let report = match_graphs(&pair.local, &pair.remote, &labels, &config);
                let (pose, matches) = match &report.outcome {
                    MatchOutcome::Aligned(a) => {
                        (Some(a.local_from_remote), a.matches.iter().map(|m| (m.local, m.remote)).collect())
                    }
                    MatchOutcome::Refused(_) => (None, Vec::new()),
                };
                if score_trial(&pair, pose.as_ref(), &matches).success {
                    success += 1;
                }
                if let Some(p) = pose {
                    errors.push(pose_error(&p, &pair.local_from_remote).translation_m);
                }
            }
            Point {
                x: sigma,
                runs: reps,
                success_pct: 100.0 * success as f64 / reps.max(1) as f64,
                error_m: (!errors.is_empty()).then(|| errors.iter().sum::<f64>() / errors.len() as f64),
                bytes_total: None,
                raw_bytes: None,
            }
        })
        .collect()
}

pub fn run_bench(options: &Options) -> anyhow::Result<Section> {
    let reduced = options.duration.is_some();
    let duration = options.duration;
    let seeds: &[u64] = if reduced { &[1] } else { &[1, 2, 3] };
    let rates: &[f64] = if reduced { &[0.0, 0.3] } else { &[0.0, 0.1, 0.2, 0.3, 0.4] };
    let mislabel_rate = sweep_missions("mislabel rate", rates, seeds, |rate, seed| {
        let mut s = load_cut("quickstart", duration)?;
        s.camera.mislabel_rate = rate;
        s.scenario.seed = seed;
        Ok((rate, s))
    })?;
    let shifts: &[f64] = if reduced { &[0.0, 45.0] } else { &[0.0, 15.0, 30.0, 45.0] };
    let overlap =
        sweep_missions("bravo shifted m", shifts, seeds, |shift, seed| overlap_scenario(shift, seed, duration))?;
    let overlap_scan_context = sweep_missions("bravo shifted m (Swarm-SC)", shifts, seeds, |shift, seed| {
        let (share, mut s) = overlap_scenario(shift, seed, duration)?;
        s.matcher.association = Association::ScanContext;
        Ok((share, s))
    })?;
    let sigmas: &[f64] = if reduced { &[0.0, 1.0] } else { &[0.0, 0.5, 1.0, 1.5, 2.0, 3.0] };
    let centroid_noise = centroid_noise(sigmas, if reduced { 5 } else { 20 });
    let sizes: &[f64] = if reduced { &[2.0, 4.0] } else { &[2.0, 4.0, 8.0, 12.0, 16.0] };
    let team_size = sweep_missions("robots", sizes, &[1], |n, _| Ok((n, team_scenario(n as usize, duration)?)))?;

    let command = format!("sgm bench sweeps{}", duration_arg(duration));
    let json = Json { command, mislabel_rate, overlap, overlap_scan_context, centroid_noise, team_size };
    if let Some(dir) = &options.plots {
        plot(&json, dir)?;
    }
    Ok(Section { markdown: table(&json, options.plots.is_some()), json: serde_json::to_value(&json)? })
}

fn plot(json: &Json, dir: &Path) -> anyhow::Result<()> {
    std::fs::create_dir_all(dir)?;
    let success = |p: &[Point]| p.iter().map(|p| (p.x, p.success_pct)).collect::<Vec<_>>();
    let error = |p: &[Point]| p.iter().filter_map(|p| Some((p.x, p.error_m?))).collect::<Vec<_>>();
    let overlap_desc = "share of bravo's path within 10 m of alpha's";
    for (name, methods, x_desc, error_desc) in [
        ("sweep_mislabel", vec![("SGM", &json.mislabel_rate)], "mislabel rate", "team ATE (m)"),
        (
            "sweep_overlap",
            vec![("SGM", &json.overlap), ("Swarm-SC (ours)", &json.overlap_scan_context)],
            overlap_desc,
            "team ATE (m)",
        ),
        ("sweep_centroid_noise", vec![("SGM", &json.centroid_noise)], "centroid noise σ (m)", "translation error (m)"),
    ] {
        let s: Vec<Series> = methods.iter().map(|(m, p)| Series { name: m, points: success(p) }).collect();
        lines(&dir.join(format!("{name}_success.png")), x_desc, "success %", &s, false).map_err(anyhow::Error::from)?;
        let e: Vec<Series> = methods.iter().map(|(m, p)| Series { name: m, points: error(p) }).collect();
        lines(&dir.join(format!("{name}_error.png")), x_desc, error_desc, &e, false).map_err(anyhow::Error::from)?;
    }
    let bytes = [
        Series { name: "SGM", points: json.team_size.iter().filter_map(|p| Some((p.x, p.bytes_total?))).collect() },
        Series {
            name: "raw point clouds",
            points: json.team_size.iter().filter_map(|p| Some((p.x, p.raw_bytes?))).collect(),
        },
    ];
    lines(&dir.join("sweep_team_size_bytes.png"), "robots", "bytes sent by the team", &bytes, true)
        .map_err(anyhow::Error::from)
}

fn table(json: &Json, plotted: bool) -> String {
    let mut s = String::new();
    let _ = writeln!(s, "# Sweeps\n");
    let _ = writeln!(s, "Command: `{}`. Missions: success = every pair aligned within {WRONG_M} m.", json.command);
    if plotted {
        let _ = writeln!(s, "Plots: `sweep_*.png` beside this report.");
    }
    let mission = |s: &mut String, title: &str, x: &str, points: &[Point], x_decimals: usize| {
        let _ = writeln!(s, "\n## {title}\n\n| {x} | missions | success % | team ATE m | SGM MB | raw MB |");
        let _ = writeln!(s, "|---|---|---|---|---|---|");
        for p in points {
            let _ = writeln!(
                s,
                "| {:.x_decimals$} | {} | {:.0} | {} | {} | {} |",
                p.x,
                p.runs,
                p.success_pct,
                or_dash(p.error_m, 2),
                or_dash(p.bytes_total.map(|b| b / 1e6), 2),
                or_dash(p.raw_bytes.map(|b| b / 1e6), 1)
            );
        }
    };
    mission(&mut s, "Mislabel rate (quickstart)", "mislabel rate", &json.mislabel_rate, 2);
    mission(&mut s, "Trajectory overlap (quickstart on 140 m)", "overlap share", &json.overlap, 2);
    mission(
        &mut s,
        "Trajectory overlap, Swarm-SC (ours) association (same missions)",
        "overlap share",
        &json.overlap_scan_context,
        2,
    );
    let _ = writeln!(s, "\n## Centroid noise (matcher, paper §V-A protocol, 35 / 32 objects, 17 shared)\n");
    let _ = writeln!(s, "| σ m | pairs | success % | mean translation error of claims m |\n|---|---|---|---|");
    for p in &json.centroid_noise {
        let _ = writeln!(s, "| {:.1} | {} | {:.0} | {} |", p.x, p.runs, p.success_pct, or_dash(p.error_m, 2));
    }
    mission(&mut s, "Team size (team_of_eight's campus, generated routes)", "robots", &json.team_size, 0);
    s
}
