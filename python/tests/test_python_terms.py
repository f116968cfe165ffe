"""The package in Python's own terms: every option of the command line as a keyword argument
(the same bytes), a typed report, errors naming arguments and dict keys, fields that pickle,
`Field.apply` taking what `deform` takes, progress, and Ctrl-C."""

import copy
import os
import pickle
import signal
import subprocess
import threading
import time
import warnings

import numpy as np
import pytest

import rigidcells
from test_rigidcells import BEND, SHARED, bar_points, cli

BEND_DICT = {
    "fixed": [{"box": {"min": [-0.1, -0.1, -0.1], "max": [0.5, 1.1, 1.1]}}],
    "handle": [
        {
            "box": {"min": [9.5, -0.1, -0.1], "max": [10.1, 1.1, 1.1]},
            "rotate": {"axis": [0.0, 1.0, 0.0], "degrees": -90.0},
            "translate": [-3.4, 0.0, 5.9],
        }
    ],
}


def test_version():
    assert rigidcells.__version__.count(".") == 2
    out = subprocess.run([cli(), "--version"], capture_output=True, text=True, check=True)
    assert out.stdout.split()[-1] == rigidcells.__version__


@pytest.mark.parametrize(
    "options, flags",
    [
        (
            {"solver": "multilevel", "tolerance": 0.0, "coarse_levels": 0},
            ["--solver", "multilevel", "--tolerance", "0", "--coarse-levels", "0"],
        ),
        (
            {"cells": 400, "inside": "flood", "loose_parts": "rest", "transfer": "blend"},
            ["--cells", "400", "--inside", "flood", "--loose-parts", "rest", "--transfer", "blend"],
        ),
        (
            {"min_cell_size": 0.125, "max_level": 4, "memory_limit": "2G"},
            ["--min-cell-size", "0.125", "--max-level", "4", "--memory-limit", "2G"],
        ),
        (
            {"cell_size": 0.25, "shell": True, "refine_strain": 0.05, "transfer": "rbf",
             "rbf_tolerance": 0.01},
            ["--cell-size", "0.25", "--shell", "--refine-strain", "0.05", "--transfer", "rbf",
             "--rbf-tolerance", "0.01"],
        ),
    ],
)
def test_every_option_gives_the_command_lines_bytes(tmp_path, options, flags):
    pts = bar_points()
    xyz = tmp_path / "bar.xyz"
    xyz.write_text("".join(f"{x:.17e} {y:.17e} {z:.17e}\n" for x, y, z in pts))
    edit = tmp_path / "bend.toml"
    edit.write_text(BEND)
    out, ours = tmp_path / "cli.xyz", tmp_path / "py.xyz"
    run = [cli(), "deform", str(xyz), "-o", str(out), "--edit", str(edit), "-q", *flags]
    subprocess.run(run, check=True)
    report = rigidcells.deform_file(xyz, ours, edit, progress=False, **options)
    assert ours.read_bytes() == out.read_bytes()
    assert isinstance(report, rigidcells.Report) and report.cells > 0
    # The same options in memory: the moved points the file holds.
    moved, _ = rigidcells.deform(pts, BEND, progress=False, **options)
    written = np.array([[float(v) for v in line.split()[:3]] for line in out.read_text().splitlines()])
    assert np.array_equal(moved, written)


def test_deform_file_writes_the_command_lines_report_and_preview(tmp_path):
    import json

    src = SHARED / "las" / "autzen_trim.laz"
    edit = tmp_path / "edit.toml"
    edit.write_text(rigidcells._rigidcells.toml_from_json(json.dumps(BEND_AUTZEN)))
    picture = ["--azimuth", "30", "--elevation", "40", "--size", "320x200", "--up", "z", "--zoom", "1.5"]
    outputs = {}
    for face in ("cli", "py"):
        d = tmp_path / face
        d.mkdir()
        outputs[face] = d
        if face == "cli":
            subprocess.run(
                [cli(), "deform", str(src), "-o", str(d / "bent.laz"), "--edit", str(edit),
                 "--cells", "2000", "--report", str(d / "r.json"), "--preview", str(d / "p.png"),
                 "--strain", "--save-field", str(d / "f.field"), "--chunk", "5000", "-q", *picture],
                check=True,
            )
        else:
            returned = rigidcells.deform_file(
                src, d / "bent.laz", edit, cells=2000, report=d / "r.json", preview=d / "p.png",
                strain=True, save_field=d / "f.field", chunk=5000, azimuth=30, elevation=40,
                size=(320, 200), up="z", zoom=1.5, progress=False,
            )
    for name in ("bent.laz", "p.png", "f.field"):
        assert (outputs["py"] / name).read_bytes() == (outputs["cli"] / name).read_bytes(), name
    a, b = (json.loads((outputs[f] / "r.json").read_text()) for f in ("cli", "py"))
    # The report returned is the one written: the same keys, the same meanings (the energy a
    # list), every value the file's but the process's peak memory and the messages' words.
    assert set(returned.keys()) == set(b) | {"normals"}
    for key, value in b.items():
        if key not in ("peak_memory_bytes", "cell_levels", "warnings", "notes"):
            assert returned[key] == value, key
    assert returned.cell_levels == {int(k): v for k, v in b["cell_levels"].items()}
    assert isinstance(returned.energy, list) and returned.energy == b["energy"]
    for varying in ("output", "timings_s", "peak_memory_bytes", "iteration_log"):
        a.pop(varying), b.pop(varying)
    assert a == b
    # A bad view is refused before any work, naming the argument.
    with pytest.raises(ValueError, match=r"^zoom=0: a factor above 0"):
        rigidcells.deform_file(src, tmp_path / "x.laz", edit, preview=tmp_path / "x.png", zoom=0)
    assert not (tmp_path / "x.laz").exists()


