"""A point that stands for an area of its triangle, as a lightmap texel stands for its footprint.

Cycles' bake averages a texel over its footprint (its jittered samples stay on the texel's
triangle); a texel whose footprint straddles a shadow's edge or reaches under an object standing on
the surface takes the share of each.  :class:`Footprint` gives, for a sample ``u`` in the unit
square, the point ``x + (u_0 - 1/2) du + (u_1 - 1/2) dv`` (``du``, ``dv`` the texel's steps on the
surface), pulled back into the triangle where it falls outside (barycentrics clamped at
:data:`INSIDE`, so that it does not lie on a neighbouring face's plane).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .sampling import triangle_barycentrics

#: the smallest barycentric a footprint's point keeps
INSIDE = 1e-4


@dataclass
class Footprint:
    """N points' footprints: steps ``du``, ``dv`` (N, 3) [m] and their triangles' ``corners`` (N, 3, 3)."""

    du: np.ndarray
    dv: np.ndarray
    corners: np.ndarray

    def subset(self, which):
        return Footprint(self.du[which], self.dv[which], self.corners[which])

    def points(self, centres, u):
        """(N, 3) points of the footprints around ``centres`` (N, 3) at samples ``u`` (N, 2) in [0, 1)^2."""
        p = centres + (u[:, :1] - 0.5) * self.du + (u[:, 1:2] - 0.5) * self.dv
        b = np.maximum(triangle_barycentrics(self.corners, p), INSIDE)
        b /= b.sum(axis=1, keepdims=True)
        return np.einsum("nk,nkc->nc", b, self.corners)
