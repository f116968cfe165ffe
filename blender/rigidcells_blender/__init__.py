"""Rigid Cells in Blender: bend meshes, soups of any number of loose parts, non-manifold meshes
and vertex-only scans with the rigidcells library, into a shape key.

The add-on turns Blender's data into the library's inputs and back and nothing more: the
vertices of the base shape, the triangles, the vertex groups as `indices` regions, each handle
Empty's motion since it was assigned as a `matrix`, pins (a vertex group's center, moved by its
Empty) and a stiffness group go to `rigidcells.deform`; the moved vertices come back as the
shape key `RigidCells`, which the artist can blend, animate or apply. Vertices of the fixed
group keep their coordinates bit for bit; vertices of a handle group land where its Empty
sends them (to Blender's single precision).

Deform solves on a thread of its own (`work.DeformJob`) while Blender stays responsive; Live
keeps a `rigidcells.Session` on a thread (`work.LiveWorker`) that follows the handle and pin
Empties as the artist moves them: one Gauss-Newton iteration and a blended preview a pose, the exact
transfer once they rest. Scripts and Blender without a window (`bpy` as a module) run Deform
on the calling thread.
"""

from __future__ import annotations

from typing import Any, List, Optional, Tuple

import bpy
import numpy as np
from bpy.props import (
    CollectionProperty,
    EnumProperty,
    FloatProperty,
    FloatVectorProperty,
    IntProperty,
    PointerProperty,
    StringProperty,
)

from .work import Cancelled, DeformJob, LiveWorker

SHAPE_KEY = "RigidCells"

TRANSFERS = [
    ("pu", "Partition of unity", "Local RBFs blended over the cells (the default)"),
    ("rbf", "RBF", "One global RBF over the cells (the paper's; a few thousand cells)"),
    ("blend", "Blend", "Each vertex follows the cells around it, blended"),
    ("blend-idw", "Blend (inverse distance)", "The blend with inverse-distance weights"),
]


def _flat(matrix: Any) -> List[float]:
    return [v for row in matrix for v in row]


def _take_rest(settings: "RigidCellsSettings", _context: Any) -> None:
    """The handle Empty's pose when it is assigned: its motion from here is the handle's."""
    empty = settings.handle_object
    if empty is not None:
        settings.handle_rest = _flat(empty.matrix_world)


def _take_item_rest(item: "RigidCellsMover", _context: Any) -> None:
    """An extra handle's or a pin's Empty pose when it is assigned."""
    if item.object is not None:
        item.rest = _flat(item.object.matrix_world)


def _is_empty(_self: Any, obj: bpy.types.Object) -> bool:
    return obj.type == "EMPTY"


class RigidCellsMover(bpy.types.PropertyGroup):
    """A vertex group moved by an Empty: another handle (the group follows the Empty's
    motion), or a pin (the group's center goes where the Empty moves it; its cell may turn)."""

    group: StringProperty(name="Group", description="The vertex group the Empty moves")
    object: PointerProperty(
        name="Empty",
        type=bpy.types.Object,
        poll=_is_empty,
        update=_take_item_rest,
        description="An Empty: its motion since it was assigned moves the group",
    )
    rest: FloatVectorProperty(size=16, options={"HIDDEN"})


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
        poll=_is_empty,
        update=_take_rest,
        description="An Empty: its motion since it was assigned moves the handle group",
    )
    handle_rest: FloatVectorProperty(size=16, options={"HIDDEN"})
    handles: CollectionProperty(type=RigidCellsMover, name="More handles")
    pins: CollectionProperty(type=RigidCellsMover, name="Pins")
    stiffness_group: StringProperty(
        name="Stiffness group",
        description="Vertex group whose cells are stiffer (or softer) than the rest",
    )
    stiffness: FloatProperty(
        name="Stiffness",
        default=10.0,
        min=1e-3,
        max=1e3,
        description="How much stiffer the stiffness group's cells are (below 1: softer)",
    )
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


