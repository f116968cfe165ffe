import os
from dataclasses import dataclass
from typing import Any, Callable, Dict, List, Literal, NamedTuple, Optional, Sequence, Tuple, Union, overload

import numpy as np

__version__: str

Spec = Union[str, os.PathLike[str], dict]
PathLike = Union[str, os.PathLike[str]]
# A LAS frame's scale or offset: one number for all axes, or (x, y, z).
Frame = Union[float, Sequence[float], np.ndarray]
Transfer = Literal["pu", "rbf", "blend", "blend-idw"]
Outside = Literal["refuse", "keep", "extend"]
# A callable (stage, done, total or None), True (a tqdm bar), False (none), or None (a tqdm
# bar where tqdm is installed and standard error is a terminal).
Progress = Union[Callable[[str, int, Optional[int]], Any], bool, None]

class FormatError(ValueError):
    """A malformed or unreadable input file."""

class TurnNotHeldError(ValueError):
    """A handle's turn that the shape gives way under: `handle` is its index in the spec's
    handles (`spec["handle"][handle]`), `line` its line in a TOML spec (None for a dict spec),
    `kind` "bend" or "twist", `said` the message after the handle's name."""

    handle: int
    line: Optional[int]
    kind: Literal["bend", "twist"]
    asked_degrees: float
    held_degrees: float
    other_way_degrees: Optional[float]
    said: str

class RigidCellsWarning(UserWarning):
    """A warning of a deformation (also in `report.warnings`), or a note of `Field.apply`."""

@dataclass
class Report:
    """What a deformation did: the library's report (`deform --report`), the same keys."""

    input: str
    inputs: List[str]
    output: str
    points: int
    cells: int
    cells_initial: int
    cell_size: float
    cell_levels: Dict[int, int]
    cell_roles: Dict[str, int]
    iterations: int
    load_steps: int
    load_step_halvings: int
    handle_turns: List[dict]
    linear_solver: str
    linear_iterations: int
    levels: int
    energy: List[float]
    converged: bool
    iteration_log: List[dict]
    residual_max: float
    residual_fixed_max: float
    residual_handle_max: float
    residual_samples: int
    target_residual_max: float
    foldovers: int
    foldovers_checked: int
    timings_s: dict
    peak_memory_bytes: Optional[int]
    estimate: Optional[dict]
    warnings: List[str]
    notes: List[str]
    control_points: List[dict]
    control_rounding: Optional[str]
    control_rmse: Optional[float]
    control_rmse_left_out: Optional[float]
    control_trend: Optional[str]
    checkpoints: Optional[dict]
    options: Dict[str, Any]
    normals: Optional[np.ndarray] = ...
    def __getitem__(self, key: str) -> Any: ...
    def __contains__(self, key: object) -> bool: ...
    def keys(self) -> List[str]: ...

class Field:
    """A solved field (`solve`): apply it to points, save it for `rigidcells apply`, load one;
    it pickles."""

    report: Optional[Report]
    @property
    def cells(self) -> int: ...
    @property
    def cell_size(self) -> float: ...
    @property
    def transfer(self) -> str: ...
    @property
    def levels(self) -> List[Tuple[float, int]]: ...
    @property
    def bounds(self) -> Tuple[Tuple[float, float, float], Tuple[float, float, float]]: ...
    # Points come back in the form they came in: an (n, 3) float array as its float type, a numpy
    # structured array with its dtype, a laspy LasData or point record as a new one; with
    # normals, (points, turned normals).
    @overload
    def apply(
        self,
        points: np.ndarray,
        *,
        normals: None = ...,
        outside: Outside = ...,
        scale: Optional[Frame] = ...,
        offset: Optional[Frame] = ...,
    ) -> np.ndarray: ...
    @overload
    def apply(
        self,
        points: Any,
        *,
        normals: Any = ...,
        outside: Outside = ...,
        scale: Optional[Frame] = ...,
        offset: Optional[Frame] = ...,
    ) -> Any: ...
    def save(self, path: PathLike) -> None: ...
    @staticmethod
    def load(path: PathLike) -> "Field": ...

@dataclass
class Step:
    """What a step of a `Session` did."""

    iterations: int
    converged: bool
    from_rest: bool
    seconds: float
    warnings: List[str]

