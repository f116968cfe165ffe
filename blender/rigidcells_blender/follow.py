"""Follow: the shape key follows the handle and pin Empties wherever they move — dragged,
typed, driven or keyframed — without running Deform again, and a frame range bakes into keyed
shapes.

Blender's Python has no custom modifiers, so an object whose *Follow* is on keeps a
`rigidcells.Session` (its cells built once) here, and two handlers serve it: after each
dependency-graph update (an Empty moved or typed in the viewport) and after each frame change
(the timeline, playback, a render), the Empties' poses are read as Deform reads them and, when
they changed, the session solves the new spec warm from where its cells are and releases it
through the transfer: the key is Deform's shape for that pose (fixed vertices bit for bit,
handle vertices where their Empties send them). While an Empty is dragged in Blender's window,
each update is a drag's step and its preview instead (as Live's), and the exact shape follows
once the Empties have rested for `SETTLE` (a timer); a frame change is always exact. A change of
the options builds the session again at once, a change of the groups at the next move of an
Empty. A failure turns Follow off and says why in the panel.

*Bake* steps the scene's frame range and keys one shape a frame (`RigidCells 12`: value 1 on
its frame, 0 on the frames beside it), so that the animation plays, renders and exports without
the add-on; Follow is then turned off and the followed key removed.
"""

from __future__ import annotations

import time
from typing import Any, Dict, Optional

import bpy
import numpy as np
from bpy.app.handlers import persistent

from .scene import key_points

# The object's name -> its session and what it was last solved for.
_sessions: Dict[str, "Followed"] = {}
# Set while the handlers write keys: the updates that writing makes are not new poses.
_writing = False


# How long the Empties rest after a move in the viewport before the shape is converged and
# released exactly (as Live's worker waits).
SETTLE = 0.25


class Followed:
    """One followed object's session, built from the spec it was first solved for."""

    def __init__(self, obj: bpy.types.Object) -> None:
        import rigidcells

        from . import Weighted, held_vertices, inputs, options

        points, triangles, spec = inputs(obj)
        self.options = options(obj.rigidcells)
        self.regions = _regions(spec)
        self.spec = spec
        self.poses: Any = None
        self.session = rigidcells.Session(points, spec, triangles=triangles, **self.options)
        # What a drag step moves besides the handles: the pins' centers and the weighted
        # vertices' pulls.
        self.centers = [np.array(p["point"]) for p in spec.get("pin", [])]
        self.weighted = Weighted(obj, points) if "target" in spec else None
        # Whether the key is the exact shape of `poses` (else a drag's preview), and when the
        # Empties last moved.
        self.exact = False
        self.moved_at = 0.0
        # The other objects' fixed vertices, given back bit for bit in every shape.
        self.held = held_vertices(obj)

    def matches(self, spec: dict, options: dict) -> bool:
        """Whether `spec` only moves this session's handles and pins (same regions, options)."""
        return options == self.options and _regions(spec) == self.regions


def _regions(spec: dict) -> Any:
    """A spec without its handles' poses and where its pins and weighted vertices go: what a
    warm solve cannot change."""
    return (
        spec.get("fixed"),
        [h.get("indices") for h in spec.get("handle", [])],
        [p.get("point") for p in spec.get("pin", [])],
        [(t.get("from"), t.get("weight")) for t in spec.get("target", [])],
        spec.get("stiffness"),
    )


