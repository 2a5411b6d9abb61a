"""Piecewise-linear reconstruction of patch values (hat functions on welded vertices).

The solver's unknowns are constant per patch side.  Where the true function slopes
(into a concave corner, towards a contact, across a wall lit at a grazing angle), a
patch holds the mean over a strip a patch wide; reading that mean at a point next to
the edge is off by up to half a patch's slope.  This module maps side values onto
the vertices of :attr:`~raybundle.scene.model.PatchScene.smooth_vertex_ids` (tside corners
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

A patch that is a cluster of many small triangles (:mod:`raybundle.patches.clusters`) has hat
functions on its own fine triangles, so the projection would only round its step over
one of them.  The projection therefore runs over the other sides only, and the welded
vertices of cluster sides alone take instead the mean of
the linear fits ``v_s + g_s . (x - c_s)`` of the clusters around them, with ``c_s`` the
cluster's centroid and ``g_s`` the least-squares gradient in its tangent plane over the
sides it shares a welded vertex with (weights 1 / distance^2): exact on linear
functions, and, as ``c_s`` is the centroid, each fit keeps the cluster's mean.

The image and the bakes read the diffuse indirect light through :meth:`projected` (the
caustic first shot, sharp-edged, through :meth:`averaged`: :meth:`smooth_and_sharp`).  Tried and dropped: sending each diffuse
side's first shot into the bundles from its projection at the point a bundle line leaves
it (no change of the Cornell error, more solver time: docs/benchmarks.md, 'Measured choices behind the
defaults'): a patch-wide linear fit of a steep fall-off is no closer near the edge than the
patch mean.
"""
from __future__ import annotations

from functools import cached_property

import numpy as np

from ..util import compiled
from ..util.arrays import stable_order, unique_ints

