"""The Blender add-on in a real Blender (the `bpy` module, headless): it registers and
unregisters cleanly, its shape key is `rigidcells.deform` of the same vertices, a soup of loose
cubes bends with every cube carried, bad input leaves the mesh as it was, Deform runs off the
main thread, Live follows scripted Empty moves to the converged shape and Esc restores the
shape key, more handles, pins and a stiffness group reach the library, a handle turns as
its Empty's rotation was typed, whole turns included, in every rotation mode and as keyed,
the Edit Mode selection makes groups, vertex weights pull part of the way, several objects
deform as one scene, fold-overs are a vertex group, Follow keys each pose and bakes frames,
and the library's messages name the panel's settings and groups.

Blender without a window runs no modal operators: the tests drive the pieces the modal
operators call on each timer tick and key press (`DeformJob`, `LiveState`);
`modal_check.py` runs the operators themselves in Blender's window."""

import math
import time
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


def grid_bar(nx=41, ny=5, nz=5, length=10.0, cuts=8):
    """A bar of vertices, `length` × 1 × 1, with faces on its outside (a closed box mesh),
    each face cut `cuts` times along each side."""
    bpy.ops.mesh.primitive_cube_add(size=1.0)
    obj = bpy.context.active_object
    obj.scale = (length, 1.0, 1.0)
    bpy.ops.object.transform_apply(scale=True)
    bpy.ops.object.mode_set(mode="EDIT")
    bpy.ops.mesh.subdivide(number_cuts=cuts)
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
    assert obj.rigidcells.run_cells == report.cells and obj.rigidcells.iterations > 0
    # Again: the key is replaced, not stacked.
    assert bpy.ops.object.rigidcells_deform() == {"FINISHED"}
    assert [k.name for k in obj.data.shape_keys.key_blocks] == ["Basis", "RigidCells"]
    assert np.abs(vertices(obj, "RigidCells") - got).max() < 1e-6


def test_the_panels_interior_stiffness_is_the_packages():
    """The panel's inside starts at the package's default (0.05), and a solid inside set on the
    panel gives the package's deformation with the same keyword, and another shape than the
    default's: the closed bar has cells inside at 0.25."""
    obj, empty = setup_bar()
    assert addon.options(obj.rigidcells)["interior_stiffness"] == 0.05
    assert bpy.ops.object.rigidcells_deform() == {"FINISHED"}
    soft = vertices(obj, "RigidCells")
    obj.rigidcells.interior_stiffness = 1.0
    assert addon.options(obj.rigidcells)["interior_stiffness"] == 1.0
    assert bpy.ops.object.rigidcells_deform() == {"FINISHED"}
    got = vertices(obj, "RigidCells")
    points, triangles, spec = addon.inputs(obj)
    want, _ = rigidcells.deform(
        points, spec, triangles=triangles, cell_size=0.25, interior_stiffness=1.0, progress=False
    )
    assert np.abs(got - want).max() < 1e-6
    assert np.abs(got - soft).max() > 1e-4


def test_deform_in_edit_mode_keeps_its_key_and_returns_to_edit_mode():
    """Run from Edit Mode, Deform writes its key out of it (Edit Mode would write its own copy of
    the mesh back over the key when it ends) and enters it again; after Tab the key is still the
    deformation, not the Basis."""
    obj, empty = setup_bar()
    bpy.context.view_layer.objects.active = obj
    bpy.ops.object.mode_set(mode="EDIT")
    assert bpy.ops.object.rigidcells_deform() == {"FINISHED"}
    assert obj.mode == "EDIT"
    bpy.ops.object.mode_set(mode="OBJECT")
    key, rest = vertices(obj, "RigidCells"), vertices(obj)
    points, triangles, spec = addon.inputs(obj)
    want, _ = rigidcells.deform(points, spec, triangles=triangles, cell_size=0.25, progress=False)
    assert np.abs(key - want).max() < 1e-6
    assert np.abs(key - rest).max() > 1.0


def select_vertices(obj, keep):
    """Selects the vertices of `obj` that `keep(co)` holds for (and the edges and faces all of
    whose vertices are), as a box selection in Edit Mode would; in Object Mode."""
    mesh = obj.data
    for v in mesh.vertices:
        v.select = keep(v.co)
    for e in mesh.edges:
        e.select = all(mesh.vertices[i].select for i in e.vertices)
    for f in mesh.polygons:
        f.select = all(mesh.vertices[i].select for i in f.vertices)


def test_the_edit_mode_selection_makes_the_groups_and_a_handle_empty():
    """In Edit Mode, "From selection" makes the selected vertices the add-on's group for the
    role and names it in the panel; a handle without an Empty gets one at their center; a
    second selection replaces the add-on's group, and the artist's own groups are left."""
    obj = grid_bar()
    s = obj.rigidcells
    s.cell_size = 0.25
    mine = group(obj, "mine", lambda co: co.x > 0)

    def select(keep):
        bpy.ops.object.mode_set(mode="OBJECT")
        select_vertices(obj, keep)
        bpy.ops.object.mode_set(mode="EDIT")

    def members(name):
        k = obj.vertex_groups[name].index
        return [v.index for v in obj.data.vertices if any(g.group == k for g in v.groups)]

    select(lambda co: False)
    with pytest.raises(RuntimeError, match="select the vertices in Edit Mode first"):
        bpy.ops.rigidcells.from_selection(role="fixed")
    with pytest.raises(RuntimeError, match=r"there is no pin 1: add it with \+ Pin first"):
        bpy.ops.rigidcells.from_selection(role="pins", index=0)
    select(lambda co: co.x < -4.4)
    assert bpy.ops.rigidcells.from_selection(role="fixed") == {"FINISHED"}
    select(lambda co: co.x > 4.4)
    assert bpy.ops.rigidcells.from_selection(role="handle") == {"FINISHED"}
    assert obj.mode == "EDIT"
    assert (s.fixed_group, s.handle_group) == ("RigidCells Fixed", "RigidCells Handle")
    empty = s.handle_object
    assert empty is not None and empty.type == "EMPTY"
    assert np.allclose(empty.location, (5.0, 0.0, 0.0), atol=1e-6)
    select(lambda co: co.x > 4.8)
    assert bpy.ops.rigidcells.from_selection(role="handle") == {"FINISHED"}
    assert s.handle_object == empty
    assert members("RigidCells Handle") == [v.index for v in obj.data.vertices if v.co.x > 4.8]
    assert len(members("mine")) == sum(1 for v in obj.data.vertices if v.co.x > 0)
    assert mine.name == "mine"

    bpy.ops.object.mode_set(mode="OBJECT")
    rest = vertices(obj)
    empty.location.z += 2.0
    bpy.context.view_layer.update()
    assert bpy.ops.object.rigidcells_deform() == {"FINISHED"}
    got = vertices(obj, "RigidCells")
    fixed = members("RigidCells Fixed")
    handle = members("RigidCells Handle")
    assert np.array_equal(got[fixed], rest[fixed])
    assert np.abs(got[handle] - (rest[handle] + [0.0, 0.0, 2.0])).max() < 1e-5


