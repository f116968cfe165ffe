"""Cuts a LAS/LAZ scan into n × n tiles by the quantiles of x and y, written as LAS with laspy:
the tiles of the Dask and Slurm figures and of python/tests/test_dask.py.

Usage: python tools/python/tiles.py SCAN OUT_DIR [TILES_PER_SIDE]   (prints the tiles' paths)
"""

import sys
from pathlib import Path
from typing import List

import laspy
import numpy as np


def cut(src, out, n: int = 4) -> List[Path]:
    """Writes ``out/tile_I_J.las`` for I, J in 0..n (every point in exactly one) and returns
    their paths, row by row."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    las = laspy.read(src)
    xs = np.quantile(las.x, np.linspace(0, 1, n + 1))
    ys = np.quantile(las.y, np.linspace(0, 1, n + 1))
    ix = np.clip(np.searchsorted(xs, las.x, side="right") - 1, 0, n - 1)
    iy = np.clip(np.searchsorted(ys, las.y, side="right") - 1, 0, n - 1)
    tiles = []
    for i in range(n):
        for j in range(n):
            tile = laspy.LasData(las.header)
            tile.points = las.points[(ix == i) & (iy == j)].copy()
            path = out / f"tile_{i}_{j}.las"
            tile.write(path)
            tiles.append(path)
    return tiles


if __name__ == "__main__":
    for path in cut(sys.argv[1], sys.argv[2], int(sys.argv[3]) if len(sys.argv) > 3 else 4):
        print(path)
