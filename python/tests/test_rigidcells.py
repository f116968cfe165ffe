"""The Python package against the command line: the same geometry bit for bit, structured
arrays round trip, errors are exceptions."""

import os
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

import rigidcells

ROOT = Path(__file__).resolve().parents[2]
SHARED = ROOT.parent / "shared" / "data"

BEND = """
[[fixed]]
box = { min = [-0.1, -0.1, -0.1], max = [0.5, 1.1, 1.1] }
[[handle]]
box = { min = [9.5, -0.1, -0.1], max = [10.1, 1.1, 1.1] }
rotate = { axis = [0.0, 1.0, 0.0], degrees = -90.0 }
translate = [-3.4, 0.0, 5.9]
"""


def cli() -> str:
    """The rigidcells binary: $RIGIDCELLS_BIN, else the workspace's release or debug build."""
    for candidate in (
        os.environ.get("RIGIDCELLS_BIN"),
        ROOT / "target" / "release" / "rigidcells",
        ROOT / "target" / "debug" / "rigidcells",
    ):
        if candidate and Path(candidate).exists():
            return str(candidate)
    pytest.skip("no rigidcells binary built")


def bar_points() -> np.ndarray:
    """A 10 × 1 × 1 bar of points, 6 per unit."""
    xs = np.linspace(0.0, 10.0, 61)
    ys = np.linspace(0.0, 1.0, 7)
    g = np.stack(np.meshgrid(xs, ys, ys, indexing="ij"), axis=-1).reshape(-1, 3)
    return np.ascontiguousarray(g)


def test_deform_gives_the_command_lines_geometry_bit_for_bit(tmp_path):
    pts = bar_points()
    xyz = tmp_path / "bar.xyz"
    # 18 significant digits a number: the CLI writes moved numbers with their column's digits,
    # and 18 keep every bit of a double.
    xyz.write_text("".join(f"{x:.17e} {y:.17e} {z:.17e}\n" for x, y, z in pts))
    edit = tmp_path / "bend.toml"
    edit.write_text(BEND)
    out = tmp_path / "out.xyz"
    subprocess.run(
        [cli(), "deform", str(xyz), "-o", str(out), "--edit", str(edit), "--cell-size", "0.25", "-q"],
        check=True,
    )
    cli_moved = np.array([[float(v) for v in line.split()[:3]] for line in out.read_text().splitlines()])
    for spec in (BEND, edit, str(edit)):
        moved, info = rigidcells.deform(pts, spec, cell_size=0.25)
        assert moved.shape == pts.shape and moved.dtype == np.float64
        assert np.array_equal(moved, cli_moved)
        assert info["cells"] > 100 and info["iterations"] > 0 and info["warnings"] == []
    # The right end turned up: its points now stand near x = 6.6, z from 5.4 to 6.4.
    end = moved[pts[:, 0] > 9.9]
    assert abs(end[:, 0].mean() - 6.6) < 0.3 and end[:, 2].mean() > 5.0


def test_deform_file_writes_the_command_lines_bytes(tmp_path):
    src = SHARED / "las" / "autzen_trim.laz"
    spec = {
        "fixed": [{"box": {"min": [636000, 848900, 0], "max": [636300, 849600, 1000]}}],
        "handle": [
            {"box": {"min": [636900, 848900, 0], "max": [637200, 849600, 1000]}, "translate": [0, 0, 20]}
        ],
    }
    edit = tmp_path / "edit.toml"
    edit.write_text(
        "[[fixed]]\nbox = { min = [636000, 848900, 0], max = [636300, 849600, 1000] }\n"
        "[[handle]]\nbox = { min = [636900, 848900, 0], max = [637200, 849600, 1000] }\n"
        "translate = [0, 0, 20]\n"
    )
    ours, theirs = tmp_path / "py.las", tmp_path / "cli.las"
    info = rigidcells.deform_file(src, ours, spec, save_field=tmp_path / "f.field")
    assert info["points"] == 110000
    subprocess.run([cli(), "deform", str(src), "-o", str(theirs), "--edit", str(edit), "-q"], check=True)
    assert ours.read_bytes() == theirs.read_bytes()
    again = tmp_path / "again.las"
    rigidcells.apply_file(tmp_path / "f.field", src, again)
    assert again.read_bytes() == theirs.read_bytes()


