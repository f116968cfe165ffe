"""laspy's objects through the Python package: a LasData or its points come back as the same
kind, coordinates rounded to the nearest step exactly as the command line's LAS writer rounds
them (checked against its output record for record); laspy's raw integer array is refused
unless scale and offset are given; an offset that no longer fits moves as the command line
moves it."""

import subprocess

import numpy as np
import pytest

import rigidcells
from test_rigidcells import SHARED, cli

laspy = pytest.importorskip("laspy")

SRC = SHARED / "las" / "autzen_trim.laz"

# The east end raised by 500.5 m over the fixed west end: the moved coordinates fall anywhere
# between two steps, so truncation and rounding differ on a third of the records.
BEND = """
[[fixed]]
box = { min = [636000, 848900, 0], max = [636300, 849600, 1000] }
[[handle]]
box = { min = [636900, 848900, 0], max = [637200, 849600, 1000] }
translate = [0, 0, 500.5]
"""

# Every point raised by 3e7 m: z no longer fits int32 steps of 0.01 from the offset 0.
FAR = """
[[handle]]
box = { min = [636000, 848900, 0], max = [637200, 849600, 1000] }
translate = [0, 0, 30000000.25]
"""

XYZ = ("X", "Y", "Z")


@pytest.fixture(scope="module")
def las():
    return laspy.read(SRC)


def records(points) -> np.ndarray:
    """The X, Y, Z record integers of a LasData, a point record or a structured array."""
    arr = getattr(points, "points", points)
    arr = getattr(arr, "array", arr)
    return np.stack([arr[k] for k in XYZ], axis=1)


def nearest(steps: np.ndarray) -> np.ndarray:
    """Steps rounded to the nearest integer, halves away from zero (the LAS writer's rule)."""
    t = np.trunc(steps)
    f = steps - t
    return t + (f >= 0.5) - (f <= -0.5)


def run_cli(*args) -> None:
    subprocess.run([cli(), *map(str, args), "-q"], check=True)


def spec_file(tmp_path, text: str):
    path = tmp_path / "edit.toml"
    path.write_text(text)
    return path


def assert_other_fields_unchanged(out, arr) -> None:
    assert out.dtype == arr.dtype and len(out) == len(arr)
    for name in arr.dtype.names:
        if name not in XYZ:
            assert out[name].tobytes() == arr[name].tobytes(), name


def assert_header_bounds_are_the_records(las) -> None:
    """The header's bounds are those of the records (as laspy's update_header makes them)."""
    r, h = records(las), las.header
    assert np.array_equal(h.mins, r.min(axis=0) * h.scales + h.offsets)
    assert np.array_equal(h.maxs, r.max(axis=0) * h.scales + h.offsets)


def test_a_las_data_comes_back_new_and_rounded_as_the_cli_writes_it(las, tmp_path):
    arr_before = las.points.array.copy()
    header_before = (las.header.scales.copy(), las.header.offsets.copy(), las.header.mins.copy())
    bent, info = rigidcells.deform(las, BEND)
    assert isinstance(bent, laspy.LasData) and bent is not las
    assert info["points"] == 110000 and info["notes"] == []
    # The input is untouched.
    assert las.points.array.tobytes() == arr_before.tobytes()
    assert all(np.array_equal(a, b) for a, b in zip(header_before, (las.header.scales, las.header.offsets, las.header.mins)))
    # The command line's LAS writer, given the same field, writes the same records and header.
    field = rigidcells.solve(las, BEND)
    field.save(tmp_path / "bend.field")
    run_cli("apply", tmp_path / "bend.field", SRC, "-o", tmp_path / "cli.las")
    theirs = laspy.read(tmp_path / "cli.las")
    assert np.array_equal(records(bent), records(theirs))
    for attr in ("scales", "offsets", "mins", "maxs"):
        assert np.array_equal(getattr(bent.header, attr), getattr(theirs.header, attr)), attr
    assert_header_bounds_are_the_records(bent)
    # Rounded to the nearest step, where truncation would differ on many records.
    moved, _ = rigidcells.deform(las.xyz, BEND)
    steps = (moved - las.header.offsets) / las.header.scales
    assert np.array_equal(records(bent), nearest(steps))
    assert np.all(np.count_nonzero(np.trunc(steps) != records(bent), axis=0) > 10000)
    # Every other field byte for byte; the coordinates read back as laspy's x, y, z.
    assert_other_fields_unchanged(bent.points.array, las.points.array)
    assert np.array_equal(bent.xyz, theirs.xyz)
    bent.write(tmp_path / "py.las")
    assert np.array_equal(records(laspy.read(tmp_path / "py.las")), records(theirs))


