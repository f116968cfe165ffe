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

ROOT = Path(__file__).resolve().parents[2]
ARGS = sys.argv[sys.argv.index("--") + 1 :] if "--" in sys.argv else []
OUT = Path(ARGS[0]).resolve() if ARGS else ROOT / "docs" / "blender_follow.png"
if len(ARGS) > 1:
    sys.path.insert(0, ARGS[1])
sys.path.insert(0, str(ROOT / "blender"))
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
    window = bpy.context.window_manager.windows[0]
    for area in window.screen.areas:
        if area.type != "VIEW_3D":
            continue
        space = area.spaces.active
        space.show_region_ui = False
        space.shading.type = "SOLID"
        space.overlay.show_floor = True
        r3d = space.region_3d
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
    window = bpy.context.window_manager.windows[0]
    path = OUT.with_name(f"{OUT.stem}_{k}.png")
    with bpy.context.temp_override(window=window):
        bpy.ops.screen.screenshot(filepath=str(path))
    area = next(a for a in window.screen.areas if a.type == "VIEW_3D")
    shot = bpy.data.images.load(str(path))
    w, h = shot.size
    pixels = np.empty(w * h * 4, dtype=np.float32)
    shot.pixels.foreach_get(pixels)
    pixels = pixels.reshape(h, w, 4)
    x0, x1 = area.x + area.width // 6, area.x + area.width * 5 // 6
    y0, y1 = area.y + area.height // 8, area.y + area.height * 7 // 8
    shots.append(np.ascontiguousarray(pixels[y0:y1, x0:x1]))
    bpy.data.images.remove(shot)
    path.unlink()
    if k + 1 < len(FRAMES):
        step(k + 1)
    else:
        save()


def save():
    """The three frames side by side, a thin dark line between them."""
    h = shots[0].shape[0]
    line = np.zeros((h, 4, 4), dtype=np.float32)
    line[..., 3] = 1.0
    row = np.concatenate([p for s in shots for p in (s, line)][:-1], axis=1)
    out = bpy.data.images.new("follow", row.shape[1], row.shape[0])
    out.pixels.foreach_set(row.ravel())
    out.filepath_raw, out.file_format = str(OUT), "PNG"
    out.save()
    print(f"wrote {OUT}: frames {', '.join(map(str, FRAMES))}")
    bpy.ops.wm.quit_blender()


def main():
    addon.register()
    animate()
    view()
    bpy.app.timers.register(step, first_interval=1.5)


main()
