"""Edge strain where the fixed and handle regions end: `rigidcells deform` against Open3D's and
libigl's as-rigid-as-possible deformation, on the same vertex sets.

    python tools/python/border_strain.py BIN MESH [--up z] [--fixed 0.2] [--handle 0.55]
        [--degrees 30] [--axis z] [--lift 0] [--lift-axis z] [--cells N ...] [--transfer pu ...] [--options '...'] [--skip-arap] [--out DIR]

MESH is a triangle mesh (PLY or OBJ); BIN the rigidcells binary. The vertices in the lowest
`--fixed` fraction of the model's height (along `--up`) are fixed; those above the `--handle`
fraction turn by `--degrees` about `--axis` (default: the up axis) around their centroid and
move by `--lift` times the model's height along `--lift-axis` (default: the up axis) (a bust with its neck fixed and its head turned; a
dragon bent and lifted). Each method's result is scored by its edges' strain: the ratio of an
edge's deformed length to its rest length, or its inverse when it shrank, so 1.5 means
stretched or shrunk by half. Printed per run: the largest strain, its 99.9th and 99th
percentiles, the edges beyond 1.2 and 1.5, and whether every fixed and handle vertex is exact.

Open3D (`TriangleMesh.deform_as_rigid_as_possible`, its default energy, 10 iterations) and
libigl (`arap_precomputation`/`arap_solve`, its default 10 iterations) take the fixed and
handle vertices as constraints, as rigidcells does.
"""

import argparse
import os
import subprocess
import sys
import tempfile
import time

import numpy as np


def read_mesh(path):
    """Vertices and triangles (Open3D's reader; the vertex order is the file's)."""
    import open3d as o3d

    mesh = o3d.io.read_triangle_mesh(path)
    return np.asarray(mesh.vertices, dtype=np.float64), np.asarray(mesh.triangles)


def edges(f):
    """The mesh's distinct edges, as index pairs."""
    e = np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]])
    e.sort(axis=1)
    return np.unique(e, axis=0)


def strain(v, u, e):
    """Each edge's strain: max(l'/l, l/l')."""
    rest = np.linalg.norm(v[e[:, 0]] - v[e[:, 1]], axis=1)
    now = np.linalg.norm(u[e[:, 0]] - u[e[:, 1]], axis=1)
    keep = (rest > 0) & (now > 0)
    r = now[keep] / rest[keep]
    return np.maximum(r, 1.0 / r)


def turn(points, degrees, up, pivot):
    """`points` turned by `degrees` about the axis `up` through `pivot`."""
    a = np.radians(degrees)
    c, s = np.cos(a), np.sin(a)
    i, j = [k for k in range(3) if k != up]
    rot = np.eye(3)
    rot[i, i], rot[i, j], rot[j, i], rot[j, j] = c, -s, s, c
    return (points - pivot) @ rot.T + pivot


def run_rigidcells(binary, mesh, spec, out, extra):
    if os.path.exists(out):
        os.remove(out)
    start = time.perf_counter()
    subprocess.run(
        [binary, "deform", mesh, "--edit", spec, "-o", out, "-q", *extra],
        check=True,
    )
    seconds = time.perf_counter() - start
    return read_mesh(out)[0], seconds


def run_open3d(v, f, fixed, handle, moved):
    import open3d as o3d

    mesh = o3d.geometry.TriangleMesh(o3d.utility.Vector3dVector(v), o3d.utility.Vector3iVector(f))
    ids = np.concatenate([fixed, handle]).astype(np.int32)
    pos = np.concatenate([v[fixed], moved])
    start = time.perf_counter()
    with o3d.utility.VerbosityContextManager(o3d.utility.VerbosityLevel.Error):
        out = mesh.deform_as_rigid_as_possible(
            o3d.utility.IntVector(ids), o3d.utility.Vector3dVector(pos), max_iter=10
        )
    return np.asarray(out.vertices), time.perf_counter() - start


def run_libigl(v, f, fixed, handle, moved):
    import igl

    b = np.concatenate([fixed, handle]).astype(np.int64)
    bc = np.concatenate([v[fixed], moved])
    start = time.perf_counter()
    data = igl.ARAPData()
    igl.arap_precomputation(v, f.astype(np.int64), 3, b, data)
    u = igl.arap_solve(bc, data, v.copy())
    return np.asarray(u), time.perf_counter() - start


