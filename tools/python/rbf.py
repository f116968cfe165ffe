"""The tube bend's RBF transfer by SciPy and by `rigidcells deform --transfer rbf`, in one run,
whole process each.

    python tools/python/rbf.py TUBE.ply BIN [--runs N]

TUBE.ply is the 480k-vertex tube (`cargo run --release -p data_gen --bin gen -- tube TUBE.ply`);
BIN the rigidcells binary. rigidcells runs the whole deform of `tools/python/arap.py`'s bend
(read, cells, solve, the triharmonic RBF transfer, write). SciPy gets the same cells, those of a
`--save-field` of that deform made once beforehand and not timed, and runs the same transfer
(read the mesh and the cells, fit `scipy.interpolate.RBFInterpolator` with the cubic kernel and
a linear polynomial to the cells' center displacements, evaluate it at every vertex, write the
mesh): SciPy's time has no solve in it. Prints the seconds of each and their ratio per run, the
best of each, and how far SciPy's vertices are from ours two cells or more away from the fixed
and handle boxes (there both interpolate the same function; in the boxes' cells ours follow
the edit's maps exactly).
"""

import os
import sys
import tempfile
import time

import numpy as np

sys.path.insert(0, os.path.dirname(__file__))
from arap import arguments, rigidcells, write_edit  # noqa: E402

RBF = ["--transfer", "rbf"]

HEADER = "end_header\n".encode()


def read_ply(path):
    """The header bytes, the vertices (n × 3 float32) and the bytes after them, of a binary
    little-endian PLY whose vertices are three floats (the tube's)."""
    data = open(path, "rb").read()
    end = data.index(HEADER) + len(HEADER)
    header = data[:end].decode()
    n = int(header.split("element vertex ")[1].split()[0])
    assert "property float x\nproperty float y\nproperty float z\nelement face" in header
    vertices = np.frombuffer(data, dtype="<f4", count=3 * n, offset=end).reshape(n, 3)
    return data[:end], vertices, data[end + 12 * n:]


def read_cells(path):
    """The cell centers and their displacements (world coordinates) of a saved 3D field."""
    data = open(path, "rb").read()
    assert data[:8] == b"RCFIELD\0" and np.frombuffer(data, "<u4", 1, 12)[0] in (3, 4)
    origin = np.frombuffer(data, "<f8", 3, 17)
    n = int(np.frombuffer(data, "<u8", 1, 41)[0])
    cells = np.frombuffer(data, "<f8", 16 * n, 49).reshape(n, 16)
    centers, positions = cells[:, 0:3], cells[:, 13:16]
    return centers + origin, positions - centers


def scipy_rbf(tube, field, out):
    """SciPy's RBF transfer of the tube to `out`: seconds in all."""
    from scipy.interpolate import RBFInterpolator

    start = time.perf_counter()
    header, vertices, faces = read_ply(tube)
    centers, displacements = read_cells(field)
    rbf = RBFInterpolator(centers, displacements, kernel="cubic", degree=1)
    moved = (vertices + rbf(vertices.astype(np.float64))).astype("<f4")
    with open(out, "wb") as ply:
        ply.write(header)
        ply.write(moved.tobytes())
        ply.write(faces)
    return time.perf_counter() - start


def main():
    args = arguments(__doc__, extra=False)
    with tempfile.TemporaryDirectory() as folder:
        edit = write_edit(folder)
        field = os.path.join(folder, "bend.field")
        ours_out, theirs_out = os.path.join(folder, "ours.ply"), os.path.join(folder, "scipy.ply")
        rigidcells(args.binary, args.tube, edit, ours_out, [*RBF, "--save-field", field])
        best = [float("inf"), float("inf")]
        for run in range(args.runs):
            ours = rigidcells(args.binary, args.tube, edit, ours_out, RBF)
            theirs = scipy_rbf(args.tube, field, theirs_out)
            best = [min(best[0], ours), min(best[1], theirs)]
            print(f"run {run + 1}: rigidcells {ours:.2f} s, SciPy RBF {theirs:.2f} s, "
                  f"{theirs / ours:.1f}x")
        print(f"best: rigidcells {best[0]:.2f} s, SciPy RBF {best[1]:.2f} s, "
              f"{best[1] / best[0]:.1f}x")
        _, rest, _ = read_ply(args.tube)
        _, a, _ = read_ply(ours_out)
        _, b, _ = read_ply(theirs_out)
        x, margin = rest[:, 0], 0.35  # two cells of `--cells 5500` (0.166)
        free = ~((np.abs(x) <= 1 + margin) | ((x >= 9 - margin) & (x <= 11 + margin)))
        gap = np.linalg.norm(a[free].astype(np.float64) - b[free], axis=1)
        print(f"SciPy's vertices from ours away from the boxes: largest {gap.max():.1e}, "
              f"median {np.median(gap):.1e} (the tube is 20 long)")


if __name__ == "__main__":
    sys.exit(main())
