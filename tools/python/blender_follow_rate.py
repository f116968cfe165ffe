"""Follow in Blender, timed as an Empty is dragged: MESH from ../shared/data with the groups and
Empty of `blender_live.py`, sized to about CELLS cells, Follow on; the Empty moves 15 times by
a hundredth of a unit, each move an update as the viewport's drag makes (the window's path:
a drag's step and its preview), then rests (the exact shape: converge and release). Prints the
milliseconds of each update and of the exact shape.

    python tools/python/blender_follow_rate.py [MESH.ply] [CELLS]

(in a venv with `bpy` and `rigidcells`; MESH defaults to the mannequin bust.)
"""

import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
import bpy  # noqa: E402
from blender_live import DATA, scene  # noqa: E402

import rigidcells_blender as addon  # noqa: E402


def main() -> None:
    path = Path(sys.argv[1]) if len(sys.argv) > 1 else DATA / "mannequin.ply"
    cells = int(sys.argv[2]) if len(sys.argv) > 2 else 15000
    obj, empty, _ = scene(path, cells)
    obj.rigidcells.follow = True  # the first, exact shape
    # What Blender's window does with an update; without a window every update is exact.
    addon.follow._in_window = lambda: True
    times = []
    for _ in range(15):
        empty.location.x += 0.01
        start = time.perf_counter()
        bpy.context.view_layer.update()
        times.append(1000 * (time.perf_counter() - start))
    state = addon.follow._sessions[obj.name]
    state.moved_at -= addon.follow.SETTLE  # rested
    start = time.perf_counter()
    addon.follow._settle()
    exact = 1000 * (time.perf_counter() - start)
    print(f"{path.name}: {state.session.cells} cells; drag updates "
          f"{min(times[1:]):.0f}-{max(times[1:]):.0f} ms (first {times[0]:.0f} ms); "
          f"exact shape at rest {exact:.0f} ms")


main()
