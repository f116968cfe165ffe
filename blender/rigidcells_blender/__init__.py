"""Rigid Cells in Blender: bend meshes, soups of any number of loose parts, non-manifold meshes
and vertex-only scans with the rigidcells library, into a shape key.

The add-on turns Blender's data into the library's inputs and back and nothing more: the
vertices of the base shape, the triangles, the vertex groups as `indices` regions, each handle
Empty's motion since it was assigned, pins (a vertex group's center, moved by its Empty) and a
stiffness group go to `rigidcells.deform`; the moved vertices come back as the shape key
`RigidCells`, which the artist can blend, animate or apply. Vertices of the fixed group keep
their coordinates bit for bit; vertices of a handle group land where its Empty sends them (to
Blender's single precision).

A handle's turn is the rotation typed on its Empty, with its winding (`handle_pose`): 360°
typed is a whole turn, not none, and 270° is not −90°. A matrix cannot say how many turns it
makes, so the add-on reads the Empty's rotation values (Euler, axis-angle or quaternion, as
keyed when animated) against those it had when assigned, and hands the library the Empty's
motion as `rotate` (axis and degrees, of any size) about the Empty's rest origin, `translate`
and `scale`: the same map as the Empty's matrices, with the typed turn. Deform and Live read
the poses alike, so the same typed pose gives the same shape.

Follow (`follow.py`) keeps the key on the Empties' poses as they move or play, as a modifier
would, and bakes a frame range into keyed shapes.

Deform solves on a thread of its own (`work.DeformJob`) while Blender stays responsive; Live
keeps a `rigidcells.Session` on a thread (`work.LiveWorker`) that follows the handle and pin
Empties as the artist moves them: a short solver step and a blended preview a pose, the exact
transfer once they rest. Scripts and Blender without a window (`bpy` as a module) run Deform
on the calling thread.
"""

from __future__ import annotations

import os
import sys
import textwrap
from typing import Any, List, Optional, Tuple

import bpy
import numpy as np
from bpy.props import (
    BoolProperty,
    CollectionProperty,
    EnumProperty,
    FloatProperty,
    FloatVectorProperty,
    IntProperty,
    PointerProperty,
    StringProperty,
)

from .handles import (  # noqa: F401  (an Empty's motion as a handle pose)
    InputError,
    _flat,
    _motion,
    _rotation_values,
    _scale_values,
    handle_pose,
    typed_turn,
)
from . import follow
from .follow import RIGIDCELLS_OT_bake
from .selection import GROUP_PREFIX, RIGIDCELLS_OT_from_selection, from_selection  # noqa: F401
from .scene import (  # noqa: F401  (the scene's inputs and keys, for the operators and tests)
    FULL_WEIGHT,
    PULL,
    SHAPE_KEY,
    Weighted,
    _group_indices,
    _group_weights,
    _movers,
    _rest_vertices,
    FOLDS_GROUP,
    KeyBefore,
    held_vertices,
    inputs,
    mark_folds,
    members,
    pin_places,
    poses,
    split,
    write_keys,
    write_shape_key,
)
from .work import Cancelled, DeformJob, LiveWorker

from .rotations import (  # noqa: F401  (the rotations' arithmetic, without Blender)
    EULER_ORDERS,
    ROTATION_MODES,
    _SAME_MAP,
    _elemental,
    _axis_rotation,
    _unit,
    _rotation,
    _axis_angle,
    _in_mode,
)

# What Blender's add-on list shows of a legacy install (Blender 3.4 to 4.1, or Install… from
# the legacy zip in later ones); an extension (4.2 and later) is described by its manifest.
bl_info = {
    "name": "Rigid Cells",
    "author": "rigidcells developers",
    "version": (0, 1, 0),
    "blender": (3, 4, 0),
    "location": "3D View > Sidebar > Rigid Cells",
    "description": "Bend meshes, soups and scans with rigid cells into a shape key",
    "category": "Mesh",
}

