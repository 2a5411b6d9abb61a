"""Uniform points on chosen patch sides, for rays that the sides gather or send by."""
from __future__ import annotations

import numpy as np

from ..tracing.sampling import points_on_triangles


class SidePoints:
    """Uniform points of chosen sides: their tsides with an area CDF per side (side id + fraction)."""

    def __init__(self, scene, chosen):
        """``chosen`` (S,) bool: the sides to draw points of."""
        self.scene = scene
        ts = np.nonzero(chosen[scene.tside_side])[0]
        self.tsides = ts = ts[np.argsort(scene.tside_side[ts], kind="stable")]
        a = scene.triangle_area[scene.tside_triangle[ts]]
        own = scene.tside_side[ts]
        total = np.bincount(own, a, minlength=scene.n_sides)
        self.cdf = own + (np.cumsum(a) - (np.cumsum(total) - total)[own]) / total[own]

    def draw(self, sides, u):
        """Points (N, 3) uniform on ``sides`` (N,) from uniforms ``u`` (N, 3), and the normals
        (N, 3) of the triangles they lie on (a cluster may be curved)."""
        sc = self.scene
        ts = self.tsides[np.minimum(np.searchsorted(self.cdf, sides + u[:, 0], side="right"), len(self.tsides) - 1)]
        return points_on_triangles(sc.triangle_corners[sc.tside_triangle[ts]], u[:, 1], u[:, 2]), sc.tside_normal[ts]
