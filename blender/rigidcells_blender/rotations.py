"""Rotations as Blender types them (Euler angles in any order, axis-angle, quaternions) and
as the library takes them (an axis and an angle): the add-on reads a handle's turn with these."""

from typing import Any, List, Optional, Tuple

import mathutils
import numpy as np

EULER_ORDERS = ("XYZ", "XZY", "YXZ", "YZX", "ZXY", "ZYX")
ROTATION_MODES = EULER_ORDERS + ("AXIS_ANGLE", "QUATERNION")


# How far the typed motion may differ from the Empty's matrices and still be taken as theirs,
# relative to the motion's scale: Blender's matrices are single precision (about 6e-8), and
# the products through a parent and the object compound it (1.4e-7 in the tests).
_SAME_MAP = 1e-6


def _elemental(axis: int, angle: float) -> np.ndarray:
    """The rotation by `angle` about the coordinate axis `axis` (0, 1, 2: x, y, z)."""
    c, s = np.cos(angle), np.sin(angle)
    i, j = (axis + 1) % 3, (axis + 2) % 3
    m = np.eye(3)
    m[i, i], m[i, j], m[j, i], m[j, j] = c, -s, s, c
    return m


def _axis_rotation(axis: np.ndarray, angle: float) -> np.ndarray:
    """The rotation by `angle` about the unit vector `axis` (Rodrigues), as the library makes
    `rotate`'s."""
    k = np.array([[0.0, -axis[2], axis[1]], [axis[2], 0.0, -axis[0]], [-axis[1], axis[0], 0.0]])
    return np.eye(3) + np.sin(angle) * k + (1.0 - np.cos(angle)) * (k @ k)


def _unit(v: Any) -> Optional[np.ndarray]:
    """`v` scaled to length 1, or None for a zero vector."""
    v = np.asarray(v, dtype=np.float64)
    n = np.linalg.norm(v)
    return v / n if n > 0.0 else None


def _rotation(mode: str, values: Any) -> np.ndarray:
    """The rotation matrix of typed rotation values (`_rotation_values`), as Blender makes it
    (Euler `XYZ` turns about x first: Rz·Ry·Rx; a quaternion normalized; a zero axis or
    quaternion turns nothing), in double precision."""
    if mode == "QUATERNION":
        q = _unit(values)
        if q is None:
            return np.eye(3)
        w, x, y, z = q
        return np.array(
            [
                [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
            ]
        )
    if mode == "AXIS_ANGLE":
        axis = _unit(values[1:])
        return np.eye(3) if axis is None else _axis_rotation(axis, values[0])
    m = np.eye(3)
    for c in mode:
        m = _elemental("XYZ".index(c), values["XYZ".index(c)]) @ m
    return m


def _axis_angle(r: np.ndarray) -> Tuple[np.ndarray, float]:
    """A rotation matrix's unit axis and angle in [0, π], through its quaternion (exact also
    near a half turn, where the matrix's antisymmetric part vanishes): Shepperd's method, from
    the largest of the quaternion's components."""
    k = int(np.argmax([np.trace(r), r[0, 0], r[1, 1], r[2, 2]]))
    if k == 0:
        w = 0.5 * np.sqrt(max(1.0 + np.trace(r), 0.0))
        v = np.array([r[2, 1] - r[1, 2], r[0, 2] - r[2, 0], r[1, 0] - r[0, 1]]) / (4 * w)
    else:
        i = k - 1
        j, l = (i + 1) % 3, (i + 2) % 3
        v = np.zeros(3)
        v[i] = 0.5 * np.sqrt(max(1.0 + r[i, i] - r[j, j] - r[l, l], 0.0))
        v[j] = (r[j, i] + r[i, j]) / (4 * v[i])
        v[l] = (r[l, i] + r[i, l]) / (4 * v[i])
        w = (r[l, j] - r[j, l]) / (4 * v[i])
    if w < 0.0:
        w, v = -w, -v
    n = np.linalg.norm(v)
    if n == 0.0:
        return np.array([1.0, 0.0, 0.0]), 0.0
    return v / n, 2.0 * np.arctan2(n, w)


def _in_mode(mode: str, rest_mode: str, rest: Any, now: Any) -> List[float]:
    """Rest rotation values typed in `rest_mode`, given in `mode` (the Empty's mode changed
    since it was assigned): the same rotation, with no winding of its own (no rotation gives
    zero angles, the unit quaternion, or a zero angle about the current axis `now` has)."""
    r = _rotation(rest_mode, rest)
    if np.allclose(r, np.eye(3), rtol=0.0, atol=1e-12):
        if mode == "QUATERNION":
            return [1.0, 0.0, 0.0, 0.0]
        return [0.0, *now[1:]] if mode == "AXIS_ANGLE" else [0.0] * 4
    m = mathutils.Matrix(r.tolist())
    if mode == "QUATERNION":
        return list(m.to_quaternion())
    if mode == "AXIS_ANGLE":
        axis, angle = _axis_angle(r)
        return [angle, *axis]
    return list(m.to_euler(mode)) + [0.0]
