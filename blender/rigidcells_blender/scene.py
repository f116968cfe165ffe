"""The scene the library deforms: an object's vertices (and those of the objects taken
*Together* with it, in its coordinates), their triangles, and the spec the vertex groups, the
handle and pin Empties and the groups' weights make; and the shape that comes back, as each
object's shape key.

A vertex of weight 1 in the fixed group keeps its coordinates bit for bit, and one in a handle
group follows its Empty exactly; a vertex of weight w below 1 is pulled, a soft target of the
library: a fixed group's towards its place with strength w, a handle group's a fraction w of
the way its Empty's motion sends it, as a Hook's weight moves a vertex. Each object of the
scene gives the vertices of its groups of the names the panel gives; the Empties and the
settings are the active object's.
"""

from __future__ import annotations

from typing import Any, Dict, List, Optional, Tuple

import bpy
import numpy as np

from .handles import InputError, _motion, handle_pose

SHAPE_KEY = "RigidCells"

# The vertex group holding the vertices where the last deformation folds space over.
FOLDS_GROUP = "RigidCells Folds"

# Weights at least this are whole: the vertex is fixed, or follows its Empty, exactly.
FULL_WEIGHT = 1.0 - 1e-6

# How hard a handle group's partly weighted vertex is pulled, relative to the glue between two
# cells: enough that it lands near its fraction of the motion, not a constraint.
PULL = 1.0


def members(obj: bpy.types.Object) -> List[bpy.types.Object]:
    """The objects deformed as one scene: `obj`, then the meshes taken *Together* with it."""
    out = [obj]
    for item in obj.rigidcells.together:
        other = item.object
        if other is not None and other.type == "MESH" and other not in out:
            out.append(other)
    return out


def _frame(obj: bpy.types.Object, other: bpy.types.Object) -> np.ndarray:
    """The 4 × 4 map from `other`'s coordinates to `obj`'s (through the world)."""
    world = np.array(obj.matrix_world, dtype=np.float64)
    return np.linalg.inv(world) @ np.array(other.matrix_world, dtype=np.float64)


def key_points(key: bpy.types.ShapeKey) -> Any:
    """A shape key's points for `foreach_get` and `foreach_set`: `points` where Blender has it
    (4.1 and later: one copy of a contiguous array, 0.03 ms for the 36k vertices of the
    Stanford bunny), else `data` (an item at a time, 3.7-7 ms: half of a Live shape's time on
    the main thread)."""
    return getattr(key, "points", None) or key.data


def _rest_vertices(mesh: bpy.types.Mesh) -> np.ndarray:
    """The base shape's vertices ((n, 3) float64): the reference shape key's where there are
    shape keys, so a deformation never stacks on the last one."""
    co = np.empty(3 * len(mesh.vertices), dtype=np.float32)
    keys = mesh.shape_keys
    if keys is not None and keys.reference_key is not None:
        key_points(keys.reference_key).foreach_get("co", co)
    else:
        mesh.vertices.foreach_get("co", co)
    return co.reshape(-1, 3).astype(np.float64)


def rest_points(obj: bpy.types.Object) -> np.ndarray:
    """The scene's rest vertices in `obj`'s coordinates, object after object (`members`);
    `obj`'s own as they are."""
    parts = []
    for other in members(obj):
        rest = _rest_vertices(other.data)
        if other is not obj:
            m = _frame(obj, other)
            rest = rest @ m[:3, :3].T + m[:3, 3]
        parts.append(rest)
    return np.concatenate(parts)


def _triangles(mesh: bpy.types.Mesh) -> Optional[np.ndarray]:
    """The faces as triangles ((m, 3) vertex indices), or None for a vertex-only mesh."""
    mesh.calc_loop_triangles()
    m = len(mesh.loop_triangles)
    if m == 0:
        return None
    tris = np.empty(3 * m, dtype=np.int64)
    mesh.loop_triangles.foreach_get("vertices", tris)
    return tris.reshape(-1, 3)


