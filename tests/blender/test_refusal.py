"""The add-on's words for a turn the library refuses: the handle as its panel names it ("the
handle Empty", "handle 2"), not by the spec the add-on wrote for the library."""

import sys
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("bpy")
import rigidcells  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "blender"))
import rigidcells_blender as addon  # noqa: E402


def test_a_refused_turn_names_the_handle_as_the_panel_does():
    g = np.linspace(0.0, 1.0, 11)
    cube = np.ascontiguousarray(np.stack(np.meshgrid(g, g, g, indexing="ij"), axis=-1).reshape(-1, 3))
    twist = {"box": {"min": [-1, -1, 0.9], "max": [2, 2, 2]}, "rotate": {"axis": [0, 0, 1], "degrees": 360}}
    still = {"box": {"min": [-1, -1, 0.45], "max": [2, 2, 0.55]}, "translate": [0, 0, 0]}
    for handles, name in (([twist], "the handle Empty"), ([still, twist], "handle 2")):
        spec = {"fixed": [{"box": {"min": [-1, -1, -1], "max": [2, 2, 0.1]}}], "handle": handles}
        with pytest.raises(rigidcells.TurnNotHeldError) as raised:
            rigidcells.deform(cube, spec, cell_size=0.1, progress=False)
        said = addon._said(raised.value)
        assert said.startswith(f"Rigid Cells: {name} twists by 360°, but the shape"), said
        assert "spec" not in said.split(", but")[0] and "line" not in said, said
    assert addon._said(ValueError("Rigid Cells: choose the handle Empty")) == "Rigid Cells: choose the handle Empty"