def test_tiles_solved_and_applied_as_the_command_line_does(tmp_path):
    import json

    tiles = [SHARED / "las" / "autzen_trim.laz", SHARED / "las" / "autzen_trim.las"]
    edit = tmp_path / "edit.toml"
    edit.write_text(rigidcells._rigidcells.toml_from_json(json.dumps(BEND_AUTZEN)))
    cli_field, py_field = tmp_path / "cli.field", tmp_path / "py.field"
    subprocess.run(
        [cli(), "solve", *map(str, tiles), "--edit", str(edit), "--save-field", str(cli_field),
         "--cells", "2000", "--transfer", "rbf", "-q"],
        check=True,
    )
    report = rigidcells.solve_files(tiles, BEND_AUTZEN, py_field, cells=2000, transfer="rbf", progress=False)
    assert py_field.read_bytes() == cli_field.read_bytes() and report.cells > 1000
    out_cli, out_py = tmp_path / "cli.laz", tmp_path / "py.laz"
    subprocess.run(
        [cli(), "apply", str(cli_field), str(tiles[0]), "-o", str(out_cli), "--rbf-tolerance", "0.01", "-q"],
        check=True,
    )
    rigidcells.apply_file(py_field, tiles[0], out_py, rbf_tolerance=0.01, chunk=1000, progress=False)
    assert out_py.read_bytes() == out_cli.read_bytes()
    with pytest.raises(ValueError, match=r'rbf_tolerance applies to transfer="rbf" only'):
        rigidcells.apply_file(py_field, tiles[0], tmp_path / "x.laz", transfer="pu", rbf_tolerance=0.01)


def test_solve_files_reports_and_refuses_as_the_command_line_does(tmp_path):
    import json

    tiles = [SHARED / "las" / "autzen_trim.laz", SHARED / "las" / "autzen_trim.las"]
    spec = dict(BEND_AUTZEN)
    spec["target"] = [{"from": [636600.0, 849200.0, 430.0], "to": [636600.5, 849200.0, 430.0], "snap": 30.0}]
    edit = tmp_path / "edit.toml"
    edit.write_text(rigidcells._rigidcells.toml_from_json(json.dumps(spec)))
    subprocess.run(
        [cli(), "solve", *map(str, tiles), "--edit", str(edit), "--save-field", str(tmp_path / "c.field"),
         "--cells", "2000", "--check-gcp", "--report", str(tmp_path / "c.json"), "-q"],
        check=True,
    )
    report = rigidcells.solve_files(
        tiles, spec, tmp_path / "p.field", cells=2000, check_gcp=True, report=tmp_path / "p.json",
        progress=False,
    )
    assert (tmp_path / "p.field").read_bytes() == (tmp_path / "c.field").read_bytes()
    a, b = (json.loads((tmp_path / f"{n}.json").read_text()) for n in ("c", "p"))
    for key in ("control_rmse", "control_rmse_left_out", "cells", "energy"):
        assert a[key] == b[key], key
    # The same points; where each was given is named by the spec's file or the dict.
    for p, q in zip(a["control_points"], b["control_points"]):
        assert p.pop("place") == "edit.toml line 14" and q.pop("place") == "spec line 14"
        assert p == q
    assert report.control_points[0]["residual"] == a["control_points"][0]["residual"]
    assert a["control_points"][0]["left_out"] is not None
    # Tiles in two coordinate systems: a ValueError naming both and the argument that overrides.
    other = SHARED / "las" / "1_4_w_evlr.las"
    with pytest.raises(ValueError, match=r"EPSG:2903") as e:
        rigidcells.solve_files([tiles[0], other], spec, tmp_path / "x.field", progress=False)
    assert "same_crs" in str(e.value) or "same-crs" in str(e.value)
    assert not (tmp_path / "x.field").exists()