def _motion(obj: bpy.types.Object, empty: bpy.types.Object, rest: Any) -> np.ndarray:
    """The Empty's motion since its rest pose (world), seen from the object: a 4 × 4 affine
    map of the object's own coordinates."""
    rest = np.array(rest, dtype=np.float64).reshape(4, 4)
    now = np.array(empty.matrix_world, dtype=np.float64)
    world = np.array(obj.matrix_world, dtype=np.float64)
    local = np.linalg.inv(world) @ (now @ np.linalg.inv(rest)) @ world
    local[3] = [0.0, 0.0, 0.0, 1.0]
    return local


def handle_matrix(obj: bpy.types.Object, settings: RigidCellsSettings) -> List[List[float]]:
    """The handle's affine map in the object's own coordinates: the Empty's motion since its
    rest pose (world), seen from the object."""
    if settings.handle_object is None:
        raise InputError("Rigid Cells: choose the handle Empty")
    return _motion(obj, settings.handle_object, settings.handle_rest).tolist()


def _movers(settings: RigidCellsSettings, kind: str) -> List[RigidCellsMover]:
    """The extra handles or the pins, each checked to name an Empty."""
    items = list(getattr(settings, kind))
    what, first = ("handle", 2) if kind == "handles" else ("pin", 1)
    for k, item in enumerate(items):
        if item.object is None:
            raise InputError(f"Rigid Cells: choose the Empty of {what} {first + k}")
    return items


def poses(obj: bpy.types.Object) -> List[dict]:
    """Each handle's pose, in the spec's order (the handle, then the extra ones): what Live
    hands the session as the Empties move."""
    settings = obj.rigidcells
    moves = [handle_matrix(obj, settings)]
    for item in _movers(settings, "handles"):
        moves.append(_motion(obj, item.object, item.rest).tolist())
    return [{"matrix": m} for m in moves]


def _pins(obj: bpy.types.Object, rest: np.ndarray) -> List[dict]:
    """The pins: each group's center at rest, and where its Empty's motion sends it."""
    items = _movers(obj.rigidcells, "pins")
    centers = [rest[_group_indices(obj, item.group, "pin")].mean(axis=0) for item in items]
    places = pin_places(obj, centers)
    return [{"point": c.tolist(), "to": to} for c, to in zip(centers, places)]


def pin_places(obj: bpy.types.Object, centers: List[np.ndarray]) -> List[List[float]]:
    """Where each pin's Empty sends its group's center now (what Live hands the session)."""
    items = _movers(obj.rigidcells, "pins")
    return [
        (_motion(obj, item.object, item.rest) @ np.append(c, 1.0))[:3].tolist()
        for item, c in zip(items, centers)
    ]


def inputs(obj: bpy.types.Object) -> Tuple[np.ndarray, Optional[np.ndarray], dict]:
    """The library's inputs for `obj`: its rest vertices, its triangles and the spec."""
    if obj is None or obj.type != "MESH":
        raise InputError("Rigid Cells: select a mesh object")
    settings = obj.rigidcells
    fixed = _group_indices(obj, settings.fixed_group, "fixed")
    handle = _group_indices(obj, settings.handle_group, "handle")
    if settings.handle_object is None:
        raise InputError("Rigid Cells: choose the handle Empty")
    groups = [handle] + [
        _group_indices(obj, item.group, f"handle {k + 2}")
        for k, item in enumerate(_movers(settings, "handles"))
    ]
    rest = _rest_vertices(obj.data)
    spec: dict = {
        "fixed": [{"indices": fixed}],
        "handle": [
            {"indices": g, **pose} for g, pose in zip(groups, poses(obj))
        ],
    }
    pins = _pins(obj, rest)
    if pins:
        spec["pin"] = pins
    if settings.stiffness_group:
        stiff = _group_indices(obj, settings.stiffness_group, "stiffness")
        spec["stiffness"] = [{"indices": stiff, "scale": settings.stiffness}]
    return rest, _triangles(obj.data), spec


def options(settings: RigidCellsSettings) -> dict:
    """The library's keyword options the settings give."""
    return {"cell_size": settings.cell_size or None, "transfer": settings.transfer}


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