# A legacy install carries the rigidcells package unpacked beside the add-on, in `site/`
# (`blender/build_extension.py`); an extension has Blender install the package's wheel.
_SITE = os.path.join(os.path.dirname(os.path.abspath(__file__)), "site")
if os.path.isdir(_SITE) and _SITE not in sys.path:
    sys.path.append(_SITE)


TRANSFERS = [
    ("pu", "Partition of unity", "Local RBFs blended over the cells (the default)"),
    ("rbf", "RBF", "One global RBF over the cells (the paper's; a few thousand cells)"),
    ("blend", "Blend", "Each vertex follows the cells around it, blended"),
    ("blend-idw", "Blend (inverse distance)", "The blend with inverse-distance weights"),
]


def _take_rest(settings: "RigidCellsSettings", _context: Any) -> None:
    """The handle Empty's pose when it is assigned: its matrix, and its rotation values and
    scale as typed; its motion from here is the handle's."""
    empty = settings.handle_object
    if empty is not None:
        settings.handle_rest = _flat(empty.matrix_world)
        settings.handle_rest_mode = empty.rotation_mode
        settings.handle_rest_rotation = _rotation_values(empty)
        settings.handle_rest_scale = _scale_values(empty)


def _take_item_rest(item: "RigidCellsMover", _context: Any) -> None:
    """An extra handle's or a pin's Empty pose when it is assigned (as `_take_rest`)."""
    empty = item.object
    if empty is not None:
        item.rest = _flat(empty.matrix_world)
        item.rest_mode = empty.rotation_mode
        item.rest_rotation = _rotation_values(empty)
        item.rest_scale = _scale_values(empty)


def _follow_changed(settings: "RigidCellsSettings", context: Any) -> None:
    from .follow import follow_changed

    follow_changed(settings, context)


def _is_empty(_self: Any, obj: bpy.types.Object) -> bool:
    return obj.type == "EMPTY"


def _is_mesh(_self: Any, obj: bpy.types.Object) -> bool:
    return obj.type == "MESH"


class RigidCellsMember(bpy.types.PropertyGroup):
    """A mesh deformed together with the object, as one scene (its own key)."""

    object: PointerProperty(name="Object", type=bpy.types.Object, poll=_is_mesh)


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
    # The Empty's rotation values, their mode and its scale when assigned (`_take_rest`).
    rest_mode: StringProperty(options={"HIDDEN"})
    rest_rotation: FloatVectorProperty(size=4, options={"HIDDEN"})
    rest_scale: FloatVectorProperty(size=3, default=(1.0, 1.0, 1.0), options={"HIDDEN"})


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
    # The handle Empty's rotation values, their mode and its scale when assigned.
    handle_rest_mode: StringProperty(options={"HIDDEN"})
    handle_rest_rotation: FloatVectorProperty(size=4, options={"HIDDEN"})
    handle_rest_scale: FloatVectorProperty(size=3, default=(1.0, 1.0, 1.0), options={"HIDDEN"})
    handles: CollectionProperty(type=RigidCellsMover, name="More handles")
    pins: CollectionProperty(type=RigidCellsMover, name="Pins")
    together: CollectionProperty(
        type=RigidCellsMember,
        name="Together",
        description="Meshes deformed with this one as one scene, each into its own key; their "
        "vertex groups of the names above are the scene's groups",
    )
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
    cells: IntProperty(
        name="Cells",
        default=0,
        min=0,
        description="About this many cells, their size found to match (0: the cell size decides)",
    )
    interior_stiffness: FloatProperty(
        name="Interior stiffness",
        default=0.05,
        min=1e-4,
        max=1e4,
        soft_min=0.01,
        soft_max=1.0,
        description="How stiff the cells inside the mesh are against those on its surface: at "
        "0.05 a turned head twists the whole neck as a surface would and a bend keeps most of "
        "its volume; 1, a uniform solid, keeps a bend's volume best and gathers a twist in the "
        "neck's thinnest part",
    )
    memory_limit: FloatProperty(
        name="Memory limit",
        default=0.0,
        min=0.0,
        description="GiB a run may take; one that would take more is refused before it starts "
        "(0: three quarters of the machine's memory)",
    )
    transfer: EnumProperty(name="Transfer", items=TRANSFERS, default="pu")
    follow: BoolProperty(
        name="Follow",
        default=False,
        update=_follow_changed,
        description="The shape key follows the Empties as they move, are typed, driven or "
        "keyframed (re-solved warm at each change and each frame), without running Deform",
    )
    # Why Follow stopped, for the panel.
    follow_said: StringProperty(options={"HIDDEN"})
    # The last run's figures, for the panel.
    run_cells: IntProperty(options={"HIDDEN"})
    iterations: IntProperty(options={"HIDDEN"})
    residual_fixed: FloatProperty(options={"HIDDEN"})
    residual_handle: FloatProperty(options={"HIDDEN"})
    foldovers: IntProperty(options={"HIDDEN"})
    # The last run's warnings, a line each, in the panel's words.
    warnings: StringProperty(options={"HIDDEN"})
    # The last estimate (`RIGIDCELLS_OT_estimate`), for the panel.
    estimate: StringProperty(options={"HIDDEN"})


