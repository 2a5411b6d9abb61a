"""Piecewise-linear reconstruction of patch values (hat functions on welded vertices).

The solver's unknowns are constant per patch side.  Where the true function slopes
(into a concave corner, towards a contact, across a wall lit at a grazing angle), a
patch holds the mean over a strip a patch wide; reading that mean at a point next to
the edge is off by up to half a patch's slope.  This module maps side values onto
the vertices of :attr:`~raybundle.scene.PatchScene.smooth_vertex_ids` (tside corners
welded by position, side normal and contact tag: nothing bleeds over a crease or a
contact line) and reads them back at any point of a tside by its barycentrics.

Two maps, both linear in the side values and exact on constants:

* :meth:`LinearReconstruction.averaged`: each vertex the area-weighted mean of the
  sides around it (Gouraud);
* :meth:`LinearReconstruction.projected`: the L2 projection onto the hat functions,
  ``x = M^-1 b`` with ``M_uv = int phi_u phi_v dA`` (the consistent mass matrix over the
  receiving area) and ``b_v = int phi_v E dA = sum_T A_T E_T / 3``: the linear function
  whose patch means match, which slopes on into an edge where averaging flattens
  (``tests/test_reconstruction.py``).

The image and the bakes read the diffuse indirect light through :meth:`projected` (the
caustic first shot, sharp-edged, through :meth:`averaged`: :meth:`smooth_and_sharp`).  Tried and dropped: sending each diffuse
side's first shot into the bundles from its projection at the point a bundle line leaves
it (no change of the Cornell error at 600 iterations, 1.81% both ways; 40% more solver
time): a patch-wide linear fit of a steep fall-off is no closer near the edge than the
patch mean.
"""
from __future__ import annotations

import numpy as np


class LinearReconstruction:
    """Side values <-> welded-vertex values of one scene.

    ``tside_area`` (TS,) is the area each triangle side receives over (the solver's
    open area: parts buried in solids do not count) [m^2]."""

    def __init__(self, scene, tside_area):
        self.scene = scene
        self.ids = scene.smooth_vertex_ids                    # (TS, 3)
        self.n_vertices = int(self.ids.max()) + 1 if self.ids.size else 0
        self.area = np.asarray(tside_area, float)
        self._flat = self.ids.ravel()
        self._weight = np.repeat(self.area, 3)
        self.lumped = np.bincount(self._flat, self._weight / 3, minlength=self.n_vertices)
        self.empty = self.lumped <= 0                          # vertices without receiving area

    def _gather(self, per_corner):
        """Sum (V, C) of per-corner values (TS, 3, C) onto the welded vertices."""
        return np.stack([np.bincount(self._flat, per_corner[..., c].ravel(), minlength=self.n_vertices)
                         for c in range(per_corner.shape[-1])], axis=1)

    def averaged(self, side_values):
        """Side values (S, C) -> (V, C): the mean of the sides around each vertex,
        weighted by their receiving area (vertices without any: unweighted)."""
        tri = np.asarray(side_values, float)[self.scene.tside_side]            # (TS, C)
        w = np.where(self.empty[self.ids], 1.0, self.area[:, None])[..., None]   # (TS, 3, 1)
        num = self._gather(w * tri[:, None, :])
        den = self._gather(w)
        return num / np.maximum(den, 1e-300)

    def projected(self, side_values):
        """Side values (S, C) -> (V, C): the L2 projection onto the hat functions,
        clamped at zero (the fit may overshoot below zero next to a jump, and the
        values are radiances).  Vertices without receiving area take :meth:`averaged`."""
        tri = np.asarray(side_values, float)[self.scene.tside_side]
        b = self._gather((self.area[:, None] * tri / 3)[:, None, :].repeat(3, axis=1))
        x = np.maximum(self._solve_mass(b), 0.0)
        if self.empty.any():
            x[self.empty] = self.averaged(side_values)[self.empty]
        return x

    def smooth_and_sharp(self, side_values, sharp=None):
        """Side values (S, C) -> (V, C): :meth:`projected` of ``side_values - sharp`` plus
        :meth:`averaged` of ``sharp`` (S, C) (the caustic first shot: sharp-edged and
        noisy, which a projection would ring on: 5.9% -> 7.6% on ``cornell-glossy``)."""
        if sharp is None:
            return self.projected(side_values)
        return self.projected(side_values - sharp) + self.averaged(sharp)

    def at(self, vertex_values, tside, bary):
        """Values (N, C) at points of triangle sides ``tside`` (N,) with barycentrics
        ``bary`` (N, 3), linear between the welded-vertex values (V, C)."""
        return np.einsum("nk,nkc->nc", bary, vertex_values[self.ids[tside]])

    def _mass(self, v):
        """M v for v (V, C): ``M_uv = sum_T A_T (1 + [u = v]) / 12`` over the triangles
        holding u and v; rows of vertices without area are the identity."""
        vi = v[self.ids]                                          # (TS, 3, C)
        s = vi.sum(axis=1)
        # (A/12) (2 v_a + v_b + v_c) = (A/12) (v_a + sum)
        r = self._gather((self.area[:, None, None] / 12) * (vi + s[:, None, :]))
        r[self.empty] = v[self.empty]
        return r

    def _solve_mass(self, b, iterations=100, tol=1e-10):
        """x (V, C) with M x = b by Jacobi-preconditioned conjugate gradients (the lumped
        mass as preconditioner keeps the condition number below 4 on any mesh: a few
        tens of iterations; ``tol`` on the preconditioned residual, relative to b's)."""
        diag = np.where(self.empty, 1.0, self.lumped)[:, None]
        b = b.copy()
        b[self.empty] = 0.0
        x = b / diag
        r = b - self._mass(x)
        z = r / diag
        p = z.copy()
        rz = np.einsum("ij,ij->j", r, z)
        bnorm = np.maximum(np.einsum("ij,ij->j", b, b / diag), 1e-300)
        for _ in range(iterations):
            if np.all(rz <= tol * bnorm):
                break
            q = self._mass(p)
            alpha = rz / np.maximum(np.einsum("ij,ij->j", p, q), 1e-300)
            x += alpha * p
            r -= alpha * q
            z = r / diag
            rz_new = np.einsum("ij,ij->j", r, z)
            p = z + (rz_new / np.maximum(rz, 1e-300)) * p
            rz = rz_new
        return x