class Session:
    """A live deformation: the cells built once, the spec solved; drag the handles a short
    solver step a pose, preview the blend, release through the transfer."""

    last: Step
    def __init__(
        self,
        points: Any,
        spec: Spec,
        *,
        triangles: Any = ...,
        normals: Any = ...,
        scale: Optional[Frame] = ...,
        offset: Optional[Frame] = ...,
        cell_size: Optional[float] = ...,
        cells: Optional[int] = ...,
        min_cell_size: Optional[float] = ...,
        max_level: Optional[int] = ...,
        shell: Optional[bool] = ...,
        inside: Optional[Literal["auto", "winding", "flood", "none"]] = ...,
        interior_stiffness: Optional[float] = ...,
        solver: Optional[Literal["auto", "direct", "multilevel", "local-global"]] = ...,
        subdomains: Optional[int] = ...,
        tolerance: Optional[float] = ...,
        coarse_levels: Optional[int] = ...,
        loose_parts: Optional[Literal["carry", "rest"]] = ...,
        refine_strain: Optional[float] = ...,
        transfer: Optional[Transfer] = ...,
        rbf_tolerance: Optional[float] = ...,
        check_gcp: Optional[bool] = ...,
        memory_limit: Union[int, str, None] = ...,
        progress: Progress = ...,
    ) -> None: ...
    def solve(
        self, spec: Spec, iterations: Optional[int] = ..., progress: Progress = ...
    ) -> Step: ...
    def drag(
        self, poses: Union[dict, Sequence[dict]], iterations: int = ..., pins: Any = ...
    ) -> Step: ...
    def refine(self) -> bool: ...
    @property
    def converged(self) -> bool: ...
    @property
    def cells(self) -> int: ...
    @property
    def cell_size(self) -> float: ...
    def preview(self) -> np.ndarray: ...
    def release(self, progress: Progress = ...) -> Tuple[Any, Report]: ...

@overload
def deform(
    points: np.ndarray,
    spec: Spec,
    *,
    triangles: Any = ...,
    normals: Any = ...,
    scale: Optional[Frame] = ...,
    offset: Optional[Frame] = ...,
    cell_size: Optional[float] = ...,
    cells: Optional[int] = ...,
    min_cell_size: Optional[float] = ...,
    max_level: Optional[int] = ...,
    shell: Optional[bool] = ...,
    inside: Optional[Literal["auto", "winding", "flood", "none"]] = ...,
    interior_stiffness: Optional[float] = ...,
    solver: Optional[Literal["auto", "direct", "multilevel", "local-global"]] = ...,
    subdomains: Optional[int] = ...,
    tolerance: Optional[float] = ...,
    coarse_levels: Optional[int] = ...,
    loose_parts: Optional[Literal["carry", "rest"]] = ...,
    refine_strain: Optional[float] = ...,
    transfer: Optional[Transfer] = ...,
    rbf_tolerance: Optional[float] = ...,
    check_gcp: Optional[bool] = ...,
    memory_limit: Union[int, str, None] = ...,
    progress: Progress = ...,
) -> Tuple[np.ndarray, Report]: ...
@overload
def deform(
    points: Any,
    spec: Spec,
    *,
    triangles: Any = ...,
    normals: Any = ...,
    scale: Optional[Frame] = ...,
    offset: Optional[Frame] = ...,
    cell_size: Optional[float] = ...,
    cells: Optional[int] = ...,
    min_cell_size: Optional[float] = ...,
    max_level: Optional[int] = ...,
    shell: Optional[bool] = ...,
    inside: Optional[Literal["auto", "winding", "flood", "none"]] = ...,
    interior_stiffness: Optional[float] = ...,
    solver: Optional[Literal["auto", "direct", "multilevel", "local-global"]] = ...,
    subdomains: Optional[int] = ...,
    tolerance: Optional[float] = ...,
    coarse_levels: Optional[int] = ...,
    loose_parts: Optional[Literal["carry", "rest"]] = ...,
    refine_strain: Optional[float] = ...,
    transfer: Optional[Transfer] = ...,
    rbf_tolerance: Optional[float] = ...,
    check_gcp: Optional[bool] = ...,
    memory_limit: Union[int, str, None] = ...,
    progress: Progress = ...,
) -> Tuple[Any, Report]: ...
def solve(
    points: Any,
    spec: Spec,
    *,
    triangles: Any = ...,
    scale: Optional[Frame] = ...,
    offset: Optional[Frame] = ...,
    cell_size: Optional[float] = ...,
    cells: Optional[int] = ...,
    min_cell_size: Optional[float] = ...,
    max_level: Optional[int] = ...,
    shell: Optional[bool] = ...,
    inside: Optional[Literal["auto", "winding", "flood", "none"]] = ...,
    interior_stiffness: Optional[float] = ...,
    solver: Optional[Literal["auto", "direct", "multilevel", "local-global"]] = ...,
    subdomains: Optional[int] = ...,
    tolerance: Optional[float] = ...,
    coarse_levels: Optional[int] = ...,
    loose_parts: Optional[Literal["carry", "rest"]] = ...,
    refine_strain: Optional[float] = ...,
    transfer: Optional[Transfer] = ...,
    rbf_tolerance: Optional[float] = ...,
    check_gcp: Optional[bool] = ...,
    memory_limit: Union[int, str, None] = ...,
    progress: Progress = ...,
) -> Field: ...
class Estimate(NamedTuple):
    """What a deformation will take, estimated without solving it."""

    cells: int
    bytes: int
    seconds: float
    solve_seconds: float
    solver: Literal["direct", "multilevel", "local-global"]
    limit: int
    fits: bool
    complete: bool

