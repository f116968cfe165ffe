"""A screenshot of the Rigid Cells panel in Blender's window, beside the soup of ten loose
cubes it bent, with its estimate shown (`docs/blender_panel.png`). Runs inside Blender with its interface, under a
virtual display where there is no screen:

    blender -b --factory-startup --python-expr \\
        "import bpy; bpy.ops.wm.save_as_mainfile(filepath='/tmp/start.blend')"
    xvfb-run -a -s "-screen 0 1500x900x24" blender /tmp/start.blend --enable-event-simulate \\
        --python tools/python/blender_panel.py -- docs/blender_panel.png [SITE]

(Opening a file skips the splash screen; the simulated click opens the sidebar's Rigid Cells
tab, which a script cannot choose.)

SITE: a folder holding the `rigidcells` package (a wheel unpacked), when Blender's Python
does not have it.
"""

import sys
from pathlib import Path

import bpy
import numpy as np

ROOT = Path(__file__).resolve().parents[2]
ARGS = sys.argv[sys.argv.index("--") + 1 :] if "--" in sys.argv else []
OUT = Path(ARGS[0]).resolve() if ARGS else ROOT / "docs" / "blender_panel.png"
if len(ARGS) > 1:
    sys.path.insert(0, ARGS[1])
sys.path.insert(0, str(ROOT / "blender"))
sys.path.insert(0, str(ROOT / "tools" / "python"))

import rigidcells_blender as addon  # noqa: E402
from blender_laplacian import rigid_soup  # noqa: E402


def scene():
    """The soup with its first cube fixed and its last on a lifted Empty, deformed."""
    for obj in list(bpy.data.objects):
        bpy.data.objects.remove(obj)
    obj = rigid_soup("soup")
    for o in bpy.context.view_layer.objects:
        o.select_set(o == obj)
    bpy.context.view_layer.objects.active = obj
    return obj


def show(obj):
    """The sidebar open on the Rigid Cells tab, the view on the soup from the front."""
    window = bpy.context.window_manager.windows[0]
    for area in window.screen.areas:
        if area.type != "VIEW_3D":
            continue
        space = area.spaces.active
        space.show_region_ui = True
        space.overlay.show_floor = True
        space.shading.type = "SOLID"
        region = next(r for r in area.regions if r.type == "WINDOW")
        with bpy.context.temp_override(window=window, area=area, region=region):
            bpy.ops.view3d.view_axis(type="FRONT")
            bpy.ops.view3d.view_selected()


def open_tab():
    """Clicks the sidebar's Rigid Cells tab: the fourth, below Item, Tool and View."""
    window = bpy.context.window_manager.windows[0]
    area = next(a for a in window.screen.areas if a.type == "VIEW_3D")
    ui = next(r for r in area.regions if r.type == "UI")
    x, y = ui.x + ui.width - 10, ui.y + ui.height - 190
    window.event_simulate(type="MOUSEMOVE", value="NOTHING", x=x, y=y)
    window.event_simulate(type="LEFTMOUSE", value="PRESS", x=x, y=y)
    window.event_simulate(type="LEFTMOUSE", value="RELEASE", x=x, y=y)
    window.event_simulate(type="MOUSEMOVE", value="NOTHING", x=x - 600, y=y - 300)
    bpy.app.timers.register(shoot, first_interval=1.0)


def shoot():
    """The window's screenshot, cut to the 3D view's right four fifths and top three quarters:
    the bent soup and the panel."""
    window = bpy.context.window_manager.windows[0]
    with bpy.context.temp_override(window=window):
        bpy.ops.screen.screenshot(filepath=str(OUT))
    area = next(a for a in window.screen.areas if a.type == "VIEW_3D")
    shot = bpy.data.images.load(str(OUT))
    w, h = shot.size
    pixels = np.empty(w * h * 4, dtype=np.float32)
    shot.pixels.foreach_get(pixels)
    pixels = pixels.reshape(h, w, 4)  # rows from the bottom, as the window's coordinates
    x0, x1 = area.x + area.width // 5, area.x + area.width
    y0, y1 = area.y + area.height // 4, area.y + area.height
    cut = np.ascontiguousarray(pixels[y0:y1, x0:x1])
    out = bpy.data.images.new("panel", x1 - x0, y1 - y0)
    out.pixels.foreach_set(cut.ravel())
    out.filepath_raw, out.file_format = str(OUT), "PNG"
    out.save()
    print(f"wrote {OUT}")
    bpy.ops.wm.quit_blender()


def main():
    addon.register()
    obj = scene()
    bpy.ops.rigidcells.estimate()  # its figures beside the button
    show(obj)
    bpy.app.timers.register(open_tab, first_interval=1.5)


main()