def weighted_bar(band_weight):
    """The bar with its right end in the handle group at weight 1 and a band across its
    middle (0 < x < 1) at `band_weight`; the Empty lifted by 2."""
    obj = grid_bar()
    group(obj, "fixed", lambda co: co.x < -4.4)
    g = group(obj, "handle", lambda co: co.x > 4.4)
    g.add([v.index for v in obj.data.vertices if 0.0 < v.co.x < 1.0], band_weight, "REPLACE")
    empty = handle_empty(obj)
    s = obj.rigidcells
    s.fixed_group, s.handle_group, s.handle_object, s.cell_size = "fixed", "handle", empty, 0.25
    empty.location.z += 2.0
    bpy.context.view_layer.update()
    return obj, empty


def test_vertex_weights_pull_part_of_the_way_as_a_hooks_do():
    """A handle group's vertex of weight w below 1 is pulled a fraction w of the way its Empty
    sends it (a soft target of the library), as a Hook's weight moves it; weight 1 follows the
    Empty exactly. 0.1 and 1.0 give different shapes, and Live and Follow pull the weighted
    vertices as Deform does."""
    rises = {}
    for w in (0.1, 0.9, 1.0):
        obj, empty = weighted_bar(w)
        rest = vertices(obj)
        assert bpy.ops.object.rigidcells_deform() == {"FINISHED"}, w
        got = vertices(obj, "RigidCells")
        band = [v.index for v in obj.data.vertices if 0.0 < v.co.x < 1.0]
        end = [v.index for v in obj.data.vertices if v.co.x > 4.4]
        fixed = [v.index for v in obj.data.vertices if v.co.x < -4.4]
        assert np.array_equal(got[fixed], rest[fixed]), w
        assert np.abs(got[end] - rest[end] - [0, 0, 2]).max() < 1e-5, w
        rises[w] = float((got[band] - rest[band])[:, 2].mean())
        _, _, spec = addon.inputs(obj)
        assert len(spec.get("target", [])) == (0 if w == 1.0 else len(band)), w
    # Weight 1: exactly the Empty's lift; 0.9 near it, 0.1 far below.
    assert abs(rises[1.0] - 2.0) < 1e-5, rises
    assert 1.2 < rises[0.9] < 2.0 and rises[0.1] < 0.8 * rises[0.9], rises

    # Follow and Live move the pull with the Empty: their shapes are Deform's.
    obj, empty = weighted_bar(0.5)
    empty.location.z = 0.0
    bpy.context.view_layer.update()
    obj.rigidcells.follow = True
    empty.location.z = 1.5
    bpy.context.view_layer.update()
    followed = vertices(obj, "RigidCells").copy()
    obj.rigidcells.follow = False
    assert bpy.ops.object.rigidcells_deform() == {"FINISHED"}
    assert np.abs(followed - vertices(obj, "RigidCells")).max() < 1e-3
    state = addon.LiveState(obj)
    live_moves(obj, empty, state, [((5.0, 0.0, 1.0), 0.0), ((5.0, 0.0, 2.5), 0.0)])
    ends_on_deforms_shape(obj, state)


def test_a_handle_group_without_a_vertex_of_weight_one_is_refused():
    obj, empty = weighted_bar(0.5)
    g = obj.vertex_groups["handle"]
    g.add([v.index for v in obj.data.vertices if v.co.x > 4.4], 0.7, "REPLACE")
    with pytest.raises(RuntimeError, match="'handle' has no vertex of weight 1"):
        bpy.ops.object.rigidcells_deform()
    assert obj.data.shape_keys is None


def half_bar(location, turned, cuts=6):
    """A 5 × 1 × 1 half bar at `location`: along x, or along y turned 90° about z (its world
    extent along x either way)."""
    bpy.ops.mesh.primitive_cube_add(size=1.0)
    obj = bpy.context.active_object
    obj.scale = (1.0, 5.0, 1.0) if turned else (5.0, 1.0, 1.0)
    bpy.ops.object.transform_apply(scale=True)
    bpy.ops.object.mode_set(mode="EDIT")
    bpy.ops.mesh.subdivide(number_cuts=cuts)
    bpy.ops.object.mode_set(mode="OBJECT")
    obj.location = location
    obj.rotation_euler = (0.0, 0.0, math.pi / 2 if turned else 0.0)
    bpy.context.view_layer.update()
    return obj


def world(obj, co):
    m = np.array(obj.matrix_world)
    return co @ m[:3, :3].T + m[:3, 3]


def test_selected_objects_deform_together_each_into_its_own_key():
    """Two objects, a bar's halves (the right one turned in its own coordinates), taken
    together: one scene whose groups come from each, each half its own key in its own
    coordinates; the fixed vertices keep their bits, the handle's follow the Empty, and the
    halves move alike where they meet."""
    left = half_bar((-2.5, 0.0, 0.0), False)
    right = half_bar((2.5, 0.0, 0.0), True)
    group(left, "fixed", lambda co: co.x < -1.9)
    group(right, "handle", lambda co: co.y < -1.9)  # world x > 4.4
    empty = handle_empty(left)
    s = left.rigidcells
    s.fixed_group, s.handle_group, s.handle_object, s.cell_size = "fixed", "handle", empty, 0.25
    for o in (left, right):
        o.select_set(True)
    bpy.context.view_layer.objects.active = left
    assert bpy.ops.rigidcells.together() == {"FINISHED"}
    assert addon.members(left) == [left, right]
    empty.location.z += 2.0
    bpy.context.view_layer.update()
    rests = {o.name: vertices(o) for o in (left, right)}
    assert bpy.ops.object.rigidcells_deform() == {"FINISHED"}
    got = {o.name: vertices(o, "RigidCells") for o in (left, right)}
    fixed = [v.index for v in left.data.vertices if v.co.x < -1.9]
    assert np.array_equal(got[left.name][fixed], rests[left.name][fixed])
    handle = [v.index for v in right.data.vertices if v.co.y < -1.9]
    lifted = got[right.name][handle] - rests[right.name][handle]
    assert np.abs(lifted - [0.0, 0.0, 2.0]).max() < 1e-5, lifted
    # Where the halves meet (world x = 0) they moved alike: one scene, no tear.
    meet = {}
    for o in (left, right):
        at = world(o, rests[o.name])
        near = np.abs(at[:, 0]) < 1e-4
        meet[o.name] = (world(o, got[o.name]) - at)[near].mean(axis=0)
    assert np.abs(meet[left.name] - meet[right.name]).max() < 0.02, meet
    assert 0.1 < meet[left.name][2] < 1.9, meet
    # The library's warning (the halves touch closer than a cell) in the panel's words, and no
    # Python warning in the package's.
    assert 'a smaller "Cell size" keeps them apart' in s.warnings, s.warnings
    assert "cell_size" not in s.warnings
    # Follow keeps both keys on the Empty.
    s.follow = True
    empty.location.z += 1.0
    bpy.context.view_layer.update()
    lifted = vertices(right, "RigidCells")[handle] - rests[right.name][handle]
    assert np.abs(lifted - [0.0, 0.0, 3.0]).max() < 1e-5, lifted
    assert np.array_equal(vertices(left, "RigidCells")[fixed], rests[left.name][fixed])
    s.follow = False
    # Alone again: the right half is no part of the scene, and the handle group is missing.
    right.select_set(False)
    assert bpy.ops.rigidcells.together() == {"FINISHED"}
    with pytest.raises(RuntimeError, match="has no vertex group 'handle'"):
        bpy.ops.object.rigidcells_deform()


