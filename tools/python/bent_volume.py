"""What a bend keeps of a solid: a closed cylinder bent by 90°, by rigidcells and by libigl's ARAP.

    python tools/python/bent_volume.py BIN [--stiffness 1,0.05,...] [--arap-iterations 10,100]

The cylinder is 10 long with radius 1 along x: 64 vertices a ring, 201 rings, and a center on
each cap. Its first unit is fixed and its last turned by -90° about y around its centroid and
moved by (-3, 0, 5) (the tube's bend). For rigidcells at each interior stiffness and for
libigl's `arap_solve` on the surface with the same vertices fixed and moved, it prints the
volume kept (the divergence theorem over the triangles) and the radius of the middle ring
about the ring's center, smallest to largest. Needs numpy, and libigl for ARAP.
"""

import argparse
import os
import subprocess
import tempfile

import numpy as np

RINGS, AROUND, RADIUS, LENGTH = 201, 64, 1.0, 10.0
SPEC = """[[fixed]]
box = { min = [-1, -2, -2], max = [1.0, 2, 2] }
[[handle]]
box = { min = [9.0, -2, -2], max = [11, 2, 2] }
rotate = { axis = [0, 1, 0], degrees = -90 }
translate = [-3, 0, 5]
"""


def cylinder():
    """The vertices and outward triangles of the closed cylinder."""
    a = 2 * np.pi * np.arange(AROUND) / AROUND
    x = np.repeat(np.linspace(0, LENGTH, RINGS), AROUND)
    ring = np.stack([np.cos(a), np.sin(a)], 1) * RADIUS
    v = np.column_stack([x, np.tile(ring, (RINGS, 1))])
    v = np.vstack([v, [[0, 0, 0], [LENGTH, 0, 0]]])
    f = []
    for r in range(RINGS - 1):
        for k in range(AROUND):
            i, j = r * AROUND + k, r * AROUND + (k + 1) % AROUND
            f += [[i, j, j + AROUND], [i, j + AROUND, i + AROUND]]
    c0, c1, last = RINGS * AROUND, RINGS * AROUND + 1, (RINGS - 1) * AROUND
    for k in range(AROUND):
        f += [[c0, (k + 1) % AROUND, k], [c1, last + k, last + (k + 1) % AROUND]]
    return v, np.array(f)


def volume(v, f):
    return np.einsum("ij,ij->i", v[f[:, 0]], np.cross(v[f[:, 1]], v[f[:, 2]])).sum() / 6


def middle_ring(u):
    m = u[(RINGS // 2) * AROUND : (RINGS // 2 + 1) * AROUND]
    r = np.linalg.norm(m - m.mean(0), axis=1)
    return r.min(), r.max()


def write_ply(path, v, f):
    with open(path, "w") as out:
        out.write(
            f"ply\nformat ascii 1.0\nelement vertex {len(v)}\nproperty double x\n"
            f"property double y\nproperty double z\nelement face {len(f)}\n"
            "property list uchar int vertex_indices\nend_header\n"
        )
        out.writelines(" ".join(repr(float(c)) for c in p) + "\n" for p in v)
        out.writelines(f"3 {t[0]} {t[1]} {t[2]}\n" for t in f)


def read_ascii_ply(path, n):
    with open(path) as src:
        while src.readline().strip() != "end_header":
            pass
        return np.array([[float(w) for w in src.readline().split()[:3]] for _ in range(n)])


def main():
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("binary")
    p.add_argument("--stiffness", default="1,0.3,0.1,0.05,0.03", help="interior stiffnesses")
    p.add_argument("--arap-iterations", default="10,100", help="libigl's iterations ('' for none)")
    args = p.parse_args()
    v, f = cylinder()
    rest = volume(v, f)
    fixed = np.where(v[:, 0] <= 1.0)[0]
    handle = np.where(v[:, 0] >= 9.0)[0]
    pivot = v[handle].mean(0)
    c, s = np.cos(np.radians(-90)), np.sin(np.radians(-90))
    turn = np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])
    moved = (v[handle] - pivot) @ turn.T + pivot + np.array([-3.0, 0, 5])

    def show(name, u):
        lo, hi = middle_ring(u)
        print(f"{name:34s} volume kept {volume(u, f) / rest:.3f}  middle ring {lo:.3f}-{hi:.3f}")

    with tempfile.TemporaryDirectory() as tmp:
        mesh, spec = os.path.join(tmp, "cylinder.ply"), os.path.join(tmp, "bend.toml")
        write_ply(mesh, v, f)
        with open(spec, "w") as out:
            out.write(SPEC)
        for k, stiffness in enumerate(filter(None, args.stiffness.split(","))):
            out = os.path.join(tmp, f"out{k}.ply")
            subprocess.run(
                [args.binary, "deform", mesh, "--edit", spec, "-o", out, "-q",
                 "--interior-stiffness", stiffness],
                check=True,
            )
            show(f"rigidcells, interior {stiffness}", read_ascii_ply(out, len(v)))
    for iterations in filter(None, args.arap_iterations.split(",")):
        import igl

        b = np.concatenate([fixed, handle]).astype(np.int64)
        data = igl.ARAPData()
        data.max_iter = int(iterations)
        igl.arap_precomputation(v, f.astype(np.int64), 3, b, data)
        u = igl.arap_solve(np.concatenate([v[fixed], moved]), data, v.copy())
        show(f"libigl ARAP, {iterations} iterations", np.asarray(u))


if __name__ == "__main__":
    main()
