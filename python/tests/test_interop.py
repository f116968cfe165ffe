"""trimesh and Open3D objects in and out: the command line's geometry, their attributes kept,
their normals turned."""

import subprocess

import numpy as np
import pytest

import rigidcells
from test_rigidcells import SHARED, cli

trimesh = pytest.importorskip("trimesh")
o3d = pytest.importorskip("open3d")

DRAGON = SHARED / "meshes" / "dragon_11k_binary.ply"


def lifted_top(points):
    """The lowest sixth fixed, the highest sixth lifted by a fifth of the height and turned."""
    lo, hi = points.min(axis=0), points.max(axis=0)
    h = hi[1] - lo[1]
    pad = 0.01 * (hi - lo).max()
    below = lo[1] + h / 6
    above = hi[1] - h / 6
    box = lambda y0, y1: {"min": [lo[0] - pad, y0, lo[2] - pad], "max": [hi[0] + pad, y1, hi[2] + pad]}
    return {
        "fixed": [{"box": box(lo[1] - pad, below)}],
        "handle": [
            {
                "box": box(above, hi[1] + pad),
                "translate": [0.0, 0.2 * h, 0.0],
                "rotate": {"axis": [0.0, 0.0, 1.0], "degrees": 25.0},
            }
        ],
    }


def test_a_trimesh_comes_back_moved_as_the_command_line_moves_it(tmp_path):
    mesh = trimesh.load(DRAGON, process=False)
    colors = np.random.default_rng(0).integers(0, 255, size=(len(mesh.vertices), 4), dtype=np.uint8)
    mesh.visual.vertex_colors = colors
    spec = lifted_top(np.asarray(mesh.vertices))
    bent, report = rigidcells.deform(mesh, spec, cells=3000, progress=False)
    assert isinstance(bent, trimesh.Trimesh) and bent is not mesh
    assert np.array_equal(bent.faces, mesh.faces)
    assert np.array_equal(bent.visual.vertex_colors, colors)
    assert report.residual_fixed_max == 0.0
    # The command line on the file: the same vertices (it writes them as the file's float32).
    edit = tmp_path / "edit.toml"
    import json

    edit.write_text(rigidcells._rigidcells.toml_from_json(json.dumps(spec)))
    out = tmp_path / "bent.ply"
    subprocess.run(
        [cli(), "deform", str(DRAGON), "-o", str(out), "--edit", str(edit), "--cells", "3000", "-q"],
        check=True,
    )
    written = trimesh.load(out, process=False)
    assert np.array_equal(np.asarray(written.vertices), bent.vertices.astype(np.float32).astype(np.float64))
    # The input is untouched, and its normals follow from the moved faces.
    assert not np.array_equal(mesh.vertices, bent.vertices)
    assert not np.allclose(bent.face_normals, mesh.face_normals)
    # A field applies to a trimesh point cloud the same way.
    field = rigidcells.solve(mesh, spec, cells=3000, progress=False)
    cloud = trimesh.PointCloud(mesh.vertices, colors=colors)
    moved = field.apply(cloud)
    assert isinstance(moved, trimesh.PointCloud) and np.array_equal(moved.vertices, bent.vertices)
    assert np.array_equal(moved.colors, colors)


def test_open3d_meshes_and_clouds_keep_colors_and_turn_normals():
    mesh = trimesh.load(DRAGON, process=False)
    vertices, faces = np.asarray(mesh.vertices), np.asarray(mesh.faces)
    spec = lifted_top(vertices)
    o_mesh = o3d.geometry.TriangleMesh(
        o3d.utility.Vector3dVector(vertices), o3d.utility.Vector3iVector(faces)
    )
    o_mesh.compute_vertex_normals()
    colors = np.random.default_rng(1).uniform(size=(len(vertices), 3))
    o_mesh.vertex_colors = o3d.utility.Vector3dVector(colors)
    normals = np.asarray(o_mesh.vertex_normals).copy()
    bent, report = rigidcells.deform(o_mesh, spec, cells=3000, progress=False)
    plain, plain_report = rigidcells.deform(
        vertices, spec, triangles=faces, normals=normals, cells=3000, progress=False
    )
    assert isinstance(bent, o3d.geometry.TriangleMesh)
    assert np.array_equal(np.asarray(bent.vertices), plain)
    assert np.array_equal(np.asarray(bent.vertex_normals), plain_report.normals)
    assert np.array_equal(np.asarray(bent.triangles), faces)
    assert np.array_equal(np.asarray(bent.vertex_colors), colors)
    assert np.array_equal(np.asarray(o_mesh.vertices), vertices)  # the input untouched
    cloud = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(vertices))
    cloud.normals = o3d.utility.Vector3dVector(normals)
    cloud.colors = o3d.utility.Vector3dVector(colors)
    field = rigidcells.solve(vertices, spec, triangles=faces, cells=3000, progress=False)
    moved = field.apply(cloud)
    assert isinstance(moved, o3d.geometry.PointCloud)
    assert np.array_equal(np.asarray(moved.points), plain)
    turned = np.asarray(moved.normals)
    assert np.allclose(turned, plain_report.normals, atol=1e-12)
    assert np.array_equal(np.asarray(moved.colors), colors)
    # A handle's normals turn with it: 25° about z.
    top = vertices[:, 1] > vertices[:, 1].max() - 0.1 * np.ptp(vertices[:, 1])
    c, s = np.cos(np.radians(25)), np.sin(np.radians(25))
    rotated = normals[top] @ np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]]).T
    assert np.allclose(turned[top], rotated, atol=1e-9)