def test_fold_overs_are_a_vertex_group_to_select():
    """A handle pushed through the bar folds it over: the vertices where are the group
    `RigidCells Folds` (the report's, by index); a bend that folds nothing removes it."""
    obj, empty = setup_bar()
    empty.rotation_euler = (0.0, 0.0, 0.0)
    empty.location = (-4.0, 0.0, 0.0)  # the handle pushed into the fixed end
    obj.rigidcells.cell_size = 1.0  # a cell across: it folds rather than buckles
    bpy.context.view_layer.update()
    assert bpy.ops.object.rigidcells_deform() == {"FINISHED"}
    s = obj.rigidcells
    assert s.foldovers > 0
    k = obj.vertex_groups[addon.FOLDS_GROUP].index
    marked = [v.index for v in obj.data.vertices if any(g.group == k for g in v.groups)]
    points, triangles, spec = addon.inputs(obj)
    _, report = rigidcells.deform(points, spec, triangles=triangles, cell_size=1.0, progress=False)
    assert marked == report.foldover_samples and len(marked) == s.foldovers
    empty.location = (5.0, 0.0, 1.0)
    bpy.context.view_layer.update()
    assert bpy.ops.object.rigidcells_deform() == {"FINISHED"}
    assert s.foldovers == 0 and addon.FOLDS_GROUP not in obj.vertex_groups


def test_the_selection_of_several_meshes_in_edit_mode_makes_one_group():
    """Two meshes in Edit Mode together, vertices selected in the one that is not active: the
    group is made in it (the scene's groups are found by name in each object), and the
    handle's Empty sits at its selection's center."""
    left = half_bar((-2.5, 0.0, 0.0), False)
    right = half_bar((2.5, 0.0, 0.0), True)
    for o in (left, right):
        o.select_set(True)
    bpy.context.view_layer.objects.active = left
    assert bpy.ops.rigidcells.together() == {"FINISHED"}
    for o, keep in ((left, lambda co: co.x < -1.9), (right, lambda co: False)):
        select_vertices(o, keep)
    bpy.ops.object.mode_set(mode="EDIT")
    assert {o.name for o in bpy.context.objects_in_mode} == {left.name, right.name}
    assert bpy.ops.rigidcells.from_selection(role="fixed") == {"FINISHED"}
    bpy.ops.object.mode_set(mode="OBJECT")
    for o, keep in ((left, lambda co: False), (right, lambda co: co.y < -1.9)):
        select_vertices(o, keep)
    bpy.ops.object.mode_set(mode="EDIT")
    assert bpy.ops.rigidcells.from_selection(role="handle") == {"FINISHED"}
    bpy.ops.object.mode_set(mode="OBJECT")
    assert "RigidCells Handle" in right.vertex_groups and "RigidCells Handle" not in left.vertex_groups
    assert "RigidCells Fixed" in left.vertex_groups and "RigidCells Fixed" not in right.vertex_groups
    empty = left.rigidcells.handle_object
    assert np.allclose(empty.location, (5.0, 0.0, 0.0), atol=1e-6), empty.location
    empty.location.z += 1.0
    bpy.context.view_layer.update()
    assert bpy.ops.object.rigidcells_deform() == {"FINISHED"}
    handle = [v.index for v in right.data.vertices if v.co.y < -1.9]
    lifted = vertices(right, "RigidCells")[handle] - vertices(right)[handle]
    assert np.abs(lifted - [0.0, 0.0, 1.0]).max() < 1e-5


def test_an_uneven_scale_and_a_typed_cell_size_are_said_as_the_artist_would():
    """An object scaled unevenly is warned about (its cells are cubes in its own coordinates);
    a cell size typed in the panel reaches the library as typed, not as Blender's single
    precision keeps it."""
    obj, empty = setup_bar()
    obj.scale = (1.0, 1.0, 0.5)
    bpy.context.view_layer.update()
    assert bpy.ops.object.rigidcells_deform() == {"FINISHED"}
    assert "is scaled unevenly (1, 1, 0.5)" in obj.rigidcells.warnings, obj.rigidcells.warnings
    obj.scale = (2.0, 2.0, 2.0)
    bpy.context.view_layer.update()
    assert bpy.ops.object.rigidcells_deform() == {"FINISHED"}
    assert "unevenly" not in obj.rigidcells.warnings
    obj.rigidcells.cell_size = 0.00001
    assert addon.options(obj.rigidcells)["cell_size"] == 0.00001
    with pytest.raises(RuntimeError, match=r"size 0\.00001\b"):
        bpy.ops.object.rigidcells_deform()


