"""Embree over a few triangles of their own (a lamp's), apart from the scene."""
from __future__ import annotations

import numpy as np


class TriangleSet:
    """Embree over a few triangles of their own (a lamp's), apart from the scene: where rays
    first meet them, whatever else lies in the way."""

    def __init__(self, corners):
        """``corners`` (K, 3, 3) [m]."""
        from embreex import rtcore_scene
        from embreex.mesh_construction import TriangleMesh

        corners = np.asarray(corners, float)
        self.center = corners.reshape(-1, 3).mean(axis=0)
        self._embree = rtcore_scene.EmbreeScene()
        TriangleMesh(self._embree, (corners.reshape(-1, 3) - self.center).astype(np.float32),
                     np.arange(3 * len(corners), dtype=np.int32).reshape(-1, 3))

    def first_hit(self, origins, directions):
        """(triangle index (N,) or -1, distance t (N,) [m]) of rays from ``origins`` along unit
        ``directions`` (N, 3)."""
        r = self._embree.run(np.ascontiguousarray(origins - self.center, np.float32),
                             np.ascontiguousarray(directions, np.float32), output=1)
        tri = np.asarray(r["primID"], np.int64)
        return np.where(tri >= 0, tri, -1), np.asarray(r["tfar"], float)
