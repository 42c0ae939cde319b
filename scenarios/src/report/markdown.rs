//! `report.md`: the one-page summary, with the message table in the paper's Table 4 layout.

use super::{MessageRow, Report};
use crate::record::Timing;
use std::fmt::Write as _;

fn metres(v: Option<f64>) -> String {
    v.map_or("—".into(), |v| format!("{v:.3}"))
}

fn kib(bytes: f64) -> String {
    format!("{:.2}", bytes / 1024.0)
}

/// The ledger: nothing lost, or exactly what was.
fn accounting(s: &mut String, ledger: &super::ledger::Ledger) {
    let _ =
        writeln!(s, "## Accounting\n\n| robot | keyframes | objects | ObjectData revision sent |\n|---|---|---|---|");
    for r in &ledger.robots {
        let _ = writeln!(s, "| {} | {} | {} | {} |", r.name, r.keyframes, r.objects, r.object_data_revision);
    }
    let _ = writeln!(
        s,
        "\n| local ← remote | ObjectData held | current | keyframes wanted | received | refused | given up | pending |\n|---|---|---|---|---|---|---|---|"
    );
    for p in &ledger.pairs {
        let _ = writeln!(
            s,
            "| {} ← {} | {} | {} | {} | {} | {} | {} | {} |",
            p.local,
            p.remote,
            p.object_data_revision.map_or("—".into(), |r| r.to_string()),
            if p.object_data_current { "yes" } else { "no" },
            p.keyframes_wanted,
            p.keyframes_received,
            p.keyframes_refused,
            p.keyframes_given_up,
            p.keyframes_pending
        );
    }
    if !ledger.restarts.is_empty() {
        let _ = writeln!(
            s,
            "\n| robot | crashed (s) | restarted (s) | snapshot of (s) | keyframes at crash | in snapshot | snapshot keyframes in the final map | objects in snapshot |\n|---|---|---|---|---|---|---|---|"
        );
        for r in &ledger.restarts {
            let _ = writeln!(
                s,
                "| {} | {:.1} | {:.1} | {} | {} | {} | {} | {} |",
                r.robot,
                r.crashed_at_s,
                r.restarted_at_s,
                r.snapshot_taken_at_s.map_or("—".into(), |t| format!("{t:.1}")),
                r.keyframes_at_crash,
                r.keyframes_in_snapshot,
                r.snapshot_keyframes_kept,
                r.objects_in_snapshot
            );
        }
    }
    let _ = writeln!(s);
}

/// The clouds the maps hold (deterministic) and the process's resident memory (not).
fn memory(s: &mut String, report: &Report, timing: &Timing) {
    let mib = |bytes: f64| bytes / 1024.0 / 1024.0;
    let held: u64 = report.robots.iter().map(|r| r.clouds.bytes as u64).sum();
    let scans: usize = report.robots.iter().map(|r| r.clouds.scans).sum();
    let compacted: usize = report.robots.iter().map(|r| r.clouds.compacted).sum();
    let evicted: u64 = report.robots.iter().map(|r| r.clouds.evicted).sum();
    let peak = report.series.iter().max_by_key(|p| p.cloud_bytes);
    let _ = write!(
        s,
        "Clouds: the maps hold {:.1} MiB in {scans} keyframe scans ({compacted} compacted, {evicted} evicted)",
        mib(held as f64)
    );
    if let Some(p) = peak {
        let _ = write!(s, ", at most {:.1} MiB (at {:.0} s)", mib(p.cloud_bytes as f64), p.t);
    }
    let _ = write!(s, ".");
    if let Some(peak) = timing.peak_resident_mb {
        let _ = write!(s, " Resident memory: peak {peak:.0} MiB");
        match crate::memory::drift_after(&timing.memory, report.sim_s / 2.0) {
            Some((lo, hi)) => {
                let _ = write!(s, ", over the second half within {:+.1} % and {:+.1} %.", lo * 100.0, hi * 100.0);
            }
            None => {
                let _ = write!(s, ".");
            }
        }
    }
    let _ = writeln!(s, "\n");
}