def test_the_report_is_typed_and_says_what_the_cli_report_says(tmp_path):
    pts = bar_points()
    moved, report = rigidcells.deform(pts, BEND, cells=600, progress=False)
    assert isinstance(report, rigidcells.Report)
    assert report.points == len(pts) and report.iterations > 0 and report.converged
    # Fixed samples keep their bytes, handle samples follow the handle.
    assert report.residual_fixed_max == 0.0 and report.residual_handle_max < 1e-12
    assert set(report.timings_s) == {"read", "voxelize", "solve", "transfer", "write", "check_gcp", "total"}
    assert report.timings_s["total"] >= report.timings_s["solve"] > 0
    # The chosen cell size: the one `cells=` picked, within 2 % of the count asked.
    assert abs(report.cells - 600) <= 0.02 * 600 or report.cell_size > 0
    again, r2 = rigidcells.deform(pts, BEND, cell_size=report.cell_size, progress=False)
    assert np.array_equal(again, moved) and r2.cells == report.cells
    assert report["cells"] == report.cells and "energy" in report
    # The options as given, by this package's keywords; None where the run decided.
    assert report.options["cells"] == 600 and report.options["cell_size"] is None
    assert report.options["transfer"] == "pu" and report.options["interior_stiffness"] == 0.05
    assert r2.options["cell_size"] == report.cell_size and r2.options["cells"] is None
    # A count the search cannot reach within 2 % is said, in Python's terms.
    thin = np.random.default_rng(0).uniform([0, 0, 0], [10, 1, 1], (20_000, 3))
    _, r3 = rigidcells.deform(thin, BEND, cells=1000, progress=False)
    assert abs(r3.cells / 1000 - 1) > 0.02
    assert any(w.startswith(f"cells=1000: {r3.cells} cells (") for w in r3.warnings), r3.warnings
    field = rigidcells.solve(pts, BEND, cells=600, progress=False)
    assert field.report.cells == report.cells and field.cell_size == pytest.approx(report.cell_size)
    lo, hi = field.bounds
    assert all(l <= p for l, p in zip(lo, pts.min(axis=0))) and all(h >= p for h, p in zip(hi, pts.max(axis=0)))
    assert "cells of" in repr(field) and field.transfer == "pu"
    assert field.levels[0][0] == field.cell_size and sum(n for _, n in field.levels) == field.cells


def test_options_are_checked_by_name():
    pts = bar_points()
    with pytest.raises(ValueError, match=r"^cells must be"):
        rigidcells.deform(pts, BEND, cells=-1)
    with pytest.raises(TypeError, match=r"^cells must be .* got a bool"):
        rigidcells.deform(pts, BEND, cells=True)
    with pytest.raises(ValueError, match=r"cell_size and cells both size the cells"):
        rigidcells.deform(pts, BEND, cells=100, cell_size=0.5)
    with pytest.raises(ValueError) as e:
        rigidcells.deform(pts, BEND, transfer="blend", rbf_tolerance=0.1)
    assert str(e.value) == 'rbf_tolerance applies to transfer="rbf" only'
    with pytest.raises(ValueError, match=r"solver `fast`: expected auto, direct, multilevel or local-global"):
        rigidcells.deform(pts, BEND, solver="fast")
    with pytest.raises(ValueError, match=r"^coarse_levels must be 0 to 8"):
        rigidcells.deform(pts, BEND, coarse_levels=9)
    with pytest.raises(ValueError, match=r"memory_limit"):
        rigidcells.deform(pts, BEND, memory_limit="lots")
    # A message that names a remedy names the argument, never a command-line flag.
    with pytest.raises(ValueError) as e:
        rigidcells.deform(pts, BEND, cell_size=1e-9, memory_limit="64M")
    assert "--" not in str(e.value) and "cell_size" in str(e.value), e.value
    # A file name keeps its dashes.
    with pytest.raises(OSError, match="no--such--file.laz"):
        rigidcells.deform_file("no--such--file.laz", "out.laz", BEND)


def test_a_softer_inside_gives_the_command_lines_bytes_and_another_shape(tmp_path):
    """The hollow bar (its surface's points) has cells inside at 0.25, found by the flood fill:
    `interior_stiffness` reaches them as `--interior-stiffness` does, and bends the bar
    otherwise than the solid's default."""
    pts = bar_points()
    hollow = pts[(np.isin(pts[:, 0], [0.0, 10.0])) | np.any(np.isin(pts[:, 1:], [0.0, 1.0]), axis=1)]
    xyz = tmp_path / "hollow.xyz"
    xyz.write_text("".join(f"{x:.17e} {y:.17e} {z:.17e}\n" for x, y, z in hollow))
    edit = tmp_path / "bend.toml"
    edit.write_text(BEND)
    solid, out, ours = tmp_path / "solid.xyz", tmp_path / "cli.xyz", tmp_path / "py.xyz"
    run = [cli(), "deform", str(xyz), "--edit", str(edit), "-q", "--cell-size", "0.25"]
    subprocess.run([*run, "-o", str(solid)], check=True)
    subprocess.run([*run, "-o", str(out), "--interior-stiffness", "0.1"], check=True)
    rigidcells.deform_file(
        xyz, ours, edit, cell_size=0.25, interior_stiffness=0.1, progress=False
    )
    assert ours.read_bytes() == out.read_bytes()
    a = np.loadtxt(out)
    b = np.loadtxt(solid)
    assert np.abs(a - b).max() > 1e-3
    # The estimate counts the cells the run starts from: adaptive cells merge only cells of one
    # stiffness, so a softer inside keeps more of them (629 against the solid's 92).
    for stiffness in (1.0, 0.1):
        options = {"min_cell_size": 0.25, "interior_stiffness": stiffness}
        estimate = rigidcells.estimate(hollow, BEND, **options)
        with warnings.catch_warnings():  # the solid's refinement stops at 8× its cells
            warnings.simplefilter("ignore", rigidcells.RigidCellsWarning)
            _, report = rigidcells.deform(hollow, BEND, progress=False, **options)
        assert estimate.cells == report.cells_initial, stiffness