#: sides of at least this many triangles are clusters, read through their linear fits
#: (module docstring)
CLUSTER_TRIANGLES = 8


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
        self.lumped = np.bincount(self._flat, np.repeat(self.area, 3) / 3, minlength=self.n_vertices)
        self.empty = self.lumped <= 0                          # vertices without receiving area
        many = np.bincount(scene.tside_side, minlength=scene.n_sides) >= CLUSTER_TRIANGLES
        self._fit = ClusterFit(scene, self.area, self.ids, many) if many.any() else None
        # the projection's mesh: the tsides of sides that are not clusters (all without any), those
        # with receiving area, on their own vertices (numbered 0 .. Vp - 1: the fits' vertices of the
        # clusters, most of a furnished room's, take no part in its solve)
        p = np.nonzero(~many[scene.tside_side])[0] if self._fit is not None else np.arange(len(self.ids))
        p = p[self.area[p] > 0]
        self._p_side, self._p_area = scene.tside_side[p], self.area[p]
        self._p_vertices, local = np.unique(self.ids[p], return_inverse=True)
        self._p_ids = local.reshape(-1, 3).astype(self.ids.dtype)
        self._p_flat = self._p_ids.ravel()
        self._p_lumped = np.bincount(self._p_flat, np.repeat(self._p_area, 3) / 3, minlength=len(self._p_vertices))
        # vertices neither the projection nor a fit gives a value: the sides' mean around them
        self._fallback = np.ones(self.n_vertices, bool)
        self._fallback[self._p_vertices] = False
        if self._fit is not None:
            self._fallback[self._fit.vertices] = False
        self._fallback_tsides = np.nonzero(self._fallback[self.ids].any(axis=1))[0]

    def _gather(self, per_corner, flat=None, n=None):
        """Sum (n, C) of per-corner values (TS, 3, C) onto the welded vertices (``flat``:
        the corners' vertex ids, default all tsides'; ``n`` default all vertices)."""
        flat = self._flat if flat is None else flat
        n = self.n_vertices if n is None else n
        return np.stack([np.bincount(flat, per_corner[..., c].ravel(), minlength=n)
                         for c in range(per_corner.shape[-1])], axis=1)

    @cached_property
    def _average_sums(self):
        """(V,) the sums of :meth:`averaged`'s weights over all tsides, at least 1e-300 (its
        divisor; the weights themselves, (TS, 3), are made per call and only on the NumPy path)."""
        if compiled.use():
            sums = _scatter_sides(self.ids, self.area, self.scene.tside_side, np.ones((self.scene.n_sides, 1)),
                                  self.n_vertices, self.empty)[:, 0]
        else:
            sums = np.bincount(self._flat, self._corner_weights(self.ids, self.area).ravel(), minlength=self.n_vertices)
        return np.maximum(sums, 1e-300, out=sums)

    def _corner_weights(self, ids, area):
        """(N, 3) :meth:`averaged`'s weight of each corner of tsides ``ids`` (N, 3) of receiving
        ``area`` (N,): the area, 1 at a vertex without receiving area."""
        return np.where(self.empty[ids], 1.0, area[:, None])

    def averaged(self, side_values, tsides=None, dtype=float):
        """Side values (S, C) -> (V, C) of ``dtype``: the mean of the sides around each vertex,
        weighted by their receiving area (vertices without any: unweighted); with
        ``tsides`` (indices) over those alone (right at the vertices all of whose tsides they hold).
        Summed in 64 bits; into a narrower ``dtype`` a column at a time (one (V,) float64 beside
        the result, not a (V, C))."""
        if np.dtype(dtype) == np.float64:
            out = self._numerator(side_values, tsides)
            out /= self._average_sums[:, None]        # in place: (V, C) is the largest array
            return out
        side_values = np.asarray(side_values, float)
        out = np.empty((self.n_vertices, side_values.shape[1]), dtype)
        for c in range(side_values.shape[1]):
            column = self._numerator(side_values[:, c:c + 1], tsides)[:, 0]
            column /= self._average_sums
            out[:, c] = column
            del column                                 # before the next one is made
        return out

    def _numerator(self, side_values, tsides=None):
        """(V, C) :meth:`averaged`'s weighted sums at each vertex, before the division."""
        ids, side, area = self.ids, self.scene.tside_side, self.area
        if tsides is not None:
            ids, side, area = ids[tsides], side[tsides], area[tsides]
        if compiled.use():
            return _scatter_sides(ids, area, side, np.ascontiguousarray(side_values, float), self.n_vertices,
                                  self.empty)
        tri = np.asarray(side_values, float)[side]                              # (TS, C)
        return self._gather(self._corner_weights(ids, area)[..., None] * tri[:, None, :], ids.ravel())

    def projected(self, side_values, dtype=float):
        """Side values (S, C) -> (V, C) of ``dtype``: the L2 projection onto the hat functions,
        clamped at zero (the fit may overshoot below zero next to a jump, and the
        values are radiances).  Vertices without receiving area take :meth:`averaged`.  The
        mass system is solved in 64 bits; the cluster fits sum their corners in ``dtype``."""
        side_values = np.ascontiguousarray(side_values, float)
        nv = len(self._p_vertices)
        if compiled.use():
            b = _scatter_sides(self._p_ids, self._p_area / 3, self._p_side, side_values, nv, np.zeros(nv, bool))
        else:
            tri = side_values[self._p_side]
            b = self._gather((self._p_area[:, None] * tri / 3)[:, None, :].repeat(3, axis=1), self._p_flat, nv)
        # the fallback's vertices read their tsides' average (the other rows are written below)
        x = self.averaged(side_values, self._fallback_tsides, dtype) if len(self._fallback_tsides) else \
            np.zeros((self.n_vertices, side_values.shape[1]), dtype)
        x[self._p_vertices] = np.maximum(self._solve_mass(b), 0.0)
        if self._fit is not None:
            self._fit.vertex_values(np.asarray(side_values, float), out=x)
        return x

    def smooth_and_sharp(self, side_values, sharp=None, dtype=float):
        """Side values (S, C) -> (V, C): :meth:`projected` of ``side_values - sharp`` plus
        :meth:`averaged` of ``sharp`` (S, C) (the caustic first shot: sharp-edged and
        noisy, which a projection would ring on; projected, it measured worse on ``cornell-glossy``:
        docs/benchmarks.md, 'Measured choices behind the defaults'), kept as ``dtype`` (float32
        for values an image reads: half the memory of the vertices)."""
        return self.smooth_and_sharp_many([(side_values, sharp)], dtype)[0]

    def smooth_and_sharp_many(self, pairs, dtype=float):
        """:meth:`smooth_and_sharp` of each ``(side_values, sharp)`` in ``pairs``, as a list: one
        projection of all their columns side by side (the same values: the projection and its
        clamp act column by column), so the mesh's work is done once, not once per pair.  The
        values are views of that one (V, C) array of ``dtype``."""
        pairs = [(np.asarray(v, float), s) for v, s in pairs]
        stacked = np.concatenate([v if s is None else v - s for v, s in pairs], axis=1)
        x = self.projected(stacked, dtype)
        out, c = [], 0
        for v, s in pairs:
            part = x[:, c:c + v.shape[1]]
            if s is not None:
                s = np.asarray(s, float)
                for j in range(s.shape[1]):    # in x's own columns, a (V,) float64 at a time beside it
                    part[:, j] += self.averaged(s[:, j:j + 1])[:, 0]
            out.append(part)
            c += v.shape[1]
        return out

    def at(self, vertex_values, tside, bary):
        """Values (N, C) at points of triangle sides ``tside`` (N,) with barycentrics
        ``bary`` (N, 3), linear between the welded-vertex values (V, C)."""
        return np.einsum("nk,nkc->nc", bary, vertex_values[self.ids[tside]])

    def _mass(self, v):
        """M v for v (Vp, C) on the projection's vertices: ``M_uv = sum_T A_T (1 + [u = v]) / 12``
        over the triangles holding u and v."""
        if compiled.use():
            return _mass_product(self._p_ids, self._p_area, np.ascontiguousarray(v), len(v))
        vi = v[self._p_ids]                                       # (TS, 3, C)
        s = vi.sum(axis=1)
        # (A/12) (2 v_a + v_b + v_c) = (A/12) (v_a + sum)
        return self._gather((self._p_area[:, None, None] / 12) * (vi + s[:, None, :]), self._p_flat, len(v))

    def _solve_mass(self, b, iterations=100, tol=1e-10):
        """x (V, C) with M x = b by Jacobi-preconditioned conjugate gradients (the lumped
        mass as preconditioner keeps the condition number below 4 on any mesh: a few
        tens of iterations; ``tol`` on the preconditioned residual, relative to b's)."""
        diag = self._p_lumped[:, None]
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