/// Per robot: how many scans were deskewed, and why the others were used as they came.
fn deskew(s: &mut String, report: &Report) {
    let _ = write!(s, "Deskew:");
    for (k, r) in report.robots.iter().enumerate() {
        let d = &r.deskew;
        let scans = d.deskewed + d.no_times + d.no_motion + d.refused;
        let _ = write!(s, "{} {}: ", if k == 0 { "" } else { ";" }, r.name);
        // On its own odometry the robot's sweeps are deskewed there, not by Fusion.
        if let Some(o) = &r.odometry {
            let c = &o.counts;
            let _ = write!(s, "by its odometry ({} sweeps estimated, {} of them frames", c.scans, d.upstream);
            if c.not_deskewed > 0 {
                let _ = write!(
                    s,
                    "; {} sweeps used as they came: no per-point time, or times that did not fit",
                    c.not_deskewed
                );
            }
            let trouble = [
                (c.imu.saturated, "IMU samples at full scale, used clipped"),
                (c.low_overlap, "sweeps that overlapped the local map little"),
                (c.coasted, "sweeps coasted on the IMU"),
                (c.resets, "resets after a divergence"),
            ];
            for (n, what) in trouble.iter().filter(|(n, _)| *n > 0) {
                let _ = write!(s, "; {n} {what}");
            }
            let _ = write!(s, ")");
            continue;
        }
        if scans == 0 {
            let _ = write!(s, "off (fusion.deskew = false) or no scan");
            continue;
        }
        let _ = write!(s, "{} of {scans} scans deskewed", d.deskewed);
        if d.with_imu > 0 {
            let _ = write!(s, " ({} with the gyro, {} with the odometry's twist)", d.with_imu, d.deskewed - d.with_imu);
        }
        let not = [
            (d.no_times, "without per-point time"),
            (d.no_motion, "before any motion"),
            (d.refused, "whose times did not fit"),
        ];
        let not: Vec<String> = not.iter().filter(|(n, _)| *n > 0).map(|(n, why)| format!("{n} {why}")).collect();
        if !not.is_empty() {
            let _ = write!(s, "; not deskewed: {}", not.join(", "));
        }
    }
    let _ = writeln!(s, ".\n");
}

