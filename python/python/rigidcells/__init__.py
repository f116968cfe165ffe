"""rigidcells: adaptive space deformations based on rigid cells (Botsch, Pauly, Wicke, Gross).

Deform point clouds and meshes held in numpy arrays or laspy objects, or files of any size,
with the same library the ``rigidcells`` command line uses::

    import numpy as np, rigidcells
    moved, info = rigidcells.deform(points, "edit.toml")        # (n, 3) float64 in and out
    bent, info = rigidcells.deform(laspy.read("scan.laz"), "edit.toml")   # a new LasData
    field = rigidcells.solve(points, {"fixed": [...], "handle": [...]})
    field.apply(other_points); field.save("bend.field")
    rigidcells.deform_file("scan.laz", "bent.laz", "edit.toml")

``spec`` is the edit spec: TOML text, a path to a ``.toml`` file, or a dict of the same
structure. ``points`` may also be a numpy structured array with float fields ``X``, ``Y``,
``Z`` (as PDAL's Python bindings hand them out): the same dtype comes back with only those
fields changed. A laspy ``LasData`` or ``ScaleAwarePointRecord`` comes back as a new one of the
same kind, its coordinates written through the header's scale and offset rounded to the
nearest step (as the command line writes LAS). Integer ``X``, ``Y``, ``Z`` (LAS records, such as
laspy's ``points.array``) are decoded with ``scale=`` and ``offset=``, and refused without them.
laspy is not a dependency: its objects are recognized when laspy is imported. Errors are
exceptions: ``ValueError`` for a bad spec or parameter, ``OSError`` for I/O,
``rigidcells.FormatError`` (a ``ValueError``) for malformed files. Heavy calls release the GIL.
"""

from __future__ import annotations

import copy
import json
import os
import sys
import warnings
from pathlib import Path
from typing import Any, List, Optional, Sequence, Tuple, Union

import numpy as np

from . import _rigidcells, dask
from ._rigidcells import FormatError

__all__ = ["deform", "solve", "deform_file", "apply_file", "Field", "FormatError"]

Spec = Union[str, "os.PathLike[str]", dict]


def _spec(spec: Spec) -> Tuple[str, str]:
    """The spec's TOML text and the folder its relative file names are resolved against."""
    if isinstance(spec, dict):
        return _rigidcells.toml_from_json(json.dumps(spec)), os.getcwd()
    if isinstance(spec, os.PathLike) or (
        isinstance(spec, str) and "\n" not in spec and spec.strip().endswith(".toml")
    ):
        path = Path(spec)
        try:
            text = path.read_text(encoding="utf-8")
        except FileNotFoundError as e:
            raise OSError(f"{path}: {e.strerror}") from e
        return text, str(path.parent.resolve())
    if isinstance(spec, str):
        return spec, os.getcwd()
    raise TypeError("spec must be TOML text, a path to a .toml file, or a dict")


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


class _Points:
    """Points in any accepted form: their coordinates ((n, 3) float64), and ``back``, which
    puts moved coordinates into a new object of the same form (the input is never changed)."""

    def __init__(self, points: Any, scale: Optional[Frame], offset: Optional[Frame]) -> None:
        laspy = _laspy()
        given = scale is not None or offset is not None
        self._las = self._record = self._structured = self._plain = None
        self._frame: Any = None
        self._reframe = False
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
            arr = np.asarray(points)
        if arr.dtype.names is not None:
            names = arr.dtype.names
            if not all(k in names for k in ("X", "Y", "Z")):
                raise ValueError(f"a structured array needs fields X, Y, Z; it has {names}")
            kinds = {arr.dtype[k].kind for k in ("X", "Y", "Z")}
            self._structured = arr
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
                xyz = np.stack([arr["X"], arr["Y"], arr["Z"]], axis=1).astype(np.float64)
                self.xyz = np.ascontiguousarray(xyz)
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
            self.xyz = np.ascontiguousarray(arr, dtype=np.float64)

    def back(self, moved: np.ndarray) -> Tuple[Any, List[str]]:
        """The moved coordinates in the input's form, and a note per re-framed axis."""
        notes: List[str] = []
        if self._frame is None:
            if self._structured is None:
                return moved, notes
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
    a = np.asarray(values)
    if a.ndim != 2 or a.shape[1] != 3 or a.dtype.kind not in "fiu":
        raise ValueError(f"{name} must be an (n, 3) array of numbers, got {a.dtype} {a.shape}")
    return np.ascontiguousarray(a, dtype=np.float64)


def _triangles(triangles: Any) -> Optional[np.ndarray]:
    """Vertex indices as int64; whole-numbered floats are taken, fractions refused (an index
    is never truncated)."""
    if triangles is None:
        return None
    t = np.asarray(triangles)
    if t.ndim != 2 or t.shape[1] != 3:
        raise ValueError(f"triangles must be an (m, 3) array, got shape {t.shape}")
    if t.dtype.kind == "f":
        if not np.all(np.isfinite(t)) or not np.array_equal(t, np.floor(t)):
            raise ValueError("triangles must hold whole vertex indices, got fractions")
        if t.size and (t.min() < 0 or t.max() >= 2.0**63):
            raise ValueError("triangles name a vertex outside the points")
    elif t.dtype.kind == "u":
        if t.size and int(t.max()) > np.iinfo(np.int64).max:
            raise ValueError("triangles name a vertex outside the points")
    elif t.dtype.kind != "i":
        raise ValueError(f"triangles must be integer vertex indices, got {t.dtype}")
    return np.ascontiguousarray(t, dtype=np.int64)