def show_report(obj: bpy.types.Object, report: Any) -> None:
    """The report's figures in the panel's settings."""
    settings = obj.rigidcells
    settings.cells = report.cells
    settings.iterations = report.iterations
    settings.residual_fixed = report.residual_fixed_max
    settings.residual_handle = report.residual_handle_max
    settings.foldovers = report.foldovers


def finish(obj: bpy.types.Object, moved: np.ndarray, report: Any) -> None:
    """A deformation's result as the shape key and the panel's figures; refused when the mesh
    no longer has the vertices it was solved for."""
    if len(moved) != len(obj.data.vertices):
        raise InputError(
            f"Rigid Cells: {obj.name} has {len(obj.data.vertices)} vertices now, "
            f"{len(moved)} were solved; deform again"
        )
    write_shape_key(obj, moved)
    show_report(obj, report)


def deform(obj: bpy.types.Object, progress: Any = False) -> Any:
    """Deforms `obj` as its settings say and writes the shape key, on this thread; returns
    the library's report. Nothing of the object changes when an error is raised."""
    import rigidcells

    points, triangles, spec = inputs(obj)
    moved, report = rigidcells.deform(
        points, spec, triangles=triangles, progress=progress, **options(obj.rigidcells)
    )
    finish(obj, moved, report)
    return report


class LiveState:
    """Live on one object, driven by the main thread: `tick` hands the session the handles'
    poses and the pins' places when an Empty moved and writes the newest shape into the shape
    key; `finish` ends
    on the exact shape of the last pose; `cancel` puts the shape key back as it was."""

    def __init__(self, obj: bpy.types.Object, settle: float = 0.25) -> None:
        points, triangles, spec = inputs(obj)
        self.name = obj.name
        self._centers = [np.array(p["point"]) for p in spec.get("pin", [])]
        self.pins = [p["to"] for p in spec.get("pin", [])]
        self.poses = poses(obj)
        self.count = len(points)
        keys = obj.data.shape_keys
        key = keys.key_blocks.get(SHAPE_KEY) if keys is not None else None
        # What Esc restores: no shape keys, no RigidCells key, or the key's shape and value.
        self._before: Optional[Tuple[Optional[np.ndarray], float]] = None
        self._had_keys = keys is not None
        if key is not None:
            co = np.empty(3 * len(key.data), dtype=np.float32)
            key.data.foreach_get("co", co)
            self._before = (co, key.value)
        self.kind: Optional[str] = None
        self.worker = LiveWorker(points, spec, triangles, options(obj.rigidcells), settle).start()

    def tick(self, obj: bpy.types.Object) -> Optional[str]:
        """One look at the Empties and the worker: the kind of shape written, if any. The
        worker's error is raised here."""
        if self.worker.error is not None:
            raise self.worker.error
        now = poses(obj)
        pins = pin_places(obj, self._centers)
        if now != self.poses or pins != self.pins:
            self.poses, self.pins = now, pins
            self.worker.move(now, pins or None)
        shape = self.worker.take()
        if shape is None:
            return None
        self.kind, moved = shape
        if len(moved) != len(obj.data.vertices):
            raise InputError(f"Rigid Cells: {obj.name} changed its vertices during Live")
        write_shape_key(obj, moved)
        if self.kind == "released" and self.worker.report is not None:
            show_report(obj, self.worker.report)
        return self.kind

    def finish(self) -> None:
        self.worker.finish()

    def cancel(self, obj: Optional[bpy.types.Object]) -> None:
        """Stops the worker and puts the shape key back as it was before Live."""
        self.worker.stop()
        if obj is None:
            return
        if not self._had_keys:
            if obj.data.shape_keys is not None:
                obj.shape_key_clear()
        elif self._before is None:
            key = obj.data.shape_keys.key_blocks.get(SHAPE_KEY)
            if key is not None:
                obj.shape_key_remove(key)
        else:
            co, value = self._before
            key = obj.data.shape_keys.key_blocks.get(SHAPE_KEY)
            if key is None:
                key = obj.shape_key_add(name=SHAPE_KEY, from_mix=False)
            key.data.foreach_set("co", co)
            key.value = value
        obj.data.update()


