"""Meshes and point clouds of trimesh and Open3D, in and out. Neither library is a
dependency: their objects are recognized only when the library is imported (an object of its
classes exists only then), and nothing here imports them.

An object gives its vertices, its triangles (which the cells' inside test uses) and its
normals where it has them; the moved object is a copy with its vertices moved and its normals
turned as the map turns the surface, every other attribute (colors, faces, metadata) kept.
"""

from __future__ import annotations

import sys
from typing import Any, Optional

import numpy as np


def _module(name: str) -> Any:
    return sys.modules.get(name)


class Geometry:
    """A trimesh or Open3D object as the package's inputs, and ``back`` to one of its kind."""

    def __init__(self, kind: str, source: Any, xyz: np.ndarray) -> None:
        self.kind = kind
        self.source = source
        self.xyz = np.ascontiguousarray(xyz, dtype=np.float64)
        self.triangles: Optional[np.ndarray] = None
        self.normals: Optional[np.ndarray] = None

    def back(self, moved: np.ndarray, turned: Optional[np.ndarray]) -> Any:
        """A copy of the source with ``moved`` vertices (and ``turned`` normals)."""
        if self.kind == "trimesh":
            out = self.source.copy()
            # trimesh derives face and vertex normals from the moved faces.
            out.vertices = moved
            return out
        if self.kind == "trimesh-points":
            out = self.source.copy()
            out.vertices = moved
            return out
        o3d = _module("open3d")
        vector = o3d.utility.Vector3dVector
        if self.kind == "open3d-points":
            out = o3d.geometry.PointCloud(self.source)
            out.points = vector(moved)
            if turned is not None:
                out.normals = vector(turned)
            return out
        out = o3d.geometry.TriangleMesh(self.source)
        out.vertices = vector(moved)
        if self.source.has_triangle_normals():
            out.compute_triangle_normals()
        # After the faces' normals, which Open3D's computation may renormalize these with.
        if turned is not None:
            out.vertex_normals = vector(turned)
        return out


def of(points: Any) -> Optional[Geometry]:
    """``points`` as a ``Geometry`` when it is a trimesh or Open3D object, else None."""
    trimesh = _module("trimesh")
    if trimesh is not None:
        if isinstance(points, trimesh.Trimesh):
            g = Geometry("trimesh", points, np.asarray(points.vertices))
            g.triangles = np.asarray(points.faces, dtype=np.int64)
            return g
        if isinstance(points, trimesh.PointCloud):
            return Geometry("trimesh-points", points, np.asarray(points.vertices))
    o3d = _module("open3d")
    if o3d is not None:
        if isinstance(points, o3d.geometry.PointCloud):
            g = Geometry("open3d-points", points, np.asarray(points.points))
            if points.has_normals():
                g.normals = np.asarray(points.normals, dtype=np.float64)
            return g
        if isinstance(points, o3d.geometry.TriangleMesh):
            g = Geometry("open3d-mesh", points, np.asarray(points.vertices))
            g.triangles = np.asarray(points.triangles, dtype=np.int64)
            if points.has_vertex_normals():
                g.normals = np.asarray(points.vertex_normals, dtype=np.float64)
            return g
    return None
