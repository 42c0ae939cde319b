#!/usr/bin/env python3
"""Which pairs of robots of a run share ground, and whether they aligned.

Usage: python3 benches/shared_ground.py RUN_DIR [--within M] [--quiet]

Two robots share ground when their true keyframe positions (`NAME.truth.tum`, the world
frame) come within M metres of each other (default 10, the sweeps' overlap radius), at any
times; the first time that happens (the later of the two stamps) is when they could first
have met. Reads `report.json`'s alignments for each direction and prints one row per pair
that shares ground, and a summary: how many directions share ground, how many of those
aligned, and how many directions aligned without sharing ground (by relaying). Standard
library only; exit status 1 when the run directory cannot be read.
"""

import json
import math
import sys
from pathlib import Path


def truth(path):
    rows = []
    for n, line in enumerate(path.read_text().splitlines(), 1):
        fields = line.split()
        if not fields or fields[0].startswith("#"):
            continue
        if len(fields) != 8:
            raise ValueError(f"{path}:{n}: {len(fields)} fields, a TUM line has 8")
        t, x, y, z = (float(v) for v in fields[:4])
        rows.append((t, x, y, z))
    return rows


def first_meeting(a, b, within):
    """The earliest time both robots had been within `within` m of a place the other saw
    (the later of the two stamps of the closest-in-time such pair); None if never."""
    cell = within
    grid = {}
    for t, x, y, z in b:
        grid.setdefault((math.floor(x / cell), math.floor(y / cell)), []).append((t, x, y, z))
    best = None
    for ta, xa, ya, za in a:
        cx, cy = math.floor(xa / cell), math.floor(ya / cell)
        for dx in (-1, 0, 1):
            for dy in (-1, 0, 1):
                for tb, xb, yb, zb in grid.get((cx + dx, cy + dy), ()):
                    if math.dist((xa, ya, za), (xb, yb, zb)) <= within:
                        when = max(ta, tb)
                        if best is None or when < best:
                            best = when
    return best


def main(argv):
    args = [a for a in argv if not a.startswith("--")]
    within = 10.0
    if "--within" in argv:
        at = argv.index("--within") + 1
        try:
            within = float(argv[at])
        except (IndexError, ValueError):
            print("shared_ground: --within needs a distance in metres, e.g. --within 10", file=sys.stderr)
            return 2
        if not (math.isfinite(within) and within > 0):
            print(f"shared_ground: --within {argv[at]}: the distance must be positive", file=sys.stderr)
            return 2
        args.remove(argv[at])
    if len(args) != 1:
        print(__doc__, file=sys.stderr)
        return 2
    run = Path(args[0])
    try:
        report = json.loads((run / "report.json").read_text())
        names = [r["name"] for r in report["robots"]]
        tracks = {n: truth(run / f"{n}.truth.tum") for n in names}
    except (OSError, ValueError, KeyError) as e:
        print(f"shared_ground: {run}: {e}", file=sys.stderr)
        return 1
    states = {(a["local"], a["remote"]): a for a in report["alignments"]}
    shared, aligned_shared, aligned_other = 0, 0, 0
    quiet = "--quiet" in argv
    if not quiet:
        print(f"| pair | first within {within:g} m (s) | local <- remote | state | first aligned (s) | error (m) |")
        print("|---|---|---|---|---|---|")
    for i, a in enumerate(names):
        for b in names[i + 1:]:
            met = first_meeting(tracks[a], tracks[b], within)
            for local, remote in ((a, b), (b, a)):
                s = states.get((local, remote), {})
                aligned = s.get("state") == "Aligned"
                if met is None:
                    aligned_other += aligned
                    continue
                shared += 1
                aligned_shared += aligned
                if not quiet:
                    err = s.get("translation_error_m")
                    first = s.get("first_aligned_s")
                    print(
                        f"| {a}-{b} | {met:.1f} | {local} <- {remote} | {s.get('state', '-')} | "
                        f"{'-' if first is None else f'{first:.1f}'} | {'-' if err is None else f'{err:.2f}'} |"
                    )
    print(
        f"{shared} directions share ground (within {within:g} m), {aligned_shared} of them aligned; "
        f"{aligned_other} directions aligned without sharing ground"
    )
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
