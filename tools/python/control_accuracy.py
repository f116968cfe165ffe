"""Control points scored at checkpoints: `rigidcells deform` against a least-squares affine fit
and a thin-plate spline on the same points, as a surveyor would compare them.

    python tools/python/control_accuracy.py BIN SCAN.las [--points 12] [--checks 40]
        [--weight 10] [--seed 1] [--trend none,affine,spline] [--cells N]

SCAN is a LAS file (`cargo run --release -p data_gen --bin gen -- vegetation 300000 SCAN.las`
makes a forest scan). Each scene moves the scan by a known field and gives `--points` of its
samples, spread over it, as control points (their rest and moved coordinates); `--checks`
other samples, away from the control points, are the checkpoints, scored by where each method
puts them against where the field does:

- **smooth**: a shift, a bilinear trend (0.1–0.25 m across the scan) and one bump of 0.25 m;
- **local**: the bump alone, with the control points around it holding the rest still;
- **affine**: a shift, a scale, a shear and a tilt (0.1–0.3 m across the scan) with the bump at
  a third of its height.

Each scene runs with 3D control points (`id,x,y,z,X,Y,Z`) and with 2D ones (`id,x,y,X,Y`,
the field's horizontal part; scored horizontally, with the largest height change of any
sample). rigidcells runs once per `--trend`; the affine fit is by least squares (for 2D
points, of x and y), the thin-plate spline is SciPy's `RBFInterpolator` (`thin_plate_spline`,
with its affine part). Printed: RMSE at the checkpoints per method, and the ratio of
rigidcells' to the better of the two peers.
"""

import argparse
import os
import subprocess
import tempfile

import laspy
import numpy as np


def field(scene, xyz, lo, hi):
    """The displacement the scene applies at `xyz` (n × 3)."""
    u = (xyz[:, 0] - lo[0]) / (hi[0] - lo[0])
    v = (xyz[:, 1] - lo[1]) / (hi[1] - lo[1])
    middle = lo[:2] + (hi[:2] - lo[:2]) * np.array([0.62, 0.45])
    radius = 0.12 * (hi[0] - lo[0])
    bump = np.exp(-np.sum((xyz[:, :2] - middle) ** 2, axis=1) / (2 * radius**2))
    d = np.zeros_like(xyz)
    d[:, 0] = 0.25 * bump
    d[:, 1] = -0.15 * bump
    d[:, 2] = 0.2 * bump
    if scene == "affine":
        d *= 0.3
        x, y = xyz[:, 0] - lo[0], xyz[:, 1] - lo[1]
        d[:, 0] += 0.4 + 2e-4 * x - 1.5e-4 * y
        d[:, 1] += -0.3 + 1e-4 * x + 2.5e-4 * y
        d[:, 2] += 0.05 + 1e-4 * x
    if scene == "smooth":
        d[:, 0] += 0.3 + 0.2 * u - 0.15 * v + 0.25 * u * v
        d[:, 1] += -0.2 + 0.1 * u + 0.2 * v - 0.2 * u * v
        d[:, 2] += 0.1 + 0.15 * u - 0.1 * v
    return d


