"""rigidcells: adaptive space deformations based on rigid cells (Botsch, Pauly, Wicke, Gross).

Deform point clouds and meshes held in numpy arrays, laspy, trimesh or Open3D objects, or
files of any size, with the same library the ``rigidcells`` command line uses::

    import numpy as np, rigidcells
    moved, report = rigidcells.deform(points, "edit.toml")      # (n, 3) float64 in and out
    bent, report = rigidcells.deform(laspy.read("scan.laz"), "edit.toml")   # a new LasData
    bent_mesh, report = rigidcells.deform(trimesh.load("part.ply"), spec)   # a new Trimesh
    field = rigidcells.solve(points, {"fixed": [...], "handle": [...]})
    field.apply(other_points); field.save("bend.field"); pickle.dumps(field)
    rigidcells.deform_file("scan.laz", "bent.laz", "edit.toml", cells=20_000)
    live = rigidcells.Session(points, spec)                # the cells built once, solved
    live.drag({"translate": [0, 0, 2]}); live.preview()     # one warm iteration, its blend
    moved, report = live.release()                          # converged, exact transfer

``spec`` is the edit spec: TOML text, a path to a ``.toml`` file, or a dict of the same
structure (numbers may be numpy scalars or arrays; an error in it names its key path, such as
``spec["handle"][0]["translate"]``). Every option of the command line's ``deform`` is a
keyword argument of the same name and default (``cell_size``, ``cells``, ``transfer``,
``solver``, ``loose_parts``, ...). ``points`` may also be a numpy structured array with float
fields ``X``, ``Y``, ``Z`` (as PDAL's Python bindings hand them out): the same dtype comes back
with only those fields changed. A laspy ``LasData`` or ``ScaleAwarePointRecord`` comes back as
a new one of the same kind, its coordinates written through the header's scale and offset
rounded to the nearest step (as the command line writes LAS); LAS records keep their classes
for the spec's ``classification`` regions. Integer ``X``, ``Y``, ``Z`` (LAS records, such as
laspy's ``points.array``) are decoded with ``scale=`` and ``offset=``, and refused without
them. An (n, 3) float32 array comes back float32. A ``trimesh.Trimesh`` or ``PointCloud``, an
Open3D ``TriangleMesh`` or ``PointCloud`` comes back as a new one with its triangles, colors
and other attributes kept and its normals turned (a Trimesh derives its own from the moved
faces). None of laspy, trimesh and
Open3D is a dependency: their objects are recognized when the library is imported.

A deformation returns a ``Report`` (a dataclass with the keys of ``deform --report``: cells,
cell size, iterations, energies, residuals, fold-overs, warnings, timings); its warnings are also emitted through Python's
``warnings`` module as ``rigidcells.RigidCellsWarning``. Errors are exceptions that name the
argument: ``TypeError`` or ``ValueError`` for a bad argument, spec or parameter, ``OSError`` for
I/O, ``rigidcells.FormatError`` (a ``ValueError``) for malformed files,
``rigidcells.TurnNotHeldError`` (a ``ValueError``) for a handle's turn the shape gives way under,
with its fields (``handle``: the handle's index in ``spec["handle"]``, ``kind``, the degrees asked
and held, ``said``: the message after the handle's name). Heavy calls release the GIL;
Ctrl-C stops them within a step (``KeyboardInterrupt``), leaving no output file behind.
"""

from __future__ import annotations

import contextlib
import json
import os
import sys
import threading
import warnings
from dataclasses import dataclass
from typing import Any, Dict, Iterator, List, NamedTuple, Optional, Sequence, Tuple, Union

import numpy as np

from . import _rigidcells, dask
from ._points import Frame, _float_dtype, _Points, _plain3, _triangles
from ._rigidcells import FormatError, TurnNotHeldError
from ._spec import (
    Spec, _call, _in_dict_terms, _key_paths, _lines_said, _plain, _said, _spec,
)

__all__ = [
    "deform", "solve", "estimate", "deform_file", "apply_file", "solve_files", "Field",
    "Report", "Estimate", "Session", "Step", "FormatError", "TurnNotHeldError",
    "RigidCellsWarning", "__version__",
]

__version__: str = _rigidcells.__version__



class RigidCellsWarning(UserWarning):
    """What the command line prints as a warning (parts no constraint reaches, a turn the shape
    did not carry, fold-overs, a cell count off its target, ...), emitted through ``warnings``
    by every call that returns a ``Report`` (which also lists them in ``report.warnings``), and
    the notes of ``Field.apply``. ``warnings.simplefilter("error", RigidCellsWarning)`` makes
    them errors; ``"ignore"`` silences them."""


def _warn(messages: Sequence[str]) -> None:
    """Each message as a ``RigidCellsWarning`` at the line that called the package's function
    calling this."""
    for message in messages:
        warnings.warn(message, RigidCellsWarning, stacklevel=3)


