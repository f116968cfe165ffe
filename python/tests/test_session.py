"""The live session: poses dragged a short solver step at a time, previewed, and
released onto what `deform` gives for the last pose; its errors in Python's terms; its calls
free of the GIL, so that a face can run it on a thread of its own."""

import threading
import time

import numpy as np
import pytest

import rigidcells
from test_rigidcells import bar_points


def bar_spec(pts, turn=0.0, lift=0.0):
    """The bar's left end fixed, its right end turned about y and lifted."""
    return {
        "fixed": [{"indices": np.nonzero(pts[:, 0] < 1.0)[0]}],
        "handle": [
            {
                "indices": np.nonzero(pts[:, 0] > 9.0)[0],
                "rotate": {"axis": [0.0, 1.0, 0.0], "degrees": turn},
                "translate": [0.0, 0.0, lift],
                "pivot": [10.0, 0.5, 0.5],
            }
        ],
    }


def test_a_drag_ends_on_the_shape_deform_gives():
    pts = bar_points()
    live = rigidcells.Session(pts, bar_spec(pts), cell_size=0.25)
    assert live.last.from_rest and live.last.converged and live.cells > 100
    assert np.abs(live.preview() - pts).max() < 1e-12
    tip = int(np.argmax(pts[:, 0] + pts[:, 2]))
    rises, iterations = [], []
    for k in range(1, 13):
        f = k / 12
        step = live.drag({"rotate": {"axis": [0, 1, 0], "degrees": -40 * f},
                          "translate": [0, 0, 3 * f], "pivot": [10.0, 0.5, 0.5]})
        assert not step.from_rest and step.iterations >= 1
        iterations.append(step.iterations)
        rises.append(live.preview()[tip, 2] - pts[tip, 2])
    assert all(b > a for a, b in zip(rises, rises[1:])), rises
    # Short steps (one Gauss-Newton iteration, or two local-global ones), but for the one pose
    # that goes more than a load step (30°) past the rest pose: the pose before it is converged
    # first, and that step counts its iterations.
    assert sum(n > 4 for n in iterations) == 1 and iterations[-1] <= 4, iterations
    while live.refine():
        pass
    assert live.converged
    moved, report = live.release()
    assert report.converged and report.cells == live.cells
    expected, _ = rigidcells.deform(pts, bar_spec(pts, -40.0, 3.0), cell_size=0.25)
    # Both converge to the solver's move test (a thousandth of a cell) from other starts.
    assert np.abs(moved - expected).max() < 1e-3 * live.cell_size
    fixed = pts[:, 0] < 1.0
    assert np.array_equal(moved[fixed], pts[fixed])
    assert report.residual_max < 1e-9


def test_a_whole_spec_with_other_regions_solves_from_rest():
    pts = bar_points()
    live = rigidcells.Session(pts, bar_spec(pts, lift=1.0), cell_size=0.25)
    same = live.solve(bar_spec(pts, lift=2.0))
    assert not same.from_rest and same.converged
    other = bar_spec(pts, lift=2.0)
    other["fixed"] = [{"indices": np.nonzero(pts[:, 0] < 2.0)[0]}]
    assert live.solve(other).from_rest
    moved, _ = live.release()
    expected, _ = rigidcells.deform(pts, other, cell_size=0.25)
    assert np.abs(moved - expected).max() < 1e-3 * live.cell_size


def test_release_gives_the_points_back_in_their_form():
    pts = bar_points()
    structured = np.zeros(len(pts), dtype=[("X", "f8"), ("Y", "f8"), ("Z", "f8"), ("i", "u2")])
    for k, name in enumerate("XYZ"):
        structured[name] = pts[:, k]
    structured["i"] = np.arange(len(pts)) % 7
    live = rigidcells.Session(structured, bar_spec(pts, lift=2.0), cell_size=0.25)
    moved, _ = live.release()
    assert moved.dtype == structured.dtype
    assert np.array_equal(moved["i"], structured["i"])
    assert moved["Z"].max() > pts[:, 2].max() + 1.5