BAD_OPTIONS = [
    ({"cell_size": -1}, "cell_size"),
    ({"cell_size": 1e-9, "memory_limit": "64M"}, "cell_size"),
    ({"cells": 0}, "cells"),
    ({"cells": 100, "cell_size": 0.5}, "cells"),
    ({"min_cell_size": -1}, "min_cell_size"),
    ({"max_level": 99}, "max_level"),
    ({"shell": True, "inside": "winding"}, "inside"),
    ({"inside": "outside"}, "inside"),
    ({"interior_stiffness": 0}, "interior_stiffness"),
    ({"shell": True, "interior_stiffness": 0.1}, "interior_stiffness"),
    ({"solver": "fast"}, "solver"),
    ({"tolerance": -1}, "tolerance"),
    ({"coarse_levels": 9}, "coarse_levels"),
    ({"loose_parts": "drift"}, "loose_parts"),
    ({"refine_strain": -1}, "refine_strain"),
    ({"transfer": "smooth"}, "transfer"),
    ({"transfer": "blend", "rbf_tolerance": 0.1}, "rbf_tolerance"),
    ({"transfer": "rbf", "rbf_tolerance": -1}, "rbf_tolerance"),
    ({"memory_limit": "lots"}, "memory_limit"),
    ({"memory_limit": -5}, "memory_limit"),
    ({"memory_limit": 0}, "memory_limit under a byte: no run fits"),
    ({"memory_limit": "0.5"}, "memory_limit under a byte: no run fits"),
    ({"chunk": 0}, "chunk"),
    ({"chunk": -1}, "chunk"),
    ({"outside": "sideways"}, "outside"),
]


def _faces(tmp_path):
    """Each face of the package, called with keyword options on the bar."""
    pts = bar_points()
    xyz = tmp_path / "bar.xyz"
    xyz.write_text("".join(f"{x:.17e} {y:.17e} {z:.17e}\n" for x, y, z in pts))
    field = tmp_path / "bar.field"
    rigidcells.solve(pts, BEND, cell_size=0.5, progress=False).save(field)
    out = tmp_path / "out"
    out.mkdir()
    return {
        "deform": lambda **o: rigidcells.deform(pts, BEND, progress=False, **o),
        "deform_file": lambda **o: rigidcells.deform_file(
            xyz, out / "d.xyz", BEND, progress=False, **o
        ),
        "apply_file": lambda **o: rigidcells.apply_file(
            field, xyz, out / "a.xyz", progress=False, **o
        ),
        "solve_files": lambda **o: rigidcells.solve_files(
            xyz, BEND, out / "s.field", progress=False, **o
        ),
        "Session": lambda **o: rigidcells.Session(pts, BEND, **o),
    }, {
        "deform": rigidcells.deform,
        "deform_file": rigidcells.deform_file,
        "apply_file": rigidcells.apply_file,
        "solve_files": rigidcells.solve_files,
        "Session": rigidcells.Session.__init__,
    }, out


def test_bad_arguments_are_named_as_arguments_on_every_face(tmp_path):
    import inspect

    faces, signatures, out = _faces(tmp_path)
    checked = 0
    for name, call in faces.items():
        takes = inspect.signature(signatures[name]).parameters
        for options, arg in BAD_OPTIONS:
            if not all(k in takes for k in options):
                continue
            with pytest.raises((ValueError, TypeError)) as e:
                call(**options)
            said = str(e.value)
            where = f"{name}(**{options}): {said}"
            assert arg in said and "--" not in said, where
            checked += 1
    assert checked > 60, checked
    assert os.listdir(out) == []


def test_inputs_python_would_misread_are_refused():
    pts = bar_points()
    for bad, kind in ((pts.astype(complex), "complex"), (pts > 1, "bool")):
        with pytest.raises(TypeError, match=f"points must hold real numbers, got {kind}"):
            rigidcells.deform(bad, BEND)
    with pytest.raises(TypeError, match="masked array"):
        rigidcells.deform(np.ma.masked_array(pts, mask=np.zeros_like(pts, dtype=bool)), BEND)
    with pytest.raises(TypeError, match="normals must hold real numbers"):
        rigidcells.deform(pts, BEND, normals=np.ones_like(pts, dtype=bool))
    with pytest.raises(TypeError, match="triangles must be integer vertex indices"):
        rigidcells.deform(pts, BEND, triangles=[[0, 1, 2.5]])