@dataclass
class Report:
    """What a deformation did: the library's report, the one ``deform --report R.json``
    writes, under the same keys with the same meanings (``energy`` is the list of energies,
    ``timings_s`` the seconds per stage), plus ``normals``. The messages (``warnings``,
    ``notes``) name options as keyword arguments and, for a dict spec, its entries by key
    path. For points in memory ``input`` and ``output`` are empty and ``timings_s`` has no
    read or write. ``report["cells"]`` and ``report.keys()`` read it as a dict."""

    input: str
    """The input file (for a solve over tiles, the files, joined by ``, ``; "" for arrays)."""
    inputs: List[str]
    """The input files (none for arrays)."""
    output: str
    """The output file (for a solve, the field; "" for arrays)."""
    points: int
    """Samples deformed."""
    cells: int
    """Cells of the complex solved (after refinement)."""
    cells_initial: int
    """Cells before refinement."""
    cell_size: float
    """The finest cells' edge length, in the points' units (the one ``cells=`` chose)."""
    cell_levels: Dict[int, int]
    """Cells per octree level (0 the finest), after refinement."""
    cell_roles: Dict[str, int]
    """Cells of each role: ``free``, ``fixed``, ``handle``, ``pin``, ``rest``, ``carried``."""
    iterations: int
    """Solver iterations in all (Gauss-Newton or local-global: ``iteration_log`` says which)."""
    load_steps: int
    """Load steps."""
    load_step_halvings: int
    """Load steps taken again in halves (a part untwisting the short way round)."""
    handle_turns: List[dict]
    """Per turning handle: its ``line`` in the spec (for a dict spec also its ``key``),
    ``turn_asked_degrees`` and ``turn_taken_degrees``."""
    linear_solver: str
    """How the last iterations were solved: ``direct``, ``multilevel`` or ``local-global``."""
    linear_iterations: int
    """Conjugate-gradient iterations over all Gauss-Newton steps (multilevel)."""
    levels: int
    """Levels of the multilevel hierarchy (0 when direct)."""
    energy: List[float]
    """The energy before each load step's first iteration and after every iteration (the
    last is the energy at the end)."""
    converged: bool
    """Whether the last load step met the tolerance."""
    iteration_log: List[dict]
    """Every iteration: ``method``, ``load_step``, ``energy``, ``decrease``,
    ``largest_move``, ``step_length``, ``linear_iterations`` and its seconds."""
    residual_max: float
    """The largest of the two residuals below."""
    residual_fixed_max: float
    """The largest distance of a sample in a fixed cell from its rest position (0: exact)."""
    residual_handle_max: float
    """The largest distance of a sample in a handle's cell from where the handle sends it."""
    residual_samples: int
    """Samples the residuals measured (every one for arrays; a file's preview proxy)."""
    target_residual_max: float
    """The largest distance of a soft target's point, under its cell's motion, from its
    target."""
    foldovers: int
    """Samples where the map folds space over (its Jacobian's determinant not positive)."""
    foldovers_checked: int
    """Samples checked for fold-overs."""
    foldover_samples: List[int]
    """The points the map folds over, by index (among those checked; for a file, whose check
    is on its preview, none are listed)."""
    timings_s: dict
    """Seconds per stage: ``read``, ``voxelize``, ``solve``, ``transfer``, ``write``,
    ``check_gcp``, ``total``."""
    peak_memory_bytes: Optional[int]
    """The process's peak resident memory (None where unknown)."""
    estimate: Optional[dict]
    """What the solve was estimated to take before it started: ``cells``, ``bytes``,
    ``seconds``, ``solver``."""
    warnings: List[str]
    """Messages for the user."""
    notes: List[str]
    """Notes on the output (an offset moved to fit, samples beyond the margin)."""
    control_points: List[dict]
    """Per control point (``[[target]]``): ``id``, ``place``, ``from``, ``wanted``, ``got``,
    ``residual``, ``check`` (a checkpoint, scored and not solved for), ``exact`` (its cell
    pinned to it), and what the report file says of it."""
    control_rounding: Optional[str]
    """What ``got`` was rounded to before the residuals were measured, as the output file
    stores it (``"the output's scale 0.01"``; None for arrays, whose values are the field's)."""
    control_rmse: Optional[float]
    """The control points' root mean square residual (None without any)."""
    control_rmse_left_out: Optional[float]
    """The root mean square of their leave-one-out prediction errors (with ``check_gcp``)."""
    control_trend: Optional[str]
    """The control points' trend (``"spline"``, ``"affine"``, …; None without one): the map
    through them that carries what is global, the cells carrying the rest."""
    checkpoints: Optional[dict]
    """The checkpoints' accuracy (rows marked ``check``; None without any): ``count``,
    ``rmse_x``, ``rmse_y``, ``rmse_r``, ``rmse_z``, and ``accuracy_r_95`` and
    ``accuracy_z_95`` as ASPRS and the NSSDA state them."""
    options: Dict[str, Any]
    """The options the run took, by this package's keywords (``cell_size``,
    ``interior_stiffness``, ...), each at the value given or None where the run decided: with
    the spec, what runs it again."""
    normals: Optional[np.ndarray] = None
    """The turned normals, when normals were given."""

    def __getitem__(self, key: str) -> Any:
        if key not in self.__dataclass_fields__:
            raise KeyError(key)
        return getattr(self, key)

    def __contains__(self, key: object) -> bool:
        return key in self.__dataclass_fields__

    def keys(self) -> List[str]:
        """The fields' names, as a dict's keys."""
        return list(self.__dataclass_fields__)

    @staticmethod
    def _of(info: dict, notes: Optional[List[str]] = None, paths: Optional[List[str]] = None) -> "Report":
        """The report of the native call's ``info`` (the library's report as a dict, its
        messages as parts), with the Python layer's ``notes`` and a dict spec's key ``paths``
        for the lines its messages name."""
        known = {k: info.get(k) for k in Report.__dataclass_fields__}
        known["cell_levels"] = {int(k): v for k, v in (info.get("cell_levels") or {}).items()}
        known["warnings"] = _lines_said(list(info.get("warnings", [])), paths)
        known["notes"] = _lines_said(list(info.get("notes", [])) + list(notes or []), paths)
        turns = [dict(t) for t in info.get("handle_turns", [])]
        if paths is not None:
            for t in turns:
                n, t["line"] = t["line"], None  # a key path, not a line of the package's TOML
                if 0 < n <= len(paths):
                    t["key"] = paths[n - 1]
        known["handle_turns"] = turns
        report = Report(**known)
        report._warning_parts = list(info.get("warnings", []))
        return report

    def warnings_in(self, option: Any = None, entry: Any = None) -> List[str]:
        """The warnings in another face's terms: each option the library names as
        ``option(keyword, value)`` says it (``value`` a ``str`` as typed, or None), each entry
        of the spec as ``entry(kind, index)`` says it (``"handle"``, 0 for the first), each
        either left in the package's terms when not given. Where ``option`` gives None the
        face lacks that option: it is said by its keyword, and advice to set it is left out.
        The Blender add-on names its panel's settings and groups so."""
        parts = getattr(self, "_warning_parts", None)
        if parts is None:
            return list(self.warnings)
        return [_said(p, None, option, entry) for p in parts]