def _typed(value: float) -> float:
    """A panel's number as the artist typed it: Blender keeps it in single precision (0.00001
    is 9.999999747378752e-06 there), the shortest decimal that is that float is what was
    typed."""
    return float(np.format_float_positional(np.float32(value), unique=True))


def options(settings: RigidCellsSettings) -> dict:
    """The library's keyword options the settings give."""
    # A positive limit is at least a byte: only the panel's 0 is its "automatic".
    gib = _typed(settings.memory_limit)
    memory = max(1, int(gib * 2**30)) if gib > 0 else 0
    return {
        "cell_size": _typed(settings.cell_size) or None,
        "cells": settings.cells or None,
        "interior_stiffness": _typed(settings.interior_stiffness),
        "memory_limit": memory or None,
        "transfer": settings.transfer,
    }


def show_report(obj: bpy.types.Object, report: Any) -> None:
    """The report's figures in the panel's settings."""
    settings = obj.rigidcells
    settings.run_cells = report.cells
    settings.iterations = report.iterations
    settings.residual_fixed = report.residual_fixed_max
    settings.residual_handle = report.residual_handle_max
    settings.foldovers = report.foldovers
    mark_folds(obj, getattr(report, "foldover_samples", None) or [])
    settings.warnings = "\n".join(warnings_said(report, obj))


def warnings_said(report: Any, obj: Optional[bpy.types.Object] = None) -> List[str]:
    """The run's warnings as the panel names things (its settings, its groups), after the
    add-on's own about `obj`; the package's own Python warnings are silenced for the add-on
    (`register`), which shows these instead."""
    said = getattr(report, "warnings_in", None)
    library = said(_option_said, _entry_said) if said is not None else list(report.warnings)
    return (uneven_scale(obj) if obj is not None else []) + library


def uneven_scale(obj: bpy.types.Object) -> List[str]:
    """A warning when `obj` is scaled unevenly: the scene is deformed in its coordinates, where
    the cells are cubes, so its shape in the world is not what the same mesh with the scale
    applied gives."""
    world = np.array(obj.matrix_world)[:3, :3]
    sizes = np.linalg.norm(world, axis=0)
    if sizes.max() <= sizes.min() * (1.0 + 1e-6):
        return []
    scale = ", ".join(f"{v:.3g}" for v in sizes)
    return [
        f"{obj.name} is scaled unevenly ({scale}): the cells are cubes in its own "
        "coordinates, not in the world's, and the bend is not the one the same mesh bends "
        "with its scale applied (Object > Apply > Scale)"
    ]


