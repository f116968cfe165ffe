import os
from typing import Any, Optional, Tuple, Union

import numpy as np

Spec = Union[str, os.PathLike[str], dict]
PathLike = Union[str, os.PathLike[str]]

class FormatError(ValueError):
    """A malformed or unreadable input file."""

class Field:
    """A solved field: apply it to samples, save it for `rigidcells apply`, load one."""

    @property
    def cells(self) -> int: ...
    def apply(self, points: np.ndarray) -> np.ndarray: ...
    def save(self, path: PathLike) -> None: ...
    @staticmethod
    def load(path: PathLike) -> "Field": ...

def deform(
    points: Any,
    spec: Spec,
    *,
    triangles: Any = ...,
    normals: Any = ...,
    cell_size: Optional[float] = ...,
    cells: Optional[int] = ...,
    transfer: Optional[str] = ...,
) -> Tuple[np.ndarray, dict]: ...
def solve(
    points: Any,
    spec: Spec,
    *,
    triangles: Any = ...,
    cell_size: Optional[float] = ...,
    cells: Optional[int] = ...,
    transfer: Optional[str] = ...,
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
