"""The add-on installed as Blender 3.4 to 4.1 install add-ons: the legacy zip
(`blender/build_extension.py`) through Preferences > Add-ons > Install…, enabled, and run.

    BLENDER_USER_SCRIPTS=$(mktemp -d) blender -b --factory-startup --python-exit-code 1 \\
        --python tests/blender/legacy_install.py -- target/rigidcells_blender-0.1.0-legacy.zip

Checks that the zip lands as one folder `rigidcells_blender` (nothing loose beside it), that it
enables and finds its bundled `rigidcells` package, and that Deform bends a bar into the shape
key: the fixed end kept, the handle end lifted with its Empty. Prints one line a check and exits
0 when all hold, 1 otherwise (Blender ends with 1 on the script's exception).
"""

import os
import sys

import bpy
import numpy as np

ZIP = sys.argv[sys.argv.index("--") + 1]
FAILED = []


def check(name, ok, detail=""):
    print(f"{'ok  ' if ok else 'FAIL'} {name} {detail}")
    if not ok:
        FAILED.append(name)


addons = bpy.utils.user_resource("SCRIPTS", path="addons")
before = set(os.listdir(addons)) if os.path.isdir(addons) else set()
bpy.ops.preferences.addon_install(filepath=os.path.abspath(ZIP), overwrite=True)
added = set(os.listdir(addons)) - before
check("the zip installs one folder", added == {"rigidcells_blender"}, f"{sorted(added)} in {addons}")
bpy.ops.preferences.addon_enable(module="rigidcells_blender")
check("it enables", hasattr(bpy.types.Object, "rigidcells"))
import rigidcells  # noqa: E402  (found in the add-on's site/ once it is enabled)

check(
    "its own rigidcells package",
    os.path.dirname(rigidcells.__file__).startswith(os.path.join(addons, "rigidcells_blender")),
    rigidcells.__file__,
)

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from bar_scene import bar_scene  # noqa: E402  (beside this script)

obj, empty = bar_scene()
empty.location = (5.0, 0.0, 2.0)
bpy.context.view_layer.update()
result = bpy.ops.object.rigidcells_deform()
check("Deform finishes", result == {"FINISHED"}, str(result))
key = obj.data.shape_keys.key_blocks["RigidCells"].data
co = np.array([k.co[:] for k in key])
rest = np.array([v.co[:] for v in obj.data.vertices])
fixed, handle = rest[:, 0] < -4.4, rest[:, 0] > 4.4
check("the fixed end kept", np.array_equal(co[fixed], rest[fixed]))
lift = co[handle, 2] - rest[handle, 2]
check("the handle end lifted by 2", np.abs(lift - 2.0).max() < 1e-4, f"{lift.min():.4f}..{lift.max():.4f}")
print(f"legacy install in Blender {bpy.app.version_string}: {len(FAILED)} failed")
if FAILED:
    raise SystemExit(1)
