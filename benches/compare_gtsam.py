"""GTSAM vs `sgm optimize` on ../shared/data/posegraph, same files, same run.

Prints final errors (GTSAM's graph.error = ½ Σ‖r‖²_Σ), iterations, optimisation wall time
(file reading excluded on both sides; best of 3) and the time ratio SGM / GTSAM.
With --outliers: replaces 20% of the loop closures of M3500 and sphere2500 by random
measurements and reports what `sgm optimize --robust gnc` rejects.
"""
import json
import random
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import gtsam
import numpy as np

ROOT = Path(__file__).resolve().parent.parent
DATA = ROOT.parent / "shared" / "data" / "posegraph"
SGM = ROOT / "target" / "release" / "sgm"
GRAPHS = ["2d/M3500.g2o", "2d/intel.g2o", "2d/city10000.g2o", "3d/sphere2500.g2o", "3d/parking-garage.g2o", "3d/smallGrid3D.g2o"]


def gtsam_run(path, is3d):
    graph, initial = gtsam.readG2o(str(path), is3d)
    first = min(initial.keys())
    if is3d:
        prior = gtsam.noiseModel.Diagonal.Variances(np.array([1e-6, 1e-6, 1e-6, 1e-4, 1e-4, 1e-4]))
        graph.add(gtsam.PriorFactorPose3(first, initial.atPose3(first), prior))
    else:
        prior = gtsam.noiseModel.Diagonal.Variances(np.array([1e-6, 1e-6, 1e-8]))
        graph.add(gtsam.PriorFactorPose2(first, initial.atPose2(first), prior))
    best = None
    for _ in range(3):
        optimizer = gtsam.LevenbergMarquardtOptimizer(graph, initial, gtsam.LevenbergMarquardtParams())
        start = time.perf_counter()
        result = optimizer.optimize()
        elapsed = (time.perf_counter() - start) * 1e3
        if best is None or elapsed < best[2]:
            best = (graph.error(result), optimizer.iterations(), elapsed)
    return best


def sgm_run(paths, robust="none"):
    best = None
    for _ in range(3):
        out = subprocess.run([str(SGM), "optimize", *map(str, paths), "--robust", robust, "--json"], check=True, capture_output=True, text=True)
        r = json.loads(out.stdout)
        if best is None or r["time_ms"] < best["time_ms"]:
            best = r
    return best


def compare():
    print("| graph | GTSAM error | SGM error | relative diff | GTSAM iters | SGM iters | GTSAM ms | SGM ms | SGM/GTSAM time |")
    print("|---|---|---|---|---|---|---|---|---|")
    for name in GRAPHS:
        path = DATA / name
        g_err, g_it, g_ms = gtsam_run(path, name.startswith("3d"))
        s = sgm_run([path])
        rel = abs(s["final_error"] - g_err) / g_err
        print(f"| {name} | {g_err:.6f} | {s['final_error']:.6f} | {rel:.1e} | {g_it} | {s['iterations']} | {g_ms:.1f} | {s['time_ms']:.1f} | {s['time_ms'] / g_ms:.2f} |")


def corrupt(path, fraction, seed):
    """Replace `fraction` of the loop closures (non-consecutive ids) by random measurements.
    Returns the corrupted text, the clean text without those edges, and their edge indices."""
    rng = random.Random(seed)
    lines = path.read_text().splitlines()
    edges = [i for i, l in enumerate(lines) if l.startswith("EDGE")]
    loops = [k for k, i in enumerate(edges) if abs(int(lines[i].split()[1]) - int(lines[i].split()[2])) != 1]
    chosen = sorted(rng.sample(loops, int(fraction * len(loops))))
    corrupted, clean = list(lines), []
    for k in chosen:
        f = lines[edges[k]].split()
        if f[0] == "EDGE_SE2":
            f[3:6] = [f"{rng.uniform(-20, 20)}", f"{rng.uniform(-20, 20)}", f"{rng.uniform(-3.1, 3.1)}"]
        else:
            q = np.array([rng.gauss(0, 1) for _ in range(4)])
            q /= np.linalg.norm(q)
            f[3:10] = [f"{rng.uniform(-20, 20)}" for _ in range(3)] + [f"{v}" for v in q]
        corrupted[edges[k]] = " ".join(f)
    drop = {edges[k] for k in chosen}
    clean = [l for i, l in enumerate(lines) if i not in drop]
    return "\n".join(corrupted) + "\n", "\n".join(clean) + "\n", chosen, len(loops)


def outliers():
    print()
    print("| graph | loop closures | outliers | rejected | outliers caught | inliers rejected | GNC error | outlier-free optimum | difference |")
    print("|---|---|---|---|---|---|---|---|---|")
    for name in ["2d/M3500.g2o", "3d/sphere2500.g2o"]:
        corrupted, clean, chosen, loops = corrupt(DATA / name, 0.2, 7)
        with tempfile.TemporaryDirectory() as tmp:
            c, k = Path(tmp) / "corrupted.g2o", Path(tmp) / "clean.g2o"
            c.write_text(corrupted)
            k.write_text(clean)
            gnc = sgm_run([c], "gnc")
            ref = sgm_run([k])
        rejected = set(gnc["rejected"])
        caught = len(rejected & set(chosen))
        diff = (gnc["final_error"] - ref["final_error"]) / ref["final_error"]
        print(f"| {name} | {loops} | {len(chosen)} | {len(rejected)} | {caught} ({100 * caught / len(chosen):.1f}%) | {len(rejected - set(chosen))} | {gnc['final_error']:.3f} | {ref['final_error']:.3f} | {100 * diff:+.2f}% |")


if __name__ == "__main__":
    compare()
    if "--outliers" in sys.argv:
        outliers()
