"""Reads a COPC file with a third-party reader (laspy's CopcReader, lazrs for LAZ) and checks
what a viewer relies on: the hierarchy reaches every point, a box query returns points inside
the box only and as many as a full read finds there, and level 0 is a subsample.

With an EPSG code after the file, also checks that the CRS is stated as a WKT naming that
code: the global encoding's WKT bit set and a WKT VLR whose text has the code's authority.

Usage: python copc_check.py FILE.copc.laz [EPSG]   (exit 0 and `ok` on success)
"""
import sys

import laspy
import numpy as np

path = sys.argv[1]
with laspy.CopcReader.open(path) as r:
    h = r.header
    assert h.version.major == 1 and h.version.minor == 4, h.version
    assert h.point_format.id in (6, 7, 8), h.point_format.id
    every = r.query()
    assert len(every) == h.point_count, (len(every), h.point_count)
    lo = h.mins + 0.3 * (h.maxs - h.mins)
    hi = h.mins + 0.7 * (h.maxs - h.mins)
    box = r.query(bounds=laspy.copc.Bounds(mins=lo, maxs=hi))
    # Points on the box's faces may go either way by a rounding: one scale step of slack.
    tol = np.asarray(h.scales)
    xyz = np.stack([box.x, box.y, box.z], 1)
    inside = np.all((xyz >= lo - tol) & (xyz <= hi + tol), axis=1)
    assert inside.all(), "a box query returned points outside the box"
    all_xyz = np.stack([every.x, every.y, every.z], 1)
    def within(slack):
        return np.all((all_xyz >= lo - slack) & (all_xyz <= hi + slack), axis=1).sum()
    assert within(-tol) <= len(box) <= within(tol), (len(box), within(-tol), within(tol))
    # The root holds a subsample (all of a small file).
    root = r.query(level=0)
    assert 0 < len(root) <= h.point_count, len(root)
    assert len(root) < h.point_count or h.point_count <= 128**2, len(root)
    if len(sys.argv) > 2:
        assert h.global_encoding.wkt, "the global encoding's WKT bit is unset"
        authority = 'AUTHORITY["EPSG","%s"]' % sys.argv[2]
        wkts = [v.string for v in h.vlrs if isinstance(v, laspy.vlrs.known.WktCoordinateSystemVlr)]
        assert any(w.rstrip("\0").endswith(authority + "]") for w in wkts), wkts
print("ok", h.point_count, len(box), len(root))