class Field:
    """A solved field (``solve``): apply it to points, save it for ``rigidcells apply``, load one."""

    def __init__(self, native: _rigidcells.Field) -> None:
        self._native = native

    def apply(
        self,
        points: Any,
        *,
        scale: Optional[Frame] = None,
        offset: Optional[Frame] = None,
    ) -> Any:
        """Moves ``points`` through the field and returns them in the same form (as ``deform``
        takes and returns them); points beyond the field's margin are a ``ValueError`` (as
        ``rigidcells apply`` refuses them). A LAS offset moved to fit the coordinates is said
        in a ``UserWarning``."""
        p = _Points(points, scale, offset)
        out, notes = p.back(self._native.apply(p.xyz))
        for note in notes:
            warnings.warn(note, stacklevel=2)
        return out

    def save(self, path: Union[str, "os.PathLike[str]"]) -> None:
        """Writes the field to ``path`` (the format ``rigidcells apply`` reads)."""
        self._native.save(os.fspath(path))

    @staticmethod
    def load(path: Union[str, "os.PathLike[str]"]) -> "Field":
        """Reads a field saved by ``save`` or ``rigidcells deform --save-field``."""
        return Field(_rigidcells.Field.load(os.fspath(path)))

    @property
    def cells(self) -> int:
        """The number of cells."""
        return self._native.cells

    def __repr__(self) -> str:
        return repr(self._native)


def deform(
    points: Any,
    spec: Spec,
    *,
    triangles: Any = None,
    normals: Any = None,
    cell_size: Optional[float] = None,
    cells: Optional[int] = None,
    transfer: Optional[str] = None,
    scale: Optional[Frame] = None,
    offset: Optional[Frame] = None,
) -> Tuple[Any, dict]:
    """Deforms ``points`` under ``spec``; returns the moved points, in the form they came in,
    and what was done.

    ``points``: an (n, 3) array of coordinates (float64 back); a numpy structured array with
    float fields ``X``, ``Y``, ``Z`` (PDAL's; the same dtype back, only those fields changed);
    a laspy ``LasData`` or its ``points`` (a new one back, coordinates written through the
    header's scale and offset, rounded to the nearest step as the command line's LAS writer
    rounds them; an offset that no longer fits moves as the command line moves it, said in
    ``info["notes"]``). Integer ``X``, ``Y``, ``Z`` (laspy's ``points.array``, LAS records) need
    ``scale`` and ``offset`` (a number or three each; offset 0 by default): they are decoded,
    moved and encoded back rounded to the nearest step, and a moved record that does not fit
    its field is a ``ValueError``. An (n, 3) integer array with ``scale`` is taken the same way.

    ``transfer``: ``"pu"`` (the command line's default), ``"rbf"``, ``"blend"`` or
    ``"blend-idw"``. ``cell_size`` or ``cells`` size the cells as ``--cell-size``/``--cells``
    do. ``normals`` ((n, 3), one per point): turned as the map turns the surface, returned
    as ``info["normals"]``.

    ``info["handle_turns"]``: per turning handle, its ``line`` in the spec, the turn asked and
    the turn the cells carry from the fixed cells to it (``turn_asked_degrees``,
    ``turn_taken_degrees``); ``info["warnings"]`` says when they differ by more than a tenth.
    A turn the shape cannot carry (a whole turn of a part as short as it is wide) is a
    ``ValueError`` rather than a part untwisted the short way round.
    """
    p = _Points(points, scale, offset)
    text, base = _spec(spec)
    nrm = None if normals is None else _plain3(normals, "normals")
    moved, info = _rigidcells.deform(
        p.xyz, text, base, _triangles(triangles), nrm, cell_size, cells, transfer
    )
    out, info["notes"] = p.back(moved)
    return out, info


def solve(
    points: Any,
    spec: Spec,
    *,
    triangles: Any = None,
    cell_size: Optional[float] = None,
    cells: Optional[int] = None,
    transfer: Optional[str] = None,
    scale: Optional[Frame] = None,
    offset: Optional[Frame] = None,
) -> Field:
    """Solves ``spec`` over ``points`` (any form ``deform`` takes, with ``scale`` and ``offset``
    as there) and returns the field (``Field.apply``, ``.save``)."""
    p = _Points(points, scale, offset)
    text, base = _spec(spec)
    field, _info = _rigidcells.solve(
        p.xyz, text, base, _triangles(triangles), cell_size, cells, transfer
    )
    return Field(field)


def deform_file(
    input: Union[str, "os.PathLike[str]"],
    output: Union[str, "os.PathLike[str]"],
    spec: Spec,
    *,
    save_field: Union[str, "os.PathLike[str]", None] = None,
    cell_size: Optional[float] = None,
    cells: Optional[int] = None,
    transfer: Optional[str] = None,
) -> dict:
    """``rigidcells deform INPUT -o OUTPUT --edit SPEC``: streams the file, writes the output
    atomically (and the field with ``save_field``); returns what was done."""
    text, base = _spec(spec)
    return _rigidcells.deform_file(
        os.fspath(input),
        os.fspath(output),
        text,
        base,
        None if save_field is None else os.fspath(save_field),
        cell_size,
        cells,
        transfer,
    )


def apply_file(
    field: Union[str, "os.PathLike[str]"],
    input: Union[str, "os.PathLike[str]"],
    output: Union[str, "os.PathLike[str]"],
    *,
    outside: str = "refuse",
) -> dict:
    """``rigidcells apply FIELD INPUT -o OUTPUT``: the same bytes as the command line."""
    return _rigidcells.apply_file(
        os.fspath(field), os.fspath(input), os.fspath(output), outside
    )
