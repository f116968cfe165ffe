"""rigidcells: adaptive space deformations based on rigid cells (Botsch, Pauly, Wicke, Gross).

Deform point clouds and meshes held in numpy arrays, or files of any size, with the same
library the ``rigidcells`` command line uses::

    import numpy as np, rigidcells
    moved, info = rigidcells.deform(points, "edit.toml")        # (n, 3) float64 in and out
    field, info = rigidcells.solve(points, {"fixed": [...], "handle": [...]})
    field.apply(other_points); field.save("bend.field")
    rigidcells.deform_file("scan.laz", "bent.laz", "edit.toml")

``spec`` is the edit spec: TOML text, a path to a ``.toml`` file, or a dict of the same
structure. ``points`` may also be a numpy structured array with fields ``X``, ``Y``, ``Z`` (as
PDAL's Python bindings hand them out): the same dtype comes back with only those fields
changed. Errors are exceptions: ``ValueError`` for a bad spec or parameter, ``OSError`` for I/O,
``rigidcells.FormatError`` (a ``ValueError``) for malformed files. Heavy calls release the GIL.
"""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any, Optional, Tuple, Union

import numpy as np

from . import _rigidcells, dask
from ._rigidcells import Field, FormatError

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


def _xyz(points: Any) -> Tuple[np.ndarray, Optional[np.ndarray]]:
    """(n, 3) float64 coordinates, and the structured array they came from (or None)."""
    arr = np.asarray(points)
    if arr.dtype.names is not None:
        names = arr.dtype.names
        if not all(k in names for k in ("X", "Y", "Z")):
            raise ValueError(f"a structured array needs fields X, Y, Z; it has {names}")
        xyz = np.stack([arr["X"], arr["Y"], arr["Z"]], axis=1).astype(np.float64)
        return np.ascontiguousarray(xyz), arr
    if arr.ndim != 2 or arr.shape[1] != 3:
        raise ValueError(f"points must be an (n, 3) array, got shape {arr.shape}")
    return np.ascontiguousarray(arr, dtype=np.float64), None


def _back(moved: np.ndarray, structured: Optional[np.ndarray]) -> np.ndarray:
    if structured is None:
        return moved
    out = structured.copy()
    for k, name in enumerate(("X", "Y", "Z")):
        out[name] = moved[:, k].astype(out.dtype[name], copy=False)
    return out


def _triangles(triangles: Any) -> Optional[np.ndarray]:
    if triangles is None:
        return None
    t = np.ascontiguousarray(np.asarray(triangles), dtype=np.int64)
    if t.ndim != 2 or t.shape[1] != 3:
        raise ValueError(f"triangles must be an (m, 3) array, got shape {t.shape}")
    return t


def deform(
    points: Any,
    spec: Spec,
    *,
    triangles: Any = None,
    normals: Any = None,
    cell_size: Optional[float] = None,
    cells: Optional[int] = None,
    transfer: Optional[str] = None,
) -> Tuple[np.ndarray, dict]:
    """Deforms ``points`` under ``spec``; returns the moved points and what was done.

    ``transfer``: ``"pu"`` (the command line's default), ``"rbf"``, ``"blend"`` or
    ``"blend-idw"``. ``cell_size`` or ``cells`` size the cells as ``--cell-size``/``--cells``
    do. ``normals`` ((n, 3), one per point): turned as the map turns the surface, returned
    as ``info["normals"]``.
    """
    xyz, structured = _xyz(points)
    text, base = _spec(spec)
    nrm = None
    if normals is not None:
        nrm, _ = _xyz(normals)
    moved, info = _rigidcells.deform(
        xyz, text, base, _triangles(triangles), nrm, cell_size, cells, transfer
    )
    return _back(moved, structured), info


def solve(
    points: Any,
    spec: Spec,
    *,
    triangles: Any = None,
    cell_size: Optional[float] = None,
    cells: Optional[int] = None,
    transfer: Optional[str] = None,
) -> Field:
    """Solves ``spec`` over ``points`` and returns the field (``Field.apply``, ``.save``)."""
    xyz, _ = _xyz(points)
    text, base = _spec(spec)
    field, _info = _rigidcells.solve(
        xyz, text, base, _triangles(triangles), cell_size, cells, transfer
    )
    return field


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