def test_errors_name_the_poses_and_arguments():
    pts = bar_points()
    live = rigidcells.Session(pts, bar_spec(pts), cell_size=0.25)
    with pytest.raises(ValueError, match=r"^poses\[0\]: unknown key `box`"):
        live.drag({"box": {"min": [0, 0, 0], "max": [1, 1, 1]}})
    with pytest.raises(ValueError, match=r"poses\[0\]\[\"translate\"\]\[2\]: nan"):
        live.drag({"translate": [0, 0, float("nan")]})
    with pytest.raises(ValueError, match="2 poses for the spec's 1 handles"):
        live.drag([{"translate": [0, 0, 1]}, {"translate": [0, 0, 1]}])
    with pytest.raises(ValueError, match="iterations must be 1 or more"):
        live.drag({"translate": [0, 0, 1]}, iterations=0)
    with pytest.raises(TypeError, match="iterations must be a whole number"):
        live.solve(bar_spec(pts), iterations=True)
    with pytest.raises(ValueError, match="^min_cell_size refines .* give cell_size or cells"):
        rigidcells.Session(pts, bar_spec(pts), min_cell_size=0.1)
    with pytest.raises(TypeError, match="unexpected"):
        rigidcells.Session(pts, bar_spec(pts), cell_sise=0.25)
    # The session goes on after a refused pose.
    live.drag({"translate": [0, 0, 1]})
    assert live.preview()[:, 2].max() > 1.5


def test_a_step_on_a_thread_leaves_the_gil_free():
    pts = bar_points()
    live = rigidcells.Session(pts, bar_spec(pts), cell_size=0.2)
    other = bar_spec(pts, turn=-120.0, lift=4.0)
    other["fixed"] = [{"indices": np.nonzero(pts[:, 0] < 2.0)[0]}]
    ticks = []
    done = threading.Event()

    def work():
        live.solve(other)  # from rest, with load steps
        done.set()

    worker = threading.Thread(target=work)
    start = time.perf_counter()
    worker.start()
    while not done.is_set():
        ticks.append(time.perf_counter())
        time.sleep(0.001)
    worker.join()
    seconds = time.perf_counter() - start
    # Python ran on this thread all along the solve (a held GIL would allow no tick).
    assert seconds > 0.05 and len(ticks) > 10, (seconds, len(ticks))
    assert live.converged


@pytest.mark.parametrize(
    "key, entry",
    [
        ("pins", {"pin": [{"point": [5.0, 0.5, 1.0], "to": [5.0, 0.5, 1.0]}]}),
        # A soft target's pull moves with the drag (a Blender vertex weight's partial pull).
        ("targets", {"target": [{"from": [5.0, 0.5, 1.0], "to": [5.0, 0.5, 1.0], "weight": 4.0}]}),
    ],
)
def test_pins_and_targets_follow_a_drag(key, entry):
    pts = bar_points()
    spec = {**bar_spec(pts, lift=1.0), **entry}
    live = rigidcells.Session(pts, spec, cell_size=0.25)
    pose = {"translate": [0, 0, 1.0], "pivot": [10.0, 0.5, 0.5]}
    for z in (1.25, 1.5, 1.75, 2.0):
        assert not live.drag(pose, **{key: [[5.0, 0.5, z]]}).from_rest
    moved, _ = live.release()
    (table,) = entry
    spec[table][0]["to"] = [5.0, 0.5, 2.0]
    expected, _ = rigidcells.deform(pts, spec, cell_size=0.25)
    assert np.abs(moved - expected).max() < 1e-3 * live.cell_size
    with pytest.raises(ValueError, match=f"2 {key} for the spec's 1"):
        live.drag(pose, **{key: [[5.0, 0.5, 2.0], [5.0, 0.5, 2.0]]})
    with pytest.raises(ValueError, match=rf"{key}\[0\]"):
        live.drag(pose, **{key: [[5.0, 0.5, float("inf")]]})


def cube_points():
    """3,000 random points in a unit cube: most of its cells are parts of their own."""
    return np.random.default_rng(7).random((3000, 3))


CUBE = {
    "fixed": [{"box": {"min": [-1, -1, -1], "max": [0.2, 2, 2]}}],
    "handle": [{"box": {"min": [0.8, -1, -1], "max": [2, 2, 2]}, "translate": [0, 0, 0.3]}],
}


def test_a_release_without_a_drag_is_deform_bit_for_bit():
    pts = cube_points()
    still = {}
    for loose_parts in (None, "carry", "rest"):
        expected, report = rigidcells.deform(pts, CUBE, loose_parts=loose_parts)
        assert any("connected parts" in w for w in report.warnings), report.warnings
        live = rigidcells.Session(pts, CUBE, loose_parts=loose_parts)
        moved, released = live.release()
        assert np.array_equal(moved, expected), loose_parts
        assert released.warnings == report.warnings
        still[loose_parts] = [
            np.count_nonzero(np.all(shape == pts, axis=1)) for shape in (moved, live.preview())
        ]
    # The loose parts ride along by default, in the release and in the preview.
    assert still[None] == still["carry"]
    assert all(c < r - 500 for c, r in zip(still["carry"], still["rest"])), still


