"""Rigid Cells in Blender: bend meshes, soups of any number of loose parts, non-manifold meshes
and vertex-only scans with the rigidcells library, into a shape key.

The add-on turns Blender's data into the library's inputs and back and nothing more: the
vertices of the base shape, the triangles, the vertex groups as `indices` regions and the
handle Empty's motion since it was assigned as a `matrix` go to `rigidcells.deform`; the moved
vertices come back as the shape key `RigidCells`, which the artist can blend, animate or
apply. Vertices of the fixed group keep their coordinates bit for bit; vertices of the handle
group land where the Empty sends them (to Blender's single precision).
"""

from __future__ import annotations

from typing import Any, List, Optional, Tuple

import bpy
import numpy as np
from bpy.props import (
    EnumProperty,
    FloatProperty,
    FloatVectorProperty,
    IntProperty,
    PointerProperty,
    StringProperty,
)

SHAPE_KEY = "RigidCells"

TRANSFERS = [
    ("pu", "Partition of unity", "Local RBFs blended over the cells (the default)"),
    ("rbf", "RBF", "One global RBF over the cells (the paper's; a few thousand cells)"),
    ("blend", "Blend", "Each vertex follows the cells around it, blended"),
    ("blend-idw", "Blend (inverse distance)", "The blend with inverse-distance weights"),
]


def _take_rest(settings: "RigidCellsSettings", _context: Any) -> None:
    """The handle Empty's pose when it is assigned: its motion from here is the handle's."""
    empty = settings.handle_object
    if empty is not None:
        settings.handle_rest = [v for row in empty.matrix_world for v in row]


class RigidCellsSettings(bpy.types.PropertyGroup):
    """What a Rigid Cells deformation of this object holds fixed and moves."""

    fixed_group: StringProperty(
        name="Fixed group", description="Vertex group whose vertices keep their place"
    )
    handle_group: StringProperty(
        name="Handle group", description="Vertex group whose vertices follow the handle Empty"
    )
    handle_object: PointerProperty(
        name="Handle",
        type=bpy.types.Object,
        poll=lambda _self, obj: obj.type == "EMPTY",
        update=_take_rest,
        description="An Empty: its motion since it was assigned moves the handle group",
    )
    handle_rest: FloatVectorProperty(size=16, options={"HIDDEN"})
    cell_size: FloatProperty(
        name="Cell size",
        default=0.0,
        min=0.0,
        description="Edge of the finest cells, in the object's units (0: automatic)",
    )
    transfer: EnumProperty(name="Transfer", items=TRANSFERS, default="pu")
    # The last run's figures, for the panel.
    cells: IntProperty(options={"HIDDEN"})
    iterations: IntProperty(options={"HIDDEN"})
    residual_fixed: FloatProperty(options={"HIDDEN"})
    residual_handle: FloatProperty(options={"HIDDEN"})
    foldovers: IntProperty(options={"HIDDEN"})


class InputError(ValueError):
    """What the artist set up cannot be deformed; said in Blender's error report."""


def _group_indices(obj: bpy.types.Object, name: str, role: str) -> List[int]:
    """The vertices of the group `name` (weight above 0)."""
    if not name:
        raise InputError(f"Rigid Cells: name the {role} vertex group")
    group = obj.vertex_groups.get(name)
    if group is None:
        raise InputError(f"Rigid Cells: {obj.name} has no vertex group {name!r}")
    k = group.index
    found = [
        v.index for v in obj.data.vertices if any(g.group == k and g.weight > 0 for g in v.groups)
    ]
    if not found:
        raise InputError(f"Rigid Cells: the vertex group {name!r} holds no vertex")
    return found


def _rest_vertices(mesh: bpy.types.Mesh) -> np.ndarray:
    """The base shape's vertices ((n, 3) float64): the reference shape key's where there are
    shape keys, so a deformation never stacks on the last one."""
    co = np.empty(3 * len(mesh.vertices), dtype=np.float32)
    keys = mesh.shape_keys
    if keys is not None and keys.reference_key is not None:
        keys.reference_key.data.foreach_get("co", co)
    else:
        mesh.vertices.foreach_get("co", co)
    return co.reshape(-1, 3).astype(np.float64)


def _triangles(mesh: bpy.types.Mesh) -> Optional[np.ndarray]:
    """The faces as triangles ((m, 3) vertex indices), or None for a vertex-only mesh."""
    mesh.calc_loop_triangles()
    m = len(mesh.loop_triangles)
    if m == 0:
        return None
    tris = np.empty(3 * m, dtype=np.int64)
    mesh.loop_triangles.foreach_get("vertices", tris)
    return tris.reshape(-1, 3)


def handle_matrix(obj: bpy.types.Object, settings: RigidCellsSettings) -> List[List[float]]:
    """The handle's affine map in the object's own coordinates: the Empty's motion since its
    rest pose (world), seen from the object."""
    rest = np.array(settings.handle_rest, dtype=np.float64).reshape(4, 4)
    now = np.array(settings.handle_object.matrix_world, dtype=np.float64)
    world = np.array(obj.matrix_world, dtype=np.float64)
    motion = now @ np.linalg.inv(rest)
    local = np.linalg.inv(world) @ motion @ world
    local[3] = [0.0, 0.0, 0.0, 1.0]
    return local.tolist()


