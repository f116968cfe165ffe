"""Points in any form the package takes, in and out: an (n, 3) array, a numpy structured array
with fields ``X``, ``Y``, ``Z`` (floats, or LAS record integers with a scale and offset), a laspy
``LasData`` or point record, a trimesh or Open3D object (``_interop``). ``_Points`` reads them
into coordinates for the native calls and puts the moved coordinates back into a new object of
the same form; LAS records are written through their frame, rounded to the nearest step as the
command line's LAS writer rounds them. Records keep their LAS classes for the spec's
classification regions, and float coordinates come back in their own precision."""

from __future__ import annotations

import copy
import sys
from typing import Any, List, Optional, Sequence, Tuple, Union

import numpy as np

from . import _interop, _rigidcells

Frame = Union[float, Sequence[float], np.ndarray]

_RAW_HINT = (
    "pass scale=(sx, sy, sz) and offset=(ox, oy, oz) to decode them (for laspy's "
    "points.array: las.header.scales and las.header.offsets), or pass the LasData or "
    "las.points itself"
)


def _laspy() -> Any:
    """laspy's module if it is imported (an object of its classes exists only then), else None:
    laspy is never imported here."""
    return sys.modules.get("laspy")


def _frame(scale: Optional[Frame], offset: Optional[Frame]) -> Tuple[Tuple[float, ...], ...]:
    """``scale`` and ``offset`` as three floats each (a single number stands for all axes)."""

    def three(value: Frame, name: str) -> Tuple[float, ...]:
        try:
            a = np.asarray(value, dtype=np.float64)
        except (TypeError, ValueError):
            a = np.empty(0)
        if a.shape == ():
            a = np.repeat(a, 3)
        if a.shape != (3,):
            raise ValueError(f"{name} must be a number or three numbers, got {value!r}")
        return tuple(float(v) for v in a)

    if scale is None:
        raise ValueError("offset was given without scale: pass scale=(sx, sy, sz) too")
    return three(scale, "scale"), three(0.0 if offset is None else offset, "offset")


def _encode(moved: np.ndarray, frame: Tuple[Tuple[float, ...], ...], reframe: bool):
    """The moved coordinates as int32 LAS records (rounded to the nearest step), with the
    frame they are in and a note per re-framed axis."""
    return _rigidcells.encode_las(np.ascontiguousarray(moved), frame[0], frame[1], reframe)


def _decode(records: np.ndarray, frame: Tuple[Tuple[float, ...], ...]) -> np.ndarray:
    """Integer records ((n, 3)) as coordinates: ``X * scale + offset`` per axis."""
    if records.dtype == np.uint64 and records.size and int(records.max()) > np.iinfo(np.int64).max:
        raise ValueError("points: X, Y, Z hold values past int64")
    return _rigidcells.decode_las(
        np.ascontiguousarray(records, dtype=np.int64), frame[0], frame[1]
    )


def _into(records: np.ndarray, dtype: np.dtype, name: str) -> np.ndarray:
    """int32 records as the integer ``dtype`` of field ``name``; a value it cannot hold is an
    error, never wrapped."""
    info = np.iinfo(dtype)
    if records.size and (int(records.min()) < info.min or int(records.max()) > info.max):
        raise ValueError(
            f"{name}: the moved records span {int(records.min())} to {int(records.max())}, "
            f"which {dtype} cannot hold"
        )
    return records.astype(dtype)


# The fields of a structured array that hold LAS classes, and the bits of the class in each:
# a byte in laspy's point formats 6 to 10 and in PDAL's arrays; in laspy's formats 0 to 5 the low
# five bits of `raw_classification` (beside the synthetic, key-point and withheld flags), which
# is what the command line reads from such a file.
_CLASS_FIELDS = (("classification", 0xFF), ("Classification", 0xFF), ("raw_classification", 0x1F))


def _classes(arr: np.ndarray) -> Optional[np.ndarray]:
    """The LAS classes ((n,) uint8) of a structured array's records, or None where it has no
    integer class field."""
    for name, bits in _CLASS_FIELDS:
        if name in arr.dtype.names and arr.dtype[name].kind in "iu":
            c = arr[name]
            if c.size and (int(c.min()) < 0 or int(c.max()) > 255):
                raise ValueError(
                    f"points: {name} holds {int(c.min())} to {int(c.max())}; LAS classes are 0 "
                    "to 255"
                )
            return np.ascontiguousarray(c.astype(np.uint8) & bits)
    return None


