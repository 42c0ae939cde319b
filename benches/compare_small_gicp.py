"""small_gicp vs `sgm icp`: same clouds, same run, one thread, same downsampling and
correspondence distance; point-to-plane (small_gicp PLANE_ICP) and point-to-point (ICP).

Clouds: the Stanford bunny scans bun0 (target) / bun4 (source), the two Kinect frames, and
three synthetic 20k-point room pairs with known transforms (errors reported against the truth): room A,
the pair the ICP was tuned on, and rooms B and C, held out.
Time: best of 15 (the two tools taking turns) of the whole registration (downsampling, normals, kd-tree, iterations) —
`time_ms` from `sgm icp`, and around `small_gicp.align` in Python. small_gicp reports the
0-based index of its last iteration; SGM reports the count of correspondence passes.

Objective check: small_gicp's PLANE_ICP minimises Σ‖n ∘ (q − p)‖² (element-wise product of the
normal and the residual, plane_icp_factor.hpp), SGM the classic point-to-plane Σ (nᵀ(p − q))².
Where the two tools disagree, a plain numpy / scipy Gauss–Newton of each objective (same
downsampled clouds and normals, from small_gicp's preprocessing; scipy kd-tree correspondences;
iterated to a 1e-10 step) says which objective each answer minimises.
"""
import json
import subprocess
import tempfile
import time
from pathlib import Path

import numpy as np
import small_gicp
from scipy.spatial import cKDTree
from scipy.spatial.transform import Rotation

ROOT = Path(__file__).resolve().parent.parent
CLOUDS = ROOT.parent / "shared" / "data" / "clouds"
SGM = ROOT / "target" / "release" / "sgm"


def read_xyz(path):
    """Finite x, y, z of any PCD (binary_compressed included): `sgm pcd-convert` to ascii."""
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "cloud.pcd"
        subprocess.run([str(SGM), "pcd-convert", str(path), str(out), "--format", "ascii"], check=True)
        rows = out.read_text().splitlines()
    start = next(k for k, l in enumerate(rows) if l.startswith("DATA")) + 1
    pts = np.array([[float(v) for v in r.split()[:3]] for r in rows[start:] if r.strip()])
    return pts[np.isfinite(pts).all(axis=1)]


def write_pcd(path, points):
    with open(path, "w") as f:
        f.write(f"VERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\nWIDTH {len(points)}\nHEIGHT 1\nPOINTS {len(points)}\nDATA ascii\n")
        for p in points:
            f.write(f"{p[0]:.7f} {p[1]:.7f} {p[2]:.7f}\n")


def room(n, seed):
    rng = np.random.default_rng(seed)
    a, b = rng.random(n), rng.random(n)
    k = np.arange(n) % 6
    pts = np.zeros((n, 3))
    pts[k == 0] = np.c_[8 * a, 6 * b, 0 * a][k == 0]
    pts[k == 1] = np.c_[8 * a, 0 * a, 3 * b][k == 1]
    pts[k == 2] = np.c_[0 * a, 6 * a, 3 * b][k == 2]
    pts[k == 3] = np.c_[8 * a, 6 + 0 * a, 3 * b][k == 3]
    pts[k == 4] = np.c_[2 + 1.5 * a, 2 + 0.8 * b, 0.75 + 0 * a][k == 4]
    pts[k == 5] = np.c_[2 + 0 * a, 2 + 0.8 * a, 0.75 * b][k == 5]
    return pts


def errors(T, truth):
    d = np.linalg.inv(truth) @ T
    return np.degrees(np.linalg.norm(Rotation.from_matrix(d[:3, :3]).as_rotvec())), 1e3 * np.linalg.norm(d[:3, 3])


def skew(v):
    return np.array([[0, -v[2], v[1]], [v[2], 0, -v[0]], [-v[1], v[0], 0]])


def exp_se3(d):
    """Exp of (ω, v) with a left perturbation: T ← Exp(δ) T (first-order-exact enough at 1e-10)."""
    T = np.eye(4)
    T[:3, :3] = Rotation.from_rotvec(d[:3]).as_matrix()
    T[:3, 3] = d[3:]
    return T


def reference_solution(target, source, voxel, max_dist, T, elementwise):
    """Gauss–Newton to convergence of one point-to-plane objective, numpy + scipy only."""
    tgt, _ = small_gicp.preprocess_points(target, voxel, num_neighbors=10)
    src, _ = small_gicp.preprocess_points(source, voxel, num_neighbors=10)
    q_all, n_all, s = tgt.points()[:, :3], tgt.normals()[:, :3], src.points()[:, :3]
    tree = cKDTree(q_all)
    for _ in range(200):
        p = s @ T[:3, :3].T + T[:3, 3]
        d, i = tree.query(p, distance_upper_bound=max_dist)
        ok = np.isfinite(d)
        p, q, n = p[ok], q_all[i[ok]], n_all[i[ok]]
        r = p - q
        H, g = np.zeros((6, 6)), np.zeros(6)
        if elementwise:  # residual n ∘ r, Jacobian diag(n) [−p^, I]
            for a in range(3):
                J = np.zeros((len(p), 6))
                J[:, 0:3] = n[:, a:a + 1] * np.cross(p, np.eye(3)[a])  # row a of −p^ = (p × e_a)ᵀ
                J[:, 3 + a] = n[:, a]
                H += J.T @ J
                g += J.T @ (n[:, a] * r[:, a])
        else:  # residual nᵀ r, Jacobian [(p × n)ᵀ, nᵀ]
            J = np.c_[np.cross(p, n), n]
            res = np.einsum("ij,ij->i", n, r)
            H, g = J.T @ J, J.T @ res
        delta = -np.linalg.solve(H, g)
        T = exp_se3(delta) @ T
        if np.linalg.norm(delta) < 1e-10:
            break
    return T