def test_the_panel_estimates_and_takes_a_cell_count_and_a_memory_limit():
    """Estimate says what Deform will take (the library's estimate, in the panel); Cells and
    Memory limit reach the library; a refusal names the panel's settings."""
    obj, empty = setup_bar()
    s = obj.rigidcells
    s.cell_size, s.cells = 0.0, 1500
    assert bpy.ops.rigidcells.estimate() == {"FINISHED"}
    points, triangles, spec = addon.inputs(obj)
    est = rigidcells.estimate(points, spec, triangles=triangles, cells=1500)
    # The seconds are partly measured (the cells are built), so they differ run to run.
    assert s.estimate.startswith(f"{est.cells:,} cells, {est.bytes / 2**30:.2g} GiB, "), s.estimate
    assert s.estimate.endswith(" s") and "over the memory limit" not in s.estimate
    assert bpy.ops.object.rigidcells_deform() == {"FINISHED"}
    assert s.run_cells == est.cells
    s.cell_size = 0.25
    with pytest.raises(RuntimeError, match='"Cell size" and "Cells" both size the cells: give one'):
        bpy.ops.object.rigidcells_deform()
    # 1 MiB: the cells asked for cannot fit; the estimate says so, and Deform refuses.
    s.cell_size, s.memory_limit = 0.0, 1 / 1024
    refusal = 'over the memory limit of 1.0 MiB \\("Memory limit"\\): ask for fewer "Cells"'
    with pytest.raises(RuntimeError, match=refusal):
        bpy.ops.rigidcells.estimate()
    assert "over the memory limit" in s.estimate, s.estimate
    with pytest.raises(RuntimeError, match=refusal):
        bpy.ops.object.rigidcells_deform()
    # Cells too fine to rasterize in it: the advice names the panel's settings and leaves out
    # the library's options the panel lacks (the command line adds --min-cell-size).
    s.cells, s.cell_size = 0, 0.001
    with pytest.raises(RuntimeError, match=r'\("Memory limit"\): use a larger "Cell size" \(or fewer "Cells"\)') as e:
        bpy.ops.object.rigidcells_deform()
    assert "min_cell_size" not in str(e.value), e.value


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
        # The library's message names the panel's setting, not the Python keyword.
        (lambda o, e: setattr(o.rigidcells, "cell_size", 1e-5), 'memory.*a larger "Cell size"'),
        # Regions named by the panel's groups, not by the spec the add-on wrote.
        (
            lambda o, e: setattr(o.rigidcells, "handle_group", "fixed"),
            r"the fixed group and the handle group both claim the cell .*\(size 0\.25\); "
            r".* a smaller \"Cell size\"",
        ),
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


def wait_for(predicate, seconds=60.0):
    """Polls `predicate` as a modal timer would, until it holds (or the time is up)."""
    end = time.monotonic() + seconds
    while not predicate():
        assert time.monotonic() < end, "timed out"
        time.sleep(0.005)


def test_deform_runs_off_the_main_thread_and_gives_the_operators_key():
    obj, empty = setup_bar()
    assert bpy.ops.object.rigidcells_deform() == {"FINISHED"}
    want = vertices(obj, "RigidCells")
    obj.shape_key_clear()
    points, triangles, spec = addon.inputs(obj)
    job = addon.DeformJob(points, spec, triangles, addon.options(obj.rigidcells)).start()
    ticks = 0
    while not job.done:  # the main thread is free meanwhile
        ticks += 1
        time.sleep(0.001)
    assert job.error is None and ticks > 0
    addon.finish(obj, *job.result)
    assert np.array_equal(vertices(obj, "RigidCells"), want)
    # Cancelled (Esc): the job ends with Cancelled, and the mesh is left as it was.
    obj.shape_key_clear()
    obj.rigidcells.cell_size = 0.08
    points, triangles, spec = addon.inputs(obj)
    job = addon.DeformJob(points, spec, triangles, addon.options(obj.rigidcells)).start()
    job.cancel()
    wait_for(lambda: job.done)
    assert isinstance(job.error, addon.Cancelled), job.error
    assert obj.data.shape_keys is None


def live_moves(obj, empty, state, poses):
    """Moves the Empty through `poses` ((location, y-angle in degrees)), ticking Live after
    each until it wrote that pose's preview."""
    for location, degrees in poses:
        empty.location = location
        empty.rotation_euler = (0.0, math.radians(degrees), 0.0)
        bpy.context.view_layer.update()
        steps = state.worker.steps
        state.tick(obj)
        wait_for(lambda: state.worker.steps > steps)
        wait_for(lambda: state.tick(obj) is not None)


def ends_on_deforms_shape(obj, state):
    """Enter: Live ends on the exact shape of the last pose, the shape Deform gives for it
    (the solver's move test, a thousandth of a cell, reached from other starts; Blender's
    single precision)."""
    state.finish()
    wait_for(lambda: (state.tick(obj), state.worker.done)[1])
    state.tick(obj)
    assert state.kind == "released" and state.worker.error is None
    live = vertices(obj, "RigidCells")
    assert bpy.ops.object.rigidcells_deform() == {"FINISHED"}
    assert np.abs(live - vertices(obj, "RigidCells")).max() < 1e-3 * obj.rigidcells.cell_size


def test_live_follows_scripted_moves_and_ends_on_the_converged_shape():
    obj, empty = setup_bar()  # the Empty at its posed place: (4, 0, 3), turned -60° about y
    empty.location, empty.rotation_euler = (5.0, 0.0, 0.0), (0.0, 0.0, 0.0)
    bpy.context.view_layer.update()
    state = addon.LiveState(obj)
    tip = max(range(len(obj.data.vertices)), key=lambda i: obj.data.vertices[i].co.x)
    rises = []
    for k in range(1, 6):  # five moves on the way to the posed place
        live_moves(obj, empty, state, [((5.0 - 0.2 * k, 0.0, 0.6 * k), -12.0 * k)])
        assert state.kind == "preview"
        rises.append(vertices(obj, "RigidCells")[tip, 2])
    assert all(b > a for a, b in zip(rises, rises[1:])) and rises[-1] > 2.0, rises
    # At rest the solve converges and the exact transfer is written; Enter ends on it.
    ends_on_deforms_shape(obj, state)
    assert obj.rigidcells.run_cells == state.worker.cells


def test_live_refines_only_once_the_handle_rests(monkeypatch):
    """A drag's poses each get their step at once; the worker refines only once the handle
    has rested for `idle` (a refinement between two poses would delay the second's shape),
    and releases once converged and at rest for `settle`."""
    from rigidcells_blender.work import LiveWorker

    now, calls = [0.0], []

    class Session:  # what the worker asks of a rigidcells.Session
        def __init__(self, *args, **kwargs):
            self.cells, self.converged = 1, True

        def drag(self, poses, pins=None, targets=None):
            calls.append(("drag", now[0]))
            self.converged = False

        def refine(self):
            calls.append(("refine", now[0]))
            self.converged = len([c for c in calls if c[0] == "refine"]) >= 3

        def preview(self):
            return np.zeros((1, 3))

        def release(self):
            calls.append(("release", now[0]))
            return np.zeros((1, 3)), None

    def until(test):
        deadline = time.monotonic() + 10.0
        while not test():
            assert time.monotonic() < deadline, calls
            time.sleep(0.005)

    monkeypatch.setattr(rigidcells, "Session", Session)
    worker = LiveWorker(np.zeros((1, 3)), {}, None, {}, settle=0.25, idle=0.05,
                        clock=lambda: now[0]).start()
    for k in range(8):  # a pose every 16 ms (the worker's clock), real time passing between
        now[0] = 0.016 * k
        worker.move([{"k": k}])
        until(lambda: worker.steps == k + 1)
        time.sleep(0.03)
    assert [c[0] for c in calls] == ["drag"] * 8
    now[0] += 0.06  # rested past `idle`: refined to convergence, not yet released
    until(lambda: sum(c[0] == "refine" for c in calls) == 3)
    time.sleep(0.1)
    assert [c[0] for c in calls][8:] == ["refine"] * 3
    now[0] += 0.25  # and past `settle`: released
    until(lambda: calls[-1][0] == "release")
    worker.stop()
    worker.thread.join(10)
    assert worker.done and worker.error is None