def _field_from_bytes(data: bytes, report: Optional[Report] = None) -> "Field":
    """A pickled field (its saved bytes and its report) back."""
    return Field(_rigidcells.Field.from_bytes(data), report)


class Field:
    """A solved field (``solve``): apply it to points, save it for ``rigidcells apply``, load
    one. It pickles (as the bytes ``save`` writes), so it goes to process pools and Dask
    workers as it is."""

    def __init__(self, native: _rigidcells.Field, report: Optional[Report] = None) -> None:
        self._native = native
        self.report = report
        """What the solve did (None for a loaded field)."""

    def apply(
        self,
        points: Any,
        *,
        normals: Any = None,
        outside: str = "refuse",
        scale: Optional[Frame] = None,
        offset: Optional[Frame] = None,
    ) -> Any:
        """Moves ``points`` through the field and returns them in the same form (as ``deform``
        takes and returns them). ``outside``: ``"refuse"`` (points beyond the field's margin
        are a ``ValueError``, as ``rigidcells apply`` refuses them), ``"keep"`` (they keep
        their coordinates) or ``"extend"`` (the transfer extrapolated). With ``normals``
        ((n, 3)), returns ``(points, normals)``, the normals turned as the map turns the
        surface. A LAS offset moved to fit the coordinates is said in a ``RigidCellsWarning``."""
        p = _Points(points, scale, offset)
        nrm = p.normals if normals is None else _plain3(normals, "normals")
        moved, turned = self._native.apply(p.xyz, nrm, outside)
        out, notes = p.back(moved, turned)
        _warn(notes)
        return out if normals is None else (out, turned.astype(_float_dtype(normals), copy=False))

    def save(self, path: Union[str, "os.PathLike[str]"]) -> None:
        """Writes the field to ``path`` (the format ``rigidcells apply`` reads)."""
        self._native.save(os.fspath(path))

    @staticmethod
    def load(path: Union[str, "os.PathLike[str]"]) -> "Field":
        """Reads a field saved by ``save`` or ``rigidcells deform --save-field``."""
        return Field(_rigidcells.Field.load(os.fspath(path)))

    def __reduce__(self) -> Any:
        return (_field_from_bytes, (self._native.to_bytes(), self.report))

    def __eq__(self, other: object) -> bool:
        """The same field: the same saved bytes (the report aside)."""
        if not isinstance(other, Field):
            return NotImplemented
        return self._native.to_bytes() == other._native.to_bytes()

    __hash__ = None  # type: ignore[assignment]

    @property
    def cells(self) -> int:
        """The number of cells."""
        return self._native.cells

    @property
    def cell_size(self) -> float:
        """The finest cells' edge length."""
        return self._native.cell_size

    @property
    def transfer(self) -> str:
        """The transfer the field was made for."""
        return self._native.transfer

    @property
    def levels(self) -> List[Tuple[float, int]]:
        """The cells' edge lengths, one per octree level they occupy, smallest first, each
        with its count of cells (as ``rigidcells info`` lists a field's levels)."""
        return self._native.levels

    @property
    def bounds(self) -> Tuple[Tuple[float, float, float], Tuple[float, float, float]]:
        """The cells' bounding box: ``((xmin, ymin, zmin), (xmax, ymax, zmax))``."""
        lo, hi = self._native.bounds
        return tuple(lo), tuple(hi)

    def __repr__(self) -> str:
        lo, hi = self.bounds
        return (
            f"rigidcells.Field({self.cells} cells of {self.cell_size:.6g}, transfer "
            f"{self.transfer}, bounds {tuple(round(v, 6) for v in lo)} to "
            f"{tuple(round(v, 6) for v in hi)})"
        )


