"""Pictures of Follow in Blender's window (`docs/blender_follow.png`): a bar whose handle Empty
is keyframed to lift and turn over 24 frames, with Follow on, at frames 1, 12 and 24 of the
timeline, side by side. Runs inside Blender with its interface, under a virtual display where
there is no screen (as `blender_panel.py`):

    blender -b --factory-startup --python-expr \\
        "import bpy; bpy.ops.wm.save_as_mainfile(filepath='/tmp/start.blend')"
    xvfb-run -a -s "-screen 0 1500x900x24" blender /tmp/start.blend \\
        --python tools/python/blender_follow.py -- docs/blender_follow.png [SITE]

Each frame is set as the timeline would set it; the add-on's frame handler solves the pose
warm and writes the key, and the window is captured after it redraws.

SITE: a folder holding the `rigidcells` package (a wheel unpacked), when Blender's Python
does not have it.
"""

import math
import sys
from pathlib import Path

import bpy
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from blender_window import ROOT, picture, save, view_3d, view_cut  # noqa: E402

OUT = picture("blender_follow.png")
sys.path.insert(0, str(ROOT / "tests" / "blender"))

import rigidcells_blender as addon  # noqa: E402
from bar_scene import bar_scene  # noqa: E402

FRAMES = (1, 12, 24)


def animate():
    """The bar, its Empty keyed at rest on frame 1 and lifted by 3 and turned 90° about y on
    frame 24, Follow on."""
    for obj in list(bpy.data.objects):
        bpy.data.objects.remove(obj)
    obj, empty = bar_scene()
    scene = bpy.context.scene
    scene.frame_start, scene.frame_end = 1, 24
    empty.keyframe_insert("location", frame=1)
    empty.keyframe_insert("rotation_euler", frame=1)
    empty.location = (4.0, 0.0, 3.0)
    empty.rotation_euler = (0.0, math.radians(-90.0), 0.0)
    empty.keyframe_insert("location", frame=24)
    empty.keyframe_insert("rotation_euler", frame=24)
    scene.frame_set(1)
    obj.rigidcells.follow = True
    return obj


def view():
    """The 3D view from the front, framing the bar's whole motion, the sidebar closed."""
    r3d = view_3d(sidebar=False)[2].region_3d
    r3d.view_perspective = "ORTHO"
    r3d.view_rotation = (math.sqrt(0.5), math.sqrt(0.5), 0.0, 0.0)  # from the front
    r3d.view_location = (1.0, 0.0, 2.0)
    r3d.view_distance = 13.0


shots = []


def step(k=0):
    """Frame `FRAMES[k]` set, then captured once the window has redrawn."""
    bpy.context.scene.frame_set(FRAMES[k])
    bpy.app.timers.register(lambda: shoot(k), first_interval=0.8)


def shoot(k):
    path = OUT.with_name(f"{OUT.stem}_{k}.png")
    shots.append(view_cut(path, (1 / 6, 5 / 6), (1 / 8, 7 / 8)))
    if k + 1 < len(FRAMES):
        step(k + 1)
    else:
        join()


def join():
    """The three frames side by side, a thin dark line between them."""
    h = shots[0].shape[0]
    line = np.zeros((h, 4, 4), dtype=np.float32)
    line[..., 3] = 1.0
    save(np.concatenate([p for s in shots for p in (s, line)][:-1], axis=1), OUT)
    bpy.ops.wm.quit_blender()


def main():
    addon.register()
    animate()
    view()
    bpy.app.timers.register(step, first_interval=1.5)


main()