def finish(obj: bpy.types.Object, moved: np.ndarray, report: Any) -> None:
    """A deformation's result as each object's shape key and the panel's figures; refused when
    the meshes no longer have the vertices they were solved for."""
    write_keys(obj, moved)
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
    on the exact shape of the last pose; `cancel` puts the shape key back as it was.

    The poses are `poses`', as Deform's spec has them, so that the same typed pose gives the
    same shape. Each goes on warm from the last shape, which winds a turn as the Empty turns;
    a pose that turns a handle by more than a load step from the last one is solved from rest
    by the session, in load steps, with its winding."""

    def __init__(self, obj: bpy.types.Object, settle: float = 0.25) -> None:
        points, triangles, spec = inputs(obj)
        self.name = obj.name
        self._centers = [np.array(p["point"]) for p in spec.get("pin", [])]
        self.pins = [p["to"] for p in spec.get("pin", [])]
        self.poses = poses(obj)
        self._weighted = Weighted(obj, points) if "target" in spec else None
        self.count = len(points)
        # What Esc restores, for each object of the scene (`members`).
        self._before = {o.name: KeyBefore(o) for o in members(obj)}
        # The other objects' fixed vertices, given back bit for bit in every shape.
        self._held = held_vertices(obj)
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
            targets = None if self._weighted is None else self._weighted.places(obj).tolist()
            self.worker.move(now, pins or None, targets)
        shape = self.worker.take()
        if shape is None:
            return None
        self.kind, moved = shape
        write_keys(obj, moved, self._held)
        if self.kind == "released" and self.worker.report is not None:
            show_report(obj, self.worker.report)
        return self.kind

    def finish(self) -> None:
        self.worker.finish()

    def cancel(self, obj: Optional[bpy.types.Object]) -> None:
        """Stops the worker and puts each object's shape key back as it was before Live."""
        self.worker.stop()
        for name, before in self._before.items():
            other = bpy.data.objects.get(name)
            if other is not None:
                before.restore(other)


def _mesh_active(context: Any) -> bool:
    """Whether the active object is a mesh, which the operator and the panel work on."""
    obj = context.active_object
    return obj is not None and obj.type == "MESH"


ERRORS = (ValueError, TypeError, OSError, RuntimeError, Cancelled)


def _leave_edit_mode(context: Any) -> bool:
    """Leaves Edit Mode, if the object is in it, so that the mesh holds its edits and the shape
    key written stays (Edit Mode writes its copy of the mesh back when it ends, over a key
    written meanwhile): whether it was on, to enter it again when done."""
    obj = context.active_object
    if obj is None or obj.mode != "EDIT":
        return False
    bpy.ops.object.mode_set(mode="OBJECT")
    return True


def _back_to_edit_mode(context: Any, was: bool) -> None:
    """Enters Edit Mode again where `_leave_edit_mode` left it: it shows the new shape key."""
    obj = context.active_object
    if was and obj is not None and obj.mode != "EDIT":
        bpy.ops.object.mode_set(mode="EDIT")


def _said(error: BaseException) -> str:
    """The error as the panel names things: a refused turn (`rigidcells.TurnNotHeldError`)
    names its handle "the handle Empty" or "handle 2", not by the spec the add-on wrote."""
    handle, said = getattr(error, "handle", None), getattr(error, "said", None)
    if isinstance(handle, int) and isinstance(said, str):
        name = "the handle Empty" if handle == 0 else f"handle {handle + 1}"
        return f"Rigid Cells: {name} {said}"
    parts = getattr(error, "parts", None)
    if isinstance(parts, list):
        from rigidcells._spec import _said as said_with

        return said_with(parts, None, _option_said, _entry_said)
    return str(error)


def _entry_said(kind: str, index: int) -> str:
    """An entry of the spec the add-on wrote, as the panel names the group that made it: the
    fixed group, the handle group, handle 2's group, pin 1's group, the stiffness group."""
    if kind == "handle":
        return "the handle group" if index == 0 else f"handle {index + 1}'s group"
    if kind == "pin":
        return f"pin {index + 1}'s group"
    if kind in ("fixed", "stiffness"):
        return f"the {kind} group"
    return f"{kind} {index + 1}"