def _mesh_active(context: Any) -> bool:
    """Whether the active object is a mesh, which the operator and the panel work on."""
    obj = context.active_object
    return obj is not None and obj.type == "MESH"


ERRORS = (ValueError, TypeError, OSError, RuntimeError, Cancelled)


def _said(error: BaseException) -> str:
    """The error as the panel names things: a refused turn (`rigidcells.TurnNotHeldError`)
    names its handle "the handle Empty" or "handle 2", not by the spec the add-on wrote."""
    handle, said = getattr(error, "handle", None), getattr(error, "said", None)
    if isinstance(handle, int) and isinstance(said, str):
        name = "the handle Empty" if handle == 0 else f"handle {handle + 1}"
        return f"Rigid Cells: {name} {said}"
    return str(error)


def _status(context: Any, text: Optional[str]) -> None:
    if context.workspace is not None:
        context.workspace.status_text_set(text)


class OBJECT_OT_rigidcells_deform(bpy.types.Operator):
    """Bend the object with rigid cells: the fixed group stays, the handle groups follow their
    Empties, the rest follows as stiffly as cells glued face to face allow"""

    bl_idname = "object.rigidcells_deform"
    bl_label = "Rigid Cells Deform"
    bl_options = {"REGISTER", "UNDO"}

    @classmethod
    def poll(cls, context: Any) -> bool:
        return _mesh_active(context)

    def execute(self, context: Any) -> set:
        """The deformation on this thread (scripts, and Blender without a window)."""
        obj = context.active_object
        wm = context.window_manager
        stages: dict = {}

        def progress(stage: str, done: int, total: Optional[int]) -> None:
            if total:
                wm.progress_update(int(100 * done / total))
            if stage not in stages:
                stages[stage] = True
                _status(context, f"Rigid Cells: {stage}")

        wm.progress_begin(0, 100)
        try:
            report = deform(obj, progress=progress)
        except ERRORS as e:
            self.report({"ERROR"}, _said(e))
            return {"CANCELLED"}
        finally:
            wm.progress_end()
            _status(context, None)
        self._done(report)
        return {"FINISHED"}

    def invoke(self, context: Any, event: Any) -> set:
        """The deformation on a thread of its own, Blender responsive meanwhile; Esc stops
        it and leaves the mesh as it was."""
        if context.window is None:
            return self.execute(context)
        obj = context.active_object
        try:
            points, triangles, spec = inputs(obj)
        except ERRORS as e:
            self.report({"ERROR"}, _said(e))
            return {"CANCELLED"}
        self._name = obj.name
        self._job = DeformJob(points, spec, triangles, options(obj.rigidcells)).start()
        wm = context.window_manager
        self._timer = wm.event_timer_add(0.1, window=context.window)
        wm.modal_handler_add(self)
        wm.progress_begin(0, 100)
        _status(context, "Rigid Cells: solving (Esc stops)")
        return {"RUNNING_MODAL"}

    def modal(self, context: Any, event: Any) -> set:
        job = self._job
        if event.type == "ESC":
            job.cancel()
            return {"RUNNING_MODAL"}
        if event.type != "TIMER":
            return {"PASS_THROUGH"}
        stage, done, total = job.progress
        wm = context.window_manager
        if total:
            wm.progress_update(int(100 * done / total))
        _status(context, f"Rigid Cells: {stage} (Esc stops)")
        if not job.done:
            return {"RUNNING_MODAL"}
        wm.event_timer_remove(self._timer)
        wm.progress_end()
        _status(context, None)
        obj = bpy.data.objects.get(self._name)
        try:
            if job.error is not None:
                raise job.error
            if obj is None:
                raise InputError(f"Rigid Cells: {self._name} was removed while solving")
            moved, report = job.result
            finish(obj, moved, report)
        except Cancelled as e:
            self.report({"INFO"}, str(e))
            return {"CANCELLED"}
        except Exception as e:  # the library's errors and Blender's: the mesh as it was
            self.report({"ERROR"}, _said(e))
            return {"CANCELLED"}
        self._done(report)
        return {"FINISHED"}

    def cancel(self, context: Any) -> None:
        """Blender ends the operator (a file loaded, the window closed): the solve stops."""
        self._job.cancel()
        context.window_manager.event_timer_remove(self._timer)
        context.window_manager.progress_end()
        _status(context, None)

    def _done(self, report: Any) -> None:
        self.report(
            {"INFO"},
            f"Rigid Cells: {report.cells} cells, {report.iterations} iterations, "
            f"{report.foldovers} fold-overs",
        )