pub fn render(report: &Report, timing: &Timing) -> String {
    let mut s = String::new();
    let _ = writeln!(s, "# Run report: {}\n", report.scenario);
    // A replayed bag has no simulated world to count.
    let world = match report.world_objects {
        0 => String::new(),
        n => format!(" {n} objects in the world."),
    };
    let _ = writeln!(
        s,
        "Seed {}, {:.0} s simulated in {:.1} s wall ({:.0}× real time).{world}\n",
        report.seed, report.sim_s, timing.wall_s, timing.realtime_factor
    );
    let _ = writeln!(
        s,
        "**Team ATE RMSE: {} m** over {} (SE(3)-aligned, merged in {}'s world). References: each map \
         joined by the true transform {} m; one graph of the team, every robot's factors solved together, {} m.\n",
        metres(report.team_ate_rmse_m),
        if report.team_ate_robots.is_empty() { "no robot".into() } else { report.team_ate_robots.join(", ") },
        report.team_ate_robots.first().map_or("—", String::as_str),
        metres(report.team_ate_oracle_join_m),
        metres(report.team_ate_team_graph_m)
    );
    let _ = writeln!(s, "## Robots\n\n| robot | ATE RMSE (m) | keyframes | objects (confirmed, moving) | merged, expired | glimpses | distance (m) | frames |\n|---|---|---|---|---|---|---|---|");
    for r in &report.robots {
        let _ = writeln!(
            s,
            "| {} | {} | {} | {} ({}, {}) | {}, {} | {} | {:.0} | {} |",
            r.name,
            metres(r.ate_rmse_m),
            r.keyframes,
            r.objects,
            r.confirmed_objects,
            r.moving_objects,
            r.merged_objects,
            r.expired_objects,
            r.glimpse_sightings,
            r.distance_m,
            r.frames
        );
    }
    let _ = writeln!(s, "\n## Alignments\n\n| local ← remote | state | first aligned (s) | translation error (m) | rotation error (°) | closure rounds | inter-robot factors (inconsistent) |\n|---|---|---|---|---|---|---|");
    for a in &report.alignments {
        let _ = writeln!(
            s,
            "| {} ← {} | {}{} | {} | {} | {} | {} | {} ({}) |",
            a.local,
            a.remote,
            a.state,
            a.contradiction_note(),
            a.first_aligned_s.map_or("—".into(), |t| format!("{t:.1}{}", a.relayed_note())),
            metres(a.translation_error_m),
            a.rotation_error_deg.map_or("—".into(), |v| format!("{v:.2}")),
            a.closures.rounds,
            a.inter_robot_factors,
            a.inconsistent_factors
        );
    }
    let withdrawn: Vec<_> = report.alignments.iter().filter_map(|a| Some((a, a.last_withdrawal.as_ref()?))).collect();
    if !withdrawn.is_empty() {
        let _ = writeln!(s, "\nAlignments withdrawn (the latest of each pair, and why):\n");
        for (a, why) in withdrawn {
            let _ = writeln!(s, "- {} ← {}: {why}", a.local, a.remote);
        }
    }
    let suspect: Vec<_> = report.alignments.iter().filter(|a| !a.suspect.is_empty()).collect();
    if !suspect.is_empty() {
        let _ = writeln!(s, "\nNeighbours held suspect (by the local robot, and why):\n");
        for a in suspect {
            let _ = writeln!(s, "- {} ← {}: {}", a.local, a.remote, a.suspect.join("; "));
        }
    }
    let unaligned: Vec<_> = report.alignments.iter().filter(|a| a.first_aligned_s.is_none()).collect();
    if !unaligned.is_empty() {
        let _ = writeln!(s, "\nNot aligned, and why (the local robot's latest object-graph match):\n");
        for a in unaligned {
            let _ = writeln!(s, "- {} ← {}: {}", a.local, a.remote, a.match_attempts.summary());
        }
    }
    let _ = writeln!(s, "\n## Messages (paper Table 4 layout; whole team)\n\n| message | count | mean (KiB) | max (KiB) | total (KiB) |\n|---|---|---|---|---|");
    let mut row = |name: &str, m: &MessageRow| {
        let (mean, max, total) = (kib(m.bytes_mean), kib(m.bytes_max as f64), kib(m.bytes_total as f64));
        let _ = writeln!(s, "| {name} | {} | {mean} | {max} | {total} |", m.count);
    };
    for (name, m) in report.messages.iter().filter(|(_, m)| m.count > 0) {
        row(name, m);
    }
    row("point-cloud raw (every frame, 16 B/point)", &report.point_cloud_raw);
    let _ =
        writeln!(s, "\nSGM sent {:.3} % of what raw point-cloud sharing would.\n", report.bytes_ratio_to_raw * 100.0);
    let r = &report.radio;
    let _ = writeln!(
        s,
        "Radio: {} packets delivered ({} of them twice), {} lost, {} out of range, {} cut by a partition, \
         {} dropped on a full queue.\n",
        r.delivered, r.duplicated, r.lost, r.out_of_range, r.partitioned, r.queue_full
    );
    let b = &report.back_end;
    let _ = write!(
        s,
        "Back end: {} loop closures and inter-robot factors, {} rejected as outliers.",
        b.candidate_factors, b.rejected_factors
    );
    if b.false_factors_injected > 0 {
        let _ = write!(
            s,
            " {} false factors injected, {} of them rejected.",
            b.false_factors_injected, b.false_factors_rejected
        );
    }
    if b.failed_solves > 0 || b.failed_own_solves > 0 {
        let _ = write!(
            s,
            " **{} pose-graph solves failed** (the map kept its poses), {} own-pose solves failed \
             (neighbours were told the joint poses); the log says why.",
            b.failed_solves, b.failed_own_solves
        );
    }
    let _ = writeln!(s, "\n");
    memory(&mut s, report, timing);
    deskew(&mut s, report);
    accounting(&mut s, &report.ledger);
    let _ = writeln!(
        s,
        "Files: `report.json` (these figures, deterministic), `timing.json` (wall and per-actor time), \
         `*.tum` (trajectories for evo), `map.png`, `ate.png`, `bytes.png`, `map.pcd` (merged semantic map)."
    );
    s
}
