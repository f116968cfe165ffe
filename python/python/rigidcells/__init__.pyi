import os
from typing import Any, Optional, Sequence, Tuple, Union, overload

import numpy as np

Spec = Union[str, os.PathLike[str], dict]
PathLike = Union[str, os.PathLike[str]]
# A LAS frame's scale or offset: one number for all axes, or (x, y, z).
Frame = Union[float, Sequence[float], np.ndarray]

class FormatError(ValueError):
    """A malformed or unreadable input file."""

class Field:
    """A solved field (`solve`): apply it to points, save it for `rigidcells apply`, load one."""

    @property
    def cells(self) -> int: ...
    # Points come back in the form they came in: an (n, 3) float array as float64, a numpy
    # structured array with its dtype, a laspy LasData or point record as a new one.
    @overload
    def apply(
        self, points: np.ndarray, *, scale: Optional[Frame] = ..., offset: Optional[Frame] = ...
    ) -> np.ndarray: ...
    @overload
    def apply(
        self, points: Any, *, scale: Optional[Frame] = ..., offset: Optional[Frame] = ...
    ) -> Any: ...
    def save(self, path: PathLike) -> None: ...
    @staticmethod
    def load(path: PathLike) -> "Field": ...

@overload
def deform(
    points: np.ndarray,
    spec: Spec,
    *,
    triangles: Any = ...,
    normals: Any = ...,
    cell_size: Optional[float] = ...,
    cells: Optional[int] = ...,
    transfer: Optional[str] = ...,
    scale: Optional[Frame] = ...,
    offset: Optional[Frame] = ...,
) -> Tuple[np.ndarray, dict]: ...
@overload
def deform(
    points: Any,
    spec: Spec,
    *,
    triangles: Any = ...,
    normals: Any = ...,
    cell_size: Optional[float] = ...,
    cells: Optional[int] = ...,
    transfer: Optional[str] = ...,
    scale: Optional[Frame] = ...,
    offset: Optional[Frame] = ...,
) -> Tuple[Any, dict]: ...
def solve(
    points: Any,
    spec: Spec,
    *,
    triangles: Any = ...,
    cell_size: Optional[float] = ...,
    cells: Optional[int] = ...,
    transfer: Optional[str] = ...,
    scale: Optional[Frame] = ...,
    offset: Optional[Frame] = ...,
) -> Field: ...
def deform_file(
    input: PathLike,
    output: PathLike,
    spec: Spec,
    *,
    save_field: Optional[PathLike] = ...,
    cell_size: Optional[float] = ...,
    cells: Optional[int] = ...,
    transfer: Optional[str] = ...,
) -> dict: ...
def apply_file(
    field: PathLike, input: PathLike, output: PathLike, *, outside: str = ...
) -> dict: ...
