"""Live in Blender, timed as an artist drags: a mesh from ../shared/data with its lowest tenth
fixed and its highest tenth on the handle Empty, sized to about CELLS cells; the Empty moves
along a bend for SECONDS while a timer does what the Live operator's timer does, at its rate
(`LIVE_RATE`, or RATE a second: hand the Empty's pose to the session, write the newest shape
into the shape key). Prints the shapes written a second while the Empty moves, the time from
a pose to its shape, and the release once it rests.

    python tools/python/blender_live.py [MESH.ply] [CELLS] [SECONDS] [RATE]

(in a venv with `bpy` and `rigidcells`; MESH defaults to the dragon soup, 3,484 loose
triangles.)
"""

import statistics
import sys
import time
from pathlib import Path

import bpy  # first: mathutils comes with it
import numpy as np
from mathutils import Vector

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "blender"))
import rigidcells  # noqa: E402
import rigidcells_blender as addon  # noqa: E402

DATA = ROOT.parent / "shared" / "data" / "meshes"


def scene(path: Path, cells: int):
    bpy.ops.wm.read_factory_settings(use_empty=True)
    addon.register()
    bpy.ops.wm.ply_import(filepath=str(path))
    obj = bpy.context.selected_objects[0]
    bpy.context.view_layer.objects.active = obj
    co = addon._rest_vertices(obj.data)
    z = co[:, 2]
    low, high = np.quantile(z, 0.1), np.quantile(z, 0.9)
    for name, keep in (("fixed", z <= low), ("handle", z >= high)):
        obj.vertex_groups.new(name=name).add(np.nonzero(keep)[0].tolist(), 1.0, "REPLACE")
    top = co[z >= high].mean(axis=0)
    bpy.ops.object.empty_add(location=tuple(obj.matrix_world @ Vector(top)))
    empty = bpy.context.active_object
    bpy.context.view_layer.objects.active = obj
    s = obj.rigidcells
    s.fixed_group, s.handle_group, s.handle_object = "fixed", "handle", empty
    # The cell size that `cells=` picks for these vertices.
    points, triangles, spec = addon.inputs(obj)
    s.cell_size = rigidcells.Session(points, spec, triangles=triangles, cells=cells).cell_size
    return obj, empty, float(high - low)


def main() -> None:
    path = Path(sys.argv[1]) if len(sys.argv) > 1 else DATA / "dragon_soup_blender.ply"
    cells = int(sys.argv[2]) if len(sys.argv) > 2 else 5000
    seconds = float(sys.argv[3]) if len(sys.argv) > 3 else 5.0
    obj, empty, height = scene(path, cells)
    start_at = np.array(empty.location)
    t0 = time.perf_counter()
    state = addon.LiveState(obj)
    while state.kind is None:  # the worker builds the cells and solves the rest pose
        state.tick(obj)
        time.sleep(0.005)
    ready = time.perf_counter() - t0
    print(f"{path.name}: {len(obj.data.vertices)} vertices, {state.worker.cells} cells, "
          f"cell size {obj.rigidcells.cell_size:.4g}; ready in {ready:.2f} s")
    written, moved_at, lags = [], {}, []
    steps0, t0 = state.worker.steps, time.perf_counter()
    tick = 1 / (float(sys.argv[4]) if len(sys.argv) > 4 else addon.LIVE_RATE)
    while (now := time.perf_counter()) - t0 < seconds:
        f = (now - t0) / seconds
        # Along a bend: up by half the height, across by a third, turned by 40°.
        empty.location = tuple(start_at + [0.33 * height * f, 0.0, 0.5 * height * f])
        empty.rotation_euler = (0.0, np.radians(-40.0 * f), 0.0)
        bpy.context.view_layer.update()
        steps = state.worker.steps
        moved_at.setdefault(steps, now)
        if state.tick(obj) == "preview":
            written.append(time.perf_counter())
            if state.worker.steps - 1 in moved_at:
                lags.append(written[-1] - moved_at[state.worker.steps - 1])
        time.sleep(max(0.0, tick - (time.perf_counter() - now)))
    moving = time.perf_counter() - t0
    steps = state.worker.steps - steps0
    t1 = time.perf_counter()
    state.finish()
    while not state.worker.done:
        state.tick(obj)
        time.sleep(0.005)
    state.tick(obj)
    released = time.perf_counter() - t1
    gaps = np.diff(written)
    print(f"  moving {moving:.1f} s: {len(written) / moving:.1f} shapes written a second, "
          f"{steps / moving:.1f} drag steps a second; between shapes median "
          f"{1000 * statistics.median(gaps):.0f} ms, 90th percentile "
          f"{1000 * np.quantile(gaps, 0.9):.0f} ms; pose to shape median "
          f"{1000 * statistics.median(lags):.0f} ms")
    report = state.worker.report
    key = obj.data.shape_keys.key_blocks[addon.SHAPE_KEY]
    co = np.empty(3 * len(key.data), dtype=np.float32)
    key.data.foreach_get("co", co)
    live = co.reshape(-1, 3).copy()
    print(f"  release (converge + transfer) {released:.2f} s: residuals fixed "
          f"{report.residual_fixed_max:.2g}, handle {report.residual_handle_max:.2g}, "
          f"{report.foldovers} of {report.foldovers_checked} folded")
    # Deform from rest on the last pose, for comparison.
    t2 = time.perf_counter()
    once = addon.deform(obj)
    key.data.foreach_get("co", co)
    off = np.abs(co.reshape(-1, 3) - live).max()
    print(f"  Deform of the last pose from rest {time.perf_counter() - t2:.2f} s: "
          f"{once.iterations} iterations, {once.foldovers} folded; Live's shape within "
          f"{off / obj.rigidcells.cell_size:.2g} cells of it")


if __name__ == "__main__":
    main()
