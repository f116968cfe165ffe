"""The Blender add-on in a real Blender (the `bpy` module, headless): it registers and
unregisters cleanly, its shape key is `rigidcells.deform` of the same vertices, a soup of loose
cubes bends with every cube carried, and bad input leaves the mesh as it was."""

import math
import sys
from pathlib import Path

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")
import rigidcells  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "blender"))
import rigidcells_blender as addon  # noqa: E402


@pytest.fixture(autouse=True)
def registered():
    bpy.ops.wm.read_factory_settings(use_empty=True)
    addon.register()
    yield
    addon.unregister()


def grid_bar(nx=41, ny=5, nz=5, length=10.0):
    """A bar of vertices, `length` × 1 × 1, with faces on its outside (a closed box mesh)."""
    bpy.ops.mesh.primitive_cube_add(size=1.0)
    obj = bpy.context.active_object
    obj.scale = (length, 1.0, 1.0)
    bpy.ops.object.transform_apply(scale=True)
    bpy.ops.object.mode_set(mode="EDIT")
    bpy.ops.mesh.subdivide(number_cuts=8)
    bpy.ops.object.mode_set(mode="OBJECT")
    return obj


def group(obj, name, select):
    """The vertex group `name` of the vertices `select(co)` holds for."""
    g = obj.vertex_groups.new(name=name)
    g.add([v.index for v in obj.data.vertices if select(v.co)], 1.0, "REPLACE")
    return g


def handle_empty(obj, at=(5.0, 0.0, 0.0)):
    bpy.ops.object.empty_add(location=at)
    empty = bpy.context.active_object
    bpy.context.view_layer.objects.active = obj
    return empty


def setup_bar():
    obj = grid_bar()
    group(obj, "fixed", lambda co: co.x < -4.4)
    group(obj, "handle", lambda co: co.x > 4.4)
    empty = handle_empty(obj)
    s = obj.rigidcells
    s.fixed_group, s.handle_group = "fixed", "handle"
    s.handle_object = empty  # its rest pose is taken now
    s.cell_size = 0.25
    # Turned 60° about y and lifted.
    empty.rotation_euler = (0.0, math.radians(-60.0), 0.0)
    empty.location = (4.0, 0.0, 3.0)
    bpy.context.view_layer.update()
    return obj, empty


def vertices(obj, key=None):
    data = obj.data.vertices if key is None else obj.data.shape_keys.key_blocks[key].data
    co = np.empty(3 * len(data), dtype=np.float32)
    data.foreach_get("co", co)
    return co.reshape(-1, 3)


def test_registers_and_unregisters_cleanly():
    assert hasattr(bpy.types.Object, "rigidcells")
    assert hasattr(bpy.ops.object, "rigidcells_deform")
    addon.unregister()
    assert not hasattr(bpy.types.Object, "rigidcells")
    addon.register()


def test_the_shape_key_is_the_librarys_deformation():
    obj, empty = setup_bar()
    rest = vertices(obj)
    assert bpy.ops.object.rigidcells_deform() == {"FINISHED"}
    got = vertices(obj, "RigidCells")
    points, triangles, spec = addon.inputs(obj)
    want, report = rigidcells.deform(points, spec, triangles=triangles, cell_size=0.25, progress=False)
    assert np.abs(got - want).max() < 1e-6
    # Fixed vertices keep their coordinates bit for bit; handle vertices follow the Empty.
    fixed = [v.index for v in obj.data.vertices if v.co.x < -4.4]
    assert np.array_equal(got[fixed], rest[fixed])
    m = np.array(empty.matrix_world) @ np.linalg.inv(np.array(obj.rigidcells.handle_rest).reshape(4, 4))
    handle = [v.index for v in obj.data.vertices if v.co.x > 4.4]
    sent = (np.c_[rest[handle], np.ones(len(handle))] @ m.T)[:, :3]
    assert np.abs(got[handle] - sent).max() < 1e-5
    assert obj.rigidcells.cells == report.cells and obj.rigidcells.iterations > 0
    # Again: the key is replaced, not stacked.
    assert bpy.ops.object.rigidcells_deform() == {"FINISHED"}
    assert [k.name for k in obj.data.shape_keys.key_blocks] == ["Basis", "RigidCells"]
    assert np.abs(vertices(obj, "RigidCells") - got).max() < 1e-6


def test_a_soup_of_loose_cubes_bends_with_every_cube_carried():
    import bmesh

    mesh = bpy.data.meshes.new("soup")
    bm = bmesh.new()
    for k in range(10):
        bmesh.ops.create_cube(bm, size=0.8, matrix=__import__("mathutils").Matrix.Translation((k - 4.5, 0, 0)))
    bm.to_mesh(mesh)
    obj = bpy.data.objects.new("soup", mesh)
    bpy.context.collection.objects.link(obj)
    bpy.context.view_layer.objects.active = obj
    group(obj, "fixed", lambda co: co.x < -4.0)
    group(obj, "handle", lambda co: co.x > 4.0)
    empty = handle_empty(obj, at=(4.5, 0, 0))
    s = obj.rigidcells
    s.fixed_group, s.handle_group, s.handle_object = "fixed", "handle", empty
    empty.location = (4.5, 0.0, 4.0)
    bpy.context.view_layer.update()
    assert bpy.ops.object.rigidcells_deform() == {"FINISHED"}
    rest, bent = vertices(obj), vertices(obj, "RigidCells")
    # Every cube rises along the bend, none left behind.
    lift = []
    for k in range(10):
        part = slice(8 * k, 8 * k + 8)
        a, b = rest[part], bent[part]
        da = np.linalg.norm(a[:, None] - a[None], axis=-1)
        db = np.linalg.norm(b[:, None] - b[None], axis=-1)
        # Each cube keeps its shape as the bend allows (the cells glue the cubes, 0.2 apart,
        # so a cube bends with the row: 0.1–0.28 of its 0.8 in the two beside the ends).
        assert np.abs(da - db).max() < 0.4 * 0.8, k
        lift.append((b - a)[:, 2].mean())
    assert lift[0] == 0.0 and abs(lift[-1] - 4.0) < 1e-5
    assert all(x <= y + 1e-6 for x, y in zip(lift, lift[1:])), lift


@pytest.mark.parametrize(
    "breaks, says",
    [
        (lambda o, e: setattr(o.rigidcells, "fixed_group", ""), "name the fixed vertex group"),
        (lambda o, e: setattr(o.rigidcells, "handle_group", "nope"), "no vertex group 'nope'"),
        (lambda o, e: o.vertex_groups.new(name="empty") and setattr(o.rigidcells, "fixed_group", "empty"), "holds no vertex"),
        (lambda o, e: setattr(o.rigidcells, "handle_object", None), "choose the handle Empty"),
        (lambda o, e: setattr(o.rigidcells, "cell_size", 1e-5), "memory"),
    ],
)
def test_bad_input_refuses_and_leaves_the_mesh_as_it_was(breaks, says):
    obj, empty = setup_bar()
    before = vertices(obj)
    breaks(obj, empty)
    with pytest.raises(RuntimeError, match=says):
        bpy.ops.object.rigidcells_deform()
    assert obj.data.shape_keys is None
    assert np.array_equal(vertices(obj), before)
