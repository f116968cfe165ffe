"""An Empty's motion as the library's handle pose: the rotation values typed on it, with their
winding (`typed_turn`), and the map its matrices make, seen from the object (`handle_pose`).

A matrix cannot say how many turns it makes, so the turn is read from the Empty's rotation
values (Euler, axis-angle or quaternion, as keyed when animated) against those it had when
assigned; the rotations' arithmetic, which needs no Blender, is in `rotations.py`.
"""

from __future__ import annotations

from typing import Any, List, Optional, Tuple

import bpy
import numpy as np

from .rotations import (
    ROTATION_MODES,
    _SAME_MAP,
    _axis_angle,
    _axis_rotation,
    _elemental,
    _in_mode,
    _rotation,
    _unit,
)


class InputError(ValueError):
    """What the artist set up cannot be deformed; said in Blender's error report."""


def _flat(matrix: Any) -> List[float]:
    return [v for row in matrix for v in row]


def _rotation_values(empty: bpy.types.Object) -> List[float]:
    """The Empty's rotation as typed (the keyed value at the current frame when animated),
    four numbers for its `rotation_mode`: Euler (x, y, z, 0) in radians, axis-angle
    (angle, x, y, z), quaternion (w, x, y, z)."""
    mode = empty.rotation_mode
    if mode == "QUATERNION":
        return list(empty.rotation_quaternion)
    if mode == "AXIS_ANGLE":
        return list(empty.rotation_axis_angle)
    return list(empty.rotation_euler) + [0.0]


def _scale_values(empty: bpy.types.Object) -> List[float]:
    """The Empty's own scale as its matrix applies it: `scale` times `delta_scale`."""
    return [a * b for a, b in zip(empty.scale, empty.delta_scale)]


def _motion(obj: bpy.types.Object, empty: bpy.types.Object, rest: Any) -> np.ndarray:
    """The Empty's motion since its rest pose (world), seen from the object: a 4 × 4 affine
    map of the object's own coordinates."""
    rest = np.array(rest, dtype=np.float64).reshape(4, 4)
    now = np.array(empty.matrix_world, dtype=np.float64)
    world = np.array(obj.matrix_world, dtype=np.float64)
    local = np.linalg.inv(world) @ (now @ np.linalg.inv(rest)) @ world
    local[3] = [0.0, 0.0, 0.0, 1.0]
    return local


def typed_turn(
    mode: str, now: Any, rest_mode: str, rest: Any
) -> Optional[Tuple[Optional[np.ndarray], float]]:
    """The turn the rotation values typed on an Empty make from `rest` to `now` (four numbers
    each, `_rotation_values`; `rest_mode` is the mode they were typed in), in the frame the
    Empty's rotation acts in (its parent's, through the parent inverse and the delta
    rotation): `(axis, radians)`, a unit axis and a signed angle of any size, `(None, 0.0)`
    for no turn, or None where the values imply no winding of their own and the matrix's
    rotation is the turn:

    - Euler (any order): when one angle changed, the turn is about that angle's axis as the
      rotations after it in the order carry it, by the change as typed (0° → 360° is a whole
      turn). When several changed, None: their composition has no single axis that carries a
      winding (a whole turn about x then 10° about z is 10° about z), and the library's
      `rotate` has one axis, so the matrix's rotation (at most 180°) is the honest turn.
    - Axis-angle: the axis unchanged (or reversed, or either angle 0), the typed angle's
      difference; the axis changed, None, as for several Euler angles.
    - Quaternion: the relative quaternion `q·q₀⁻¹`, its angle `2·atan2(|v|, w)` in [0°, 360°]
      about its vector's direction: a quaternion holds a turn modulo 720°, so this is its
      whole range (a turn beyond ±360° cannot be typed, and +360° and −360° are the same
      quaternion, `w = −1`). That whole turn names no axis when its vector is exactly zero,
      and is refused (`InputError`); turned there with Blender's tools, the vector keeps the
      axis in its rounding.

    A rest in another mode (the mode changed since the Empty was assigned) is converted into
    the current mode first, with no winding (`_in_mode`). An unknown rest mode (an Empty
    assigned before the add-on kept the values) gives None."""
    if rest_mode not in ROTATION_MODES or mode not in ROTATION_MODES:
        return None
    now = [float(v) for v in now]
    rest = [float(v) for v in rest]
    if rest_mode != mode:
        rest = _in_mode(mode, rest_mode, rest, now)
    if mode == "QUATERNION":
        q1, q0 = _unit(now), _unit(rest)
        q1 = np.array([1.0, 0, 0, 0]) if q1 is None else q1
        q0 = np.array([1.0, 0, 0, 0]) if q0 is None else q0
        w0, v0 = q0[0], -q0[1:]  # q0's inverse (conjugate, q0 being a unit)
        w1, v1 = q1[0], q1[1:]
        w = w1 * w0 - v1 @ v0
        v = w1 * v0 + w0 * v1 + np.cross(v1, v0)
        n = np.linalg.norm(v)
        if n == 0.0:
            if w >= 0.0:
                return None, 0.0
            raise InputError(
                "Rigid Cells: the handle Empty's quaternion makes a whole turn from its rest "
                "(W −1, X, Y and Z 0), which names no axis to turn about: type the turn in "
                "Axis Angle or Euler rotation mode"
            )
        return v / n, 2.0 * np.arctan2(n, w)
    if mode == "AXIS_ANGLE":
        a1, a0 = _unit(now[1:]), _unit(rest[1:])
        t1 = now[0] if a1 is not None else 0.0
        t0 = rest[0] if a0 is not None else 0.0
        if t0 == 0.0:
            return (a1, t1) if t1 != 0.0 else (None, 0.0)
        if t1 == 0.0:
            return a0, -t0
        if np.abs(a1 - a0).max() <= 1e-6:
            return (a1, t1 - t0) if t1 != t0 else (None, 0.0)
        if np.abs(a1 + a0).max() <= 1e-6:
            return a1, t1 + t0
        return None
    change = np.array(now[:3]) - np.array(rest[:3])
    changed = [k for k in range(3) if abs(change[k]) > 1e-6]
    if not changed:
        return None, 0.0
    if len(changed) > 1:
        return None
    k = changed[0]
    carry = np.eye(3)
    for c in mode[mode.index("XYZ"[k]) + 1 :]:
        carry = _elemental("XYZ".index(c), now["XYZ".index(c)]) @ carry
    return carry[:, k], float(change[k])