def triangles(obj: bpy.types.Object) -> Optional[np.ndarray]:
    """The scene's triangles, numbered as `rest_points` numbers the vertices; None when no
    object has faces."""
    parts, start = [], 0
    for other in members(obj):
        tris = _triangles(other.data)
        if tris is not None:
            parts.append(tris + start)
        start += len(other.data.vertices)
    return np.concatenate(parts) if parts else None


def _group_weights(
    obj: bpy.types.Object, name: str, role: str
) -> Tuple[np.ndarray, np.ndarray]:
    """The scene's vertices in the groups named `name` with a weight above 0 (numbered as
    `rest_points` numbers them), and their weights."""
    if not name:
        raise InputError(f"Rigid Cells: name the {role} vertex group")
    indices: List[int] = []
    weights: List[float] = []
    start, found = 0, False
    objects = members(obj)
    for other in objects:
        group = other.vertex_groups.get(name)
        if group is not None:
            found = True
            k = group.index
            for v in other.data.vertices:
                for g in v.groups:
                    if g.group == k and g.weight > 0:
                        indices.append(start + v.index)
                        weights.append(g.weight)
        start += len(other.data.vertices)
    if not found:
        if len(objects) == 1:
            raise InputError(f"Rigid Cells: {obj.name} has no vertex group {name!r}")
        names = ", ".join(o.name for o in objects)
        raise InputError(f"Rigid Cells: none of {names} has a vertex group {name!r}")
    if not indices:
        raise InputError(
            f"Rigid Cells: the vertex group {name!r} holds no vertex of a weight above 0"
        )
    return np.array(indices, dtype=np.int64), np.array(weights, dtype=np.float64)


def _group_indices(obj: bpy.types.Object, name: str, role: str) -> List[int]:
    """The scene's vertices in the groups named `name` (weight above 0)."""
    return _group_weights(obj, name, role)[0].tolist()


def _movers(settings: Any, kind: str) -> List[Any]:
    """The extra handles or the pins, each checked to name an Empty."""
    items = list(getattr(settings, kind))
    what, first = ("handle", 2) if kind == "handles" else ("pin", 1)
    for k, item in enumerate(items):
        if item.object is None:
            raise InputError(f"Rigid Cells: choose the Empty of {what} {first + k}")
    return items


def _handle_groups(settings: Any) -> List[Tuple[str, str]]:
    """Each handle's vertex group and its name in messages, in the spec's order."""
    return [(settings.handle_group, "handle")] + [
        (item.group, f"handle {k + 2}") for k, item in enumerate(_movers(settings, "handles"))
    ]


def _handle_empties(settings: Any) -> List[Tuple[Any, Any]]:
    """Each handle's Empty and its rest matrix, in the spec's order."""
    return [(settings.handle_object, settings.handle_rest)] + [
        (item.object, item.rest) for item in _movers(settings, "handles")
    ]


