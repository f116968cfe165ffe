"""The tiles' figures: apply a field to tiles in one process (one apply_file after
another; each already uses every core through rayon) and on a Dask LocalCluster of worker
processes, and report the speed-up and the throughput.

Usage: python tools/python/dask_tiles.py SCAN.las [TILES_PER_SIDE] [WORKERS]
(needs laspy, dask[distributed] and the rigidcells package: pip install ./python)
"""

import sys
import tempfile
import time
from pathlib import Path

import laspy
import numpy as np
from dask.distributed import Client, LocalCluster

import rigidcells
import rigidcells.dask
from tiles import cut


def main() -> None:
    src = Path(sys.argv[1])
    n = int(sys.argv[2]) if len(sys.argv) > 2 else 4
    workers = int(sys.argv[3]) if len(sys.argv) > 3 else 2
    with tempfile.TemporaryDirectory(dir=".") as d:
        d = Path(d)
        tiles = cut(src, d, n)
        with laspy.open(src) as f:
            header = f.header
        lo, hi = np.array(header.mins), np.array(header.maxs)
        w = hi[0] - lo[0]
        spec = {
            "fixed": [{"box": {"min": list(lo - 1), "max": [lo[0] + 0.15 * w, hi[1] + 1, hi[2] + 1]}}],
            "handle": [
                {"box": {"min": [hi[0] - 0.15 * w, lo[1] - 1, lo[2] - 1], "max": list(hi + 1)}, "translate": [0, 0, 5]}
            ],
        }
        field = d / "bend.field"
        rigidcells.deform_file(src, d / "whole.laz", spec, save_field=field, cells=5000)
        points = header.point_count
        (d / "seq").mkdir()
        t = time.perf_counter()
        for tile in tiles:
            rigidcells.apply_file(field, tile, d / "seq" / tile.name)
        one = time.perf_counter() - t
        with LocalCluster(n_workers=workers, threads_per_worker=1, processes=True) as cluster:
            with Client(cluster) as client:
                rigidcells.dask.apply_tiles(field, tiles[:1], d / "warm", client)
                t = time.perf_counter()
                rigidcells.dask.apply_tiles(field, tiles, d / "dask", client)
                many = time.perf_counter() - t
        same = all((d / "seq" / t.name).read_bytes() == (d / "dask" / t.name).read_bytes() for t in tiles)
        print(
            f"{points} points in {len(tiles)} tiles: one process {one:.2f} s ({points / one:,.0f} points/s), "
            f"dask {workers} workers {many:.2f} s ({points / many:,.0f} points/s), "
            f"speed-up {one / many:.2f}; outputs identical: {same}"
        )


if __name__ == "__main__":
    main()
