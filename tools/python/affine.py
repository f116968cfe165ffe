"""The peer of `rigidcells apply` in the streaming benchmark (`tools/src/bin/apply_speed.rs`):
laspy reads a LAS or LAZ file a million points at a time, turns x and y by a few degrees about the
file's middle and lifts z with numpy, and writes the points (LAZ through lazrs, in parallel).

    python tools/python/affine.py IN.las|laz OUT.las|laz
"""

import math
import sys

import laspy
import numpy as np

CHUNK = 1_000_000


def main(src: str, dst: str) -> None:
    backend = None
    if src.lower().endswith(".laz") or dst.lower().endswith(".laz"):
        backend = laspy.LazBackend.LazrsParallel
    with laspy.open(src, laz_backend=backend) as reader:
        header = reader.header
        middle = (header.mins + header.maxs) / 2.0
        c, s = math.cos(math.radians(3.0)), math.sin(math.radians(3.0))
        out_header = laspy.LasHeader(
            point_format=header.point_format, version=header.version
        )
        out_header.offsets = header.offsets
        out_header.scales = header.scales
        with laspy.open(
            dst, mode="w", header=out_header, laz_backend=backend
        ) as writer:
            for points in reader.chunk_iterator(CHUNK):
                x = np.asarray(points.x) - middle[0]
                y = np.asarray(points.y) - middle[1]
                points.x = middle[0] + c * x - s * y
                points.y = middle[1] + s * x + c * y
                points.z = np.asarray(points.z) + 1.0
                writer.write_points(points)


if __name__ == "__main__":
    main(sys.argv[1], sys.argv[2])