def test_esc_puts_the_shape_key_back():
    obj, empty = setup_bar()
    # No shape keys before Live: none after Esc.
    state = addon.LiveState(obj)
    live_moves(obj, empty, state, [((4.0, 0.0, 4.0), -30.0)])
    assert obj.data.shape_keys is not None
    state.cancel(obj)
    assert obj.data.shape_keys is None
    # A RigidCells key before Live: the same key and value after Esc.
    assert bpy.ops.object.rigidcells_deform() == {"FINISHED"}
    before = vertices(obj, "RigidCells")
    obj.data.shape_keys.key_blocks["RigidCells"].value = 0.5
    state = addon.LiveState(obj)
    live_moves(obj, empty, state, [((3.0, 0.0, 5.0), -80.0)])
    assert not np.array_equal(vertices(obj, "RigidCells"), before)
    state.cancel(obj)
    assert np.array_equal(vertices(obj, "RigidCells"), before)
    assert obj.data.shape_keys.key_blocks["RigidCells"].value == 0.5
    state.worker.thread.join(10)
    assert state.worker.done


def test_more_handles_pins_and_stiffness():
    obj = grid_bar()
    group(obj, "fixed", lambda co: abs(co.x) < 0.6)
    group(obj, "left", lambda co: co.x < -4.4)
    group(obj, "right", lambda co: co.x > 4.4)
    rest = vertices(obj)
    pinned = int(np.argmin(np.linalg.norm(rest - [2.5, 0.0, 0.5], axis=1)))
    obj.vertex_groups.new(name="pin").add([pinned], 1.0, "REPLACE")
    group(obj, "stiff", lambda co: co.x < -1.0)
    s = obj.rigidcells
    s.fixed_group, s.handle_group, s.cell_size = "fixed", "right", 0.25
    right = handle_empty(obj, at=(5.0, 0.0, 0.0))
    s.handle_object = right
    left = handle_empty(obj, at=(-5.0, 0.0, 0.0))
    bpy.ops.rigidcells.add(kind="handles")
    s.handles[0].group = "left"
    # An extra handle without its Empty is refused, the mesh untouched.
    with pytest.raises(RuntimeError, match="choose the Empty of handle 2"):
        bpy.ops.object.rigidcells_deform()
    assert obj.data.shape_keys is None
    s.handles[0].object = left
    right.location = (5.0, 0.0, 2.0)
    left.location = (-5.0, 0.0, 1.0)
    bpy.context.view_layer.update()
    assert bpy.ops.object.rigidcells_deform() == {"FINISHED"}
    free = vertices(obj, "RigidCells")
    ends = {"left": (rest[:, 0] < -4.4, 1.0), "right": (rest[:, 0] > 4.4, 2.0)}
    for name, (on, lift) in ends.items():
        # Each handle group lands where its Empty sends it.
        assert np.abs(free[on] - (rest[on] + [0.0, 0.0, lift])).max() < 1e-5, name
    # A pin: its vertex group's center (here one vertex) goes where its Empty moves it, its
    # cell turning freely about it.
    pin = handle_empty(obj, at=tuple(rest[pinned]))
    bpy.ops.rigidcells.add(kind="pins")
    s.pins[0].group, s.pins[0].object = "pin", pin
    pin.location = tuple(rest[pinned] + [0.0, 0.0, 0.1])
    bpy.context.view_layer.update()
    assert bpy.ops.object.rigidcells_deform() == {"FINISHED"}
    pinned_shape = vertices(obj, "RigidCells")
    move = free[pinned, 2] - rest[pinned, 2]
    assert move > 0.3, move
    want = rest[pinned] + [0.0, 0.0, 0.1]
    assert np.abs(pinned_shape[pinned] - want).max() < 1e-5, pinned_shape[pinned] - want
    # A stiffness group: the left half, a hundred times stiffer, changes the shape there,
    # as the library's stiffness region of those vertices does.
    s.stiffness_group, s.stiffness = "stiff", 100.0
    assert bpy.ops.object.rigidcells_deform() == {"FINISHED"}
    stiff = vertices(obj, "RigidCells")
    points, triangles, spec = addon.inputs(obj)
    assert spec["stiffness"][0]["scale"] == 100.0
    assert len(spec["handle"]) == 2 and len(spec["pin"]) == 1
    want, _ = rigidcells.deform(points, spec, triangles=triangles, cell_size=0.25, progress=False)
    assert np.abs(stiff - want).max() < 1e-6
    part = rest[:, 0] < -1.0
    assert np.abs(stiff[part] - pinned_shape[part]).max() > 0.01


def test_live_follows_a_pin_empty():
    obj, empty = setup_bar()
    rest = vertices(obj)
    pinned = int(np.argmin(np.linalg.norm(rest - [0.0, 0.0, 0.5], axis=1)))
    obj.vertex_groups.new(name="pin").add([pinned], 1.0, "REPLACE")
    pin = handle_empty(obj, at=tuple(rest[pinned]))
    bpy.ops.rigidcells.add(kind="pins")
    obj.rigidcells.pins[0].group, obj.rigidcells.pins[0].object = "pin", pin
    state = addon.LiveState(obj)
    for k in range(1, 4):  # the pin's Empty alone moves: Live follows it warm
        pin.location = tuple(rest[pinned] + [0.0, 0.0, 0.3 * k])
        bpy.context.view_layer.update()
        steps = state.worker.steps
        state.tick(obj)
        wait_for(lambda: state.worker.steps > steps)
    ends_on_deforms_shape(obj, state)