_OPTIONS_DOC = """
    Options (each as the command line's option of the same name; None: its default):
    ``cell_size`` (edge of the finest cells; default: longest extent / 32), ``cells`` (about
    this many cells, within 2 % where the counts allow, else ``report.warnings`` gives the
    count; not with ``cell_size``), ``min_cell_size`` (adaptive cells
    down to this size), ``max_level`` (octree levels above the finest cells), ``shell`` (occupied
    cells only), ``inside`` (``"auto"``, ``"winding"``, ``"flood"``, ``"none"``),
    ``interior_stiffness`` (the cells inside the shape against those on its surface: 0.05 by
    default, a twist spreads along a thin neck as on a surface; 1, a uniform solid's, keeps a
    bend's volume best; 0.0001 to 10000, not with ``shell``), ``solver``
    (``"auto"``, ``"direct"``, ``"multilevel"``, ``"local-global"``), ``subdomains``
    (local-global iterations with each global step split into this many subdomains, each
    block factored alone; ``rigidcells.dask.solve_tiles`` gives the blocks to Dask workers;
    0: as ``solver`` says), ``tolerance`` (the move
    test, in finest cell sizes; default 1e-3; 0: the energy test only), ``coarse_levels`` (coarser complexes solved
    first, 0 to 8), ``loose_parts`` (``"carry"`` or ``"rest"``), ``refine_strain`` (split
    cells strained past this and solve again), ``transfer`` (``"pu"``, ``"rbf"``,
    ``"blend"``, ``"blend-idw"``), ``rbf_tolerance`` (with ``transfer="rbf"``: the far
    field's error bound, a length), ``check_gcp`` (the control points' leave-one-out check),
    ``memory_limit`` (bytes, or a size such as ``"8G"``).

    ``progress``: a callable ``(stage, done, total)`` (``total`` None when unknown), called at
    most ten times a second; by default a tqdm bar where tqdm is installed and standard error
    is a terminal; ``False`` for none. Ctrl-C stops the call within a step (a solver
    iteration, a chunk of a file) and raises ``KeyboardInterrupt``; an exception the callable
    raises stops it the same way.
"""


def _options(**given: Any) -> dict:
    """The options given (not None), for the native calls."""
    return {k: v for k, v in given.items() if v is not None}


# The keyword arguments that are options of a deformation (the command line's names).
_OPTION_NAMES = (
    "cell_size", "cells", "min_cell_size", "max_level", "shell", "inside", "interior_stiffness",
    "solver",
    "subdomains", "tolerance", "coarse_levels", "loose_parts", "refine_strain", "transfer",
    "rbf_tolerance", "check_gcp", "memory_limit",
)


def _picked(arguments: dict) -> dict:
    """The options among a call's ``arguments`` (its ``locals()``) that were given."""
    return _options(**{k: arguments[k] for k in _OPTION_NAMES if k in arguments})


class _Tqdm:
    """A tqdm bar per stage, as a progress callable."""

    def __init__(self, tqdm: Any) -> None:
        self._tqdm, self._bar, self._stage = tqdm, None, None

    def __call__(self, stage: str, done: int, total: Optional[int]) -> None:
        if stage != self._stage:
            self.close()
            self._stage = stage
            self._bar = self._tqdm(total=total, desc=stage, leave=False, unit=" ")
        self._bar.n = done
        self._bar.refresh()

    def close(self) -> None:
        if self._bar is not None:
            self._bar.close()
            self._bar = None


def _progress(progress: Any) -> Tuple[Any, Any]:
    """The progress callable to pass on, and what to close after the call."""
    if progress is False:
        return None, None
    if progress is not None and progress is not True:
        if not callable(progress):
            raise TypeError("progress must be a callable (stage, done, total), True or False")
        return progress, None
    interactive = progress is True or (hasattr(sys.stderr, "isatty") and sys.stderr.isatty())
    if not interactive:
        return None, None
    try:
        from tqdm.auto import tqdm
    except ImportError:
        return None, None
    bar = _Tqdm(tqdm)
    return bar, bar


def _with_progress(progress: Any, f: Any) -> Any:
    """``f(callback)`` with the progress callable ``progress`` asks for."""
    callback, bar = _progress(progress)
    try:
        return f(callback)
    finally:
        if bar is not None:
            bar.close()


def deform(
    points: Any,
    spec: Spec,
    *,
    triangles: Any = None,
    normals: Any = None,
    scale: Optional[Frame] = None,
    offset: Optional[Frame] = None,
    cell_size: Optional[float] = None,
    cells: Optional[int] = None,
    min_cell_size: Optional[float] = None,
    max_level: Optional[int] = None,
    shell: Optional[bool] = None,
    inside: Optional[str] = None,
    interior_stiffness: Optional[float] = None,
    solver: Optional[str] = None,
    subdomains: Optional[int] = None,
    tolerance: Optional[float] = None,
    coarse_levels: Optional[int] = None,
    loose_parts: Optional[str] = None,
    refine_strain: Optional[float] = None,
    transfer: Optional[str] = None,
    rbf_tolerance: Optional[float] = None,
    check_gcp: Optional[bool] = None,
    memory_limit: Union[int, str, None] = None,
    progress: Any = None,
) -> Tuple[Any, Report]:
    """Deforms ``points`` under ``spec``; returns the moved points, in the form they came in,
    and a ``Report`` of what was done.

    ``points``: an (n, 3) array of coordinates (float32 back for float32, else float64); a
    numpy structured array with float fields ``X``, ``Y``, ``Z`` (PDAL's; the same dtype back,
    only those fields changed); a laspy ``LasData`` or its ``points`` (a new one back,
    coordinates written through the header's scale and offset, rounded to the nearest step as
    the command line's LAS writer rounds them; an offset that no longer fits moves as the
    command line moves it, said in ``report.notes``). Records keep their LAS classes for the
    spec's ``classification`` regions (laspy's, or a structured array's ``classification``,
    ``Classification`` or ``raw_classification`` field, read as the command line reads a
    file's). Integer ``X``, ``Y``, ``Z`` (laspy's ``points.array``, LAS records) need
    ``scale`` and ``offset`` (a number or three each; offset 0 by default): they are decoded,
    moved and encoded back rounded to the nearest step, and a moved record that does not fit
    its field is a ``ValueError``. An (n, 3) integer array with ``scale`` is taken the same way.
    A trimesh or Open3D mesh or point cloud: its vertices, triangles and normals are taken,
    and a new object of its kind comes back. Masked, complex and bool arrays are refused.
    ``triangles``: (m, 3) vertex indices.
    ``normals`` ((n, 3), one per point): turned as the map turns the surface, returned as
    ``report.normals`` (in the normals' float type).

    ``report.warnings`` are also emitted as ``RigidCellsWarning`` warnings.
    ``report.handle_turns``: per turning handle, its ``line`` in a TOML spec (a dict spec's
    ``key``, ``line`` None), the turn asked and the turn the cells carry from the fixed cells
    to it; ``report.warnings`` says when they differ by more than a tenth. A turn the shape
    cannot carry (a whole turn of a part as short as it is wide) is a ``TurnNotHeldError``.
    """
    options = _picked(locals())
    p = _Points(points, scale, offset)
    text, base, paths = _spec(spec)
    nrm = p.normals if normals is None else _plain3(normals, "normals")
    tris = p.triangles if triangles is None else _triangles(triangles)
    moved, info = _with_progress(
        progress, lambda cb: _call(
            paths, _rigidcells.deform, p.xyz, text, base, tris, nrm, options, cb, p.classes
        )
    )
    out, notes = p.back(moved, _turned(info, _float_dtype(normals)))
    report = Report._of(info, notes, paths)
    _warn(report.warnings)
    return out, report