class ClusterFit:
    """The linear fits of cluster sides and the welded vertices read from them (module docstring).

    ``scene``, ``tside_area`` (TS,) [m^2] and welded vertex ``ids`` (TS, 3) as in
    :class:`LinearReconstruction`; ``cluster`` (S,) bool marks the cluster sides."""

    def __init__(self, scene, tside_area, ids, cluster):
        side = scene.tside_side
        n_sides = scene.n_sides
        a = np.where(np.bincount(side, tside_area, minlength=n_sides)[side] > 0, tside_area,
                     scene.triangle_area[scene.tside_triangle])
        centre = scene.triangle_corners.mean(axis=1)[scene.tside_triangle]
        side_area = np.bincount(side, a, minlength=n_sides)
        self.centroid = np.stack([np.bincount(side, a * centre[:, k], minlength=n_sides)
                                  for k in range(3)], axis=1) / np.maximum(side_area, 1e-300)[:, None]
        del centre
        # sides that share a welded vertex: distinct (vertex, side) pairs, neighbours within a vertex
        # (pairs as one integer key each: one sort, no dense ids first)
        cv, cs = ids.ravel(), np.repeat(side.astype(np.int32 if n_sides < 2 ** 31 else np.int64), 3)
        key = cv.astype(np.int64)
        key *= n_sides
        key += cs                                 # made in place, and sorted in place
        first = unique_ints(key, own=True, inverse=False)[1]
        del key
        order = first[stable_order(cv[first])[0]]
        v, s = cv[order], cs[order]
        del first, order
        start = np.flatnonzero(np.r_[True, v[1:] != v[:-1]])
        size = np.diff(np.r_[start, len(v)])
        left = np.repeat(size, size) - (np.arange(len(v)) - np.repeat(start, size)) - 1
        s1, s2 = [], []
        for off in range(1, int(size.max(initial=1))):
            i = np.nonzero(left >= off)[0]
            s1 += [s[i], s[i + off]]
            s2 += [s[i + off], s[i]]
        del v, s, start, size, left
        s1 = np.concatenate(s1) if s1 else np.zeros(0, np.int64)
        s2 = np.concatenate(s2) if s2 else np.zeros(0, np.int64)
        at = cluster[s1]                                  # pairs from a cluster side, each once
        s1, s2 = s1[at], s2[at]
        pair = s1.astype(np.int64)
        pair *= n_sides
        pair += s2
        keep = unique_ints(pair, own=True, inverse=False)[1]
        del pair
        self.s1, self.s2 = s1[keep], s2[keep]
        del s1, s2, keep
        d = self.centroid[self.s2] - self.centroid[self.s1]
        self.wd = d / np.maximum(np.einsum("ij,ij->i", d, d), 1e-300)[:, None]            # w d, w = 1 / |d|^2
        self.sides = np.nonzero(cluster)[0]
        row = np.full(n_sides, -1, np.int64)
        row[self.sides] = np.arange(len(self.sides))
        self.row = row
        r1 = row[self.s1]
        m = np.zeros((len(self.sides), 3, 3))
        for i in range(3):
            for j in range(3):
                m[:, i, j] = np.bincount(r1, self.wd[:, i] * d[:, j], minlength=len(self.sides))
        # only the tangent plane: the normal direction gets a stiff weight, so g . n = 0
        n = scene.side_normal[self.sides]
        scale = np.trace(m, axis1=1, axis2=2)[:, None, None] / 3 + 1e-12
        m += scale * (n[:, :, None] * n[:, None, :]) + 1e-9 * scale * np.eye(3)
        self.inverse = np.linalg.inv(m)
        # welded vertices all of whose corners lie on cluster sides, and those corners
        n_vertices = int(ids.max()) + 1
        on_other = np.zeros(n_vertices, bool)
        on_other[cv[~cluster[cs]]] = True
        used = np.zeros(n_vertices, bool)
        used[cv] = True
        self.vertices = np.nonzero(used & ~on_other)[0]
        vrow = np.full(n_vertices, -1, np.int64)
        vrow[self.vertices] = np.arange(len(self.vertices))
        self._scene = scene
        # flat tside corners 3 t + k and their rows (int32: half the memory of what a pass reads
        # most; a scene of 700M tsides would not fit in memory anyway)
        self._corner = np.nonzero((vrow >= 0)[cv])[0].astype(np.int32)
        self._corner_vertex = vrow[cv[self._corner]].astype(np.int32)
        self._weight = a                                          # per tside
        # the pairs grouped by cluster: the limiter's reach (vertex_values)
        self._by_cluster = stable_order(r1)[0]
        self._cluster_start = np.searchsorted(r1[self._by_cluster], np.arange(len(self.sides)))

    def vertex_values(self, side_values, out):
        """The values of :attr:`vertices` from side values (S, C), clamped at zero (the
        projection's clamp, :meth:`LinearReconstruction.projected`), written into their rows of
        ``out`` (V, C), which is returned: no (len(vertices), C) array beside it."""
        v = side_values
        dv = v[self.s2] - v[self.s1]                                                    # (K, C)
        r1 = self.row[self.s1]
        rhs = np.stack([np.stack([np.bincount(r1, self.wd[:, i] * dv[:, c], minlength=len(self.sides))
                                  for c in range(v.shape[1])], axis=1) for i in range(3)], axis=1)   # (Sc, 3, C)
        g = np.einsum("sij,sjc->sic", self.inverse, rhs)
        reach = np.zeros((len(self.sides), v.shape[1]))
        if len(dv):
            has = np.bincount(r1, minlength=len(self.sides)) > 0
            most = np.maximum.reduceat(np.abs(dv[self._by_cluster]), self._cluster_start[has], axis=0)
            reach[has] = most
        sc, nv, n_c = self._scene, len(self.vertices), v.shape[1]
        if compiled.use():
            _fit_corners(self._corner, self._corner_vertex, sc.tside_side, sc.tside_triangle,
                         np.asarray(sc.vertices, float), np.asarray(sc.triangles, np.int64), self.centroid, self.row,
                         np.ascontiguousarray(g), reach, np.ascontiguousarray(v, float), self._weight,
                         self.vertices, out)
            return out
        num, den = np.zeros((nv, n_c)), np.zeros(nv)
        step = 1 << 18                          # corners per chunk: bounded temporaries on big scenes
        for lo in range(0, len(self._corner), step):
            c = self._corner[lo:lo + step]
            ts, k = np.divmod(c, 3)
            side = sc.tside_side[ts]
            x = sc.triangle_corners[sc.tside_triangle[ts], k] - self.centroid[side]
            row, vert, w = self.row[side], self._corner_vertex[lo:lo + step], self._weight[ts]
            for ch in range(n_c):
                # limited: a fit departs from its side's value by no more than a neighbour does (exact
                # on a linear function, whose corners lie closer than the farthest neighbour's centroid;
                # a fit steepened by one noisy tiny neighbour, read far from the centroid, is not)
                pred = v[side, ch] + np.clip(np.einsum("nk,nk->n", x, g[row, :, ch]), -reach[row, ch], reach[row, ch])
                num[:, ch] += np.bincount(vert, w * pred, minlength=nv)
            den += np.bincount(vert, w, minlength=nv)
        num /= np.maximum(den, 1e-300)[:, None]
        out[self.vertices] = np.maximum(num, 0.0, out=num)
        return out