def test_estimate_counts_the_cells_a_deformation_makes():
    pts = bar_points()
    e = rigidcells.estimate(pts, BEND, cell_size=0.25)
    assert isinstance(e, rigidcells.Estimate)
    _, report = rigidcells.deform(pts, BEND, cell_size=0.25, progress=False)
    assert e.cells == report.cells
    assert e.complete and e.fits and e.solver == "direct"
    assert 0 < e.bytes <= e.limit and e.seconds > 0
    # Cells that cannot fit the budget are forecast, not built: the least they take.
    tight = rigidcells.estimate(pts, BEND, cell_size=0.25, memory_limit="2M")
    assert not tight.complete and not tight.fits and tight.bytes > tight.limit
    assert abs(tight.cells / e.cells - 1) < 0.03
    with pytest.raises(ValueError, match="memory_limit"):
        rigidcells.deform(pts, BEND, cell_size=0.25, memory_limit="2M", progress=False)
    # A budget too small even to find the occupied cells leaves nothing to estimate from: the
    # refusal deform gives, naming what shrinks the run.
    for run in (rigidcells.estimate, rigidcells.deform):
        with pytest.raises(ValueError, match=r"over the memory limit .*\(memory_limit\): use a larger cell_size"):
            run(pts, BEND, cell_size=0.001, memory_limit="64K")


def test_normals_turn_with_the_bend():
    pts = bar_points()
    up = np.tile([0.0, 0.0, 1.0], (len(pts), 1))
    moved, info = rigidcells.deform(pts, BEND, normals=up, cell_size=0.25)
    same, _ = rigidcells.deform(pts, BEND, cell_size=0.25)
    assert np.array_equal(moved, same)
    turned = info["normals"]
    assert turned.shape == pts.shape
    assert np.allclose(np.linalg.norm(turned, axis=1), 1.0, atol=1e-9)
    # The fixed end keeps its normals; the turned end's point along -x (turned by -90° about y).
    assert np.allclose(turned[pts[:, 0] < 0.3], [0.0, 0.0, 1.0], atol=1e-9)
    end = turned[pts[:, 0] > 9.9].mean(axis=0)
    assert end[0] < -0.9, end
    with pytest.raises(ValueError):
        rigidcells.deform(pts, BEND, normals=up[:5])


def test_a_solved_field_applies_saves_and_loads(tmp_path):
    pts = bar_points()
    field = rigidcells.solve(pts, BEND, cell_size=0.25)
    assert field.cells > 100
    moved, _ = rigidcells.deform(pts, BEND, cell_size=0.25)
    assert np.array_equal(field.apply(pts), moved)
    path = tmp_path / "bend.field"
    field.save(path)
    assert np.array_equal(rigidcells.Field.load(path).apply(pts), moved)
    with pytest.raises(ValueError, match="beyond the field"):
        field.apply(pts + 100.0)


def test_an_rbf_field_keeps_the_transfers_coefficients(tmp_path):
    pts = bar_points()
    field = rigidcells.solve(pts, BEND, cell_size=0.5, transfer="rbf")
    moved, _ = rigidcells.deform(pts, BEND, cell_size=0.5, transfer="rbf")
    assert np.array_equal(field.apply(pts), moved)
    field.save(tmp_path / "rbf.field")
    assert np.array_equal(rigidcells.Field.load(tmp_path / "rbf.field").apply(pts), moved)