class Weighted:
    """The fixed and handle groups' vertices: those of weight 1, the spec's regions; the others,
    the library's soft targets, each pulled to where `places` says for the Empties' poses."""

    def __init__(self, obj: bpy.types.Object, rest: np.ndarray) -> None:
        settings = obj.rigidcells
        fixed, w = _group_weights(obj, settings.fixed_group, "fixed")
        part = w < FULL_WEIGHT
        self.fixed: List[int] = fixed[~part].tolist()
        # The fixed group's partly weighted vertices: held at rest with strength w.
        self.points = [rest[fixed[part]]]
        self.strength = [w[part]]
        self.fraction = [np.zeros(int(part.sum()))]
        self.mover: List[Optional[int]] = [None]
        # Each handle group's: pulled a fraction w of its Empty's motion.
        self.full: List[List[int]] = []
        for k, (name, role) in enumerate(_handle_groups(settings)):
            indices, w = _group_weights(obj, name, role)
            part = w < FULL_WEIGHT
            if part.all():
                raise InputError(
                    f"Rigid Cells: the vertex group {name!r} has no vertex of weight 1 (those "
                    "of weight 1 follow the Empty, the others are pulled part of the way)"
                )
            self.full.append(indices[~part].tolist())
            self.points.append(rest[indices[part]])
            self.strength.append(np.full(int(part.sum()), PULL))
            self.fraction.append(w[part])
            self.mover.append(k)

    def places(self, obj: bpy.types.Object) -> np.ndarray:
        """Where each target pulls now ((t, 3)), in the order of `targets`."""
        moved = []
        empties = _handle_empties(obj.rigidcells)
        for points, fraction, mover in zip(self.points, self.fraction, self.mover):
            if mover is None:
                moved.append(points)
                continue
            m = _motion(obj, *empties[mover])
            sent = points @ m[:3, :3].T + m[:3, 3]
            moved.append(points + fraction[:, None] * (sent - points))
        return np.concatenate(moved)

    def targets(self, obj: bpy.types.Object) -> List[dict]:
        """The spec's `target` entries."""
        points = np.concatenate(self.points)
        strength = np.concatenate(self.strength)
        return [
            {"from": p.tolist(), "to": to.tolist(), "weight": float(w)}
            for p, to, w in zip(points, self.places(obj), strength)
        ]


def poses(obj: bpy.types.Object) -> List[dict]:
    """Each handle's pose (`handle_pose`), in the spec's order (the handle, then the extra
    ones): what Deform puts in the spec and Live hands the session as the Empties move, so
    that both give the same shape for the same typed pose."""
    settings = obj.rigidcells
    if settings.handle_object is None:
        raise InputError("Rigid Cells: choose the handle Empty")
    moves = [
        handle_pose(
            obj,
            settings.handle_object,
            settings.handle_rest,
            settings.handle_rest_mode,
            settings.handle_rest_rotation,
            settings.handle_rest_scale,
        )
    ]
    for item in _movers(settings, "handles"):
        moves.append(
            handle_pose(
                obj, item.object, item.rest, item.rest_mode, item.rest_rotation, item.rest_scale
            )
        )
    return moves


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
    """The library's inputs for `obj` and the objects taken together with it: the rest
    vertices, the triangles and the spec."""
    if obj is None or obj.type != "MESH":
        raise InputError("Rigid Cells: select a mesh object")
    settings = obj.rigidcells
    if settings.handle_object is None:
        raise InputError("Rigid Cells: choose the handle Empty")
    rest = rest_points(obj)
    weighted = Weighted(obj, rest)
    spec: dict = {
        "fixed": [{"indices": weighted.fixed}] if weighted.fixed else [],
        "handle": [{"indices": g, **pose} for g, pose in zip(weighted.full, poses(obj))],
    }
    targets = weighted.targets(obj)
    if targets:
        spec["target"] = targets
    pins = _pins(obj, rest)
    if pins:
        spec["pin"] = pins
    if settings.stiffness_group:
        stiff = _group_indices(obj, settings.stiffness_group, "stiffness")
        spec["stiffness"] = [{"indices": stiff, "scale": settings.stiffness}]
    return rest, triangles(obj), spec


def write_shape_key(obj: bpy.types.Object, moved: np.ndarray) -> bpy.types.ShapeKey:
    """`moved` as the shape key `RigidCells` of `obj` (replacing one of that name), over a
    Basis."""
    if obj.data.shape_keys is None:
        obj.shape_key_add(name="Basis", from_mix=False)
    key = obj.data.shape_keys.key_blocks.get(SHAPE_KEY)
    if key is None:
        key = obj.shape_key_add(name=SHAPE_KEY, from_mix=False)
    key_points(key).foreach_set("co", moved.astype(np.float32).ravel())
    key.value = 1.0
    obj.data.update()
    return key


