"""The README's Python examples run as written, on a real scan and a real mesh."""

import os
import re
import subprocess
import sys

import pytest

from test_rigidcells import ROOT, SHARED


def example(name: str) -> str:
    """The README's code block marked `<!-- example: NAME -->`."""
    text = (ROOT / "README.md").read_text(encoding="utf-8")
    m = re.search(rf"<!-- example: {name} -->\n```python\n(.*?)```", text, re.S)
    assert m, f"no example {name} in the README"
    return m.group(1)


def run(code: str, folder) -> str:
    out = subprocess.run(
        [sys.executable, "-c", code], cwd=folder, capture_output=True, text=True, timeout=600
    )
    assert out.returncode == 0, out.stderr
    return out.stdout


def test_the_scan_example(tmp_path):
    laspy = pytest.importorskip("laspy")
    os.symlink(SHARED / "las" / "autzen_trim.laz", tmp_path / "scan.laz")
    printed = run(example("scan"), tmp_path).split()
    las, bent = laspy.read(tmp_path / "scan.laz"), laspy.read(tmp_path / "bent.laz")
    assert len(bent.points) == len(las.points)
    # The east fifth lifted by 20 (the file's units), the west fifth where it was.
    x0, x1 = las.header.mins[0], las.header.maxs[0]
    east, west = las.x > x1 - 0.2 * (x1 - x0), las.x < x0 + 0.2 * (x1 - x0)
    assert abs((bent.z - las.z)[east].mean() - 20) < 0.01 and (bent.z == las.z)[west].all()
    cells, iterations, fixed = int(printed[0]), int(printed[1]), float(printed[2])
    assert abs(cells - 5000) <= 100 and iterations > 0 and fixed == 0.0


def test_the_mesh_example(tmp_path):
    trimesh = pytest.importorskip("trimesh")
    os.symlink(SHARED / "meshes" / "dragon_11k_binary.ply", tmp_path / "part.ply")
    run(example("mesh"), tmp_path)
    part = trimesh.load(tmp_path / "part.ply", process=False)
    bent = trimesh.load(tmp_path / "bent.ply", process=False)
    assert len(bent.vertices) == len(part.vertices) and (bent.faces == part.faces).all()
    assert abs(bent.vertices - part.vertices).max() > 0.05 * part.extents.max()