def report(name, v, u, e, fixed, handle, moved, seconds):
    s = strain(v, u, e)
    # PLY writes float32: exact means to a float32's rounding of the coordinates.
    tol = 1e-6 * np.abs(v).max()
    exact = np.array_equal(u[fixed], v[fixed]) and np.allclose(u[handle], moved, atol=tol, rtol=0)
    print(
        f"{name:28s} max {s.max():5.2f}  99.9% {np.percentile(s, 99.9):5.3f}  "
        f"99% {np.percentile(s, 99):5.3f}  >1.2: {int((s > 1.2).sum()):5d}  "
        f">1.5: {int((s > 1.5).sum()):5d}  exact: {'yes' if exact else 'no '}  {seconds:6.2f} s"
    )
    sys.stdout.flush()


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("binary")
    p.add_argument("mesh")
    p.add_argument("--up", default="z", choices="xyz")
    p.add_argument("--fixed", type=float, default=0.2)
    p.add_argument("--handle", type=float, default=0.55)
    p.add_argument("--degrees", type=float, default=30.0)
    p.add_argument("--axis", default=None, choices="xyz", help="the turn's axis (default: --up)")
    p.add_argument("--lift", type=float, default=0.0, help="the handle's rise, times the height")
    p.add_argument("--lift-axis", default=None, choices="xyz")
    p.add_argument("--cells", default="", help="comma-separated --cells values (default: none)")
    p.add_argument("--transfer", default="pu", help="comma-separated transfers")
    p.add_argument("--options", default="", help="more `deform` options, as one string")
    p.add_argument("--skip-arap", action="store_true")
    p.add_argument("--out", default=None, help="keep the results in this folder")
    a = p.parse_args()

    up = "xyz".index(a.up)
    v, f = read_mesh(a.mesh)
    e = edges(f)
    lo, hi = v[:, up].min(), v[:, up].max()
    zf, zh = lo + a.fixed * (hi - lo), lo + a.handle * (hi - lo)
    fixed = np.flatnonzero(v[:, up] <= zf)
    handle = np.flatnonzero(v[:, up] >= zh)
    pivot = v[handle].mean(axis=0)
    about = "xyz".index(a.axis or a.up)
    lift = np.zeros(3)
    lift["xyz".index(a.lift_axis or a.up)] = a.lift * (hi - lo)
    moved = turn(v[handle], a.degrees, about, pivot) + lift
    print(
        f"{os.path.basename(a.mesh)}: {len(v)} vertices, {len(e)} edges; {len(fixed)} fixed, "
        f"{len(handle)} turned by {a.degrees:g}° about {a.axis or a.up}, lifted {a.lift:g}"
    )

    folder = a.out or tempfile.mkdtemp()
    spec = os.path.join(folder, "edit.toml")
    big = 1e9
    box = lambda z0, z1: (  # noqa: E731
        "{ min = [" + ", ".join(str(z0 if k == up else -big) for k in range(3)) + "], max = ["
        + ", ".join(str(z1 if k == up else big) for k in range(3)) + "] }"
    )
    axis = [0, 0, 0]
    axis[about] = 1
    with open(spec, "w") as s:
        s.write(f"[[fixed]]\nbox = {box(-big, repr(float(zf)))}\n")
        s.write(f"[[handle]]\nbox = {box(repr(float(zh)), big)}\n")
        s.write(f"rotate = {{ axis = {axis}, degrees = {a.degrees} }}\n")
        s.write(f"pivot = {pivot.tolist()}\n")
        s.write(f"translate = {lift.tolist()}\n")
    cells = [c for c in a.cells.split(",") if c] or [None]
    for transfer in a.transfer.split(","):
        for c in cells:
            extra = ["--transfer", transfer] + (["--cells", c] if c else []) + a.options.split()
            out = os.path.join(folder, f"rigidcells_{transfer}_{c or 'default'}.ply")
            u, secs = run_rigidcells(a.binary, a.mesh, spec, out, extra)
            name = f"rigidcells {transfer}" + (f" {c} cells" if c else "") + (f" {a.options}" if a.options else "")
            report(name, v, u, e, fixed, handle, moved, secs)
    if not a.skip_arap:
        u, secs = run_open3d(v, f, fixed, handle, moved)
        report("Open3D ARAP", v, u, e, fixed, handle, moved, secs)
        u, secs = run_libigl(v, f, fixed, handle, moved)
        report("libigl ARAP", v, u, e, fixed, handle, moved, secs)


if __name__ == "__main__":
    main()