def test_a_point_record_comes_back_as_a_point_record(las):
    arr_before = las.points.array.copy()
    bent, _ = rigidcells.deform(las, BEND)
    rec, info = rigidcells.deform(las.points, BEND)
    assert isinstance(rec, laspy.ScaleAwarePointRecord) and rec is not las.points
    assert np.array_equal(rec.scales, las.header.scales)
    assert np.array_equal(rec.offsets, las.header.offsets)
    assert np.array_equal(records(rec), records(bent))
    assert_other_fields_unchanged(rec.array, las.points.array)
    assert las.points.array.tobytes() == arr_before.tobytes()


def test_a_saved_field_applies_to_a_las_data_as_the_cli_deforms_the_file(las, tmp_path):
    edit = spec_file(tmp_path, BEND)
    run_cli("deform", SRC, "-o", tmp_path / "cli.las", "--edit", edit, "--save-field", tmp_path / "f.field")
    theirs = laspy.read(tmp_path / "cli.las")
    field = rigidcells.Field.load(tmp_path / "f.field")
    assert np.array_equal(records(field.apply(las)), records(theirs))
    assert np.array_equal(records(field.apply(las.points)), records(theirs))


def test_laspys_raw_integer_array_is_refused_with_how_to_pass_scale_and_offset(las):
    raw = las.points.array
    field = rigidcells.solve(las.xyz, BEND)
    for call in (
        lambda: rigidcells.deform(raw, BEND),
        lambda: rigidcells.solve(raw, BEND),
        lambda: field.apply(raw),
    ):
        with pytest.raises(ValueError, match=r"scale=\(sx, sy, sz\) and offset=\(ox, oy, oz\)"):
            call()
    with pytest.raises(ValueError, match="come from the LasData's header"):
        rigidcells.deform(las, BEND, scale=0.01)


def test_a_raw_array_with_scale_and_offset_is_decoded_moved_and_rounded(las):
    raw = las.points.array
    before = raw.copy()
    bent, _ = rigidcells.deform(las, BEND)
    frame = dict(scale=las.header.scales, offset=las.header.offsets)
    out, info = rigidcells.deform(raw, BEND, **frame)
    assert isinstance(out, np.ndarray) and out.dtype == raw.dtype
    assert np.array_equal(records(out), records(bent))
    assert_other_fields_unchanged(out, raw)
    assert raw.tobytes() == before.tobytes()
    # The X, Y, Z records alone, as an (n, 3) int32 array: the same records back.
    stacked = records(raw)
    moved, _ = rigidcells.deform(stacked, BEND, **frame)
    assert moved.dtype == np.int32 and np.array_equal(moved, records(bent))
    # solve and apply take them the same way.
    field = rigidcells.solve(raw, BEND, **frame)
    assert np.array_equal(records(field.apply(raw, **frame)), records(bent))