def _turned(info: dict, dtype: np.dtype) -> Optional[np.ndarray]:
    """The turned normals of a native call's ``info`` (None without) as ``dtype``: the float
    type of the normals given (float64 for a mesh's own)."""
    turned = info.get("normals")
    if turned is not None:
        info["normals"] = turned = turned.astype(dtype, copy=False)
    return turned


@dataclass
class Step:
    """What a step of a ``Session`` did."""

    iterations: int
    """Solver iterations of this step (local-global ones, or Gauss-Newton's)."""
    converged: bool
    """Whether the pose is solved (a drag's step may stop short; ``refine`` goes on)."""
    from_rest: bool
    """Whether the spec was solved from rest (the first, or its regions changed)."""
    seconds: float
    """Seconds of the step."""
    warnings: List[str]
    """A solve from rest's warnings: the cells', the constraints', the solver's."""


def _iterations(iterations: Any) -> int:
    """A number of solver steps, 1 or more."""
    if isinstance(iterations, bool) or not isinstance(iterations, (int, np.integer)):
        raise TypeError(f"iterations must be a whole number, got {type(iterations).__name__}")
    if iterations < 1:
        raise ValueError(f"iterations must be 1 or more, got {iterations}")
    return int(iterations)


_NESTED = (
    "this Session is busy with the call that runs this code (a progress callback, or code it "
    "runs): use the session after that call returns"
)
"""Said when a call on a session comes from within a call on it (the native session says it
alike)."""


def _poses_path(path: str) -> str:
    """A pose's key path said from the ``poses`` given to ``Session.drag``."""
    return path.replace('spec["handle"]', "poses", 1)