def test_a_structured_array_comes_back_with_only_xyz_changed():
    pts = bar_points()
    dtype = [("X", "<f8"), ("Y", "<f8"), ("Z", "<f8"), ("Intensity", "<u2"), ("Classification", "u1")]
    arr = np.zeros(len(pts), dtype=dtype)
    arr["X"], arr["Y"], arr["Z"] = pts[:, 0], pts[:, 1], pts[:, 2]
    arr["Intensity"] = np.arange(len(pts)) % 65535
    arr["Classification"] = 2
    out, _ = rigidcells.deform(arr, BEND, cell_size=0.25)
    assert out.dtype == arr.dtype and len(out) == len(arr)
    assert np.array_equal(out["Intensity"], arr["Intensity"])
    assert np.array_equal(out["Classification"], arr["Classification"])
    moved, _ = rigidcells.deform(pts, BEND, cell_size=0.25)
    assert np.array_equal(np.stack([out["X"], out["Y"], out["Z"]], 1), moved)


def test_errors_are_exceptions(tmp_path):
    pts = bar_points()
    with pytest.raises(ValueError, match="unknown key"):
        rigidcells.deform(pts, "[[fixed]]\nbox = { min = [0,0,0], max = [1,1,1] }\nradius = 2\n")
    with pytest.raises(ValueError):
        rigidcells.deform(pts, BEND, transfer="cubic")
    with pytest.raises(ValueError):
        rigidcells.deform(pts[:, :2], BEND)
    with pytest.raises(OSError):
        rigidcells.deform(pts, tmp_path / "missing.toml")
    with pytest.raises(OSError):
        rigidcells.deform_file(tmp_path / "missing.las", tmp_path / "o.las", BEND)
    bad = tmp_path / "bad.las"
    bad.write_bytes(b"LASF" + b"\0" * 300)
    with pytest.raises(rigidcells.FormatError):
        rigidcells.deform_file(bad, tmp_path / "o.las", BEND)
    assert issubclass(rigidcells.FormatError, ValueError)
    assert not (tmp_path / "o.las").exists()


# Every point of the bar in one handle: a rigid translation, exact at every point.
SHIFT = """
[[handle]]
box = { min = [99.0, 199.0, 299.0], max = [111.0, 202.0, 302.0] }
translate = [0.0006, -0.0006, -0.0016]
"""


def bar_records(dtype=np.int32) -> np.ndarray:
    """The bar as LAS-style integer records: steps of 0.001 from the offset (100, 200, 300)."""
    pts = bar_points() + [100.0, 200.0, 300.0]
    arr = np.zeros(len(pts), dtype=[("X", dtype), ("Y", dtype), ("Z", dtype), ("Intensity", "<u2")])
    for k, name in enumerate("XYZ"):
        arr[name] = np.round((pts[:, k] - [100.0, 200.0, 300.0][k]) / 0.001)
    arr["Intensity"] = np.arange(len(pts)) % 65535
    return arr


def test_integer_xyz_fields_without_scale_are_refused():
    with pytest.raises(ValueError, match=r"X, Y, Z are integer fields .*pass scale=\(sx, sy, sz\) and offset=\(ox, oy, oz\)"):
        rigidcells.deform(bar_records(), SHIFT)
    with pytest.raises(ValueError, match="scale="):
        rigidcells.solve(bar_records(), SHIFT)


def test_integer_records_round_to_the_nearest_step_never_truncated():
    arr = bar_records()
    frame = dict(scale=0.001, offset=(100.0, 200.0, 300.0))
    out, info = rigidcells.deform(arr, SHIFT, **frame)
    assert out.dtype == arr.dtype and info["notes"] == []
    # +0.6, −0.6 and −1.6 steps: +1, −1, −2 to the nearest (truncation gives 0, 0, −1).
    assert np.array_equal(out["X"], arr["X"] + 1)
    assert np.array_equal(out["Y"], arr["Y"] - 1)
    assert np.array_equal(out["Z"], arr["Z"] - 2)
    assert np.array_equal(out["Intensity"], arr["Intensity"])
    field = rigidcells.solve(arr, SHIFT, **frame)
    assert np.array_equal(field.apply(arr, **frame), out)
    # The records alone as an (n, 3) array come back as the same integers.
    plain = np.stack([arr["X"], arr["Y"], arr["Z"]], axis=1).astype(np.int64)
    moved, _ = rigidcells.deform(plain, SHIFT, **frame)
    assert moved.dtype == np.int64
    assert np.array_equal(moved, np.stack([out["X"], out["Y"], out["Z"]], axis=1))


