"""What the scripts that photograph Blender's window share (`blender_panel.py`,
`blender_follow.py`): their arguments (the picture to write, and a folder holding the
`rigidcells` package where Blender's Python has none), the add-on on the path, and a cut of
the window's screenshot saved as a PNG."""

import sys
from pathlib import Path

import bpy
import numpy as np

ROOT = Path(__file__).resolve().parents[2]


def picture(name: str) -> Path:
    """The picture to write (the first argument after `--`, else `docs/NAME`), with the SITE
    argument and the add-on's folder put on the path."""
    args = sys.argv[sys.argv.index("--") + 1 :] if "--" in sys.argv else []
    if len(args) > 1:
        sys.path.insert(0, args[1])
    sys.path.insert(0, str(ROOT / "blender"))
    return Path(args[0]).resolve() if args else ROOT / "docs" / name


def view_3d(sidebar: bool):
    """The window's 3D view, shaded solid over its floor, with its sidebar shown or not:
    `(window, area, space)`."""
    window = bpy.context.window_manager.windows[0]
    area = next(a for a in window.screen.areas if a.type == "VIEW_3D")
    space = area.spaces.active
    space.show_region_ui = sidebar
    space.shading.type = "SOLID"
    space.overlay.show_floor = True
    return window, area, space


def view_cut(path: Path, x: tuple, y: tuple) -> np.ndarray:
    """The window's screenshot (written to `path`, then removed), cut to the fractions `x` and
    `y` of the 3D view's width and height (from its left and bottom): RGBA rows from the
    bottom, as the window's coordinates."""
    window = bpy.context.window_manager.windows[0]
    with bpy.context.temp_override(window=window):
        bpy.ops.screen.screenshot(filepath=str(path))
    area = next(a for a in window.screen.areas if a.type == "VIEW_3D")
    shot = bpy.data.images.load(str(path))
    w, h = shot.size
    pixels = np.empty(w * h * 4, dtype=np.float32)
    shot.pixels.foreach_get(pixels)
    bpy.data.images.remove(shot)
    path.unlink()
    pixels = pixels.reshape(h, w, 4)
    x0, x1 = (area.x + int(area.width * f) for f in x)
    y0, y1 = (area.y + int(area.height * f) for f in y)
    return np.ascontiguousarray(pixels[y0:y1, x0:x1])


def save(pixels: np.ndarray, out: Path) -> None:
    """RGBA rows from the bottom as the PNG `out`."""
    image = bpy.data.images.new(out.stem, pixels.shape[1], pixels.shape[0])
    image.pixels.foreach_set(pixels.ravel())
    image.filepath_raw, image.file_format = str(out), "PNG"
    image.save()
    print(f"wrote {out}")