@pytest.mark.parametrize("kind", ["vertices only", "non-manifold"])
def test_a_scan_of_vertices_and_a_non_manifold_mesh_bend(kind):
    """How imported scans arrive (vertices, no faces), and a mesh whose edges are shared by
    three faces (a fin glued along a plate's middle): both bend, exact at both ends."""
    xs, ys = np.meshgrid(np.linspace(-5, 5, 41), np.linspace(-0.5, 0.5, 5), indexing="ij")
    verts = [(x, y, 0.0) for x, y in zip(xs.ravel(), ys.ravel())]
    faces = []
    if kind == "non-manifold":
        def at(i, j):
            return i * 5 + j
        faces = [(at(i, j), at(i + 1, j), at(i + 1, j + 1), at(i, j + 1))
                 for i in range(40) for j in range(4)]
        # A fin standing on the plate's middle row: its bottom edges are the plate's.
        n = len(verts)
        verts += [(x, 0.0, 0.5) for x in np.linspace(-5, 5, 41)]
        faces += [(at(i, 2), at(i + 1, 2), n + i + 1, n + i) for i in range(40)]
    mesh = bpy.data.meshes.new(kind)
    mesh.from_pydata(verts, [], faces)
    obj = bpy.data.objects.new(kind, mesh)
    bpy.context.collection.objects.link(obj)
    bpy.context.view_layer.objects.active = obj
    group(obj, "fixed", lambda co: co.x < -4.4)
    group(obj, "handle", lambda co: co.x > 4.4)
    empty = handle_empty(obj, at=(5.0, 0.0, 0.0))
    s = obj.rigidcells
    s.fixed_group, s.handle_group, s.handle_object, s.cell_size = "fixed", "handle", empty, 0.25
    empty.location = (5.0, 0.0, 2.0)
    bpy.context.view_layer.update()
    assert bpy.ops.object.rigidcells_deform() == {"FINISHED"}
    rest, bent = vertices(obj), vertices(obj, "RigidCells")
    fixed, handle = rest[:, 0] < -4.4, rest[:, 0] > 4.4
    assert np.array_equal(bent[fixed], rest[fixed])
    assert np.abs(bent[handle] - (rest[handle] + [0, 0, 2.0])).max() < 1e-5
    rise = (bent - rest)[:, 2]
    middle = np.abs(rest[:, 0]) < 0.2
    assert 0.3 < rise[middle].mean() < 1.7, rise[middle].mean()


def turns_along(rest, bent):
    """How far each cross-section of a bar along x turned about x from the fixed end (x = −5)
    on, in degrees, by x: its vertices' turn about their center, unwrapped section by section
    (neighbors turn by far less than a half turn), so that a whole turn is 360, not 0."""
    turns, last = {}, 0.0
    for x in np.unique(np.round(rest[:, 0], 4)):
        on = np.abs(rest[:, 0] - x) < 1e-3
        a = rest[on][:, 1:] - rest[on][:, 1:].mean(axis=0)
        b = bent[on][:, 1:] - bent[on][:, 1:].mean(axis=0)
        cross, dot = (a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0]).sum(), (a * b).sum()
        degrees = math.degrees(math.atan2(cross, dot))
        last += (degrees - last + 180.0) % 360.0 - 180.0
        turns[float(x)] = last
    return turns


def twist_bar(cell_size=0.4):
    """The 10-unit bar along x with a cross-section at its middle (x = 0), fixed at x = −5,
    its handle the end at x = 5 with an Empty there (assigned at rest), in coarse cells: 0.4,
    which lie alike at both ends, so that a twist turns the middle by half of it (180.0° of
    360°; at 0.5 the ends' cells differ, and the middle turns by 170°)."""
    obj = grid_bar(cuts=9)
    group(obj, "fixed", lambda co: co.x < -4.4)
    group(obj, "handle", lambda co: co.x > 4.4)
    empty = handle_empty(obj)
    s = obj.rigidcells
    s.fixed_group, s.handle_group, s.cell_size = "fixed", "handle", cell_size
    s.handle_object = empty
    return obj, empty


def typed(empty, degrees, mode="XYZ"):
    """`degrees` about x typed on the Empty in rotation mode `mode`."""
    empty.rotation_mode = mode
    half = math.radians(degrees) / 2.0
    if mode == "QUATERNION":
        empty.rotation_quaternion = (math.cos(half), math.sin(half), 0.0, 0.0)
    elif mode == "AXIS_ANGLE":
        empty.rotation_axis_angle = (math.radians(degrees), 1.0, 0.0, 0.0)
    else:
        empty.rotation_euler = (math.radians(degrees), 0.0, 0.0)
    bpy.context.view_layer.update()


def deformed_turns(obj):
    """Deform, and the bar's turn along x (`turns_along`)."""
    assert bpy.ops.object.rigidcells_deform() == {"FINISHED"}
    return turns_along(vertices(obj), vertices(obj, "RigidCells"))


def test_a_whole_turn_typed_twists_the_bar_a_whole_turn():
    """360° typed about the bar's axis: a whole twist, the middle turned by half of it (the
    matrix of a whole turn is the identity, which bends nothing). Live, following the Empty
    as it turns to the same typed pose, ends on Deform's shape."""
    obj, empty = twist_bar()
    typed(empty, 360.0)
    (pose,) = addon.poses(obj)
    assert pose["rotate"]["axis"] == [1.0, 0.0, 0.0]
    assert abs(pose["rotate"]["degrees"] - 360.0) < 1e-4, pose
    turns = deformed_turns(obj)
    assert abs(turns[5.0] - 360.0) < 0.01 and turns[-5.0] == 0.0, turns
    assert abs(turns[0.0] - 180.0) < 5.0, turns
    # Live from the rest pose, the Empty turned 30° at a time up to the typed 360°.
    live_ends_on_deforms_shape(obj, empty, turns, [30.0 * k for k in range(1, 13)])


def live_ends_on_deforms_shape(obj, empty, turns, angles):
    """Live from the rest pose on `obj`, its Empty typed to each of `angles` in turn, then
    Enter: the exact shape of the last pose is Deform's (its shape key now, with the turns
    `turns` along the bar). Converged from the dragged cells, not from rest by load steps, it
    ends by Newton's iterations as Deform's last load step does, from another start: about
    1e-4 of a cell apart in runs here; allow a hundredth (0.004 on the 10-unit bar), and the
    turns along the bar within a tenth of a degree."""
    want = vertices(obj, "RigidCells")
    obj.shape_key_clear()
    typed(empty, 0.0)
    state = addon.LiveState(obj)
    for angle in angles:
        typed(empty, angle)
        steps = state.worker.steps
        state.tick(obj)
        wait_for(lambda: state.worker.steps > steps)
        wait_for(lambda: state.tick(obj) is not None)
    state.finish()
    wait_for(lambda: (state.tick(obj), state.worker.done)[1])
    state.tick(obj)
    assert state.kind == "released" and state.worker.error is None
    live = vertices(obj, "RigidCells")
    assert np.abs(live - want).max() < 1e-2 * obj.rigidcells.cell_size
    live_turns = turns_along(vertices(obj), live)
    assert max(abs(live_turns[x] - turns[x]) for x in turns) < 0.1, (live_turns, turns)


def test_live_turned_faster_than_it_follows_keeps_two_whole_turns():
    """720° reached 15° a pose, each pose given one step (a hand faster than the solver): Live
    converges its last pose before it goes a load step past the one it last converged on, so
    the cells never fall half a turn behind, and Enter ends on Deform's two whole turns (the
    middle a whole turn round, not back at rest)."""
    obj, empty = twist_bar()
    typed(empty, 720.0)
    turns = deformed_turns(obj)
    assert abs(turns[0.0] - 360.0) < 5.0, turns
    live_ends_on_deforms_shape(obj, empty, turns, [15.0 * k for k in range(1, 49)])