def _kernel_sample():
    return np.array([[0, 1, 2]], np.int32), np.ones(1), np.zeros(1, np.int64), np.ones((1, 2)), 3, np.zeros(3, bool)


@compiled.kernel(_kernel_sample)
def _scatter_sides(ids, weight, side, side_values, n_vertices, unit):
    """(V, C): the sum over tsides t and their corners k of ``w side_values[side[t]]`` at vertex
    ``ids[t, k]``, ``w`` = 1 where ``unit[ids[t, k]]`` and ``weight[t]`` elsewhere (``ids`` (TS, 3)
    int, ``weight`` (TS,), ``side`` (TS,) int, ``side_values`` (S, C), ``unit`` (V,) bool): no
    (TS, 3) array of weights is made."""
    out = np.zeros((n_vertices, side_values.shape[1]))
    for t in range(ids.shape[0]):
        s = side[t]
        for k in range(3):
            v = ids[t, k]
            w = 1.0 if unit[v] else weight[t]
            for c in range(side_values.shape[1]):
                out[v, c] += w * side_values[s, c]
    return out


@compiled.kernel(lambda: (np.array([[0, 1, 2]], np.int32), np.ones(1), np.ones((3, 2)), 3))
def _mass_product(ids, area, v, n_vertices):
    """(V, C) ``M v`` over tsides ``ids`` (TS, 3) of ``area`` (TS,): each triangle adds
    ``A / 12 (2 v_a + v_b + v_c) = A / 12 (v_a + v_a + v_b + v_c)`` at its corner a."""
    out = np.zeros((n_vertices, v.shape[1]))
    for t in range(ids.shape[0]):
        a, b, c3, w = ids[t, 0], ids[t, 1], ids[t, 2], area[t] / 12
        for c in range(v.shape[1]):
            s = v[a, c] + v[b, c] + v[c3, c]
            out[a, c] += w * (v[a, c] + s)
            out[b, c] += w * (v[b, c] + s)
            out[c3, c] += w * (v[c3, c] + s)
    return out