def _float_dtype(values: Any) -> np.dtype:
    """The dtype results take for coordinates or normals given as ``values``: theirs where it is
    a float (float32 in, float32 out), else float64."""
    dtype = getattr(values, "dtype", None)
    return dtype if dtype is not None and dtype.kind == "f" else np.dtype(np.float64)


class _Points:
    """Points in any accepted form: their coordinates ((n, 3) float64), their LAS ``classes``
    (or None), and ``back``, which puts moved coordinates into a new object of the same form
    (the input is never changed). ``dtype``: the float type of the coordinates given (float64
    where they are not floats), which moved coordinates take."""

    def __init__(self, points: Any, scale: Optional[Frame], offset: Optional[Frame]) -> None:
        laspy = _laspy()
        given = scale is not None or offset is not None
        self._las = self._record = self._structured = self._plain = None
        self._frame: Any = None
        self._reframe = False
        self.classes: Optional[np.ndarray] = None
        self.dtype = np.dtype(np.float64)
        # A trimesh or Open3D object's triangles and normals, taken where none are given.
        self.triangles: Optional[np.ndarray] = None
        self.normals: Optional[np.ndarray] = None
        self._geometry = _interop.of(points)
        if self._geometry is not None:
            if given:
                raise ValueError(
                    f"scale and offset decode LAS records; a {type(points).__name__} holds "
                    "coordinates: leave them out"
                )
            self.xyz = self._geometry.xyz
            self.triangles = self._geometry.triangles
            self.normals = self._geometry.normals
            return
        if laspy is not None and isinstance(points, laspy.LasData):
            if given:
                raise ValueError(
                    "scale and offset come from the LasData's header; leave them out "
                    "(las.change_scaling changes them)"
                )
            self._las = points
            h = points.header
            self._frame = _frame(h.scales, h.offsets)
            self._reframe = True
            arr = points.points.array
        elif laspy is not None and isinstance(points, laspy.PackedPointRecord):
            self._record = points
            if isinstance(points, laspy.ScaleAwarePointRecord):
                if given:
                    raise ValueError(
                        "scale and offset come from the point record's scales and offsets; "
                        "leave them out"
                    )
                self._frame = _frame(points.scales, points.offsets)
                self._reframe = True
            arr = points.array
        else:
            arr = _numbers(points, "points")
        if arr.dtype.names is not None:
            names = arr.dtype.names
            if not all(k in names for k in ("X", "Y", "Z")):
                raise ValueError(f"a structured array needs fields X, Y, Z; it has {names}")
            kinds = {arr.dtype[k].kind for k in ("X", "Y", "Z")}
            self._structured = arr
            self.classes = _classes(arr)
            if kinds <= {"i", "u"}:
                if self._frame is None:
                    if not given:
                        raise ValueError(
                            "points: X, Y, Z are integer fields "
                            f"({', '.join(str(arr.dtype[k]) for k in 'XYZ')}), LAS records in "
                            f"steps of the file's scale; {_RAW_HINT}"
                        )
                    self._frame = _frame(scale, offset)
                records = np.stack([arr["X"], arr["Y"], arr["Z"]], axis=1)
                self.xyz = _decode(records, self._frame)
            elif kinds == {"f"}:
                if given:
                    raise ValueError(
                        "scale and offset decode integer X, Y, Z; these are floats (coordinates "
                        "already): leave scale and offset out"
                    )
                xyz = np.stack([arr["X"], arr["Y"], arr["Z"]], axis=1)
                self.dtype = _float_dtype(xyz)
                self.xyz = np.ascontiguousarray(xyz, dtype=np.float64)
            else:
                raise ValueError(
                    "points: X, Y, Z must be all floats (coordinates) or all integers (LAS "
                    f"records, with scale and offset), got {[str(arr.dtype[k]) for k in 'XYZ']}"
                )
            return
        if arr.ndim != 2 or arr.shape[1] != 3:
            raise ValueError(f"points must be an (n, 3) array, got shape {arr.shape}")
        if given:
            if arr.dtype.kind not in "iu":
                raise ValueError(
                    "scale and offset decode integer records; these points are "
                    f"{arr.dtype} (coordinates already): leave scale and offset out"
                )
            self._frame = _frame(scale, offset)
            self._plain = arr
            self.xyz = _decode(arr, self._frame)
        else:
            self.dtype = _float_dtype(arr)
            self.xyz = np.ascontiguousarray(arr, dtype=np.float64)

    def back(
        self, moved: np.ndarray, turned: Optional[np.ndarray] = None
    ) -> Tuple[Any, List[str]]:
        """The moved coordinates in the input's form (a trimesh or Open3D object with its
        normals ``turned``), and a note per re-framed axis."""
        notes: List[str] = []
        if self._geometry is not None:
            return self._geometry.back(moved, turned), notes
        if self._frame is None:
            if self._structured is None:
                return moved.astype(self.dtype, copy=False), notes
            out = self._structured.copy()
            for k, name in enumerate(("X", "Y", "Z")):
                out[name] = moved[:, k]  # a float field: rounded to its nearest value
            return out, notes
        records, scale, offset, notes = _encode(moved, self._frame, self._reframe)
        if self._structured is None:
            return _into(records, self._plain.dtype, "points"), notes
        out = self._structured.copy()
        for k, name in enumerate(("X", "Y", "Z")):
            out[name] = _into(records[:, k], out.dtype[name], name)
        laspy = _laspy()
        if self._las is not None:
            header = copy.deepcopy(self._las.header)
            header.scales = np.array(scale)
            header.offsets = np.array(offset)
            if len(records):  # the bounds of the records, as laspy's update_header makes them
                header.mins = records.min(axis=0) * header.scales + header.offsets
                header.maxs = records.max(axis=0) * header.scales + header.offsets
            rec = laspy.ScaleAwarePointRecord(out, header.point_format, header.scales, header.offsets)
            return laspy.LasData(header=header, points=rec), notes
        if self._record is not None:
            fmt = copy.deepcopy(self._record.point_format)
            if self._reframe:
                return laspy.ScaleAwarePointRecord(out, fmt, np.array(scale), np.array(offset)), notes
            return laspy.PackedPointRecord(out, fmt), notes
        return out, notes


