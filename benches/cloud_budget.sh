#!/usr/bin/env bash
# What a smaller cloud budget costs: the quickstart over seeds 1–5 at several
# `tracker.cloud_store.budget_mb` (with keep_recent = 5, so that small budgets are reached),
# then the mean team ATE, the mean error of the directed alignments, how many aligned, and what
# the maps held. Prints a markdown table (book/src/scene_graph.md, "The cloud store").
#
#   cargo build --release -p sgm-scenarios && bash benches/cloud_budget.sh
set -euo pipefail
cd "$(dirname "$0")/.."
sgm=./target/release/sgm
[ -x "$sgm" ] || { echo "build first: cargo build --release -p sgm-scenarios" >&2; exit 1; }
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
budgets=${BUDGETS:-"256 12 6 3"}
seeds=${SEEDS:-"1 2 3 4 5"}
for budget in $budgets; do
    toml="$work/quickstart_$budget.toml"
    cp scenarios/library/quickstart.toml "$toml"
    printf '\n[tracker.cloud_store]\nbudget_mb = %s\nkeep_recent = 5\n' "$budget" >> "$toml"
    for seed in $seeds; do
        "$sgm" run "$toml" --seed "$seed" --out "$work/run_${budget}_$seed" --quiet > /dev/null
    done
done
python3 - "$work" "$budgets" "$seeds" <<'PY'
import json, sys, statistics
work, budgets, seeds = sys.argv[1], sys.argv[2].split(), sys.argv[3].split()
print("| budget per robot (MiB) | team ATE (m) | alignment error (m) | aligned | clouds held per robot (MiB) | compacted | evicted |")
print("|---|---|---|---|---|---|---|")
for b in budgets:
    ate, err, aligned, pairs, held, compacted, evicted = [], [], 0, 0, [], 0, 0
    for s in seeds:
        r = json.load(open(f"{work}/run_{b}_{s}/report.json"))
        if r["team_ate_rmse_m"] is not None:
            ate.append(r["team_ate_rmse_m"])
        for a in r["alignments"]:
            pairs += 1
            if a["state"] == "Aligned":
                aligned += 1
                err.append(a["translation_error_m"])
        for robot in r["robots"]:
            held.append(robot["clouds"]["bytes"] / 1024 / 1024)
            compacted += robot["clouds"]["compacted"]
            evicted += robot["clouds"]["evicted"]
    mean = lambda v: f"{statistics.mean(v):.3f}" if v else "—"
    print(f"| {b} | {mean(ate)} | {mean(err)} | {aligned}/{pairs} | {statistics.mean(held):.1f} | {compacted} | {evicted} |")
PY