def test_live_winds_a_whole_turn_typed_at_once():
    """360° typed into the Empty at once while Live runs: the session solves that pose from
    rest in load steps, and Enter ends on Deform's whole twist (a warm step would have taken the
    identity the short way)."""
    obj, empty = twist_bar()
    typed(empty, 360.0)
    turns = deformed_turns(obj)
    assert abs(turns[0.0] - 180.0) < 5.0, turns
    live_ends_on_deforms_shape(obj, empty, turns, [360.0])


def test_three_quarters_typed_turn_three_quarters_not_back_a_quarter():
    """270° typed is +270° (its matrix is −90°'s): the middle turns by 135°, not −45°."""
    obj, empty = twist_bar()
    typed(empty, 270.0)
    turns = deformed_turns(obj)
    assert abs(turns[5.0] - 270.0) < 0.01, turns
    assert abs(turns[0.0] - 135.0) < 5.0, turns


@pytest.mark.parametrize("mode", ["ZYX", "AXIS_ANGLE", "QUATERNION"])
def test_every_rotation_mode_gives_the_typed_turn(mode):
    """270° about x typed in another Euler order, as an axis-angle or as a quaternion (which
    holds turns up to 720°) is the same pose as in XYZ, and turns the bar alike."""
    obj, empty = twist_bar()
    typed(empty, 270.0)
    (want,) = addon.poses(obj)
    typed(empty, 0.0, mode)
    typed(empty, 270.0, mode)
    (pose,) = addon.poses(obj)
    assert pose.keys() == want.keys()
    assert np.allclose(pose["rotate"]["axis"], want["rotate"]["axis"], atol=1e-9), pose
    assert abs(pose["rotate"]["degrees"] - want["rotate"]["degrees"]) < 1e-4, pose
    turns = deformed_turns(obj)
    assert abs(turns[5.0] - 270.0) < 0.01 and abs(turns[0.0] - 135.0) < 5.0, turns


def test_an_animated_empty_turns_as_keyed():
    """Keys of 0° and 360° about x: the value between is the F-curve's, unwrapped (180° half
    way, a half turn, not none), and at the last key the bar twists a whole turn."""
    obj, empty = twist_bar()
    scene = bpy.context.scene
    for frame, degrees in ((1, 0.0), (11, 360.0)):
        empty.rotation_euler = (math.radians(degrees), 0.0, 0.0)
        empty.keyframe_insert("rotation_euler", index=0, frame=frame)
    for frame, degrees in ((6, 180.0), (11, 360.0)):
        scene.frame_set(frame)
        (pose,) = addon.poses(obj)
        assert abs(pose["rotate"]["degrees"] - degrees) < 1e-3, (frame, pose)
        assert np.allclose(pose["rotate"]["axis"], [1.0, 0.0, 0.0], atol=1e-9), pose
    turns = deformed_turns(obj)
    assert abs(turns[5.0] - 360.0) < 0.01 and abs(turns[0.0] - 180.0) < 5.0, turns


def test_a_half_turn_about_an_empty_beside_the_bar_bends_it_into_a_u():
    """The bar from x = 0 to 10 (the object moved there), fixed at x < 1, its handle the end
    at x > 9 with an Empty beside its middle, at (5, 2, 0), turned 180° about z: the handle
    end comes back to x ≈ 0 at y ≈ 4, turning about the Empty the way it was typed, and the
    bar's middle bulges out at x ≈ 4 between the two legs."""
    obj = grid_bar()
    obj.location = (5.0, 0.0, 0.0)
    bpy.context.view_layer.update()
    group(obj, "fixed", lambda co: co.x < -4.0)
    group(obj, "handle", lambda co: co.x > 4.0)
    empty = handle_empty(obj, at=(5.0, 2.0, 0.0))
    s = obj.rigidcells
    s.fixed_group, s.handle_group, s.cell_size = "fixed", "handle", 0.5
    s.handle_object = empty
    empty.rotation_euler = (0.0, 0.0, math.radians(180.0))
    bpy.context.view_layer.update()
    (pose,) = addon.poses(obj)
    # The pivot is the Empty's rest origin in the object's coordinates.
    assert np.allclose(pose["pivot"], [0.0, 2.0, 0.0]) and pose["rotate"]["axis"] == [0.0, 0.0, 1.0]
    start = time.monotonic()
    assert bpy.ops.object.rigidcells_deform() == {"FINISHED"}
    seconds = time.monotonic() - start
    rest, bent = vertices(obj) + [5.0, 0.0, 0.0], vertices(obj, "RigidCells") + [5.0, 0.0, 0.0]
    end = rest[:, 0] > 9.0
    assert np.abs(bent[end] - (rest[end] * [-1.0, -1.0, 1.0] + [10.0, 4.0, 0.0])).max() < 1e-5
    assert np.all(bent[end][:, 0] < 1.0) and np.all(np.abs(bent[end][:, 1] - 4.0) < 0.6)
    middle = bent[np.abs(rest[:, 0] - 5.0) < 0.6].mean(axis=0)
    assert 3.0 < middle[0] < 4.5 and abs(middle[1] - 2.0) < 0.5, middle
    assert obj.rigidcells.foldovers == 0 and seconds < 30.0, seconds


def pose_map(pose):
    """The affine map (4 × 4) a handle dict of the spec gives."""
    if "matrix" in pose:
        return np.array(pose["matrix"])
    axis, degrees = pose.get("rotate", {}).get("axis", [1.0, 0.0, 0.0]), 0.0
    if "rotate" in pose:
        degrees = pose["rotate"]["degrees"]
    linear = pose.get("scale", 1.0) * addon._axis_rotation(np.array(axis), math.radians(degrees))
    pivot = np.array(pose["pivot"])
    m = np.eye(4)
    m[:3, :3] = linear
    m[:3, 3] = pivot - linear @ pivot + pose["translate"]
    return m