def test_dict_specs_take_numpy_values_and_errors_name_the_key():
    pts = bar_points()
    plain, _ = rigidcells.deform(pts, BEND_DICT, cell_size=0.25, progress=False)
    numpy_spec = copy.deepcopy(BEND_DICT)
    numpy_spec["fixed"][0]["box"]["min"] = np.array([-0.1, -0.1, -0.1])
    numpy_spec["handle"][0]["translate"] = np.array([-3.4, 0.0, 5.9], dtype=np.float64)
    numpy_spec["handle"][0]["rotate"]["axis"] = [np.int64(0), np.float32(1.0), np.int32(0)]
    numpy_spec["handle"][0]["rotate"]["degrees"] = np.float64(-90.0)
    moved, _ = rigidcells.deform(pts, numpy_spec, cell_size=0.25, progress=False)
    assert np.array_equal(moved, plain)
    bad = copy.deepcopy(BEND_DICT)
    bad["handle"][0]["translate"] = [1.0, 2.0]
    with pytest.raises(ValueError) as e:
        rigidcells.deform(pts, bad)
    assert str(e.value).startswith('spec["handle"][0]["translate"]: '), e.value
    assert "line" not in str(e.value)


def test_a_field_pickles_and_applies_what_deform_takes():
    pts = bar_points()
    field = rigidcells.solve(pts, BEND, cell_size=0.25, progress=False)
    moved = field.apply(pts)
    for copied in (pickle.loads(pickle.dumps(field)), copy.deepcopy(field)):
        assert np.array_equal(copied.apply(pts), moved) and copied.cells == field.cells
    assert np.array_equal(field.apply(pts.tolist()), moved)
    # float32 points are moved as the float64 numbers they are, and come back float32.
    single = field.apply(pts.astype(np.float32))
    assert single.dtype == np.float32
    assert np.array_equal(single, field.apply(pts.astype(np.float32).astype(np.float64)).astype(np.float32))
    structured = np.zeros(len(pts), dtype=[("X", "f8"), ("Y", "f8"), ("Z", "f8"), ("i", "u2")])
    structured["X"], structured["Y"], structured["Z"] = pts.T
    out = field.apply(structured)
    assert out.dtype == structured.dtype and np.array_equal(out["X"], moved[:, 0])
    # Normals turn as deform turns them.
    normals = np.tile([0.0, 0.0, 1.0], (len(pts), 1))
    _, report = rigidcells.deform(pts, BEND, cell_size=0.25, normals=normals, progress=False)
    got, turned = field.apply(pts, normals=normals)
    assert np.array_equal(got, moved) and np.allclose(turned, report.normals, atol=1e-12)
    # Beyond the margin: refused by default, kept or extended when asked.
    far = np.array([[100.0, 0.0, 0.0]])
    with pytest.raises(ValueError, match='outside="keep"'):
        field.apply(far)
    assert np.array_equal(field.apply(far, outside="keep"), far)
    assert not np.array_equal(field.apply(far, outside="extend"), far)
    with pytest.raises(ValueError, match="point 0 has a coordinate that is not a finite number"):
        field.apply(np.array([[np.nan, 0.0, 0.0]]))


def test_progress_reaches_a_callable_and_an_exception_there_stops_the_call(tmp_path):
    pts = bar_points()
    seen = []
    rigidcells.deform(pts, BEND, cell_size=0.25, progress=lambda *a: seen.append(a))
    stages = [s for s, _, _ in seen]
    assert "solving" in stages and all(d >= 0 for _, d, _ in seen)

    class Stop(Exception):
        pass

    def stop(stage, done, total):
        if stage == "solving":
            raise Stop()

    with pytest.raises(Stop):
        rigidcells.deform(pts, BEND, cell_size=0.25, progress=stop)
    out = tmp_path / "out.laz"
    with pytest.raises(Stop):
        rigidcells.deform_file(SHARED / "las" / "autzen_trim.laz", out, BEND_AUTZEN, progress=stop)
    assert os.listdir(tmp_path) == []


BEND_AUTZEN = {
    "fixed": [{"box": {"min": [636000, 848900, 0], "max": [636300, 849600, 1000]}}],
    "handle": [{"box": {"min": [636900, 848900, 0], "max": [637200, 849600, 1000]}, "translate": [0, 0, 20]}],
}


@pytest.fixture
def ctrl_c():
    """Python's own Ctrl-C handler, as in a terminal (a shell starts background jobs with
    SIGINT ignored, and Python then installs none)."""
    before = signal.signal(signal.SIGINT, signal.default_int_handler)
    yield
    signal.signal(signal.SIGINT, before)


def interrupt_after(seconds):
    """Sends this process SIGINT (Ctrl-C) after `seconds`; returns when it was sent."""
    sent = {}

    def fire():
        sent["at"] = time.monotonic()
        os.kill(os.getpid(), signal.SIGINT)

    timer = threading.Timer(seconds, fire)
    timer.start()
    return sent, timer