def _option_said(keyword: str, value: Optional[str]) -> Optional[str]:
    """A library option as the panel names it (`"Cell size" 0.02`); None for one the panel
    does not have, which the package then says by its keyword (`min_cell_size`), leaving
    unsaid any advice to set it."""
    prop = RigidCellsSettings.bl_rna.properties.get(keyword)
    if prop is None:
        return None
    return f'"{prop.name}"' if value is None else f'"{prop.name}" {value}'


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
        """The deformation on this thread (scripts, and Blender without a window), out of Edit
        Mode and back."""
        editing = _leave_edit_mode(context)
        try:
            return self._execute(context)
        finally:
            _back_to_edit_mode(context, editing)

    def _execute(self, context: Any) -> set:
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
        self._done(obj, report)
        return {"FINISHED"}

    def invoke(self, context: Any, event: Any) -> set:
        """The deformation on a thread of its own, Blender responsive meanwhile; Esc stops
        it and leaves the mesh as it was."""
        if context.window is None:
            return self.execute(context)
        self._editing = _leave_edit_mode(context)
        obj = context.active_object
        try:
            points, triangles, spec = inputs(obj)
        except ERRORS as e:
            self.report({"ERROR"}, _said(e))
            _back_to_edit_mode(context, self._editing)
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
            return self._finished(context, job, obj)
        finally:
            _back_to_edit_mode(context, self._editing)

    def _finished(self, context: Any, job: DeformJob, obj: Any) -> set:
        """The job's shape on the key, or why not."""
        try:
            if job.error is not None:
                raise job.error
            if obj is None:
                raise InputError(f"Rigid Cells: {self._name} was removed while solving")
            moved, report = job.result
            # Edit Mode entered while it solved would write its copy over the key.
            if context.active_object == obj:
                self._editing = _leave_edit_mode(context) or self._editing
            finish(obj, moved, report)
        except Cancelled as e:
            self.report({"INFO"}, str(e))
            return {"CANCELLED"}
        except Exception as e:  # the library's errors and Blender's: the mesh as it was
            self.report({"ERROR"}, _said(e))
            return {"CANCELLED"}
        self._done(obj, report)
        return {"FINISHED"}

    def cancel(self, context: Any) -> None:
        """Blender ends the operator (a file loaded, the window closed): the solve stops."""
        self._job.cancel()
        context.window_manager.event_timer_remove(self._timer)
        context.window_manager.progress_end()
        _status(context, None)

    def _done(self, obj: bpy.types.Object, report: Any) -> None:
        self.report(
            {"INFO"},
            f"Rigid Cells: {report.cells:,} cells, {report.iterations} iterations, "
            f"{report.foldovers} fold-overs",
        )
        for warning in filter(None, obj.rigidcells.warnings.split("\n")):
            self.report({"WARNING"}, f"Rigid Cells: {warning}")


# The objects Live runs on, with their state (the panel shows it).
_live: dict = {}

# How often Live looks at the Empties and the worker, a second. Twice a 60 Hz display's rate,
# so that a shape the worker finishes between two frames is on the shape key by the next one:
# at 60 the look itself capped Live at 55-59 shapes a second, with a pose 21 ms from its shape
# at 5,000 cells; at 120, 75 a second and 14 ms (`tools/python/blender_live.py`). Faster
# looks take the worker's CPU on two cores (240: 71 a second).
LIVE_RATE = 120


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
        self._editing = _leave_edit_mode(context)
        try:
            self._state = LiveState(context.active_object)
        except ERRORS as e:
            self.report({"ERROR"}, _said(e))
            _back_to_edit_mode(context, self._editing)
            return {"CANCELLED"}
        _live[self._state.name] = self._state
        self._finishing = False
        wm = context.window_manager
        self._timer = wm.event_timer_add(1 / LIVE_RATE, window=context.window)
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
        _back_to_edit_mode(context, self._editing)
        return result