def test_coordinates_past_int32_move_the_offset_as_the_cli_does(las, tmp_path):
    edit = spec_file(tmp_path, FAR)
    run_cli("deform", SRC, "-o", tmp_path / "cli.las", "--edit", edit, "--save-field", tmp_path / "far.field")
    theirs = laspy.read(tmp_path / "cli.las")
    assert theirs.header.offsets[2] != 0.0
    with pytest.warns(UserWarning, match=r"axis z: .* offset 0 -> "):
        applied = rigidcells.Field.load(tmp_path / "far.field").apply(las)
    for attr in ("scales", "offsets"):
        assert np.array_equal(getattr(applied.header, attr), getattr(theirs.header, attr)), attr
    assert np.array_equal(applied.points.offsets, theirs.header.offsets)
    assert np.array_equal(records(applied), records(theirs))
    assert_header_bounds_are_the_records(applied)
    far, info = rigidcells.deform(las, FAR)
    assert np.array_equal(far.header.offsets, theirs.header.offsets)
    assert len(info["notes"]) == 1 and "axis z" in info["notes"][0]
    assert np.allclose(far.xyz, las.xyz + [0, 0, 30000000.25], atol=0.006, rtol=0)
    assert np.array_equal(las.header.offsets, [0.0, 0.0, 0.0])
    rec, _ = rigidcells.deform(las.points, FAR)
    assert np.array_equal(rec.offsets, theirs.header.offsets)
    # A raw array has no header to move: refused, naming the axis.
    with pytest.raises(ValueError, match=r"axis z: .*32-bit record integers with scale 0.01 and offset 0"):
        rigidcells.deform(las.points.array, FAR, scale=las.header.scales, offset=las.header.offsets)


# The ground (class 2) at the east end of a small scan raised over its fixed west end: a spec
# whose handle selects by class, as the README's surveyor spec does.
SMALL = SHARED / "las" / "extrabytes.las"
GROUND = """
[[fixed]]
box = { min = [635000, 848000, 0], max = [636300, 854000, 1000] }
[[handle]]
classification = [2]
box = { min = [638300, 848000, 0], max = [639500, 854000, 1000] }
translate = [0, 0, 20]
"""


@pytest.mark.parametrize("point_format", [3, 6])
def test_a_class_region_selects_in_memory_what_the_cli_selects(tmp_path, point_format):
    # Point format 3 holds the class in the low five bits of a byte, format 6 in a byte.
    src = tmp_path / f"small{point_format}.las"
    laspy.convert(laspy.read(SMALL), point_format_id=point_format).write(src)
    las = laspy.read(src)
    run_cli("deform", src, "-o", tmp_path / "cli.las", "--edit", spec_file(tmp_path, GROUND))
    theirs = records(laspy.read(tmp_path / "cli.las"))
    raised = np.asarray(las.classification) == 2
    assert np.count_nonzero((theirs[:, 2] - records(las)[:, 2] == 2000) & raised) > 10
    frame = dict(scale=las.header.scales, offset=las.header.offsets)
    fields = [(k, "f8") for k in XYZ] + [("Classification", "u1")]
    structured = np.zeros(len(las.points), dtype=fields)
    for k, name in enumerate(XYZ):
        structured[name] = las.xyz[:, k]
    structured["Classification"] = las.classification
    outs = {
        "LasData": records(rigidcells.deform(las, GROUND)[0]),
        "points": records(rigidcells.deform(las.points, GROUND)[0]),
        "array": records(rigidcells.deform(las.points.array, GROUND, **frame)[0]),
        "Session": records(rigidcells.Session(las, GROUND).release()[0]),
        "Field": records(rigidcells.solve(las, GROUND).apply(las)),
    }
    # PDAL's arrays: float coordinates and a Classification field.
    moved = rigidcells.deform(structured, GROUND)[0]
    xyz = np.stack([moved[k] for k in XYZ], axis=1)
    outs["structured"] = nearest((xyz - las.header.offsets) / las.header.scales)
    for name, out in outs.items():
        off = np.abs(out - theirs).max(axis=0)
        assert np.all(off <= 1), (name, off)  # within the LAS quantum of the command line's
    # Without classes, the class region is refused as the command line refuses it.
    with pytest.raises(ValueError, match="`classification` region needs an input with LAS classes"):
        rigidcells.deform(las.xyz, GROUND)