def test_the_turn_reaches_the_objects_coordinates_through_parents_and_scales():
    """The mesh object turned, moved and scaled, the Empty under a turned and scaled parent
    and scaled unevenly itself: the typed 270° about the Empty's own x arrives as 270° about
    that axis in the object's coordinates, the same map as the Empty's matrices. Its scale
    changed alike on three axes is the pose's `scale`; changed unevenly, the pose is the
    matrix; a parent turned since the rest turns the handle as the matrices do, with the
    winding nearest the typed one."""
    obj, empty = twist_bar()
    obj.location, obj.rotation_euler, obj.scale = (1.0, 2.0, 3.0), (0.3, 0.2, 1.1), (2.0,) * 3
    bpy.ops.object.empty_add(location=(-1.0, 0.5, 2.0), rotation=(0.4, -0.7, 0.2))
    parent = bpy.context.active_object
    parent.scale = (1.5,) * 3
    bpy.context.view_layer.update()
    empty.parent = parent
    empty.rotation_mode = "XZY"
    empty.location, empty.rotation_euler = (0.5, 1.0, 0.0), (0.1, 0.6, -0.4)
    empty.scale = (1.0, 3.0, 0.5)
    bpy.context.view_layer.update()
    obj.rigidcells.handle_object = empty  # the rest, under its parent
    rest = np.array(empty.matrix_world)
    local_x = rest[:3, 0] / np.linalg.norm(rest[:3, 0])  # the Empty's own x, in the world

    def pose_now():
        bpy.context.view_layer.update()
        (pose,) = addon.poses(obj)
        motion = addon._motion(obj, empty, obj.rigidcells.handle_rest)
        assert np.abs(pose_map(pose) - motion).max() < 1e-5, (pose, motion)
        return pose

    # In XZY, x turns first (Ry·Rz·Rx): its axis is the Empty's own x, wherever z and y turn
    # it.
    empty.rotation_euler = (0.1 + math.radians(270.0), 0.6, -0.4)
    pose = pose_now()
    assert abs(pose["rotate"]["degrees"] - 270.0) < 1e-3 and "scale" not in pose, pose
    world = np.array(obj.matrix_world)[:3, :3] @ pose["rotate"]["axis"]
    assert np.abs(world / np.linalg.norm(world) - local_x).max() < 1e-6, world
    empty.scale = (2.0, 6.0, 1.0)
    pose = pose_now()
    assert abs(pose["scale"] - 2.0) < 1e-9 and abs(pose["rotate"]["degrees"] - 270.0) < 1e-3, pose
    empty.scale = (2.0, 3.0, 1.0)
    assert "matrix" in pose_now()
    empty.scale = (1.0, 3.0, 0.5)
    # The parent turned a little since the rest: the map is the matrices', its turn the
    # winding nearest the typed one.
    parent.rotation_euler = (0.4, -0.7, 0.3)
    pose = pose_now()
    assert 260.0 < pose["rotate"]["degrees"] < 280.0, pose
    parent.rotation_euler = (0.4, -0.7, 0.2)
    # A quaternion's whole turn names no axis: refused, not taken as none.
    empty.rotation_mode = "QUATERNION"
    empty.rotation_quaternion = (-1.0, 0.0, 0.0, 0.0)
    bpy.context.view_layer.update()
    obj.rigidcells.handle_object = None
    obj.rigidcells.handle_object = empty
    empty.rotation_quaternion = (1.0, 0.0, 0.0, 0.0)
    bpy.context.view_layer.update()
    with pytest.raises(addon.InputError, match="names no axis"):
        addon.poses(obj)


def test_follow_keys_the_shape_of_each_pose_as_deform_would(monkeypatch):
    """Follow on: the key follows the Empty as it moves and as its keyframes play, each shape
    Deform's for that pose; Bake keys one shape a frame and removes the followed key."""
    obj, empty = setup_bar()
    scene = bpy.context.scene
    empty.location, empty.rotation_euler = (5.0, 0.0, 0.0), (0.0, 0.0, 0.0)
    empty.keyframe_insert("location", frame=1)
    empty.location = (5.0, 0.0, 3.0)
    empty.keyframe_insert("location", frame=5)
    scene.frame_set(1)
    obj.rigidcells.follow = True
    assert "Following" in (addon.follow.status(obj) or "")
    shapes = {}
    for frame in (5, 3):
        scene.frame_set(frame)
        shapes[frame] = vertices(obj, "RigidCells").copy()
        points, triangles, spec = addon.inputs(obj)
        want, _ = rigidcells.deform(points, spec, triangles=triangles, cell_size=0.25, progress=False)
        # Solved warm from the last frame's cells: the same shape to the solver's tolerance
        # (as Live ends on Deform's), not bit for bit.
        assert np.abs(shapes[frame] - want).max() < 1e-3, frame
    handle = [v.index for v in obj.data.vertices if v.co.x > 4.4]
    rest = vertices(obj)
    assert np.abs(shapes[5][handle] - rest[handle] - [0, 0, 3]).max() < 1e-5
    assert np.abs(shapes[3][handle] - rest[handle] - [0, 0, 1.5]).max() < 1e-5
    # Moved by hand (no keyframe at this frame): followed on the update.
    empty.location = (5.0, 0.0, 2.0)
    bpy.context.view_layer.update()
    assert np.abs(vertices(obj, "RigidCells")[handle] - rest[handle] - [0, 0, 2]).max() < 1e-5

    # Dragged in a window: a drag's step and its preview at each update, the exact shape once
    # the Empty has rested (the timer, run here by hand).
    monkeypatch.setattr(addon.follow, "_in_window", lambda: True)
    empty.location = (5.0, 0.0, 2.5)
    bpy.context.view_layer.update()
    state = addon.follow._sessions[obj.name]
    assert not state.exact and bpy.app.timers.is_registered(addon.follow._settle)
    preview = vertices(obj, "RigidCells").copy()
    assert 1.0 < (preview[handle] - rest[handle])[:, 2].mean() < 3.0
    state.moved_at -= addon.follow.SETTLE
    assert addon.follow._settle() is None and state.exact
    points, triangles, spec = addon.inputs(obj)
    want, _ = rigidcells.deform(points, spec, triangles=triangles, cell_size=0.25, progress=False)
    assert np.abs(vertices(obj, "RigidCells") - want).max() < 1e-3
    assert np.abs(vertices(obj, "RigidCells")[handle] - rest[handle] - [0, 0, 2.5]).max() < 1e-5
    bpy.app.timers.unregister(addon.follow._settle)
    monkeypatch.undo()

    scene.frame_start, scene.frame_end = 1, 5
    assert bpy.ops.rigidcells.bake() == {"FINISHED"}
    names = [k.name for k in obj.data.shape_keys.key_blocks]
    assert names == ["Basis"] + [f"RigidCells {f}" for f in range(1, 6)], names
    assert not obj.rigidcells.follow
    baked = vertices(obj, "RigidCells 5")
    assert np.abs(baked - shapes[5]).max() < 1e-3  # warm from frame 4 here, from frame 1 there
    # Each baked key is on at its frame only, as the animation plays.
    third = obj.data.shape_keys.key_blocks["RigidCells 3"]
    played = []
    for f in (2, 3, 4):
        scene.frame_set(f)
        played.append(third.value)
    assert played == [0.0, 1.0, 0.0], played