def _fit_sample(dtype):
    return lambda: (np.array([0, 1, 2], np.int32), np.array([0, 1, 2], np.int32), np.zeros(1, np.int64),
                    np.zeros(1, np.int64), np.zeros((3, 3)), np.array([[0, 1, 2]], np.int64), np.zeros((1, 3)),
                    np.zeros(1, np.int64), np.zeros((1, 3, 2)), np.zeros((1, 2)), np.ones((1, 2)), np.ones(1),
                    np.arange(3), np.zeros((3, 2), dtype))


@compiled.kernel(_fit_sample(np.float64), _fit_sample(np.float32))
def _fit_corners(corner, corner_vertex, tside_side, tside_triangle, vertices, triangles, centroid, row, g, reach,
                 v, weight, fitted, out):
    """:meth:`ClusterFit.vertex_values` at its corners: each flat tside corner ``corner`` (3 t + k)
    reads its side's fit ``v_s + clip(g_s . (x - c_s), -reach_s, reach_s)`` (``g`` (Sc, 3, C), ``reach``
    (Sc, C) by cluster row ``row[s]``), weighted by ``weight[t]`` into its vertex ``corner_vertex``
    (a row of ``fitted``, the rows of ``out`` its mean goes to, clamped at zero; summed in
    ``out``'s precision, 64 or 32 bits)."""
    n_c = v.shape[1]
    den = np.zeros(fitted.shape[0])
    for j in range(fitted.shape[0]):
        for ch in range(n_c):
            out[fitted[j], ch] = 0.0
    for i in range(corner.shape[0]):
        t = corner[i] // 3
        k = corner[i] - 3 * t
        side, w, vert = tside_side[t], weight[t], corner_vertex[i]
        p = triangles[tside_triangle[t], k]
        r = row[side]
        x0 = vertices[p, 0] - centroid[side, 0]
        x1 = vertices[p, 1] - centroid[side, 1]
        x2 = vertices[p, 2] - centroid[side, 2]
        for ch in range(n_c):
            d = x0 * g[r, 0, ch] + x1 * g[r, 1, ch] + x2 * g[r, 2, ch]
            d = min(max(d, -reach[r, ch]), reach[r, ch])
            out[fitted[vert], ch] += w * (v[side, ch] + d)
        den[vert] += w
    for j in range(fitted.shape[0]):
        for ch in range(n_c):
            q = out[fitted[j], ch] / max(den[j], 1e-300)
            out[fitted[j], ch] = 0.0 if q < 0.0 else q
    return out