def _plain3(values: Any, name: str) -> np.ndarray:
    a = _numbers(values, name)
    if a.ndim != 2 or a.shape[1] != 3:
        raise ValueError(f"{name} must be an (n, 3) array of numbers, got shape {a.shape}")
    return np.ascontiguousarray(a, dtype=np.float64)


def _numbers(values: Any, name: str) -> np.ndarray:
    """``values`` as a numpy array of real numbers: masked, complex, bool and object arrays
    are refused, never read silently."""
    if isinstance(values, np.ma.MaskedArray):
        raise TypeError(
            f"{name}: a masked array; pass its unmasked rows (a.compressed() or a[~a.mask.any(1)])"
        )
    a = np.asarray(values)
    if a.dtype.names is None and a.dtype.kind not in "fiu":
        kind = {"b": "bool", "c": "complex"}.get(a.dtype.kind, str(a.dtype))
        raise TypeError(f"{name} must hold real numbers, got {kind} values")
    return a


def _triangles(triangles: Any) -> Optional[np.ndarray]:
    """Vertex indices as int64; an index is never rounded or truncated, so floats are refused."""
    if triangles is None:
        return None
    t = _numbers(triangles, "triangles")
    if t.dtype.kind not in "iu":
        raise TypeError(
            f"triangles must be integer vertex indices, got {t.dtype} (a whole-numbered float "
            "array: .astype(np.int64))"
        )
    if t.ndim != 2 or t.shape[1] != 3:
        raise ValueError(f"triangles must be an (m, 3) array, got shape {t.shape}")
    if t.dtype.kind == "u":
        if t.size and int(t.max()) > np.iinfo(np.int64).max:
            raise ValueError("triangles name a vertex outside the points")
    return np.ascontiguousarray(t, dtype=np.int64)