class Session:
    """A live deformation, the paper's interactive setting: the cells of ``points`` are built
    once and ``spec`` is solved; then each ``drag`` moves the handles to a new pose with a short
    step from where the cells are (two local-global iterations on a matrix factored once, or a
    Gauss-Newton iteration: 10 to 20 milliseconds at a few thousand cells), ``preview`` blends
    the cells' motions at the points, ``refine`` goes on while the handles rest, and ``release`` converges and moves the points through the transfer with its
    exact constraints, as ``deform`` does. ``points``, ``triangles`` and the keyword options
    are ``deform``'s, but a session keeps the cells it built: ``min_cell_size`` and
    ``refine_strain`` (which refine them) are refused. ``release`` gives the points back in
    the form they came in; released without a drag, they are ``deform``'s, bit for bit.

    Every call but the light properties releases the GIL: a face may run the session on a
    thread of its own. Calls from several threads run one at a time, each waiting for the last.
    A call's progress callback cannot use its session (``RuntimeError``): the session is busy
    with that call until it returns.
    """

    def __init__(
        self,
        points: Any,
        spec: Spec,
        *,
        triangles: Any = None,
        normals: Any = None,
        scale: Optional[Frame] = None,
        offset: Optional[Frame] = None,
        cell_size: Optional[float] = None,
        cells: Optional[int] = None,
        min_cell_size: Optional[float] = None,
        max_level: Optional[int] = None,
        shell: Optional[bool] = None,
        inside: Optional[str] = None,
        interior_stiffness: Optional[float] = None,
        solver: Optional[str] = None,
        subdomains: Optional[int] = None,
        tolerance: Optional[float] = None,
        coarse_levels: Optional[int] = None,
        loose_parts: Optional[str] = None,
        refine_strain: Optional[float] = None,
        transfer: Optional[str] = None,
        rbf_tolerance: Optional[float] = None,
        check_gcp: Optional[bool] = None,
        memory_limit: Union[int, str, None] = None,
        progress: Any = None,
    ) -> None:
        options = _picked(locals())
        self._points = _Points(points, scale, offset)
        tris = self._points.triangles if triangles is None else _triangles(triangles)
        nrm = self._points.normals if normals is None else _plain3(normals, "normals")
        self._normals_dtype = _float_dtype(normals)
        self._native = _rigidcells.Session(
            self._points.xyz, tris, nrm, options, self._points.classes
        )
        self._paths: Optional[List[str]] = None
        # The spec's key paths and the last step go with the native session's state: one call
        # at a time changes them together.
        self._lock = threading.Lock()
        self._holder: Optional[int] = None
        self.last: Step = self.solve(spec, progress=progress)

    def solve(self, spec: Spec, iterations: Optional[int] = None, progress: Any = None) -> Step:
        """Moves to the whole ``spec``: warm from the cells' current motions when only its
        handles' poses changed, else resolved and solved from rest; at most ``iterations``
        steps (each one Gauss-Newton iteration or two local-global ones; all it takes when
        None)."""
        if iterations is not None:
            iterations = _iterations(iterations)
        text, base, paths = _spec(spec)
        with self._turn():
            info = _with_progress(
                progress, lambda cb: _call(paths, self._native.solve, text, base, iterations, cb)
            )
            self._paths = paths
            self.last = self._step(info)
            return self.last

    def drag(
        self,
        poses: Union[dict, Sequence[dict]],
        iterations: int = 1,
        pins: Any = None,
        targets: Any = None,
    ) -> Step:
        """Moves the handles to ``poses``: one dict a handle, in the spec's order (a dict alone
        for one handle), each with a handle's motion keys only (``translate``, ``rotate``,
        ``scale``, ``pivot``, or ``matrix``), solved with ``iterations`` steps (each one
        Gauss-Newton iteration or two local-global ones) from where the cells are. ``pins``
        ((k, 3), one point a pin of the spec): where the pins go now; ``targets`` ((t, 3), one
        point a target of the spec): where the targets pull now (None: where they did)."""
        if isinstance(poses, dict):
            poses = [poses]
        iterations = _iterations(iterations)
        try:
            plain = _plain({"handle": list(poses)}, [])
        except (TypeError, ValueError) as e:
            raise type(e)(_poses_path(str(e))) from None
        text = _rigidcells.toml_from_json(json.dumps(plain))
        to = None if pins is None else _plain3(pins, "pins")
        pulled = None if targets is None else _plain3(targets, "targets")
        with self._turn():
            try:
                info = self._native.pose(text, iterations, to, pulled)
            except ValueError as e:
                # The poses' key paths, worked out only for an error (a drag is the hot path).
                paths = [_poses_path(p) for p in _key_paths(text)]
                raised = _in_dict_terms(e, paths)
                if raised is e:
                    raise
                raise raised from None
            self.last = self._step(info)
            return self.last

    def refine(self) -> bool:
        """One more step on the current pose when its solve stopped short (a Gauss-Newton
        iteration, or four local-global ones); whether one ran (False once converged)."""
        with self._turn():
            return self._native.refine()

    @property
    def converged(self) -> bool:
        """Whether the current pose is solved."""
        return self._native.converged

    @property
    def cells(self) -> int:
        """The number of cells."""
        return self._native.cells

    @property
    def cell_size(self) -> float:
        """The finest cells' edge length."""
        return self._native.cell_size

    def preview(self) -> np.ndarray:
        """The points ((n, 3), float32 for float32 points, else float64) moved by the cells'
        current motions, blended: the shape of the current pose, without the transfer's exact
        constraints."""
        with self._turn():
            return self._native.preview().astype(self._points.dtype, copy=False)

    def release(self, progress: Any = None) -> Tuple[Any, Report]:
        """The current pose's deformation, as ``deform`` gives it: the solve converged, the
        points moved through the transfer (fixed points keep their coordinates, handle points
        follow their handle), in the form they came in, and a ``Report`` (its warnings also
        emitted as ``RigidCellsWarning`` warnings)."""
        with self._turn():
            moved, info = _with_progress(progress, lambda cb: self._native.release(cb))
            paths = self._paths
        turned = _turned(info, self._normals_dtype)
        out, notes = self._points.back(moved, turned)
        report = Report._of(info, notes, paths)
        _warn(report.warnings)
        return out, report

    @contextlib.contextmanager
    def _turn(self) -> Iterator[None]:
        """The session, one call at a time: a call from another thread waits its turn; a call
        from within the call that holds it (its progress callback) is refused, as it would
        wait for itself."""
        me = _rigidcells.caller()
        if self._holder == me:
            raise RuntimeError(_NESTED)
        with self._lock:
            self._holder = me
            try:
                yield
            finally:
                self._holder = None

    def _step(self, info: dict) -> Step:
        return Step(
            iterations=info["iterations"],
            converged=info["converged"],
            from_rest=info["from_rest"],
            seconds=info["seconds"],
            warnings=_lines_said(list(info["warnings"]), self._paths),
        )

    def __repr__(self) -> str:
        state = "converged" if self.converged else "not converged"
        return f"<rigidcells.Session: {self.cells} cells, {state}>"


def solve(
    points: Any,
    spec: Spec,
    *,
    triangles: Any = None,
    scale: Optional[Frame] = None,
    offset: Optional[Frame] = None,
    cell_size: Optional[float] = None,
    cells: Optional[int] = None,
    min_cell_size: Optional[float] = None,
    max_level: Optional[int] = None,
    shell: Optional[bool] = None,
    inside: Optional[str] = None,
    interior_stiffness: Optional[float] = None,
    solver: Optional[str] = None,
    subdomains: Optional[int] = None,
    tolerance: Optional[float] = None,
    coarse_levels: Optional[int] = None,
    loose_parts: Optional[str] = None,
    refine_strain: Optional[float] = None,
    transfer: Optional[str] = None,
    rbf_tolerance: Optional[float] = None,
    check_gcp: Optional[bool] = None,
    memory_limit: Union[int, str, None] = None,
    progress: Any = None,
) -> Field:
    """Solves ``spec`` over ``points`` (any form ``deform`` takes, with ``scale`` and ``offset``
    as there) and returns the field (``Field.apply``, ``.save``; ``field.report`` says what the
    solve did, its warnings also emitted as ``RigidCellsWarning`` warnings)."""
    options = _picked(locals())
    p = _Points(points, scale, offset)
    text, base, paths = _spec(spec)
    tris = p.triangles if triangles is None else _triangles(triangles)
    field, info = _with_progress(
        progress, lambda cb: _call(
            paths, _rigidcells.solve, p.xyz, text, base, tris, options, cb, p.classes
        )
    )
    report = Report._of(info, paths=paths)
    _warn(report.warnings)
    return Field(field, report)