def estimate(
    points: Any,
    spec: Spec,
    *,
    triangles: Any = ...,
    scale: Optional[Frame] = ...,
    offset: Optional[Frame] = ...,
    cell_size: Optional[float] = ...,
    cells: Optional[int] = ...,
    min_cell_size: Optional[float] = ...,
    max_level: Optional[int] = ...,
    shell: Optional[bool] = ...,
    inside: Optional[Literal["auto", "winding", "flood", "none"]] = ...,
    interior_stiffness: Optional[float] = ...,
    solver: Optional[Literal["auto", "direct", "multilevel", "local-global"]] = ...,
    subdomains: Optional[int] = ...,
    tolerance: Optional[float] = ...,
    coarse_levels: Optional[int] = ...,
    loose_parts: Optional[Literal["carry", "rest"]] = ...,
    refine_strain: Optional[float] = ...,
    transfer: Optional[Transfer] = ...,
    rbf_tolerance: Optional[float] = ...,
    check_gcp: Optional[bool] = ...,
    memory_limit: Union[int, str, None] = ...,
) -> Estimate: ...
def deform_file(
    input: PathLike,
    output: PathLike,
    spec: Spec,
    *,
    save_field: Optional[PathLike] = ...,
    report: Optional[PathLike] = ...,
    preview: Optional[PathLike] = ...,
    strain: Optional[bool] = ...,
    azimuth: Optional[float] = ...,
    elevation: Optional[float] = ...,
    size: Optional[Tuple[int, int]] = ...,
    up: Optional[Literal["x", "y", "z"]] = ...,
    zoom: Optional[float] = ...,
    chunk: Optional[int] = ...,
    cell_size: Optional[float] = ...,
    cells: Optional[int] = ...,
    min_cell_size: Optional[float] = ...,
    max_level: Optional[int] = ...,
    shell: Optional[bool] = ...,
    inside: Optional[Literal["auto", "winding", "flood", "none"]] = ...,
    interior_stiffness: Optional[float] = ...,
    solver: Optional[Literal["auto", "direct", "multilevel", "local-global"]] = ...,
    subdomains: Optional[int] = ...,
    tolerance: Optional[float] = ...,
    coarse_levels: Optional[int] = ...,
    loose_parts: Optional[Literal["carry", "rest"]] = ...,
    refine_strain: Optional[float] = ...,
    transfer: Optional[Transfer] = ...,
    rbf_tolerance: Optional[float] = ...,
    check_gcp: Optional[bool] = ...,
    memory_limit: Union[int, str, None] = ...,
    progress: Progress = ...,
) -> Report: ...
def apply_file(
    field: PathLike,
    input: PathLike,
    output: PathLike,
    *,
    outside: Outside = ...,
    transfer: Optional[Transfer] = ...,
    rbf_tolerance: Optional[float] = ...,
    memory_limit: Union[int, str, None] = ...,
    chunk: Optional[int] = ...,
    progress: Progress = ...,
) -> dict: ...
def solve_files(
    inputs: Sequence[PathLike],
    spec: Spec,
    save_field: PathLike,
    *,
    chunk: Optional[int] = ...,
    cell_size: Optional[float] = ...,
    cells: Optional[int] = ...,
    min_cell_size: Optional[float] = ...,
    max_level: Optional[int] = ...,
    shell: Optional[bool] = ...,
    inside: Optional[Literal["auto", "winding", "flood", "none"]] = ...,
    interior_stiffness: Optional[float] = ...,
    solver: Optional[Literal["auto", "direct", "multilevel", "local-global"]] = ...,
    subdomains: Optional[int] = ...,
    tolerance: Optional[float] = ...,
    coarse_levels: Optional[int] = ...,
    loose_parts: Optional[Literal["carry", "rest"]] = ...,
    transfer: Optional[Transfer] = ...,
    memory_limit: Union[int, str, None] = ...,
    progress: Progress = ...,
) -> Report: ...