class RIGIDCELLS_OT_estimate(bpy.types.Operator):
    """What Deform will take with these settings, without solving: its cells, memory and
    seconds (the cells are built, the solve counted)"""

    bl_idname = "rigidcells.estimate"
    bl_label = "Estimate"
    bl_options = {"REGISTER", "INTERNAL"}

    @classmethod
    def poll(cls, context: Any) -> bool:
        return _mesh_active(context)

    def execute(self, context: Any) -> set:
        import rigidcells

        obj = context.active_object
        editing = _leave_edit_mode(context)
        try:
            points, triangles, spec = inputs(obj)
            est = rigidcells.estimate(points, spec, triangles=triangles, **options(obj.rigidcells))
        except ERRORS as e:
            # The panel keeps the refusal beside the button (a budget the cells cannot fit).
            obj.rigidcells.estimate = _said(e)
            self.report({"ERROR"}, _said(e))
            return {"CANCELLED"}
        finally:
            _back_to_edit_mode(context, editing)
        obj.rigidcells.estimate = estimate_said(est)
        self.report({"INFO"}, f"Rigid Cells: {obj.rigidcells.estimate}")
        return {"FINISHED"}


def estimate_said(est: Any) -> str:
    """An estimate as the panel says it: `12,345 cells, 1.2 GiB, 3 s`, and whether the memory
    limit refuses it."""
    gib, s = est.bytes / 2**30, est.seconds
    said = f"{'at least ' if not est.complete else ''}{est.cells:,} cells, {gib:.2g} GiB, "
    said += f"{s:.2g} s" if s < 10 else f"{s:.0f} s"
    if not est.fits:
        said += f": over the memory limit ({est.limit / 2**30:.2g} GiB)"
    return said


class RIGIDCELLS_OT_together(bpy.types.Operator):
    """Deform the other selected meshes with this one, as one scene: each gets its own key, and
    their vertex groups of the names above are the scene's groups (none selected: this one
    alone)"""

    bl_idname = "rigidcells.together"
    bl_label = "Together"
    bl_options = {"REGISTER", "UNDO", "INTERNAL"}

    @classmethod
    def poll(cls, context: Any) -> bool:
        return _mesh_active(context)

    def execute(self, context: Any) -> set:
        obj = context.active_object
        together = obj.rigidcells.together
        together.clear()
        for other in context.selected_objects:
            if other.type == "MESH" and other != obj:
                together.add().object = other
        n = len(together)
        said = "alone" if n == 0 else f"with {n} other mesh{'es' if n > 1 else ''}"
        self.report({"INFO"}, f"Rigid Cells: {obj.name} deforms {said}")
        return {"FINISHED"}


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


