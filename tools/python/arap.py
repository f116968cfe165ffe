"""The tube bend by libigl's as-rigid-as-possible deformation and by `rigidcells deform`, in one
run, whole process each: read, solve, write.

    python tools/python/arap.py TUBE.ply BIN [--runs N] [-- EXTRA DEFORM FLAGS]

TUBE.ply is the 480k-vertex tube (`cargo run --release -p data_gen --bin gen -- tube TUBE.ply`);
BIN the rigidcells binary. Both take the same edit: the vertices with x in [-1, 1] fixed, those
with x in [9, 11] turned by -90 degrees about y around their centroid and moved by (-3, 0, 5)
(`tools/src/bin/solver.rs`'s tube scene). libigl's ARAP (the `libigl` package from PyPI) runs its
default 10 local-global iterations, with the handle's vertices at their destinations. Prints the
seconds of each and their ratio, per run, and the best of each.
"""

import argparse
import os
import subprocess
import sys
import tempfile
import time

import numpy as np

EDIT = """[[fixed]]
box = { min = [-1, -2, -2], max = [1.0, 2, 2] }
[[handle]]
box = { min = [9.0, -2, -2], max = [11, 2, 2] }
rotate = { axis = [0, 1, 0], degrees = -90 }
translate = [-3, 0, 5]
"""


def libigl(tube, out):
    """libigl's ARAP of the tube to `out`: seconds in all."""
    import igl

    start = time.perf_counter()
    v, f = igl.read_triangle_mesh(tube)
    fixed = np.flatnonzero((v[:, 0] >= -1) & (v[:, 0] <= 1))
    handle = np.flatnonzero((v[:, 0] >= 9) & (v[:, 0] <= 11))
    turn = np.radians(-90.0)
    c, s = np.cos(turn), np.sin(turn)
    rotation = np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])
    pivot = v[handle].mean(axis=0)
    moved = (v[handle] - pivot) @ rotation.T + pivot + np.array([-3.0, 0.0, 5.0])
    b = np.concatenate([fixed, handle]).astype(np.int32)
    bc = np.concatenate([v[fixed], moved])
    data = igl.ARAPData()
    igl.arap_precomputation(v, f.astype(np.int64), 3, b, data)
    u = igl.arap_solve(bc, data, v.copy())
    igl.write_triangle_mesh(out, u, f)
    return time.perf_counter() - start


def rigidcells(binary, tube, edit, out, extra):
    """`rigidcells deform` of the tube to `out`: seconds in all."""
    start = time.perf_counter()
    subprocess.run(
        [binary, "deform", tube, "--edit", edit, "-o", out, "--cells", "5500", "-q", *extra],
        check=True,
    )
    return time.perf_counter() - start


def arguments(doc, extra):
    """The command line of a tube benchmark: the tube, the binary, `--runs` and, with `extra`,
    more flags for `rigidcells deform`."""
    parser = argparse.ArgumentParser(description=doc.split("\n\n")[0])
    parser.add_argument("tube")
    parser.add_argument("binary")
    parser.add_argument("--runs", type=int, default=3)
    if extra:
        parser.add_argument("extra", nargs="*", help="more flags for rigidcells deform")
    return parser.parse_args()


def write_edit(folder):
    """The bend's edit spec, written in `folder`: its path."""
    edit = os.path.join(folder, "bend.toml")
    with open(edit, "w") as spec:
        spec.write(EDIT)
    return edit


def main():
    args = arguments(__doc__, extra=True)
    with tempfile.TemporaryDirectory() as folder:
        edit = write_edit(folder)
        best = [float("inf"), float("inf")]
        for run in range(args.runs):
            ours = rigidcells(
                args.binary, args.tube, edit, os.path.join(folder, "ours.ply"), args.extra
            )
            theirs = libigl(args.tube, os.path.join(folder, "igl.ply"))
            best = [min(best[0], ours), min(best[1], theirs)]
            print(f"run {run + 1}: rigidcells {ours:.2f} s, libigl ARAP {theirs:.2f} s, "
                  f"{theirs / ours:.1f}x")
        print(f"best: rigidcells {best[0]:.2f} s, libigl ARAP {best[1]:.2f} s, "
              f"{best[1] / best[0]:.1f}x")


if __name__ == "__main__":
    sys.exit(main())