# The objects Live runs on, with their state (the panel shows it).
_live: dict = {}


class OBJECT_OT_rigidcells_live(bpy.types.Operator):
    """Re-solve while you move the handle Empties: a blended preview on the shape key as they
    move, the exact shape once they rest. Enter keeps it, Esc puts the shape key back"""

    bl_idname = "object.rigidcells_live"
    bl_label = "Rigid Cells Live"
    bl_options = {"REGISTER", "UNDO"}

    @classmethod
    def poll(cls, context: Any) -> bool:
        return _mesh_active(context) and not _live

    def invoke(self, context: Any, event: Any) -> set:
        if context.window is None:
            self.report({"ERROR"}, "Rigid Cells: Live follows the Empties in Blender's window")
            return {"CANCELLED"}
        try:
            self._state = LiveState(context.active_object)
        except ERRORS as e:
            self.report({"ERROR"}, _said(e))
            return {"CANCELLED"}
        _live[self._state.name] = self._state
        self._finishing = False
        wm = context.window_manager
        self._timer = wm.event_timer_add(1 / 60, window=context.window)
        wm.modal_handler_add(self)
        _status(context, "Rigid Cells Live: move the handle Empties; Enter keeps, Esc restores")
        return {"RUNNING_MODAL"}

    def modal(self, context: Any, event: Any) -> set:
        state = self._state
        obj = bpy.data.objects.get(state.name)
        if event.type == "ESC" and event.value == "PRESS":
            state.cancel(obj)
            return self._end(context, {"CANCELLED"})
        if event.type in {"RET", "NUMPAD_ENTER"} and event.value == "PRESS":
            self._finishing = True
            state.finish()
            _status(context, "Rigid Cells Live: releasing")
            return {"RUNNING_MODAL"}
        if event.type != "TIMER":
            return {"PASS_THROUGH"}
        # Whether the worker had ended before this tick takes its last shape.
        done = state.worker.done
        try:
            if obj is None:
                raise InputError(f"Rigid Cells: {state.name} was removed during Live")
            # The Empties' world matrices as they are now, also when a script moved them and
            # nothing has been redrawn since.
            context.view_layer.update()
            state.tick(obj)
        except Exception as e:  # a deleted Empty, a failed solve: the mesh as it was
            state.cancel(obj)
            self.report({"ERROR"}, _said(e))
            return self._end(context, {"CANCELLED"})
        if self._finishing and done:
            return self._end(context, {"FINISHED"})
        return {"PASS_THROUGH"}

    def cancel(self, context: Any) -> None:
        """Blender ends the operator (a file loaded, the window closed): the shape key as it
        was before Live."""
        self._state.cancel(bpy.data.objects.get(self._state.name))
        self._end(context, {"CANCELLED"})

    def _end(self, context: Any, result: set) -> set:
        context.window_manager.event_timer_remove(self._timer)
        _live.pop(self._state.name, None)
        _status(context, None)
        return result


class RIGIDCELLS_OT_add(bpy.types.Operator):
    """Add another handle or a pin: a vertex group moved by an Empty"""

    bl_idname = "rigidcells.add"
    bl_label = "Add"
    bl_options = {"REGISTER", "UNDO", "INTERNAL"}
    kind: EnumProperty(items=[("handles", "Handle", ""), ("pins", "Pin", "")])

    @classmethod
    def poll(cls, context: Any) -> bool:
        return _mesh_active(context)

    def execute(self, context: Any) -> set:
        getattr(context.active_object.rigidcells, self.kind).add()
        return {"FINISHED"}


