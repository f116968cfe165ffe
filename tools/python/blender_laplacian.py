"""The soup of ten loose cubes in a row, bent by Blender's Laplacian Deform modifier (what an
artist tries first: the end cubes anchored, the last one hooked to an Empty lifted by 4) and by
the Rigid Cells add-on, side by side: how far each cube rises, and how much it loses its shape.

    python tools/python/blender_laplacian.py [PICTURE.png RIGIDCELLS]

(in a venv with `bpy` and `rigidcells`). With a picture's path and the `rigidcells` binary, it
also writes both bent soups as one PLY, Laplacian Deform below, and renders it.
"""

import sys
from pathlib import Path

import bpy  # first: bmesh and mathutils come with it
import bmesh
import numpy as np
from mathutils import Matrix

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "blender"))
import rigidcells_blender as addon  # noqa: E402

CUBES, SIZE, LIFT = 10, 0.8, 4.0


def soup(name):
    mesh = bpy.data.meshes.new(name)
    bm = bmesh.new()
    for k in range(CUBES):
        bmesh.ops.create_cube(bm, size=SIZE, matrix=Matrix.Translation((k - 4.5, 0, 0)))
    bm.to_mesh(mesh)
    obj = bpy.data.objects.new(name, mesh)
    bpy.context.collection.objects.link(obj)
    for group, test in (("fixed", lambda x: x < -4.0), ("handle", lambda x: x > 4.0)):
        g = obj.vertex_groups.new(name=group)
        g.add([v.index for v in mesh.vertices if test(v.co.x)], 1.0, "REPLACE")
    both = obj.vertex_groups.new(name="anchors")
    both.add([v.index for v in mesh.vertices if abs(v.co.x) > 4.0], 1.0, "REPLACE")
    return obj


def coords(data):
    co = np.empty(3 * len(data), dtype=np.float32)
    data.foreach_get("co", co)
    return co.reshape(-1, 3).astype(np.float64)


def faces(obj):
    """The mesh's quads as triangles."""
    return [
        tri
        for p in obj.data.polygons
        for tri in ((p.vertices[0], p.vertices[1], p.vertices[2]),
                    (p.vertices[0], p.vertices[2], p.vertices[3]))
    ]


def per_cube(rest, bent):
    """Each cube's mean rise and the largest change of a distance between its corners."""
    rows = []
    for k in range(CUBES):
        a, b = rest[8 * k : 8 * k + 8], bent[8 * k : 8 * k + 8]
        da = np.linalg.norm(a[:, None] - a[None], axis=-1)
        db = np.linalg.norm(b[:, None] - b[None], axis=-1)
        rows.append(((b - a)[:, 2].mean(), np.abs(da - db).max()))
    return rows


def laplacian():
    obj = soup("laplacian")
    bpy.ops.object.empty_add(location=(4.5, 0, 0))
    empty = bpy.context.active_object
    hook = obj.modifiers.new("hook", "HOOK")
    hook.object, hook.vertex_group = empty, "handle"
    bpy.context.view_layer.objects.active = obj
    lap = obj.modifiers.new("laplacian", "LAPLACIANDEFORM")
    lap.vertex_group = "anchors"
    bpy.ops.object.laplaciandeform_bind(modifier="laplacian")
    empty.location = (4.5, 0, LIFT)
    depsgraph = bpy.context.evaluated_depsgraph_get()
    bent = coords(obj.evaluated_get(depsgraph).data.vertices)
    return per_cube(coords(obj.data.vertices), bent), bent, faces(obj)


def rigid_soup(name):
    """The soup bent by the add-on: its first cube the fixed group, its last on the Empty."""
    obj = soup(name)
    bpy.ops.object.empty_add(location=(4.5, 0, 0))
    empty = bpy.context.active_object
    bpy.context.view_layer.objects.active = obj
    s = obj.rigidcells
    s.fixed_group, s.handle_group, s.handle_object = "fixed", "handle", empty
    empty.location = (4.5, 0, LIFT)
    bpy.context.view_layer.update()
    bpy.ops.object.rigidcells_deform()
    return obj


def rigid_cells():
    obj = rigid_soup("rigidcells")
    key = obj.data.shape_keys.key_blocks["RigidCells"]
    bent = coords(key.data)
    return per_cube(coords(obj.data.vertices), bent), bent, faces(obj)


def main():
    bpy.ops.wm.read_factory_settings(use_empty=True)
    addon.register()
    (lap, lap_bent, tris), (ours, our_bent, _) = laplacian(), rigid_cells()
    print("| cube | Laplacian Deform: rise | shape change | Rigid Cells: rise | shape change |")
    print("|---|---|---|---|---|")
    for k, ((la, ls), (ra, rs)) in enumerate(zip(lap, ours)):
        print(f"| {k} | {la:.3f} | {ls:.3f} | {ra:.3f} | {rs:.3f} |")
    if len(sys.argv) > 2:
        picture(Path(sys.argv[1]), sys.argv[2], lap_bent, our_bent, tris)


def picture(out, binary, lap_bent, our_bent, tris):
    """Both soups in one PLY (the Laplacian's 5.5 below), rendered by `rigidcells render`."""
    import subprocess
    import tempfile

    behind = lap_bent + [0.0, 0.0, -5.5]
    verts = np.vstack([our_bent, behind])
    n = len(our_bent)
    all_tris = list(tris) + [tuple(i + n for i in t) for t in tris]
    with tempfile.TemporaryDirectory() as d:
        ply = Path(d) / "soups.ply"
        lines = ["ply", "format ascii 1.0", "comment up z", f"element vertex {len(verts)}",
                 "property float x", "property float y", "property float z",
                 f"element face {len(all_tris)}", "property list uchar int vertex_indices",
                 "end_header"]
        lines += [f"{x:.6f} {y:.6f} {z:.6f}" for x, y, z in verts]
        lines += [f"3 {a} {b} {c}" for a, b, c in all_tris]
        ply.write_text("\n".join(lines) + "\n")
        subprocess.run([binary, "render", str(ply), "-o", str(out), "--azimuth", "-80",
                        "--elevation", "15", "--size", "800x500"], check=True)


if __name__ == "__main__":
    main()
