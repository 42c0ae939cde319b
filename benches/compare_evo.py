"""evo_ape (SE(3) Umeyama, `-a`) on the TUM files of an `sgm run` report directory, against the
ATE figures of its report.json. Without an argument, runs the quickstart into a temporary
directory first. Prints one row per trajectory and exits 1 if any pair differs by more than
1e-6 m (the TUM files round to 1 nm)."""

import json
import subprocess
import sys
import tempfile
from pathlib import Path

from evo.core import metrics, sync
from evo.tools import file_interface


def evo_rmse(truth: Path, estimate: Path) -> float:
    reference = file_interface.read_tum_trajectory_file(str(truth))
    trajectory = file_interface.read_tum_trajectory_file(str(estimate))
    reference, trajectory = sync.associate_trajectories(reference, trajectory)
    trajectory.align(reference, correct_scale=False)
    ape = metrics.APE(metrics.PoseRelation.translation_part)
    ape.process_data((reference, trajectory))
    return ape.get_statistic(metrics.StatisticsType.rmse)


def main() -> int:
    if len(sys.argv) > 1:
        run = Path(sys.argv[1])
    else:
        run = Path(tempfile.mkdtemp()) / "quickstart"
        subprocess.run(["target/release/sgm", "run", "--quiet", "--out", str(run)], check=True)
    report = json.loads((run / "report.json").read_text())
    rows = [("team", report["team_ate_rmse_m"])] + [(r["name"], r["ate_rmse_m"]) for r in report["robots"]]
    worst = 0.0
    print(f"{'trajectory':<12} {'sgm ATE (m)':>14} {'evo_ape -a (m)':>16} {'difference':>12}")
    for name, ours in rows:
        if ours is None:
            continue
        theirs = evo_rmse(run / f"{name}.truth.tum", run / f"{name}.tum")
        worst = max(worst, abs(theirs - ours))
        print(f"{name:<12} {ours:>14.6f} {theirs:>16.6f} {theirs - ours:>12.2e}")
    print(f"run: {run}")
    return 0 if worst <= 1e-6 else 1


if __name__ == "__main__":
    sys.exit(main())
