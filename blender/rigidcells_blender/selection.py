"""From the Edit Mode selection: the button beside each group's field in the panel makes the
selected vertices that group — the add-on's own vertex group (`RigidCells Fixed`,
`RigidCells Handle`, `RigidCells Pin 1`, …), replaced by the next selection, in each mesh of
the scene with a selection — and gives a handle or pin without an Empty one at their center,
as Blender's "Hook to New Object" does. A group the artist made and named is never changed.
"""

from __future__ import annotations

from typing import Any, List

import bpy
import numpy as np
from bpy.props import EnumProperty, IntProperty

from .handles import InputError
from .scene import _rest_vertices, members


# The vertex groups "From selection" makes: the add-on's own, replaced each time; a group the
# artist made and named in the panel is never changed.
GROUP_PREFIX = "RigidCells "

ROLES = [
    ("fixed", "Fixed", "The fixed group"),
    ("handle", "Handle", "The handle group, and its Empty"),
    ("handles", "More handles", "Handle `index + 2`'s group, and its Empty"),
    ("pins", "Pins", "Pin `index + 1`'s group, and its Empty"),
    ("stiffness", "Stiffness", "The stiffness group"),
]


def _selected_vertices(obj: bpy.types.Object) -> List[int]:
    """The vertices selected in Edit Mode (the mesh's selection, brought up to date when the
    object is in Edit Mode)."""
    if obj.mode == "EDIT":
        obj.update_from_editmode()
    return [v.index for v in obj.data.vertices if v.select]


def _selecting(context: Any) -> List[bpy.types.Object]:
    """The meshes whose Edit Mode selection makes a group: the active object, those taken
    together with it, and the others in Edit Mode with it."""
    obj = context.active_object
    out = members(obj)
    if obj.mode == "EDIT":
        out += [o for o in context.objects_in_mode if o.type == "MESH" and o not in out]
    return out


def from_selection(context: Any, role: str, index: int = 0) -> bpy.types.VertexGroup:
    """The selected vertices as the group of `role` (`index` among the extra handles or the
    pins): in each mesh with a selection (`_selecting`), the add-on's vertex group
    `RigidCells <Role>` holds exactly them, at weight 1 (and no other mesh holds that group),
    and the panel names it; a handle or pin without an Empty gets a new one at their center,
    as Blender's "Hook to New Object" does. Returns the active object's group, or None where
    it has none selected."""
    from . import _back_to_edit_mode, _leave_edit_mode

    obj = context.active_object
    s = obj.rigidcells
    if role in ("handles", "pins"):
        items = getattr(s, role)
        what = f"handle {index + 2}" if role == "handles" else f"pin {index + 1}"
        if not 0 <= index < len(items):
            add = "+ Handle" if role == "handles" else "+ Pin"
            raise InputError(f"Rigid Cells: there is no {what}: add it with {add} first")
        item, label = items[index], what.capitalize()
    else:
        item, label = s, role.capitalize()
    chosen = {o.name: _selected_vertices(o) for o in _selecting(context)}
    if not any(chosen.values()):
        raise InputError("Rigid Cells: select the vertices in Edit Mode first")
    name = GROUP_PREFIX + label
    editing = _leave_edit_mode(context)
    try:
        mathutils = _mathutils()
        at = []
        for other_name, picked in chosen.items():
            other = bpy.data.objects[other_name]
            group = other.vertex_groups.get(name)
            if not picked:
                if group is not None:
                    other.vertex_groups.remove(group)
                continue
            group = group or other.vertex_groups.new(name=name)
            group.remove(range(len(other.data.vertices)))
            group.add(picked, 1.0, "REPLACE")
            world = np.array(other.matrix_world)
            at.append(_rest_vertices(other.data)[picked] @ world[:3, :3].T + world[:3, 3])
        if role in ("handles", "pins"):
            item.group = name
        else:
            setattr(s, f"{role}_group", name)
        empty_of = {"handle": "handle_object", "handles": "object", "pins": "object"}.get(role)
        if empty_of is not None and getattr(item, empty_of) is None:
            center = mathutils.Vector(np.concatenate(at).mean(axis=0))
            empty = bpy.data.objects.new(f"{obj.name} {label}", None)
            empty.empty_display_type = "ARROWS"
            empty.location = center
            empty.matrix_world = mathutils.Matrix.Translation(center)
            for collection in obj.users_collection:
                collection.objects.link(empty)
            setattr(item, empty_of, empty)  # its rest pose is taken now
    finally:
        _back_to_edit_mode(context, editing)
    return obj.vertex_groups.get(name)


def _mathutils() -> Any:
    import mathutils

    return mathutils


class RIGIDCELLS_OT_from_selection(bpy.types.Operator):
    """Make the vertices selected in Edit Mode this group (the add-on's own vertex group holds
    them); a handle or pin without an Empty gets one at their center"""

    bl_idname = "rigidcells.from_selection"
    bl_label = "From selection"
    bl_options = {"REGISTER", "UNDO", "INTERNAL"}
    role: EnumProperty(items=ROLES)
    index: IntProperty()

    @classmethod
    def poll(cls, context: Any) -> bool:
        from . import _mesh_active

        return _mesh_active(context)

    def execute(self, context: Any) -> set:
        from . import ERRORS, _said

        try:
            group = from_selection(context, self.role, self.index)
        except ERRORS as e:
            self.report({"ERROR"}, _said(e))
            return {"CANCELLED"}
        count = sum(
            sum(1 for v in o.data.vertices if v.select) for o in _selecting(context)
        )
        name = group.name if group is not None else "the group"
        self.report({"INFO"}, f"Rigid Cells: {name} holds {count:,} vertices")
        return {"FINISHED"}