def test_calls_from_two_threads_wait_their_turn():
    pts = bar_points()
    live = rigidcells.Session(pts, bar_spec(pts), cell_size=0.2)
    other = bar_spec(pts, turn=-60.0, lift=2.0)
    other["fixed"] = [{"indices": np.nonzero(pts[:, 0] < 2.0)[0]}]
    errors = []

    def run(calls):
        try:
            for call in calls:
                call()
        except Exception as e:  # noqa: BLE001 - what the test reports
            errors.append(e)

    solving = threading.Thread(target=run, args=([lambda: live.solve(other)] * 3,))
    posing = threading.Thread(
        target=run,
        args=([lambda: live.drag({"translate": [0, 0, 1]}), live.preview, live.release] * 5,),
    )
    solving.start()
    posing.start()
    solving.join()
    posing.join()
    assert errors == []
    moved, _ = live.release()
    assert np.isfinite(moved).all()


def test_a_progress_callback_that_uses_its_session_is_refused():
    pts = bar_points()
    live = rigidcells.Session(pts, bar_spec(pts), cell_size=0.25)
    other = bar_spec(pts, lift=1.0)
    other["fixed"] = [{"indices": np.nonzero(pts[:, 0] < 2.0)[0]}]
    seen = []

    def touching(use):
        def progress(stage, done, total):
            try:
                use()
            except RuntimeError as e:
                seen.append(str(e))
                raise
        return progress

    def run():
        # The native session (`converged`), and the package's lock (`preview`, `drag`).
        for use in (lambda: live.converged, live.preview, lambda: live.drag({})):
            # Other regions: a solve from rest, which reports its progress.
            with pytest.raises(RuntimeError, match="busy with the call that runs this code"):
                live.solve(other, progress=touching(use))
            with pytest.raises(RuntimeError, match="busy with the call that runs this code"):
                live.release(progress=touching(use))

    # Run aside, so that a call that waits for itself fails the test instead of hanging it.
    errors = []
    worker = threading.Thread(target=lambda: _reported(run, errors), daemon=True)
    worker.start()
    worker.join(timeout=120)
    assert not worker.is_alive(), "a callback's call on its session waits for itself"
    assert errors == [] and len(seen) >= 6, (errors, seen)
    # The refused calls leave the session to the next caller.
    assert live.solve(other).converged
    moved, _ = live.release()
    assert np.isfinite(moved).all()


def _reported(f, errors):
    try:
        f()
    except BaseException as e:  # noqa: BLE001 - what the test reports
        errors.append(e)


def test_float32_points_and_normals_come_back_float32():
    pts = bar_points().astype(np.float32)
    normals = np.tile(np.array([0, 0, 1], np.float32), (len(pts), 1))
    moved, report = rigidcells.deform(pts, bar_spec(pts, lift=1.0), normals=normals, cell_size=0.25)
    assert moved.dtype == np.float32 and report.normals.dtype == np.float32
    live = rigidcells.Session(pts, bar_spec(pts, lift=1.0), normals=normals, cell_size=0.25)
    assert live.preview().dtype == np.float32
    released, report = live.release()
    assert released.dtype == np.float32 and report.normals.dtype == np.float32
    assert np.array_equal(released, moved)
    field = rigidcells.solve(pts, bar_spec(pts, lift=1.0), cell_size=0.25)
    applied, turned = field.apply(pts, normals=normals)
    assert applied.dtype == np.float32 and turned.dtype == np.float32
    assert field.apply(pts.astype(np.float64)).dtype == np.float64


def test_warnings_are_emitted_as_rigidcells_warnings():
    pts = cube_points()
    for call in (
        lambda: rigidcells.deform(pts, CUBE),
        lambda: rigidcells.solve(pts, CUBE),
        lambda: rigidcells.Session(pts, CUBE).release(),
    ):
        with pytest.warns(rigidcells.RigidCellsWarning, match="have no constraint and ride along"):
            call()
    assert issubclass(rigidcells.RigidCellsWarning, UserWarning)
