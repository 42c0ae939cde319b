"""KISS-ICP vs SGM's LiDAR-inertial front end: the same sweeps, in the same run.

`sgm bench odometry --bag-out DIR` runs our front end on each scenario's first robot (10 Hz
sweeps with per-point time, 200 Hz IMU) and writes those sweeps as a ROS 1 bag, with our
estimate and the truth as TUM files. KISS-ICP then runs on each bag through its own rosbag
dataloader (`kiss_icp.datasets.rosbag.RosbagDataset`) and its own pipeline class
(`kiss_icp.kiss_icp.KissICP`, default configuration: deskewing on, voxel size from the 100 m
maximum range, adaptive threshold), on one thread (`registration.max_num_threads = 1`); only
`register_frame` is timed, as only the estimator is timed on our side.

Both trajectories are scored on the same frames (those our front end took: it waits for a
second of IMU samples to level itself) against the truth at those frames:
- KITTI's relative drift (`kiss_icp.metrics.sequence_error`: segments of 100–800 m, the KITTI
  devkit's), where the path is long enough for a segment;
- the end error: the translation error of the last frame relative to the first
  (‖(T_gt,0⁻¹ T_gt,N)⁻¹ (T_0⁻¹ T_N)‖), as a % of the path length.

Usage: benches/compare_kiss_icp.sh [--duration S] [--only NAME] [--out DIR]
"""
import argparse
import json
import subprocess
import time
from pathlib import Path

import numpy as np
from kiss_icp.config import load_config
from kiss_icp.datasets.rosbag import RosbagDataset
from kiss_icp.kiss_icp import KissICP
from kiss_icp.metrics import sequence_error
from scipy.spatial.transform import Rotation

ROOT = Path(__file__).resolve().parent.parent
SGM = ROOT / "target" / "release" / "sgm"


def read_tum(path):
    """{stamp: 4×4 pose} from a TUM file (stamps rounded to the microsecond)."""
    poses = {}
    for line in Path(path).read_text().splitlines():
        v = [float(x) for x in line.split()]
        if len(v) != 8:
            continue
        pose = np.eye(4)
        pose[:3, :3] = Rotation.from_quat(v[4:8]).as_matrix()
        pose[:3, 3] = v[1:4]
        poses[round(v[0], 6)] = pose
    return poses


def kiss_icp_on(bag, topic):
    """KISS-ICP's poses, one per cloud in the bag, and its time per frame (s)."""
    config = load_config(None)
    config.registration.max_num_threads = 1
    dataset = RosbagDataset(bag, topic)
    odometry = KissICP(config)
    poses, spent = [], 0.0
    for k in range(len(dataset)):
        points, timestamps = dataset[k]
        started = time.perf_counter()
        odometry.register_frame(points, timestamps)
        spent += time.perf_counter() - started
        poses.append(odometry.last_pose.copy())
    return poses, spent / max(len(poses), 1)


def path_length(poses):
    return float(sum(np.linalg.norm(b[:3, 3] - a[:3, 3]) for a, b in zip(poses, poses[1:])))


def end_error_pct(truth, estimate):
    gt = np.linalg.inv(truth[0]) @ truth[-1]
    est = np.linalg.inv(estimate[0]) @ estimate[-1]
    error = np.linalg.inv(gt) @ est
    return 100.0 * float(np.linalg.norm(error[:3, 3])) / max(path_length(truth), 1e-9)


def score(truth, estimate):
    length = path_length(truth)
    drift = None
    if length >= 100.0:
        translation, rotation = sequence_error(np.array(truth), np.array(estimate))
        drift = (float(translation), float(rotation))
    return {"path_m": length, "drift": drift, "end_error_pct": end_error_pct(truth, estimate)}


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--duration", type=float)
    parser.add_argument("--only")
    parser.add_argument("--out", type=Path, default=ROOT / "target" / "kiss-icp")
    args = parser.parse_args()
    bags = args.out / "bags"
    command = [str(SGM), "bench", "odometry", "--bag-out", str(bags), "--json", str(args.out / "ours.json")]
    if args.duration:
        command += ["--duration", str(args.duration)]
    if args.only:
        command += ["--only", args.only]
    subprocess.run(command, check=True, stdout=subprocess.DEVNULL)
    ours_rows = json.loads((args.out / "ours.json").read_text())
    ours_rows = ours_rows.get("rows", ours_rows) if isinstance(ours_rows, dict) else ours_rows
    rows = []
    for row in ours_rows:
        scenario, robot = row["scenario"], row["robot"]
        folder = bags / scenario
        truth_by_stamp = read_tum(folder / f"{robot}.truth.tum")
        ours_by_stamp = read_tum(folder / f"{robot}.ours.tum")
        stamps = sorted(truth_by_stamp)
        kiss_poses, kiss_s = kiss_icp_on(folder / f"{robot}.bag", f"/{robot}/points")
        if len(kiss_poses) != len(stamps):
            raise SystemExit(f"{scenario}: {len(kiss_poses)} clouds in the bag, {len(stamps)} truth poses")
        kiss_by_stamp = dict(zip(stamps, kiss_poses))
        common = [s for s in stamps if s in ours_by_stamp]
        truth = [truth_by_stamp[s] for s in common]
        rows.append(
            {
                "scenario": scenario,
                "frames": len(common),
                "ours": score(truth, [ours_by_stamp[s] for s in common]),
                "kiss_icp": score(truth, [kiss_by_stamp[s] for s in common]),
                "ours_ms": row["ms_per_frame"],
                "kiss_icp_ms": kiss_s * 1e3,
            }
        )
    (args.out / "compare.json").write_text(json.dumps(rows, indent=2))
    print("| scenario | path m | drift % ours | drift % KISS-ICP | ours ÷ KISS-ICP | end error % ours | end error % KISS-ICP | ms/frame ours | ms/frame KISS-ICP |")
    print("|---|---|---|---|---|---|---|---|---|")
    for r in rows:
        o, k = r["ours"], r["kiss_icp"]
        drift = lambda s: f"{s['drift'][0]:.3f}" if s["drift"] else "–"
        ratio = f"{o['drift'][0] / k['drift'][0]:.2f}" if o["drift"] and k["drift"] and k["drift"][0] > 0 else "–"
        print(
            f"| {r['scenario']} | {o['path_m']:.0f} | {drift(o)} | {drift(k)} | {ratio} | "
            f"{o['end_error_pct']:.3f} | {k['end_error_pct']:.3f} | {r['ours_ms']:.1f} | {r['kiss_icp_ms']:.1f} |"
        )


if __name__ == "__main__":
    main()