def _group_row(col: Any, owner: Any, prop: str, obj: Any, role: str, index: int = 0) -> None:
    """A group's field, and the button that makes it the Edit Mode selection."""
    row = col.row(align=True)
    row.prop_search(owner, prop, obj, "vertex_groups", text="")
    op = row.operator(RIGIDCELLS_OT_from_selection.bl_idname, text="", icon="RESTRICT_SELECT_OFF")
    op.role, op.index = role, index


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
        _group_row(col, s, "fixed_group", obj, "fixed")
        col = layout.column(align=True)
        col.label(text="Handle: group, Empty")
        _group_row(col, s, "handle_group", obj, "handle")
        col.prop(s, "handle_object", text="")
        for kind, label in (("handles", "Handle"), ("pins", "Pin")):
            first = 2 if kind == "handles" else 1
            for k, item in enumerate(getattr(s, kind)):
                col = layout.box().column(align=True)
                row = col.row()
                row.label(text=f"{label} {first + k}: group, Empty")
                remove = row.operator(RIGIDCELLS_OT_remove.bl_idname, text="", icon="X")
                remove.kind, remove.index = kind, k
                _group_row(col, item, "group", obj, kind, k)
                col.prop(item, "object", text="")
        row = layout.row(align=True)
        row.operator(RIGIDCELLS_OT_add.bl_idname, text="Handle", icon="ADD").kind = "handles"
        row.operator(RIGIDCELLS_OT_add.bl_idname, text="Pin", icon="ADD").kind = "pins"
        row = layout.row(align=True)
        n = len(members(obj)) - 1
        row.label(text=f"With {n} more" if n else "Alone")
        row.operator(RIGIDCELLS_OT_together.bl_idname, text="Take selected")
        col = layout.column(align=True)
        col.label(text="Stiffness group")
        _group_row(col, s, "stiffness_group", obj, "stiffness")
        if s.stiffness_group:
            col.prop(s, "stiffness")
        col = layout.column(align=True)
        col.prop(s, "cell_size")
        col.prop(s, "cells")
        col.prop(s, "interior_stiffness")
        col.prop(s, "memory_limit")
        col.prop(s, "transfer", text="")
        col = layout.column(align=True)
        col.operator(RIGIDCELLS_OT_estimate.bl_idname, text="Estimate")
        # The sidebar is narrow: the estimate (or its refusal) wrapped, a label a line.
        for line in textwrap.wrap(s.estimate, 30):
            col.label(text=line)
        row = layout.row(align=True)
        row.prop(s, "follow", toggle=True)
        row.operator(RIGIDCELLS_OT_bake.bl_idname, text="Bake frames")
        for line in textwrap.wrap(follow.status(obj) or "", 30):
            layout.label(text=line)
        row = layout.row(align=True)
        row.operator(OBJECT_OT_rigidcells_deform.bl_idname, text="Deform")
        if obj.name in _live:
            row.label(text="Live: Enter keeps, Esc restores")
        else:
            row.operator(OBJECT_OT_rigidcells_live.bl_idname, text="Live")
        if s.run_cells:
            col = layout.column(align=True)
            col.label(text=f"{s.run_cells:,} cells, {s.iterations} iterations")
            col.label(text=f"Residual: fixed {s.residual_fixed:.3g}, handle {s.residual_handle:.3g}")
            col.label(text=f"Fold-overs: {s.foldovers}")
            for warning in filter(None, s.warnings.split("\n")):
                for k, line in enumerate(textwrap.wrap(warning, 26)):
                    col.label(text=line, icon="ERROR" if k == 0 else "BLANK1")
            if s.foldovers:
                # Where: the group to select in Edit Mode (Vertex Groups > Select).
                col.label(text=f'in the vertex group "{FOLDS_GROUP}"')


CLASSES = (
    RigidCellsMover,
    RigidCellsMember,
    RigidCellsSettings,
    OBJECT_OT_rigidcells_deform,
    OBJECT_OT_rigidcells_live,
    RIGIDCELLS_OT_estimate,
    RIGIDCELLS_OT_bake,
    RIGIDCELLS_OT_from_selection,
    RIGIDCELLS_OT_together,
    RIGIDCELLS_OT_add,
    RIGIDCELLS_OT_remove,
    VIEW3D_PT_rigidcells,
)


# The add-on shows the library's warnings in its own words (`warnings_said`): the package's
# Python warnings, in the package's words, are silenced for calls from the add-on's modules
# (`rigidcells_blender.work`, or `bl_ext.user_default.rigidcells_blender.work` as an extension).
_QUIET = {"action": "ignore", "module": r"(.+\.)?rigidcells_blender(\..+)?$"}


def register() -> None:
    import warnings

    import rigidcells

    for cls in CLASSES:
        bpy.utils.register_class(cls)
    bpy.types.Object.rigidcells = PointerProperty(type=RigidCellsSettings)
    follow.register()
    warnings.filterwarnings(category=rigidcells.RigidCellsWarning, **_QUIET)


def unregister() -> None:
    for state in list(_live.values()):
        state.worker.stop()
        state.worker.thread.join(5.0)
    _live.clear()
    follow.unregister()
    del bpy.types.Object.rigidcells
    for cls in reversed(CLASSES):
        bpy.utils.unregister_class(cls)