def handle_pose(
    obj: bpy.types.Object,
    empty: bpy.types.Object,
    rest: Any,
    rest_mode: str = "",
    rest_rotation: Any = (0.0, 0.0, 0.0, 0.0),
    rest_scale: Any = (1.0, 1.0, 1.0),
) -> dict:
    """A handle's pose for the library, in the object's own coordinates: the Empty's motion
    since its rest (the world matrix `rest`, and the rotation values `rest_rotation` typed in
    `rest_mode` and scale `rest_scale` it had then), as a handle dict of the spec.

    The map is the Empty's motion seen from the object, `_motion`, and the pose says it as
    `A(x) = s·R·(x − pivot) + pivot + translate`: `pivot` is the Empty's rest origin (the
    load steps of a solve from rest turn the handle about it, as the Empty turned), `translate`
    takes it to the Empty's origin now, `R` is `rotate = {axis, degrees}` with the typed turn
    (`typed_turn`: its axis carried into the object's coordinates through the Empty's parent,
    parent inverse, delta rotation and the object's matrix; the Empty's own scale, unchanged,
    drops out) and `s` is `scale` where the Empty's scale changed alike on its three axes.
    The typed motion is taken where it is the matrices' map (to Blender's single precision);
    where it is not (the Empty's parent moved, or a constraint turns it), the turn is the
    matrices' rotation with the winding nearest the typed turn, so the map stays the
    matrices' exactly.

    A motion that stretches unevenly (an Empty scaled differently on its axes, a parent or
    object scaled unevenly) goes as its `matrix`, whose turn the library takes in [0°, 180°]:
    the spec's `rotate` takes only a uniform `scale` beside it, so a `rotate` could carry the
    winding or the stretch exactly, not both, and the map must be exact."""
    local = _motion(obj, empty, rest)
    lin = local[:3, :3]
    to_obj = np.linalg.inv(np.array(obj.matrix_world, dtype=np.float64))
    now = np.array(empty.matrix_world, dtype=np.float64)
    rest_m = np.array(rest, dtype=np.float64).reshape(4, 4)
    pivot = (to_obj @ rest_m[:, 3])[:3]
    translate = (to_obj @ now[:, 3])[:3] - pivot
    mode, values = empty.rotation_mode, _rotation_values(empty)
    turn = typed_turn(mode, values, rest_mode, rest_rotation)
    scale_now, scale_rest = np.array(_scale_values(empty)), np.array(rest_scale, dtype=np.float64)
    # The typed turn in the object's coordinates: its axis through the frame the Empty's
    # rotation acts in (the matrix with the Empty's own rotation and scale taken off).
    typed = None
    if turn is not None and np.all(scale_now != 0.0):
        axis, angle = turn
        if axis is not None:
            frame = to_obj[:3, :3] @ now[:3, :3] @ np.diag(1.0 / scale_now)
            frame = frame @ _rotation(mode, values).T
            axis = _unit(np.sign(np.linalg.det(frame)) * (frame @ axis))
        typed = (axis, angle) if axis is not None else (None, 0.0)
    ratio = scale_now / scale_rest if np.all(scale_rest != 0.0) else None
    size = max(1.0, np.abs(lin).max())
    chosen = None
    if typed is not None and ratio is not None and np.ptp(ratio) <= 1e-6 * np.abs(ratio).max():
        s = 1.0 if np.all(scale_now == scale_rest) else float(ratio.mean())
        axis, angle = typed
        r = np.eye(3) if axis is None else _axis_rotation(axis, angle)
        if np.abs(s * r - lin).max() <= _SAME_MAP * size:
            chosen = (axis, angle, s)
    if chosen is None:
        u, sv, vt = np.linalg.svd(lin)
        if np.linalg.det(lin) <= 0.0 or np.ptp(sv) > _SAME_MAP * sv.max():
            return {"matrix": local.tolist()}
        s = float(sv.mean())
        s = 1.0 if abs(s - 1.0) <= _SAME_MAP else s
        axis, angle = _axis_angle(u @ vt)
        # The winding nearest the typed turn (none: the matrix's own, at most 180°).
        want = np.zeros(3) if typed is None or typed[0] is None else typed[0] * typed[1]
        along = axis @ want
        angle = min(
            (a + 2 * np.pi * round((along - a) / (2 * np.pi)) for a in (angle, -angle)),
            key=lambda a: abs(a - along),
        )
        if along < 0.0:
            axis, angle = -axis, -angle
        chosen = (axis if angle != 0.0 else None, angle, s)
    axis, angle, s = chosen
    pose: dict = {"pivot": pivot.tolist(), "translate": translate.tolist()}
    if axis is not None and angle != 0.0:
        pose["rotate"] = {"axis": axis.tolist(), "degrees": float(np.degrees(angle))}
    if s != 1.0:
        pose["scale"] = s
    return pose
