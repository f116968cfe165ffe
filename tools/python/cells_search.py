"""The `--cells N` search, binary against binary: seconds and the counts reached.

    python tools/python/cells_search.py BIN [BIN ...] [--meshes A.ply,B.obj,...] [--counts 700,2000,...]

Each binary runs `cells MESH -o TMP --cells N` for every mesh and count, the binaries
alternating on each case so that the machine's drift falls on all alike. Printed per binary:
the seconds in all, and the cases whose count ended more than 2 % from N (the search then
keeps the nearest try and says so). MESH paths default to the paper's models and the scans'
meshes in `../shared/data/meshes`.
"""

import argparse
import os
import re
import subprocess
import sys
import tempfile
import time

HERE = os.path.dirname(os.path.abspath(__file__))
DATA = os.path.join(HERE, "..", "..", "..", "shared", "data", "meshes")
MESHES = [
    "bun_zipper.ply",
    "dragon_11k_binary.ply",
    "horse.ply",
    "mannequin.ply",
    "dragon_soup_blender.ply",
    "spot.obj",
    "ogre.obj",
    "Wuson.ply",
    "bunny_vn.ply",
    "sofa.ply",
    "cycloidal.ply",
]
COUNTS = [700, 1200, 2000, 3000, 5000, 8000, 20000, 50000]


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("bins", nargs="+")
    ap.add_argument("--meshes", default=",".join(os.path.join(DATA, m) for m in MESHES))
    ap.add_argument("--counts", default=",".join(map(str, COUNTS)))
    a = ap.parse_args()
    meshes = a.meshes.split(",")
    counts = [int(c) for c in a.counts.split(",")]
    seconds = {b: 0.0 for b in a.bins}
    misses = {b: [] for b in a.bins}
    with tempfile.TemporaryDirectory() as tmp:
        out = os.path.join(tmp, "cells.ply")
        for mesh in meshes:
            for n in counts:
                for b in a.bins:
                    t = time.perf_counter()
                    r = subprocess.run(
                        [b, "cells", mesh, "-o", out, "--cells", str(n)],
                        capture_output=True,
                        text=True,
                    )
                    seconds[b] += time.perf_counter() - t
                    if r.returncode != 0:
                        sys.exit(f"{b} on {mesh} at {n}: {r.stderr}")
                    got = re.search(r"-> \S+: (\d+) cells", r.stdout + r.stderr)
                    c = int(got.group(1))
                    if abs(c / n - 1) > 0.02:
                        misses[b].append(f"{os.path.basename(mesh)} {n}: {c}")
    for b in a.bins:
        print(f"{b}: {seconds[b]:.1f} s, {len(misses[b])} of {len(meshes) * len(counts)} "
              f"more than 2 % off")
        for m in misses[b]:
            print(f"    {m}")


if __name__ == "__main__":
    main()
