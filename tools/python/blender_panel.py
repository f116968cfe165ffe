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

sys.path.insert(0, str(Path(__file__).resolve().parent))
from blender_window import picture, save, view_3d, view_cut  # noqa: E402

OUT = picture("blender_panel.png")

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
    window, area, _ = view_3d(sidebar=True)
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
    """The window's screenshot, cut to the 3D view's right four fifths and all but its
    lowest twenty-fifth: the bent soup and the panel with the run's warning."""
    save(view_cut(OUT, (0.2, 1.0), (0.04, 1.0)), OUT)
    bpy.ops.wm.quit_blender()


def main():
    addon.register()
    obj = scene()
    bpy.ops.rigidcells.estimate()  # its figures beside the button
    show(obj)
    bpy.app.timers.register(open_tab, first_interval=1.5)


main()