class Estimate(NamedTuple):
    """What a deformation will take, estimated without solving it (``estimate``).

    ``cells``: the cells; ``bytes``: the run's peak memory; ``seconds``: the whole run (the
    cells as built, the solve and the transfer as estimated, on the development machine's two
    cores: scale by the cores); ``solve_seconds``: the solve alone; ``solver``: ``"direct"``,
    ``"multilevel"`` or ``"local-global"``, the path the memory is priced for (with
    ``solver="auto"``: Gauss-Newton's system where it fits the budget, which the run may
    switch to, else the local-global iterations it keeps to); ``limit``: the memory budget
    (``memory_limit``, else three quarters of the machine's memory); ``fits``: whether
    ``bytes`` fit it (a ``deform`` that does not is refused with a ``ValueError``);
    ``complete``: False where the cells were only forecast, because they cannot fit the
    budget (``bytes`` and ``seconds`` are then the least the run takes).
    """

    cells: int
    bytes: int
    seconds: float
    solve_seconds: float
    solver: str
    limit: int
    fits: bool
    complete: bool


def estimate(
    points: Any,
    spec: Spec,
    *,
    triangles: Any = None,
    scale: Optional[Frame] = None,
    offset: Optional[Frame] = None,
    cell_size: Optional[float] = None,
    cells: Optional[int] = None,
    min_cell_size: Optional[float] = None,
    max_level: Optional[int] = None,
    shell: Optional[bool] = None,
    inside: Optional[str] = None,
    interior_stiffness: Optional[float] = None,
    solver: Optional[str] = None,
    subdomains: Optional[int] = None,
    tolerance: Optional[float] = None,
    coarse_levels: Optional[int] = None,
    loose_parts: Optional[str] = None,
    refine_strain: Optional[float] = None,
    transfer: Optional[str] = None,
    rbf_tolerance: Optional[float] = None,
    check_gcp: Optional[bool] = None,
    memory_limit: Union[int, str, None] = None,
) -> Estimate:
    """What ``deform`` (or ``solve``) of ``points`` under ``spec`` with these options will
    take, without solving: the cells are built and the spec resolved on them (cells that
    cannot fit the budget are only forecast, in about the time their occupied cells take to
    find), and the solve is counted, not run. Returns an ``Estimate`` (``fits``: whether it
    fits ``memory_limit``). A budget too small even to find the occupied cells, or to hold the
    ``cells`` asked for, raises the ``ValueError`` ``deform`` would, naming what to change."""
    options = _picked(locals())
    p = _Points(points, scale, offset)
    text, base, paths = _spec(spec)
    tris = p.triangles if triangles is None else _triangles(triangles)
    info = _call(paths, _rigidcells.estimate, p.xyz, text, base, tris, options, p.classes)
    return Estimate(**info)


def deform_file(
    input: Union[str, "os.PathLike[str]"],
    output: Union[str, "os.PathLike[str]"],
    spec: Spec,
    *,
    save_field: Union[str, "os.PathLike[str]", None] = None,
    report: Union[str, "os.PathLike[str]", None] = None,
    preview: Union[str, "os.PathLike[str]", None] = None,
    strain: Optional[bool] = None,
    azimuth: Optional[float] = None,
    elevation: Optional[float] = None,
    size: Optional[Tuple[int, int]] = None,
    up: Optional[str] = None,
    zoom: Optional[float] = None,
    chunk: Optional[int] = None,
    cell_size: Optional[float] = None,
    cells: Optional[int] = None,
    min_cell_size: Optional[float] = None,
    max_level: Optional[int] = None,
    shell: Optional[bool] = None,
    inside: Optional[str] = None,
    interior_stiffness: Optional[float] = None,
    solver: Optional[str] = None,
    subdomains: Optional[int] = None,
    tolerance: Optional[float] = None,
    coarse_levels: Optional[int] = None,
    loose_parts: Optional[str] = None,
    refine_strain: Optional[float] = None,
    transfer: Optional[str] = None,
    rbf_tolerance: Optional[float] = None,
    check_gcp: Optional[bool] = None,
    memory_limit: Union[int, str, None] = None,
    progress: Any = None,
) -> Report:
    """``rigidcells deform INPUT -o OUTPUT --edit SPEC``: streams the file, writes the output
    atomically; returns a ``Report`` (its residuals measured on the preview proxy, as the
    command line's report measures them). Beside the output, all together or none:
    ``save_field`` (the field, for ``apply_file``), ``report`` (the command line's JSON
    report), ``preview`` (a PNG of the input and the output side by side, with the strained
    cells beside them with ``strain=True``, seen from ``azimuth``, ``elevation`` in degrees,
    ``size`` (width, height) in pixels, ``up`` ``"x"``, ``"y"`` or ``"z"``, ``zoom``).
    ``chunk``: samples per streamed chunk (the bytes written are the same). Stopped (Ctrl-C,
    or ``progress`` raising), it leaves no output behind."""
    options = _picked(locals())
    text, base, paths = _spec(spec)
    path = lambda p: None if p is None else os.fspath(p)
    view = _options(
        strain=strain, azimuth=azimuth, elevation=elevation, size=size, up=up, zoom=zoom
    )
    if view and preview is None:
        raise ValueError(f"{next(iter(view))} applies to the preview: pass preview= too")
    info = _with_progress(
        progress, lambda cb: _call(
            paths, _rigidcells.deform_file, os.fspath(input), os.fspath(output), text, base,
            path(save_field), path(report), path(preview), view, chunk, options, cb,
        )
    )
    report = Report._of(info, paths=paths)
    _warn(report.warnings)
    return report