REPEATS = 15


def run_small_gicp(target, source, kind, voxel, max_dist):
    t = time.perf_counter()
    r = small_gicp.align(target, source, registration_type=kind, downsampling_resolution=voxel,
                         max_correspondence_distance=max_dist, num_threads=1)
    ms = (time.perf_counter() - t) * 1e3
    return r.T_target_source, r.converged, r.iterations, ms


def run_sgm(source_path, target_path, method, voxel, max_dist):
    out = subprocess.run([str(SGM), "icp", str(source_path), str(target_path), "--method", method, "--voxel", str(voxel),
                          "--max-distance", str(max_dist), "--rotation-epsilon", str(np.radians(0.1)), "--translation-epsilon", "0.001"],
                         capture_output=True, text=True, check=True)
    r = json.loads(out.stdout)
    return np.array(r["T"]), r["converged"], r["iterations"], r["time_ms"]


def best_of_interleaved(runs):
    """Each tool's fastest of REPEATS runs, the tools taking turns, so that a busy spell of a
    shared machine slows both rather than one."""
    best = [None] * len(runs)
    for _ in range(REPEATS):
        for k, run in enumerate(runs):
            r = run()
            if best[k] is None or r[3] < best[k][3]:
                best[k] = r
    return best


def main():
    tmp = Path(tempfile.mkdtemp())
    # Room A is the pair SGM's ICP was tuned on; B and C are held out: other samples of the room
    # (seeds), other transforms, never looked at while tuning.
    rooms = [("room A 20k+20k", (1, 2), [2.0, -1.5, 5.0], [0.3, -0.2, 0.1]),
             ("room B 20k+20k (held out)", (3, 4), [-1.0, 2.0, -8.0], [-0.4, 0.3, 0.05]),
             ("room C 20k+20k (held out)", (5, 6), [0.5, 0.5, 3.0], [0.2, 0.2, 0.0])]
    cases = []
    for name, (seed_t, seed_s), euler, t in rooms:
        truth = np.eye(4)
        truth[:3, :3] = Rotation.from_euler("xyz", euler, degrees=True).as_matrix()
        truth[:3, 3] = t
        room_target = room(20000, seed_t)
        room_source = (np.linalg.inv(truth) @ np.c_[room(20000, seed_s), np.ones(20000)].T).T[:, :3]
        src_path, tgt_path = tmp / f"room_{seed_s}.pcd", tmp / f"room_{seed_t}.pcd"
        write_pcd(tgt_path, room_target)
        write_pcd(src_path, room_source)
        cases.append((name, src_path, tgt_path, room_source, room_target, 0.1, 1.0, truth))
    cases += [
        ("bunny bun4→bun0", CLOUDS / "bun4.pcd", CLOUDS / "bun0.pcd", None, None, 0.002, 0.05, None),
        ("kinect frames", CLOUDS / "kinect_frame_20121214T142256.068683.pcd", CLOUDS / "kinect_frame_20121214T142255.814212.pcd", None, None, 0.02, 0.1, None),
    ]
    print("| pair | method | voxel m | small_gicp ms | SGM ms | SGM/small_gicp time | small_gicp iters | SGM iters | rotation error ° (sg / SGM) | translation error mm (sg / SGM) | transforms differ by ° / mm |")
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    disagreements = []
    for name, src_path, tgt_path, src, tgt, voxel, max_dist, gt in cases:
        if src is None:
            src, tgt = read_xyz(src_path), read_xyz(tgt_path)
        for kind, method in [("PLANE_ICP", "point-to-plane"), ("ICP", "point-to-point")]:
            (T_sg, conv_sg, it_sg, ms_sg), (T_sgm, conv_sgm, it_sgm, ms_sgm) = best_of_interleaved([
                lambda: run_small_gicp(tgt, src, kind, voxel, max_dist),
                lambda: run_sgm(src_path, tgt_path, method, voxel, max_dist)])
            if gt is not None:
                rs, ts = errors(T_sg, gt)
                rm, tm = errors(T_sgm, gt)
                err = f"{rs:.4f} / {rm:.4f} | {ts:.2f} / {tm:.2f}"
            else:
                err = "– | –"
            dr, dt = errors(T_sgm, T_sg)
            print(f"| {name} | {method} | {voxel} | {ms_sg:.1f} | {ms_sgm:.1f} | {ms_sgm / ms_sg:.2f} | {it_sg} | {it_sgm} | {err} | {dr:.3f} / {dt:.2f} |")
            if method == "point-to-plane" and (dr > 0.05 or dt > 1.0):
                disagreements.append((name, tgt, src, voxel, max_dist, T_sg, T_sgm))
    print("\n| pair | objective | reference − small_gicp ° / mm | reference − SGM ° / mm |")
    print("|---|---|---|---|")
    for name, tgt, src, voxel, max_dist, T_sg, T_sgm in disagreements:
        for elementwise, label in [(False, "classic Σ (nᵀ r)²"), (True, "element-wise Σ ‖n ∘ r‖²")]:
            ref = reference_solution(tgt, src, voxel, max_dist, T_sgm if not elementwise else T_sg, elementwise)
            (a, b), (c, d) = errors(ref, T_sg), errors(ref, T_sgm)
            print(f"| {name} | {label} | {a:.3f} / {b:.2f} | {c:.3f} / {d:.2f} |")


if __name__ == "__main__":
    main()