def held_vertices(obj: bpy.types.Object) -> Dict[str, List[int]]:
    """For each object of the scene but `obj`, its vertices of weight 1 in the fixed group:
    those `split` gives back bit for bit. Found once for a session (Live, Follow), whose every
    shape is split."""
    out: Dict[str, List[int]] = {}
    for other in members(obj)[1:]:
        group = other.vertex_groups.get(obj.rigidcells.fixed_group)
        if group is not None:
            k = group.index
            out[other.name] = [
                v.index
                for v in other.data.vertices
                if any(g.group == k and g.weight >= FULL_WEIGHT for g in v.groups)
            ]
    return out


def split(
    obj: bpy.types.Object, moved: np.ndarray, held: Optional[Dict[str, List[int]]] = None
) -> List[Tuple[bpy.types.Object, np.ndarray]]:
    """The scene's moved vertices as each object's, in its own coordinates; the vertices of
    weight 1 in the fixed group (`held`, else found now) keep their coordinates bit for bit in
    every object. Refused when an object no longer has the vertices it was solved for."""
    objects = members(obj)
    counts = [len(o.data.vertices) for o in objects]
    if sum(counts) != len(moved):
        names = ", ".join(o.name for o in objects)
        raise InputError(
            f"Rigid Cells: {names} have {sum(counts)} vertices now, {len(moved)} were solved; "
            "deform again"
        )
    if held is None:
        held = held_vertices(obj)
    out, start = [], 0
    for other, n in zip(objects, counts):
        part = np.asarray(moved[start : start + n], dtype=np.float64)
        if other is not obj:
            back = np.linalg.inv(_frame(obj, other))
            part = part @ back[:3, :3].T + back[:3, 3]
            kept = held.get(other.name, [])
            part[kept] = _rest_vertices(other.data)[kept]
        out.append((other, part))
        start += n
    return out


def write_keys(
    obj: bpy.types.Object, moved: np.ndarray, held: Optional[Dict[str, List[int]]] = None
) -> None:
    """The scene's moved vertices as each object's shape key `RigidCells` (`split`)."""
    for other, part in split(obj, moved, held):
        write_shape_key(other, part)


def mark_folds(obj: bpy.types.Object, folded: List[int]) -> None:
    """The scene's vertices where the deformation folds space over (their indices, as
    `rest_points` numbers them) as each object's vertex group `RigidCells Folds`, to select
    and look at; the group is removed from an object where none fold."""
    start = 0
    for other in members(obj):
        n = len(other.data.vertices)
        mine = [i - start for i in folded if start <= i < start + n]
        group = other.vertex_groups.get(FOLDS_GROUP)
        if mine:
            if group is None:
                group = other.vertex_groups.new(name=FOLDS_GROUP)
            group.remove(range(n))
            group.add(mine, 1.0, "REPLACE")
        elif group is not None:
            other.vertex_groups.remove(group)
        start += n


class KeyBefore:
    """An object's `RigidCells` key as it was: no shape keys, no such key, or its shape and
    value; `restore` puts it back."""

    def __init__(self, obj: bpy.types.Object) -> None:
        keys = obj.data.shape_keys
        key = keys.key_blocks.get(SHAPE_KEY) if keys is not None else None
        self.had_keys = keys is not None
        self.shape: Optional[Tuple[np.ndarray, float]] = None
        if key is not None:
            co = np.empty(3 * len(key.data), dtype=np.float32)
            key_points(key).foreach_get("co", co)
            self.shape = (co, key.value)

    def restore(self, obj: bpy.types.Object) -> None:
        if not self.had_keys:
            if obj.data.shape_keys is not None:
                obj.shape_key_clear()
        elif self.shape is None:
            key = obj.data.shape_keys.key_blocks.get(SHAPE_KEY)
            if key is not None:
                obj.shape_key_remove(key)
        else:
            co, value = self.shape
            key = obj.data.shape_keys.key_blocks.get(SHAPE_KEY)
            if key is None:
                key = obj.shape_key_add(name=SHAPE_KEY, from_mix=False)
            key_points(key).foreach_set("co", co)
            key.value = value
        obj.data.update()