class RIGIDCELLS_OT_remove(bpy.types.Operator):
    """Remove this handle or pin"""

    bl_idname = "rigidcells.remove"
    bl_label = "Remove"
    bl_options = {"REGISTER", "UNDO", "INTERNAL"}
    kind: EnumProperty(items=[("handles", "Handle", ""), ("pins", "Pin", "")])
    index: IntProperty()

    @classmethod
    def poll(cls, context: Any) -> bool:
        return _mesh_active(context)

    def execute(self, context: Any) -> set:
        getattr(context.active_object.rigidcells, self.kind).remove(self.index)
        return {"FINISHED"}


class VIEW3D_PT_rigidcells(bpy.types.Panel):
    """The settings, Deform, Live, and the last run's figures, in the 3D view's sidebar."""

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
        # Each label above its field: the sidebar is narrow.
        col = layout.column(align=True)
        col.label(text="Fixed group")
        col.prop_search(s, "fixed_group", obj, "vertex_groups", text="")
        col = layout.column(align=True)
        col.label(text="Handle: group, Empty")
        col.prop_search(s, "handle_group", obj, "vertex_groups", text="")
        col.prop(s, "handle_object", text="")
        for kind, label in (("handles", "Handle"), ("pins", "Pin")):
            first = 2 if kind == "handles" else 1
            for k, item in enumerate(getattr(s, kind)):
                col = layout.box().column(align=True)
                row = col.row()
                row.label(text=f"{label} {first + k}: group, Empty")
                remove = row.operator(RIGIDCELLS_OT_remove.bl_idname, text="", icon="X")
                remove.kind, remove.index = kind, k
                col.prop_search(item, "group", obj, "vertex_groups", text="")
                col.prop(item, "object", text="")
        row = layout.row(align=True)
        row.operator(RIGIDCELLS_OT_add.bl_idname, text="Handle", icon="ADD").kind = "handles"
        row.operator(RIGIDCELLS_OT_add.bl_idname, text="Pin", icon="ADD").kind = "pins"
        col = layout.column(align=True)
        col.label(text="Stiffness group")
        col.prop_search(s, "stiffness_group", obj, "vertex_groups", text="")
        if s.stiffness_group:
            col.prop(s, "stiffness")
        col = layout.column(align=True)
        col.prop(s, "cell_size")
        col.prop(s, "transfer", text="")
        row = layout.row(align=True)
        row.operator(OBJECT_OT_rigidcells_deform.bl_idname, text="Deform")
        if obj.name in _live:
            row.label(text="Live: Enter keeps, Esc restores")
        else:
            row.operator(OBJECT_OT_rigidcells_live.bl_idname, text="Live")
        if s.cells:
            col = layout.column(align=True)
            col.label(text=f"{s.cells} cells, {s.iterations} iterations")
            col.label(text=f"Residual: fixed {s.residual_fixed:.3g}, handle {s.residual_handle:.3g}")
            col.label(text=f"Fold-overs: {s.foldovers}")


CLASSES = (
    RigidCellsMover,
    RigidCellsSettings,
    OBJECT_OT_rigidcells_deform,
    OBJECT_OT_rigidcells_live,
    RIGIDCELLS_OT_add,
    RIGIDCELLS_OT_remove,
    VIEW3D_PT_rigidcells,
)


def register() -> None:
    for cls in CLASSES:
        bpy.utils.register_class(cls)
    bpy.types.Object.rigidcells = PointerProperty(type=RigidCellsSettings)


def unregister() -> None:
    for state in list(_live.values()):
        state.worker.stop()
        state.worker.thread.join(5.0)
    _live.clear()
    del bpy.types.Object.rigidcells
    for cls in reversed(CLASSES):
        bpy.utils.unregister_class(cls)