def spread(xyz, lo, hi, count, rng):
    """Indices of `count` samples spread over the scan: the nearest to each node of a jittered
    grid."""
    cols = int(np.ceil(np.sqrt(count * (hi[0] - lo[0]) / (hi[1] - lo[1]))))
    rows = int(np.ceil(count / cols))
    chosen = []
    for k in range(count):
        cell = np.array([(k % cols + 0.5 + rng.uniform(-0.3, 0.3)) / cols,
                         (k // cols + 0.5 + rng.uniform(-0.3, 0.3)) / rows])
        want = lo[:2] + cell * (hi[:2] - lo[:2])
        chosen.append(int(np.argmin(np.sum((xyz[:, :2] - want) ** 2, axis=1))))
    return np.array(chosen)


def away(xyz, count, rng, control, gap):
    """Indices of `count` random samples each farther than `gap` from every control point."""
    chosen = []
    while len(chosen) < count:
        i = int(rng.integers(len(xyz)))
        if np.min(np.linalg.norm(xyz[control, :2] - xyz[i, :2], axis=1)) > gap:
            chosen.append(i)
    return np.array(chosen)


def affine_fit(src, dst):
    """Least-squares affine map src → dst (columns of dst fitted independently)."""
    a = np.hstack([src, np.ones((len(src), 1))])
    coef, *_ = np.linalg.lstsq(a, dst, rcond=None)
    return lambda p: np.hstack([p, np.ones((len(p), 1))]) @ coef


def tps_fit(src, dst):
    from scipy.interpolate import RBFInterpolator

    center = src.mean(axis=0)
    rbf = RBFInterpolator(src - center, dst - src, kernel="thin_plate_spline", degree=1)
    return lambda p: p + rbf(p - center)


def run_rigidcells(binary, scan, folder, rows, header, trend, weight, cells):
    csv = os.path.join(folder, "gcp.csv")
    with open(csv, "w") as f:
        f.write(header + "\n" + "\n".join(rows) + "\n")
    edit = os.path.join(folder, "edit.toml")
    with open(edit, "w") as f:
        f.write(f'trend = "{trend}"\n[[target]]\nfile = "gcp.csv"\nweight = {weight}\n')
    out = os.path.join(folder, "out.las")
    if os.path.exists(out):
        os.remove(out)
    extra = ["--cells", str(cells)] if cells else []
    subprocess.run([binary, "deform", scan, "--edit", edit, "-o", out, "-q", *extra], check=True)
    moved = laspy.read(out)
    return np.column_stack([moved.x, moved.y, moved.z])


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("binary")
    p.add_argument("scan")
    p.add_argument("--points", type=int, default=12)
    p.add_argument("--checks", type=int, default=40)
    p.add_argument("--weight", type=float, default=10.0)
    p.add_argument("--seed", type=int, default=1)
    p.add_argument("--trend", default="none,affine,spline")
    p.add_argument("--cells", type=int, default=0)
    a = p.parse_args()

    las = laspy.read(a.scan)
    xyz = np.column_stack([las.x, las.y, las.z])
    lo, hi = xyz.min(axis=0), xyz.max(axis=0)
    rng = np.random.default_rng(a.seed)
    control = spread(xyz, lo, hi, a.points, rng)
    gap = 0.25 * np.sqrt((hi[0] - lo[0]) * (hi[1] - lo[1]) / a.points)
    checks = away(xyz, a.checks, rng, control, gap)
    folder = tempfile.mkdtemp()
    print(f"{os.path.basename(a.scan)}: {len(xyz)} samples; {len(control)} control points, "
          f"{len(checks)} checkpoints (at least {gap:.0f} m from a control point)")
    for scene in ["smooth", "local", "affine"]:
        for dims in ["3D", "2D"]:
            src, chk = xyz[control], xyz[checks]
            dst = src + field(scene, src, lo, hi)
            want = chk + field(scene, chk, lo, hi)
            flat = dims == "2D"
            axes = slice(0, 2) if flat else slice(0, 3)

            def score(got):
                return float(np.sqrt(np.mean(np.sum((got[:, axes] - want[:, axes]) ** 2, axis=1))))

            results = {}
            if flat:
                aff = affine_fit(src[:, :2], dst[:, :2])
                results["affine"] = score(np.column_stack([aff(chk[:, :2]), chk[:, 2]]))
                tps = tps_fit(src[:, :2], dst[:, :2])
                results["thin-plate spline"] = score(np.column_stack([tps(chk[:, :2]), chk[:, 2]]))
                rows = [f"P{i},{s[0]:.3f},{s[1]:.3f},{d[0]:.4f},{d[1]:.4f}" for i, (s, d) in enumerate(zip(src, dst))]
                header = "id,x,y,X,Y"
            else:
                results["affine"] = score(affine_fit(src, dst)(chk))
                results["thin-plate spline"] = score(tps_fit(src, dst)(chk))
                rows = [f"P{i},{s[0]:.3f},{s[1]:.3f},{s[2]:.3f},{d[0]:.4f},{d[1]:.4f},{d[2]:.4f}"
                        for i, (s, d) in enumerate(zip(src, dst))]
                header = "id,x,y,z,X,Y,Z"
            heights = {}
            for trend in a.trend.split(","):
                out = run_rigidcells(a.binary, a.scan, folder, rows, header, trend, a.weight, a.cells)
                name = f"rigidcells, trend {trend}"
                results[name] = score(out[checks])
                heights[name] = float(np.max(np.abs(out[:, 2] - xyz[:, 2])))
            best_peer = min(results["affine"], results["thin-plate spline"])
            print(f"\n{scene}, {dims} points (RMSE at the checkpoints, m; "
                  f"{'horizontal' if flat else '3D'})")
            for name, value in results.items():
                ratio = f"  {value / best_peer:5.2f}× the better peer" if name.startswith("rigidcells") else ""
                moved = f", heights moved up to {heights[name]:.3f} m" if flat and name in heights else ""
                print(f"  {name:28s} {value:.4f}{ratio}{moved}")


if __name__ == "__main__":
    main()