def test_ctrl_c_stops_a_call_within_a_second_and_leaves_no_file(tmp_path, ctrl_c):
    rng = np.random.default_rng(1)
    pts = rng.uniform([0, 0, 0], [40, 10, 4], size=(300_000, 3))
    spec = {
        "fixed": [{"box": {"min": [-1, -1, -1], "max": [2, 11, 5]}}],
        "handle": [{"box": {"min": [38, -1, -1], "max": [41, 11, 5]},
                    "rotate": {"axis": [1, 0, 0], "degrees": 170}}],
    }
    # Steps of a fraction of a second (a Gauss-Newton iteration at 20k cells), so that the
    # bound holds on a loaded machine too.
    sent, timer = interrupt_after(0.5)
    start = time.monotonic()
    with pytest.raises(KeyboardInterrupt):
        rigidcells.deform(pts, spec, cells=20_000, progress=False)
        pytest.fail(f"the call ended after {time.monotonic() - start:.1f} s before Ctrl-C")
    timer.join()
    assert time.monotonic() - sent["at"] < 1.0
    # A file: the output is not left behind, complete or not.
    out = tmp_path / "bent.laz"
    sent, timer = interrupt_after(0.3)
    with pytest.raises(KeyboardInterrupt):
        rigidcells.deform_file(SHARED / "las" / "autzen_trim.laz", out, BEND_AUTZEN, cells=20_000, progress=False)
    timer.join()
    assert time.monotonic() - sent["at"] < 1.0
    assert os.listdir(tmp_path) == []


def test_a_tqdm_bar_shows_where_asked(capsys):
    pytest.importorskip("tqdm")
    rigidcells.deform(bar_points(), BEND, cell_size=0.25, progress=True)
    assert "solving" in capsys.readouterr().err
    # Not a terminal, not asked: no bar.
    rigidcells.deform(bar_points(), BEND, cell_size=0.25)
    assert capsys.readouterr().err == ""


def test_cells_sizes_samples_in_memory_as_the_command_line_sizes_their_file(tmp_path):
    laspy = pytest.importorskip("laspy")
    import json

    src = SHARED / "las" / "autzen_trim.laz"
    edit = tmp_path / "edit.toml"
    edit.write_text(rigidcells._rigidcells.toml_from_json(json.dumps(BEND_AUTZEN)))
    out = tmp_path / "cli.laz"
    subprocess.run(
        [cli(), "deform", str(src), "-o", str(out), "--edit", str(edit), "--cells", "5000", "-q"],
        check=True,
    )
    bent, report = rigidcells.deform(laspy.read(src), BEND_AUTZEN, cells=5000, progress=False)
    written = laspy.read(out)
    assert np.array_equal(bent.points.array["Z"], written.points.array["Z"])
    assert np.array_equal(bent.points.array["X"], written.points.array["X"])
    assert report.cells == rigidcells.deform_file(src, tmp_path / "py.laz", edit, cells=5000, progress=False).cells


def test_mistakes_are_said_in_python_terms(tmp_path):
    pts = bar_points()
    for value, said in ((np.nan, "nan is not a finite number"), (None, "None is not a value")):
        bad = copy.deepcopy(BEND_DICT)
        bad["handle"][0]["translate"] = [value, 0.0, 0.0]
        with pytest.raises(ValueError, match=r'^spec\["handle"\]\[0\]\["translate"\]\[0\]: ' + said):
            rigidcells.deform(pts, bad)
    bad = copy.deepcopy(BEND_DICT)
    bad["handle"] = bad["handle"][0]
    with pytest.raises(ValueError, match=r'^spec\["handle"\]: expected a list, got a dict$'):
        rigidcells.deform(pts, bad)
    # A warning that names a spec's line names the dict's key path.
    loose = copy.deepcopy(BEND_DICT)
    loose["fixed"].append({"box": {"min": [100, 100, 100], "max": [101, 101, 101]}})
    _, report = rigidcells.deform(pts, loose, cell_size=0.25, progress=False)
    assert report.warnings and all("line" not in w for w in report.warnings), report.warnings
    assert report.handle_turns[0]["key"] == 'spec["handle"][0]'
    assert report.handle_turns[0]["line"] is None
    assert report.foldovers_checked > 0 and report.residual_max == 0.0 and "points" in report.keys()
    # Arguments.
    with pytest.raises(ValueError, match="^the input has no points$"):
        rigidcells.deform(np.zeros((0, 3)), BEND)
    with pytest.raises(ValueError, match="^tolerance=-1: a number of finest cell sizes"):
        rigidcells.deform(pts, BEND, tolerance=-1)
    with pytest.raises(ValueError, match="^min_cell_size=-1 must be positive"):
        rigidcells.deform(pts, BEND, min_cell_size=-1)
    with pytest.raises(ValueError, match="^cell_size=-1 must be positive"):
        rigidcells.deform(pts, BEND, cell_size=-1)
    with pytest.raises(ValueError, match='^shell keeps no inside; inside="winding" asks for one'):
        rigidcells.deform(pts, BEND, shell=True, inside="winding")
    src = SHARED / "las" / "autzen_trim.laz"
    with pytest.raises(ValueError, match="^strain applies to the preview: pass preview= too"):
        rigidcells.deform_file(src, tmp_path / "x.laz", BEND_AUTZEN, strain=True)
    with pytest.raises(ValueError, match="^size=\\(0, 5\\): 16 to 8192 pixels each way"):
        rigidcells.deform_file(src, tmp_path / "x.laz", BEND_AUTZEN, preview=tmp_path / "p.png", size=(-1, 5))
    # One tile as a path, not a list of them.
    report = rigidcells.solve_files(src, BEND_AUTZEN, tmp_path / "f.field", cells=500, progress=False)
    assert report.points == 110000
    assert os.listdir(tmp_path) == ["f.field"]