def test_a_moved_record_its_field_cannot_hold_is_refused_not_wrapped():
    arr = bar_records(np.int16)
    with pytest.raises(ValueError, match="X: the moved records span .* int16 cannot hold"):
        rigidcells.deform(arr, SHIFT.replace("0.0006, ", "30.0, "), scale=0.001, offset=(100, 200, 300))
    with pytest.raises(ValueError, match="axis x: the moved coordinates span .*32-bit record integers"):
        rigidcells.deform(bar_records(), SHIFT.replace("0.0006, ", "3.0e6, "), scale=0.001, offset=(100, 200, 300))


def test_scale_and_offset_are_for_integers_only():
    pts = bar_points()
    with pytest.raises(ValueError, match="leave scale and offset out"):
        rigidcells.deform(pts, SHIFT, scale=0.001)
    with pytest.raises(ValueError, match="offset was given without scale"):
        rigidcells.deform(bar_records(), SHIFT, offset=(100, 200, 300))
    with pytest.raises(ValueError, match="scale must be a number or three numbers"):
        rigidcells.deform(bar_records(), SHIFT, scale=(0.001, 0.001))
    with pytest.raises(ValueError, match="out of range"):
        rigidcells.deform(bar_records(), SHIFT, scale=-0.001)


def test_triangles_are_integer_indices_never_truncated():
    pts = bar_points()
    ints, _ = rigidcells.deform(pts, BEND, triangles=[[0, 1, 2]], cell_size=0.5)
    small, _ = rigidcells.deform(pts, BEND, triangles=np.array([[0, 1, 2]], dtype=np.uint16), cell_size=0.5)
    assert np.array_equal(small, ints)
    for floats in ([[0.0, 1.0, 2.0]], [[0, 1.5, 2]]):
        with pytest.raises(TypeError, match="triangles must be integer vertex indices, got float64"):
            rigidcells.deform(pts, BEND, triangles=floats, cell_size=0.5)
    with pytest.raises(ValueError, match="outside"):
        rigidcells.deform(pts, BEND, triangles=np.array([[0, 1, 2**64 - 1]], dtype=np.uint64))
    with pytest.raises(TypeError):
        rigidcells.deform(pts, BEND, cells=100.5)


def test_info_gives_each_turn_and_a_short_part_refuses_a_whole_turn():
    twist = (
        "[[fixed]]\nbox = { min = [-0.1, -0.1, -0.1], max = [0.5, 1.1, 1.1] }\n"
        "[[handle]]\nbox = { min = [9.5, -0.1, -0.1], max = [10.1, 1.1, 1.1] }\n"
        "rotate = { axis = [1.0, 0.0, 0.0], degrees = 360.0 }\npivot = [9.75, 0.5, 0.5]\n"
    )
    _, info = rigidcells.deform(bar_points(), twist, cell_size=0.25)
    (turn,) = info["handle_turns"]
    assert turn["line"] == 3 and turn["turn_asked_degrees"] == 360.0
    assert abs(turn["turn_taken_degrees"] - 360.0) < 36.0, turn
    # A cube as long as it is wide cannot carry a whole turn: refused, not untwisted.
    g = np.linspace(0.0, 1.0, 11)
    cube = np.stack(np.meshgrid(g, g, g, indexing="ij"), axis=-1).reshape(-1, 3)
    short = (
        "[[fixed]]\nbox = { min = [-1, -1, -1], max = [2, 2, 0.1] }\n"
        "[[handle]]\nbox = { min = [-1, -1, 0.9], max = [2, 2, 2] }\n"
        "rotate = { axis = [0.0, 0.0, 1.0], degrees = 360.0 }\n"
    )
    with pytest.raises(ValueError, match="gives way past"):
        rigidcells.deform(np.ascontiguousarray(cube), short, cell_size=0.1)
