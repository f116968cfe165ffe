"""The add-on's modal operators in Blender's window, driven as an artist drives them: Deform
invoked from the panel (solved on its thread while the window runs), again from Edit Mode (the
key kept after Tab), then Live with the handle Empty moved a few times and Enter pressed, then
Live again with Esc, once more with the Empty deleted, and Follow after the Empty moved and
keyframed. Blender without a window runs no modal operator, so this runs in Blender itself,
under a virtual display:

    blender -b --factory-startup --python-expr \\
        "import bpy; bpy.ops.wm.save_as_mainfile(filepath='/tmp/start.blend')"
    xvfb-run -a -s "-screen 0 1280x800x24" blender /tmp/start.blend --enable-event-simulate \\
        --python tests/blender/modal_check.py -- [SITE]

SITE: a folder holding the `rigidcells` package, when Blender's Python does not have it.
Prints one line a check and exits 0 when all hold, 1 otherwise.
"""

import math
import sys
import traceback
from pathlib import Path

import bpy
import numpy as np

ROOT = Path(__file__).resolve().parents[2]
ARGS = sys.argv[sys.argv.index("--") + 1 :] if "--" in sys.argv else []
if ARGS:
    sys.path.insert(0, ARGS[0])
sys.path.insert(0, str(ROOT / "blender"))
sys.path.insert(0, str(Path(__file__).resolve().parent))

import rigidcells_blender as addon  # noqa: E402
from bar_scene import bar_scene  # noqa: E402  (beside this script)

FAILED = []


def check(name, ok, detail=""):
    print(f"{'ok  ' if ok else 'FAIL'} {name} {detail}")
    if not ok:
        FAILED.append(name)


def key_co(obj):
    keys = obj.data.shape_keys
    key = keys.key_blocks.get("RigidCells") if keys is not None else None
    if key is None:
        return None
    co = np.empty(3 * len(key.data), dtype=np.float32)
    key.data.foreach_get("co", co)
    return co.reshape(-1, 3)


def setup():
    for o in list(bpy.data.objects):
        bpy.data.objects.remove(o)
    return bar_scene()


def override():
    window = bpy.context.window_manager.windows[0]
    area = next(a for a in window.screen.areas if a.type == "VIEW_3D")
    region = next(r for r in area.regions if r.type == "WINDOW")
    return window, area, region


def press(key):
    window, area, region = override()
    x, y = region.x + region.width // 2, region.y + region.height // 2
    window.event_simulate(type="MOUSEMOVE", value="NOTHING", x=x, y=y)
    window.event_simulate(type=key, value="PRESS", x=x, y=y)
    window.event_simulate(type=key, value="RELEASE", x=x, y=y)


def invoke(op):
    window, area, region = override()
    with bpy.context.temp_override(window=window, area=area, region=region):
        return op("INVOKE_DEFAULT")


def wait(seconds):
    """Gives the window `seconds`, waking its event loop every 20 ms (a virtual display
    sends no events of its own, and Blender's loop sleeps until one comes)."""
    for _ in range(max(1, round(seconds / 0.02))):
        yield 0.02