def test_a_pickled_field_keeps_its_report_and_equals_itself():
    field = rigidcells.solve(bar_points(), BEND, cell_size=0.25, progress=False)
    back = pickle.loads(pickle.dumps(field))
    assert back == field and back.report == field.report and back.report.cells == field.cells
    assert field != rigidcells.solve(bar_points(), BEND, cell_size=0.5, progress=False)


def test_a_chunk_past_the_largest_is_taken_as_the_largest_as_the_cli_takes_it(tmp_path):
    """``chunk`` above 16,777,216 writes what the largest chunk writes, as ``--chunk`` does."""
    pts = bar_points()
    xyz = tmp_path / "bar.xyz"
    xyz.write_text("".join(f"{x:.17e} {y:.17e} {z:.17e}\n" for x, y, z in pts))
    outs = []
    for chunk in (16_777_216, 2**40):
        out = tmp_path / f"out{chunk}.xyz"
        rigidcells.deform_file(xyz, out, BEND, cell_size=0.5, chunk=chunk, progress=False)
        outs.append(out.read_bytes())
    assert outs[0] == outs[1]


def test_a_refused_turn_names_the_handle_as_the_spec_was_written():
    """A turn the shape gives way under is a ``TurnNotHeldError`` (a ``ValueError``) whose
    fields say which handle, a bend or a twist, and the degrees; its message names the handle
    as the spec was written: a dict's key path, a TOML spec's line."""
    import json

    g = np.linspace(0.0, 1.0, 11)
    cube = np.ascontiguousarray(np.stack(np.meshgrid(g, g, g, indexing="ij"), axis=-1).reshape(-1, 3))
    spec = {
        "fixed": [{"box": {"min": [-1, -1, -1], "max": [2, 2, 0.1]}}],
        "handle": [
            {"box": {"min": [-1, -1, 0.9], "max": [2, 2, 2]}, "rotate": {"axis": [0, 0, 1], "degrees": 360}},
        ],
    }
    with pytest.raises(rigidcells.TurnNotHeldError) as raised:
        rigidcells.deform(cube, spec, cell_size=0.1, progress=False)
    e = raised.value
    assert isinstance(e, ValueError)
    assert str(e).startswith('spec["handle"][0] twists by 360°, but the shape'), str(e)
    assert "line" not in str(e) and "edit spec" not in str(e) and "bend" not in str(e), str(e)
    text = rigidcells._rigidcells.toml_from_json(json.dumps(spec))
    line = text.splitlines().index("[[handle]]") + 1
    # A dict has no lines: the TOML it became is the package's.
    assert (e.handle, e.line, e.kind, e.asked_degrees) == (0, None, "twist", 360.0)
    assert 90.0 < e.held_degrees < 300.0 and f"past {e.held_degrees:g}°" in str(e), str(e)
    assert e.other_way_degrees is None and str(e).endswith(e.said)
    with pytest.raises(rigidcells.TurnNotHeldError, match=rf"^handle #1 \(line {line}\) twists by 360°") as raised:
        rigidcells.deform(cube, text, cell_size=0.1, progress=False)
    assert raised.value.line == line
    # The second handle is spec["handle"][1], whatever line of TOML it became.
    still = {"box": {"min": [-1, -1, 0.45], "max": [2, 2, 0.55]}, "translate": [0, 0, 0]}
    spec["handle"].insert(0, still)
    with pytest.raises(rigidcells.TurnNotHeldError, match=r'^spec\["handle"\]\[1\] twists by 360°') as raised:
        rigidcells.deform(cube, spec, cell_size=0.1, progress=False)
    assert raised.value.handle == 1


