"""The scene the scripts run in Blender itself bend (`modal_check.py`, `legacy_install.py`): a
10 × 1 × 1 box bar, each face cut eight times, its left end the group `fixed`, its right end
the group `handle` with an Empty at its end, set in the Rigid Cells panel (cells of 0.25)."""

import bpy


def bar_scene():
    """The bar and its handle Empty, the bar active and alone selected."""
    bpy.ops.mesh.primitive_cube_add(size=1.0)
    obj = bpy.context.active_object
    obj.scale = (10.0, 1.0, 1.0)
    bpy.ops.object.transform_apply(scale=True)
    bpy.ops.object.mode_set(mode="EDIT")
    bpy.ops.mesh.subdivide(number_cuts=8)
    bpy.ops.object.mode_set(mode="OBJECT")
    for name, keep in (("fixed", lambda x: x < -4.4), ("handle", lambda x: x > 4.4)):
        obj.vertex_groups.new(name=name).add(
            [v.index for v in obj.data.vertices if keep(v.co.x)], 1.0, "REPLACE"
        )
    bpy.ops.object.empty_add(location=(5.0, 0.0, 0.0))
    empty = bpy.context.active_object
    for o in bpy.context.view_layer.objects:
        o.select_set(o == obj)
    bpy.context.view_layer.objects.active = obj
    s = obj.rigidcells
    s.fixed_group, s.handle_group, s.handle_object, s.cell_size = "fixed", "handle", empty, 0.25
    return obj, empty