def follow_now(obj: bpy.types.Object, exact: bool = True) -> bool:
    """Solves `obj` for its Empties' current poses when they changed since its last shape, and
    writes the key: whether it wrote one. `exact`: converged and released through the
    transfer (a frame, a render, the Empties at rest); else, while an Empty is dragged in the
    viewport, a drag's step and its preview, the exact shape following once they rest."""
    from . import SHAPE_KEY, inputs, options, pin_places, poses

    state = _sessions.get(obj.name)
    # The Empties' poses alone first: most updates (a selection, another object) move none.
    moves = poses(obj)
    unchanged = (
        state is not None
        and moves == state.poses
        and not obj.rigidcells.pins
        and options(obj.rigidcells) == state.options
        and SHAPE_KEY in _keys(obj)
    )
    if unchanged and (state.exact or not exact):
        return False
    if not exact and state is not None and options(obj.rigidcells) == state.options:
        pins = pin_places(obj, state.centers) or None
        targets = None if state.weighted is None else state.weighted.places(obj).tolist()
        state.session.drag(moves, pins=pins, targets=targets)
        state.poses, state.exact, state.moved_at = moves, False, time.monotonic()
        _write(obj, state.session.preview(), None, state.held)
        if not bpy.app.timers.is_registered(_settle):
            bpy.app.timers.register(_settle, first_interval=SETTLE)
        return True
    _, _, spec = inputs(obj)
    if state is not None and state.matches(spec, options(obj.rigidcells)):
        if spec == state.spec and state.exact and SHAPE_KEY in _keys(obj):
            return False
        state.session.solve(spec)
        state.spec = spec
    else:
        state = _sessions[obj.name] = Followed(obj)
    state.poses, state.exact = moves, True
    _write(obj, *state.session.release(), state.held)
    return True


def _write(obj: bpy.types.Object, moved: Any, report: Any, held: Any) -> None:
    """The shape as the scene's keys (`held`: the other objects' fixed vertices), and the
    report's figures when it is exact."""
    global _writing
    from . import show_report, write_keys

    _writing = True
    try:
        write_keys(obj, np.asarray(moved), held)
        if report is not None:
            show_report(obj, report)
    finally:
        _writing = False


def _settle() -> Optional[float]:
    """The timer after a drag's steps: each followed object whose Empties have rested for
    `SETTLE` gets its exact shape; again later while some still move."""
    from . import ERRORS, _said

    waiting = [
        (name, state) for name, state in _sessions.items() if not state.exact
    ]
    later = []
    for name, state in waiting:
        obj = bpy.data.objects.get(name)
        if obj is None:
            _sessions.pop(name, None)
            continue
        rested = time.monotonic() - state.moved_at
        if rested < SETTLE:
            later.append(SETTLE - rested)
            continue
        try:
            follow_now(obj, exact=True)
        except ERRORS as e:
            stop(obj)
            obj.rigidcells.follow_said = _said(e)
    return min(later) if later else None


def _keys(obj: bpy.types.Object) -> Any:
    keys = obj.data.shape_keys
    return keys.key_blocks if keys is not None else {}


def _follow_all(exact: bool = True) -> None:
    """Every object whose Follow is on, followed (`follow_now`); one that fails is turned off,
    with why."""
    from . import ERRORS, _said

    for obj in list(bpy.data.objects):
        settings = getattr(obj, "rigidcells", None)
        if settings is None or not settings.follow or obj.type != "MESH":
            continue
        try:
            follow_now(obj, exact)
        except ERRORS as e:
            stop(obj)
            settings.follow_said = _said(e)


def stop(obj: bpy.types.Object) -> None:
    """Follow off for `obj`: its session dropped, its key left as it is."""
    _sessions.pop(obj.name, None)
    if obj.rigidcells.follow:
        obj.rigidcells.follow = False


def follow_changed(settings: Any, context: Any) -> None:
    """The Follow setting's update: on, the object is followed at once; off, its session goes."""
    obj = settings.id_data
    if not settings.follow:
        _sessions.pop(obj.name, None)
        return
    settings.follow_said = ""
    _follow_all()


def _following() -> bool:
    return not _writing and any(
        getattr(o, "rigidcells", None) is not None and o.rigidcells.follow for o in bpy.data.objects
    )


@persistent
def on_update(_scene: Any, _depsgraph: Any = None) -> None:
    """An update (an Empty dragged or typed in the viewport): in Blender's window a drag's
    step, the exact shape once the Empties rest; without a window, the exact shape."""
    if _following():
        _follow_all(exact=not _in_window())


def _in_window() -> bool:
    """Whether Blender runs with its window (where a dragged Empty's updates come quickly)."""
    return not bpy.app.background


@persistent
def on_frame(_scene: Any, _depsgraph: Any = None) -> None:
    """A frame (the timeline, playback, a render): the exact shape of the frame's poses."""
    if _following():
        _follow_all(exact=True)


