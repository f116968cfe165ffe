"""The solve by subdomains on Dask workers against the solve in one process: the tiles of a
scan bent (its west end fixed, its east end lifted), solved by the default solver, by
local-global iterations with the global step split into K subdomains in one process, and by
``rigidcells.dask.solve_tiles`` on a LocalCluster of W worker processes (one thread, a memory
limit each). Prints, per cell size: seconds, iterations, the last energy, the largest distance
of a sample from the default solve's (in cells), the round trips to the workers and their mean
time, and each worker's peak memory.

Usage: python tools/python/dask_solve.py SCAN.las|laz [CELL_SIZE ...] [--subdomains K]
[--workers W] [--memory-limit 4GiB]
(needs laspy, dask[distributed] and the rigidcells package: pip install ./python)
"""

import argparse
import resource
import tempfile
import time
from pathlib import Path

import laspy
import numpy as np
from dask.distributed import Client, LocalCluster

import rigidcells
import rigidcells.dask
from tiles import cut


def peak_bytes() -> int:
    """This process's peak resident memory (Linux: kilobytes)."""
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("scan", type=Path)
    ap.add_argument("cell_sizes", type=float, nargs="*", default=[16.0, 8.0])
    ap.add_argument("--subdomains", type=int, default=4)
    ap.add_argument("--workers", type=int, default=4)
    ap.add_argument("--memory-limit", default="4GiB")
    a = ap.parse_args()
    las = laspy.read(a.scan)
    points = np.column_stack([las.x, las.y, las.z])[::5]
    lo, hi = points.min(axis=0), points.max(axis=0)
    w = hi[0] - lo[0]
    spec = {
        "fixed": [{"box": {"min": list(lo - 1), "max": [lo[0] + 0.2 * w, hi[1] + 1, hi[2] + 1]}}],
        "handle": [
            {"box": {"min": [hi[0] - 0.2 * w, lo[1] - 1, lo[2] - 1], "max": list(hi + 1)},
             "translate": [0, 0, 20]}
        ],
    }
    trips = {"n": 0, "s": 0.0}
    solve = rigidcells.dask._Factored.solve

    def timed(self, rhs):
        t = time.perf_counter()
        out = solve(self, rhs)
        trips["n"] += 1
        trips["s"] += time.perf_counter() - t
        return out

    rigidcells.dask._Factored.solve = timed
    with tempfile.TemporaryDirectory(dir=".") as d:
        d = Path(d)
        tiles = cut(a.scan, d)
        cluster = LocalCluster(
            n_workers=a.workers, threads_per_worker=1, processes=True,
            memory_limit=a.memory_limit,
        )
        client = Client(cluster)
        print(f"{a.scan.name}: {len(tiles)} tiles; {a.subdomains} subdomains; "
              f"{a.workers} workers of {a.memory_limit}")
        print("| cell | run | cells | s | iterations | energy | from default (cells) "
              "| round trips | ms a trip | worker peak MB |")
        print("|---|---|---|---|---|---|---|---|---|---|")
        for cell in a.cell_sizes:
            common = dict(cell_size=cell, progress=False)
            runs = [
                ("default", lambda f: rigidcells.solve_files(tiles, spec, f, **common)),
                (f"{a.subdomains} subdomains here", lambda f: rigidcells.solve_files(
                    tiles, spec, f, subdomains=a.subdomains, **common)),
                (f"{a.subdomains} subdomains on Dask", lambda f: rigidcells.dask.solve_tiles(
                    tiles, spec, f, client, subdomains=a.subdomains, **common)),
            ]
            reference = None
            for name, run in runs:
                field = d / f"{name.replace(' ', '_')}_{cell}.field"
                trips.update(n=0, s=0.0)
                t = time.perf_counter()
                report = run(field)
                seconds = time.perf_counter() - t
                moved = rigidcells.Field.load(field).apply(points)
                if reference is None:
                    reference = moved
                gap = np.abs(moved - reference).max() / cell
                on_dask = "Dask" in name
                peaks = client.run(peak_bytes) if on_dask else {}
                peak = max(peaks.values()) / 2**20 if peaks else None
                trip = f"{1000 * trips['s'] / trips['n']:.1f}" if trips["n"] else ""
                print(f"| {cell:g} | {name} | {report.cells:,} | {seconds:.2f} | "
                      f"{report.iterations} | {report.energy[-1]:.9g} | {gap:.1e} | "
                      f"{trips['n'] or ''} | {trip} | {'' if peak is None else f'{peak:.0f}'} |",
                      flush=True)
        client.close()
        cluster.close()


if __name__ == "__main__":
    main()