def test_entries_are_named_by_key_path_or_line():
    """A warning or an error about an entry names it as the spec was written: a dict's key path
    (`spec["handle"][1]`), a TOML spec's `handle #2 (line N)`."""
    import json

    g = np.linspace(0.0, 1.0, 11)
    cube = np.ascontiguousarray(np.stack(np.meshgrid(g, g, g, indexing="ij"), axis=-1).reshape(-1, 3))
    nowhere = {"box": {"min": [5, 5, 5], "max": [6, 6, 6]}, "translate": [0, 0, 0.1]}
    spec = {
        "fixed": [{"box": {"min": [-1, -1, -1], "max": [2, 2, 0.1]}}],
        "handle": [{"box": {"min": [-1, -1, 0.9], "max": [2, 2, 2]}, "translate": [0, 0, 0.1]}, nowhere],
    }
    _, report = rigidcells.deform(cube, spec, cell_size=0.1, progress=False)
    assert 'spec["handle"][1] selects no cell' in report.warnings, report.warnings
    text = rigidcells._rigidcells.toml_from_json(json.dumps(spec))
    line = [k + 1 for k, t in enumerate(text.splitlines()) if t == "[[handle]]"][1]
    _, report = rigidcells.deform(cube, text, cell_size=0.1, progress=False)
    assert f"handle #2 (line {line}) selects no cell" in report.warnings, report.warnings
    # Another face's terms (the Blender add-on's): its own name for each entry.
    named = report.warnings_in(entry=lambda kind, index: f"{kind} {index + 1} of the panel")
    assert "handle 2 of the panel selects no cell" in named, named
    # Two entries claiming the same cells: both named by key path.
    spec["handle"][1] = {"box": {"min": [-1, -1, -1], "max": [2, 2, 0.1]}, "translate": [0, 0, 0.1]}
    with pytest.raises(ValueError) as e:
        rigidcells.deform(cube, spec, cell_size=0.1, progress=False)
    assert 'spec["fixed"][0]' in str(e.value) and 'spec["handle"][1]' in str(e.value), e.value
    assert "line" not in str(e.value), e.value


def test_the_points_that_fold_are_listed():
    """An edit that pushes a bar's end through its middle folds space over: the report lists
    the points where, by index, as many as it counts; a plain bend lists none."""
    pts = bar_points()
    spec = {
        "fixed": [{"box": {"min": [-1, -1, -1], "max": [2, 2, 2]}}],
        "handle": [{"box": {"min": [8, -1, -1], "max": [11, 2, 2]}, "translate": [-7, 0, 0]}],
    }
    _, report = rigidcells.deform(pts, spec, cell_size=0.5, progress=False)
    folded = report.foldover_samples
    assert report.foldovers == len(folded) > 0, report.foldovers
    assert folded == sorted(set(folded)) and 0 <= folded[0] and folded[-1] < len(pts)
    assert any("folds space over" in w for w in report.warnings)
    _, report = rigidcells.deform(pts, BEND, cell_size=0.5, progress=False)
    assert report.foldovers == 0 and report.foldover_samples == []


def test_control_points_take_the_trend_as_the_command_line_does(tmp_path):
    """A scan pulled onto control points from a CSV with a dict spec and a chosen trend: the
    command line's bytes, the trend in the report, and a bad trend named as the dict's key."""
    scan = SHARED / "las" / "autzen_trim.laz"
    rows = ["id,x,y,X,Y"]
    for k, (x, y) in enumerate([(636200, 849000), (637000, 849000), (636600, 849450), (636300, 849300)]):
        rows.append(f"P{k},{x},{y},{x + 0.5 + 2e-4 * (y - 849000)},{y - 0.3}")
    (tmp_path / "gcp.csv").write_text("\n".join(rows) + "\n")
    toml = tmp_path / "edit.toml"
    toml.write_text('trend = "affine"\n[[target]]\nfile = "gcp.csv"\nweight = 10\n')
    out, ours = tmp_path / "cli.laz", tmp_path / "py.laz"
    subprocess.run([cli(), "deform", str(scan), "-o", str(out), "--edit", str(toml), "-q"], check=True)
    spec = {"trend": "affine", "target": [{"file": str(tmp_path / "gcp.csv"), "weight": 10}]}
    report = rigidcells.deform_file(scan, ours, spec, progress=False)
    assert ours.read_bytes() == out.read_bytes()
    assert report.control_trend == "affine" and report.control_rmse < 1e-3
    # Without `trend`, control points from a file take the spline.
    del spec["trend"]
    assert rigidcells.deform_file(scan, ours, spec, progress=False).control_trend == "spline"
    spec["trend"] = "helmert"
    with pytest.raises(ValueError) as e:
        rigidcells.deform_file(scan, ours, spec, progress=False)
    assert str(e.value).startswith('spec["trend"]: '), e.value
    assert '"similarity"' in str(e.value) and "line 1" not in str(e.value)


def test_checkpoints_are_scored_in_the_report(tmp_path):
    """Rows marked as checks: scored as the command line scores them, not solved for."""
    scan = SHARED / "las" / "autzen_trim.laz"
    rows = ["id,x,y,X,Y,type"]
    for x in (636200, 636600, 637000):
        for y in (849000, 849200, 849400):
            rows.append(f"P{x}{y},{x},{y},{x + 0.5},{y},gcp")
    rows.append("C1,636400,849100,636400.53,849100,check")
    (tmp_path / "gcp.csv").write_text("\n".join(rows) + "\n")
    spec = {"target": [{"file": str(tmp_path / "gcp.csv"), "weight": 10}]}
    report = rigidcells.deform_file(scan, tmp_path / "out.laz", spec, progress=False)
    a = report.checkpoints
    assert a["count"] == 1 and abs(a["rmse_x"] - 0.03) < 1e-3 and a["rmse_z"] is None
    assert abs(a["accuracy_r_95"] - 1.7308 * a["rmse_r"]) < 1e-12
    assert [p["check"] for p in report.control_points].count(True) == 1