def steps():
    """The checks, as a generator: each `yield` gives the window time (seconds) to run."""
    obj, empty = setup()
    empty.location, empty.rotation_euler = (4.0, 0.0, 3.0), (0.0, math.radians(-60), 0.0)
    bpy.context.view_layer.update()
    started = invoke(bpy.ops.object.rigidcells_deform)
    check("deform invoked runs modal", started == {"RUNNING_MODAL"})
    for _ in range(200):
        if key_co(obj) is not None:
            break
        yield from wait(0.05)
    threaded = key_co(obj)
    check("deform off the main thread wrote the key", threaded is not None)
    assert bpy.ops.object.rigidcells_deform() == {"FINISHED"}
    check("and it is the one execute writes", np.array_equal(threaded, key_co(obj)))
    deformed = key_co(obj).copy()

    # From Edit Mode: Deform leaves it for the solve and enters it again; after Tab the key is
    # still the deformation (Edit Mode would write its copy of the mesh back over it).
    obj.shape_key_clear()
    bpy.ops.object.mode_set(mode="EDIT")
    started = invoke(bpy.ops.object.rigidcells_deform)
    check("deform invoked from edit mode runs modal", started == {"RUNNING_MODAL"})
    for _ in range(200):
        if obj.mode == "EDIT" and key_co(obj) is not None:
            break
        yield from wait(0.05)
    check("and is back in edit mode", obj.mode == "EDIT", obj.mode)
    bpy.ops.object.mode_set(mode="OBJECT")
    after = key_co(obj)
    check("whose key stays after Tab", after is not None and np.array_equal(after, deformed))

    # Live, from the rest pose to the same pose in five moves, then Enter.
    empty.location, empty.rotation_euler = (5.0, 0.0, 0.0), (0.0, 0.0, 0.0)
    bpy.context.view_layer.update()
    check("live invoked runs modal", invoke(bpy.ops.object.rigidcells_live) == {"RUNNING_MODAL"})
    yield from wait(1.0)
    tip = max(range(len(obj.data.vertices)), key=lambda i: obj.data.vertices[i].co.x)
    rises = []
    for k in range(1, 6):
        empty.location = (5.0 - 0.2 * k, 0.0, 0.6 * k)
        empty.rotation_euler = (0.0, math.radians(-12.0 * k), 0.0)
        yield from wait(0.3)
        rises.append(float(key_co(obj)[tip, 2]))
    check("live previews follow the Empty", all(b > a for a, b in zip(rises, rises[1:])), rises)
    press("RET")
    for _ in range(200):
        if not addon._live:
            break
        yield from wait(0.05)
    check("enter ends live", not addon._live)
    off = np.abs(key_co(obj) - deformed).max()
    check("live ends on deform's shape", off < 1e-3 * 0.25, f"{off:.2g}")

    # Live again, a move, then Esc: the key as it was before this Live.
    before = key_co(obj).copy()
    check("live again", invoke(bpy.ops.object.rigidcells_live) == {"RUNNING_MODAL"})
    yield from wait(1.0)
    steps = addon._live[obj.name].worker.steps
    empty.location = (2.0, 0.0, 5.0)
    yield from wait(0.5)
    moved = addon._live[obj.name].worker.steps > steps
    press("ESC")
    yield from wait(0.3)
    check("esc ends live", not addon._live)

    # Live, and the handle Empty deleted meanwhile: an error, Live ended, the key as it was.
    before = key_co(obj).copy()
    check("live once more", invoke(bpy.ops.object.rigidcells_live) == {"RUNNING_MODAL"})
    yield from wait(1.0)
    empty.location = (3.0, 0.0, 4.0)
    yield from wait(0.3)
    bpy.data.objects.remove(empty)
    yield from wait(0.3)
    check("a deleted Empty ends live", not addon._live)
    check("and the key is as it was", np.array_equal(key_co(obj), before))
    check("the move was solved", moved)
    back = key_co(obj)
    check("esc restores the key", back is not None and np.array_equal(back, before))

    # Follow, in the window: the key follows the Empty moved in the viewport and its keyframes
    # as the frames change, and the panel draws its row.
    obj, empty = setup()
    handle = [v.index for v in obj.data.vertices if v.co.x > 4.4]
    rest = np.array([v.co[:] for v in obj.data.vertices], dtype=np.float32)
    obj.rigidcells.follow = True
    yield from wait(0.3)
    empty.location = (5.0, 0.0, 2.0)
    yield from wait(0.5)
    lift = key_co(obj)[handle, 2] - rest[handle, 2]
    check("follow takes the moved Empty", np.abs(lift - 2.0).max() < 1e-5, f"{lift.min():.5f}")
    scene = bpy.context.scene
    empty.keyframe_insert("location", frame=1)
    empty.location = (5.0, 0.0, -1.0)
    empty.keyframe_insert("location", frame=3)
    scene.frame_set(3)
    yield from wait(0.3)
    lift = key_co(obj)[handle, 2] - rest[handle, 2]
    check("and its keyframes", np.abs(lift + 1.0).max() < 1e-5, f"{lift.min():.5f}")
    check("still following", obj.rigidcells.follow and not obj.rigidcells.follow_said,
          obj.rigidcells.follow_said)


def main():
    addon.register()
    run = steps()

    def tick():
        try:
            return next(run)
        except StopIteration:
            pass
        except Exception:
            traceback.print_exc()
            FAILED.append("exception")
        print("all checks hold" if not FAILED else f"failed: {FAILED}")
        sys.stdout.flush()
        import os

        os._exit(1 if FAILED else 0)

    bpy.app.timers.register(tick, first_interval=0.5)


main()