@persistent
def on_load(_path: Any = None, _other: Any = None) -> None:
    """A file loaded: the sessions were of the last one's objects (a followed object in the
    new file builds its own at its first update)."""
    _sessions.clear()


def _handlers() -> Any:
    h = bpy.app.handlers
    return (
        (h.depsgraph_update_post, on_update),
        (h.frame_change_post, on_frame),
        (h.load_post, on_load),
    )


def register() -> None:
    for handlers, f in _handlers():
        if f not in handlers:
            handlers.append(f)


def unregister() -> None:
    for handlers, f in _handlers():
        while f in handlers:
            handlers.remove(f)
    _sessions.clear()


class RIGIDCELLS_OT_bake(bpy.types.Operator):
    """Key one shape a frame over the scene's frame range, as Follow gives it: the animation
    then plays, renders and exports without the add-on. Follow is turned off and its key
    removed"""

    bl_idname = "rigidcells.bake"
    bl_label = "Bake frames"
    bl_options = {"REGISTER", "UNDO"}

    @classmethod
    def poll(cls, context: Any) -> bool:
        obj = context.active_object
        return obj is not None and obj.type == "MESH"

    def execute(self, context: Any) -> set:
        from . import ERRORS, _back_to_edit_mode, _leave_edit_mode, _said

        obj, scene = context.active_object, context.scene
        editing = _leave_edit_mode(context)
        start, end, now = scene.frame_start, scene.frame_end, scene.frame_current
        try:
            baked = bake(obj, scene, start, end)
        except ERRORS as e:
            self.report({"ERROR"}, _said(e))
            return {"CANCELLED"}
        finally:
            scene.frame_set(now)
            _back_to_edit_mode(context, editing)
        self.report({"INFO"}, f"Rigid Cells: {baked} frames baked, {start} to {end}")
        return {"FINISHED"}


def bake(obj: bpy.types.Object, scene: Any, start: int, end: int) -> int:
    """Keys `RigidCells F` for each frame F of `start`..`end` on each object of the scene
    (replacing keys of those names); turns Follow off and removes the followed keys. The number
    of frames baked."""
    global _writing
    from . import SHAPE_KEY, members

    stop(obj)
    objects = members(obj)
    shapes: Dict[str, list] = {o.name: [] for o in objects}
    # Followed by hand, one session warm from frame to frame: Follow is off while baking, so
    # the handlers stay out of the way.
    for frame in range(start, end + 1):
        scene.frame_set(frame)
        follow_now(obj)
        for other in objects:
            co = np.empty(3 * len(other.data.vertices), dtype=np.float32)
            key_points(_keys(other)[SHAPE_KEY]).foreach_get("co", co)
            shapes[other.name].append(co)
    _sessions.pop(obj.name, None)
    _writing = True
    try:
        for other in objects:
            _key_frames(other, shapes[other.name], start)
    finally:
        _writing = False
    scene.frame_set(scene.frame_current)
    return end + 1 - start


def _key_frames(obj: bpy.types.Object, shapes: list, start: int) -> None:
    """`shapes` as `obj`'s keys `RigidCells F` from frame `start`, each on at its frame only;
    the followed key removed."""
    from . import SHAPE_KEY

    obj.shape_key_remove(_keys(obj)[SHAPE_KEY])
    for frame, co in enumerate(shapes, start):
        name = f"{SHAPE_KEY} {frame}"
        old = _keys(obj).get(name)
        if old is not None:
            obj.shape_key_remove(old)
        key = obj.shape_key_add(name=name, from_mix=False)
        key_points(key).foreach_set("co", co.ravel())
        for f, v in ((frame - 1, 0.0), (frame, 1.0), (frame + 1, 0.0)):
            key.value = v
            key.keyframe_insert("value", frame=f)
    obj.data.update()


def status(obj: bpy.types.Object) -> Optional[str]:
    """The panel's line for a followed object: its cells, or why Follow stopped."""
    settings = obj.rigidcells
    if settings.follow_said:
        return settings.follow_said
    state = _sessions.get(obj.name)
    if settings.follow and state is not None:
        return f"Following: {state.session.cells:,} cells"
    return None
