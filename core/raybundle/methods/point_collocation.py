"""Point collocation with linear basis functions (thesis 3): the incoming radiance at mesh
vertices, linear over each triangle, beside the Galerkin constant-per-patch unknowns of the
bundle iteration.

The unknowns are the welded vertices of :attr:`~raybundle.scene.model.PatchScene.smooth_vertex_ids`
(tside corners joined by position, side normal and contact tag: one value per corner of a
smooth surface, separate values on either side of a crease or a contact line), so the
interpolation the image reads is the solution itself, not a projection of patch means.  The
equation is collocated at the vertices (algorithms.md 3):

    E_v = integral L(h(x_v, -d), d) cos_v(d) dd,
    L(y, d) = Le(y, d) + kd(y)/pi (sum_u E_u b_u(y) + E1(y))     (diffuse surfaces)

with b_u the hat functions (barycentrics of the triangle y lies on), E1 the first shot and
E [W/m^2] the incoming irradiance-like value of the iteration.  One step is the stochastic
iteration's random operator with uniform global directions d_k (k = 1..K per step): each
vertex looks upstream along -d_k by one ray from a point just inside one of its triangles,
reads the radiance sent along d_k at the hit from the previous iterate, and

    E_v <- (1/K) sum_k 4 pi max(-n_v . d_k, 0) L(h(x_v, -d_k), d_k)

(unbiased: E[4 pi cos+ L] over uniform d is the integral).  The image is the running average
after a burn-in, read through the same linear interpolation; per side, the mean of its
vertex values stands in for bakes and flat reads.  Diffuse scenes only; a step costs one ray
per vertex and direction (the bundles of the Galerkin version: one per grid cell).
"""
from __future__ import annotations

import time

import numpy as np

from ..patches.reconstruction import LinearReconstruction
from ..tracing.sampling import uniform_sphere
from .patch_solution import PatchSolution

#: collocation points sit this fraction of the way from a vertex towards its triangle's centroid
#: (a ray from the exact corner may slip through the neighbouring face's edge)
INSET = 1e-3


class CollocationReconstruction(LinearReconstruction):
    """The reconstruction of a collocation solver.  Its readers (image, final gather, bakes)
    pass side values that hold the solver's side means (``solver.mean_incoming``, plus first
    shot or caustics); the collocation solution is more than the projection of those means,
    so every projected read adds the difference, ``detail = V - projected(side_means(V))``
    for the running-average vertex values V (0 for a solution that is linear over patches;
    exactly V for the solver's own side means)."""

    def __init__(self, scene, tside_area, solver):
        super().__init__(scene, tside_area)
        self.solver = solver
        self._detail = (None, None)                           # (averaged count, detail)

    def detail(self):
        s = self.solver
        if self._detail[0] != (s.stats.iterations, s.averaged):
            self._detail = ((s.stats.iterations, s.averaged),
                            s.mean_vertex_incoming - super().projected(s.mean_incoming))
        return self._detail[1]

    def projected(self, side_values, dtype=float):
        x = super().projected(side_values, dtype)
        x += self.detail()
        return x