def apply_file(
    field: Union[str, "os.PathLike[str]"],
    input: Union[str, "os.PathLike[str]"],
    output: Union[str, "os.PathLike[str]"],
    *,
    outside: str = "refuse",
    transfer: Optional[str] = None,
    rbf_tolerance: Optional[float] = None,
    memory_limit: Union[int, str, None] = None,
    chunk: Optional[int] = None,
    progress: Any = None,
    same_crs: bool = False,
) -> dict:
    """``rigidcells apply FIELD INPUT -o OUTPUT``: the same bytes as the command line.
    ``outside``: ``"refuse"`` (samples beyond the field's margin are an error), ``"keep"`` or
    ``"extend"``; ``transfer`` (default: the one the field was solved for), ``rbf_tolerance``,
    ``memory_limit`` and ``chunk`` as for ``deform_file``. A field solved in another coordinate
    system than the input declares is a ``ValueError`` unless ``same_crs`` (``--same-crs``).
    Returns ``samples``, ``notes``, ``warnings`` and ``seconds``."""
    info = _with_progress(
        progress, lambda cb: _rigidcells.apply_file(
            os.fspath(field), os.fspath(input), os.fspath(output), outside, transfer,
            rbf_tolerance, memory_limit, chunk, cb, same_crs,
        )
    )
    _warn(info["warnings"])
    return info


def solve_files(
    inputs: Sequence[Union[str, "os.PathLike[str]"]],
    spec: Spec,
    save_field: Union[str, "os.PathLike[str]"],
    *,
    report: Union[str, "os.PathLike[str]", None] = None,
    preview: Union[str, "os.PathLike[str]", None] = None,
    strain: Optional[bool] = None,
    azimuth: Optional[float] = None,
    elevation: Optional[float] = None,
    size: Optional[Tuple[int, int]] = None,
    up: Optional[str] = None,
    zoom: Optional[float] = None,
    chunk: Optional[int] = None,
    cell_size: Optional[float] = None,
    cells: Optional[int] = None,
    min_cell_size: Optional[float] = None,
    max_level: Optional[int] = None,
    shell: Optional[bool] = None,
    inside: Optional[str] = None,
    interior_stiffness: Optional[float] = None,
    solver: Optional[str] = None,
    subdomains: Optional[int] = None,
    tolerance: Optional[float] = None,
    coarse_levels: Optional[int] = None,
    loose_parts: Optional[str] = None,
    transfer: Optional[str] = None,
    check_gcp: Optional[bool] = None,
    memory_limit: Union[int, str, None] = None,
    progress: Any = None,
    same_crs: bool = False,
) -> Report:
    """``rigidcells solve INPUTS --edit SPEC --save-field FIELD``: the field of the edit over
    several files taken as one (the tiles of a scan), streamed, written to ``save_field``;
    ``apply_file`` of it to each tile gives what ``deform_file`` gives on the merged file,
    record for record. Beside the field, all together or none, as for ``deform_file``:
    ``report`` (the JSON report) and ``preview`` (a PNG of a proxy across all tiles before and
    after, with ``strain`` and the view's ``azimuth``, ``elevation``, ``size``, ``up``,
    ``zoom``); ``check_gcp`` runs the control points' leave-one-out check. Tiles that declare
    different coordinate systems are a ``ValueError`` unless ``same_crs`` (``--same-crs``).
    Returns a ``Report`` of the solve: what ``deform_file`` returns for the merged file."""
    return _solve_files(locals(), None)


def _solve_files(arguments: dict, workers: Any) -> Report:
    """``solve_files`` with its ``arguments`` (its ``locals()``), the subdomains' blocks given
    to ``workers`` where not None (``rigidcells.dask.solve_tiles``)."""
    options = _picked(arguments)
    text, base, paths = _spec(arguments["spec"])
    inputs = arguments["inputs"]
    one = isinstance(inputs, (str, bytes, os.PathLike))
    files = [os.fspath(inputs)] if one else [os.fspath(p) for p in inputs]
    path = lambda p: None if p is None else os.fspath(p)
    view = _options(
        **{k: arguments[k] for k in ("strain", "azimuth", "elevation", "size", "up", "zoom")}
    )
    preview = arguments["preview"]
    if view and preview is None:
        raise ValueError(f"{next(iter(view))} applies to the preview: pass preview= too")
    info = _with_progress(
        arguments["progress"], lambda cb: _call(
            paths, _rigidcells.solve_files, files, os.fspath(arguments["save_field"]), text,
            base, path(arguments["report"]), path(preview), view, arguments["chunk"], options,
            cb, arguments["same_crs"], workers,
        )
    )
    report = Report._of(info, paths=paths)
    _warn(report.warnings)
    return report


for _f in (deform, solve, deform_file):
    _f.__doc__ = (_f.__doc__ or "") + _OPTIONS_DOC