def inputs(obj: bpy.types.Object) -> Tuple[np.ndarray, Optional[np.ndarray], dict]:
    """The library's inputs for `obj`: its rest vertices, its triangles and the spec."""
    if obj is None or obj.type != "MESH":
        raise InputError("Rigid Cells: select a mesh object")
    settings = obj.rigidcells
    fixed = _group_indices(obj, settings.fixed_group, "fixed")
    handle = _group_indices(obj, settings.handle_group, "handle")
    if settings.handle_object is None:
        raise InputError("Rigid Cells: choose the handle Empty")
    spec = {
        "fixed": [{"indices": fixed}],
        "handle": [{"indices": handle, "matrix": handle_matrix(obj, settings)}],
    }
    return _rest_vertices(obj.data), _triangles(obj.data), spec


def write_shape_key(obj: bpy.types.Object, moved: np.ndarray) -> bpy.types.ShapeKey:
    """`moved` as the shape key `RigidCells` (replacing one of that name), over a Basis."""
    if obj.data.shape_keys is None:
        obj.shape_key_add(name="Basis", from_mix=False)
    key = obj.data.shape_keys.key_blocks.get(SHAPE_KEY)
    if key is None:
        key = obj.shape_key_add(name=SHAPE_KEY, from_mix=False)
    key.data.foreach_set("co", moved.astype(np.float32).ravel())
    key.value = 1.0
    obj.data.update()
    return key


def deform(obj: bpy.types.Object, progress: Any = False) -> Any:
    """Deforms `obj` as its settings say and writes the shape key; returns the library's
    report. Nothing of the object changes when an error is raised."""
    import rigidcells

    points, triangles, spec = inputs(obj)
    settings = obj.rigidcells
    moved, report = rigidcells.deform(
        points,
        spec,
        triangles=triangles,
        cell_size=settings.cell_size or None,
        transfer=settings.transfer,
        progress=progress,
    )
    write_shape_key(obj, moved)
    settings.cells = report.cells
    settings.iterations = report.iterations
    settings.residual_fixed = report.residual_fixed_max
    settings.residual_handle = report.residual_handle_max
    settings.foldovers = report.foldovers
    return report


def _mesh_active(context: Any) -> bool:
    """Whether the active object is a mesh, which the operator and the panel work on."""
    obj = context.active_object
    return obj is not None and obj.type == "MESH"


class OBJECT_OT_rigidcells_deform(bpy.types.Operator):
    """Bend the object with rigid cells: the fixed group stays, the handle group follows the
    handle Empty, the rest follows as stiffly as cells glued face to face allow"""

    bl_idname = "object.rigidcells_deform"
    bl_label = "Rigid Cells Deform"
    bl_options = {"REGISTER", "UNDO"}

    @classmethod
    def poll(cls, context: Any) -> bool:
        return _mesh_active(context)

    def execute(self, context: Any) -> set:
        obj = context.active_object
        wm = context.window_manager
        stages: dict = {}

        def progress(stage: str, done: int, total: Optional[int]) -> None:
            if total:
                wm.progress_update(int(100 * done / total))
            if stage not in stages and context.workspace is not None:
                stages[stage] = True
                context.workspace.status_text_set(f"Rigid Cells: {stage}")

        wm.progress_begin(0, 100)
        try:
            report = deform(obj, progress=progress)
        except (ValueError, TypeError, OSError, RuntimeError) as e:
            self.report({"ERROR"}, str(e))
            return {"CANCELLED"}
        finally:
            wm.progress_end()
            if context.workspace:
                context.workspace.status_text_set(None)
        self.report(
            {"INFO"},
            f"Rigid Cells: {report.cells} cells, {report.iterations} iterations, "
            f"{report.foldovers} fold-overs",
        )
        return {"FINISHED"}


class VIEW3D_PT_rigidcells(bpy.types.Panel):
    """The settings, Deform, and the last run's figures, in the 3D view's sidebar."""

    bl_space_type = "VIEW_3D"
    bl_region_type = "UI"
    bl_category = "Rigid Cells"
    bl_label = "Rigid Cells"

    @classmethod
    def poll(cls, context: Any) -> bool:
        return _mesh_active(context)

    def draw(self, context: Any) -> None:
        obj = context.active_object
        s = obj.rigidcells
        layout = self.layout
        layout.prop_search(s, "fixed_group", obj, "vertex_groups")
        layout.prop_search(s, "handle_group", obj, "vertex_groups")
        layout.prop(s, "handle_object")
        layout.prop(s, "cell_size")
        layout.prop(s, "transfer")
        layout.operator(OBJECT_OT_rigidcells_deform.bl_idname, text="Deform")
        if s.cells:
            col = layout.column(align=True)
            col.label(text=f"{s.cells} cells, {s.iterations} iterations")
            col.label(text=f"Residual: fixed {s.residual_fixed:.3g}, handle {s.residual_handle:.3g}")
            col.label(text=f"Fold-overs: {s.foldovers}")


CLASSES = (RigidCellsSettings, OBJECT_OT_rigidcells_deform, VIEW3D_PT_rigidcells)


def register() -> None:
    for cls in CLASSES:
        bpy.utils.register_class(cls)
    bpy.types.Object.rigidcells = PointerProperty(type=RigidCellsSettings)


def unregister() -> None:
    del bpy.types.Object.rigidcells
    for cls in reversed(CLASSES):
        bpy.utils.unregister_class(cls)