class PointCollocationSolver(PatchSolution):
    """Stochastic iteration on vertex unknowns with linear basis functions (module docstring).
    The first shot, the image and the set-up are the bundle iteration's."""

    SEPARATES_WORLD_DIRECT = False        # its own step: the world's light stays in its solution

    name = "point-collocation"
    #: each step applies a random operator to the previous iterate (thesis 1.2)
    iterates = True
    #: its vertex averages are not in :class:`~raybundle.app.chains.ChainState`
    merges_chains = False

    #: diffuse scenes only: no glossy reflection of the first shot
    TAKES_CAUSTIC_SHOT = False

    def __init__(self, scene, tracer, direct, settings, camera=None):
        super().__init__(scene, tracer, direct, settings)
        if not self.diffuse_only:
            raise ValueError("point collocation handles diffuse scenes only; this scene has glossy surfaces "
                             "(use stochastic-iteration)")
        rec = CollocationReconstruction(scene, self.tside_open_area, self)
        self.reconstruction = rec
        ids = rec.ids                                         # (TS, 3) vertex of each tside corner
        n_v = rec.n_vertices
        # one collocation point per vertex: a corner of one of its tsides with receiving area
        order = np.argsort(np.where(rec.area[:, None] > 0, 0, 1).repeat(3, axis=1).ravel(), kind="stable")
        flat = ids.ravel()[order]
        first = np.full(n_v, -1, np.int64)
        first[flat[::-1]] = order[::-1]
        ts, corner = np.divmod(first, 3)
        c = scene.triangle_corners[scene.tside_triangle[ts]]                # (V, 3, 3)
        x = c[np.arange(n_v), corner]
        self.vertex_point = x + INSET * (c.mean(axis=1) - x)
        self.vertex_normal = scene.tside_normal[ts]
        self.vertex_receives = ~rec.empty
        self.vertex_incoming = np.zeros((n_v, 3))
        self.mean_vertex_incoming = np.zeros((n_v, 3))
        # side means of the vertex values: each tside's corner mean, weighted by its area
        self._tside_weight = rec.area / np.maximum(np.bincount(scene.tside_side, rec.area,
                                                               minlength=scene.n_sides)[scene.tside_side], 1e-300)

    def side_means(self, vertex_values):
        """(S, 3): each side's area-weighted mean of the linear function with ``vertex_values``."""
        sc = self.scene
        per_tside = vertex_values[self.reconstruction.ids].mean(axis=1) * self._tside_weight[:, None]
        return np.stack([np.bincount(sc.tside_side, per_tside[:, c], minlength=sc.n_sides) for c in range(3)],
                        axis=1)

    def collocate(self, directions):
        """E_v (V, 3) [W/m^2] from the current iterate along ``directions`` (K, 3) (module docstring)."""
        sc, tr = self.scene, self.tracer
        fs = self.first_shot.E.sum(axis=1)                    # (S, 3) first shot per side
        out = np.zeros_like(self.vertex_incoming)
        recv = np.nonzero(self.vertex_receives)[0]
        for d in directions:
            cos = -(self.vertex_normal[recv] @ d)
            v = recv[cos > 0]
            cos = cos[cos > 0]
            if not len(v):
                continue
            up = np.broadcast_to(-d, (len(v), 3))
            tri, _, bu, bv = tr.first_hit(self.vertex_point[v] + self.vertex_normal[v] * tr.eps, up)
            self.stats.rays += len(v)
            hit = tri >= 0
            L = np.zeros((len(v), 3))
            if sc.world.emits:
                L[~hit] = sc.world.radiance(up[~hit])
            h = np.nonzero(hit)[0]
            if len(h):
                ts = sc.seen_tside(tri[h], up[h])
                side = sc.tside_side[ts]
                facing = np.einsum("ij,j->i", sc.tside_normal[ts], d) > 0
                h, ts, side = h[facing], ts[facing], side[facing]
                bary = np.stack([1 - bu[h] - bv[h], bu[h], bv[h]], axis=1)
                e = self.reconstruction.at(self.vertex_incoming, ts, bary) + fs[side]
                L[h] = self.radiance(side, np.broadcast_to(d, (len(h), 3)), diffuse_incoming=e,
                                     first_shot_emission=False)
            out[v] += 4.0 * np.pi * cos[:, None] * L
        return out / len(directions)

    def step(self):
        """One iteration: ``directions_per_step`` global directions, every vertex collocated
        along each, then the running average (restarted once after ``burn_in``)."""
        t0 = time.perf_counter()
        before = self.direct.rays
        self.refine_first_shot()
        k = self.directions_per_step
        d = np.array([uniform_sphere(*self.sequence.next(2)) for _ in range(k)])
        self.vertex_incoming = self.collocate(d)
        self.incoming = self.side_means(self.vertex_incoming)
        st = self.stats
        st.iterations += 1
        st.directions += k
        self.direction = d[-1]
        self.averaged = st.iterations - (self.burn_in if st.iterations > self.burn_in else 0)
        self.mean_vertex_incoming += (self.vertex_incoming - self.mean_vertex_incoming) / self.averaged
        self.mean_incoming = self.side_means(self.mean_vertex_incoming)
        st.rays += self.direct.rays - before
        st.seconds += time.perf_counter() - t0

    def report(self):
        return {"vertices": int(self.reconstruction.n_vertices)}
