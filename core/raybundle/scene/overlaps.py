"""Coplanar overlaps: two objects with faces in one plane, facing the same way, over the
same area (a floor strip of the walls' mesh lying on the floor's own mesh).

Such faces *z-fight*: Cycles starts each bounce and shadow ray on one of them and meets the
other at a distance of about zero, which it counts as a hit, so the overlap comes out darker
than either surface alone (a sunlit strip black: ``tests/test_addon_export.py``).  Raybundle's tracer merges hits
closer than ``eps`` (:mod:`raybundle.tracing.visibility`) and lights the overlap as one
surface.  Neither is modelled as the other: the export warns, naming the objects.

Faces are grouped by plane (their unit normal rounded to 1e-4 and their offset to 1e-6 of
the scene radius, not canonicalised: a box's bottom on a floor faces the other way and is a
contact, not an overlap); in each plane holding faces of two groups, the triangles whose
bounding box meets another group's are kept, and points of each (centroid and three points
halfway to the corners) are tested against the kept triangles of other groups at once,
vectorised in blocks, whatever the number of groups.
"""
from __future__ import annotations

import numpy as np

from ..tracing.sampling import orthonormal_basis
from ..util.arrays import group_ids

#: points x triangles tested at a time (memory: about 50 bytes each)
BLOCK = 1 << 20
#: at most about this many point-in-triangle tests per plane: beyond, a random subset of each
#: group's triangles is tested and its covered area scaled up by the area sampled
MAX_TESTS = 1 << 27
#: sample points per triangle: its centroid and three points halfway to its corners (barycentric)
_SAMPLES = np.array([[1, 1, 1], [4, 1, 1], [1, 4, 1], [1, 1, 4]], float) / np.array([[3.0], [6.0], [6.0], [6.0]])


def coplanar_overlaps(corners, groups, min_area=0.0):
    """``[(a, b, area)]``: pairs of ``groups`` ids (a < b) whose triangles ``corners`` (T, 3, 3)
    [m] overlap in one plane, facing the same way, over about ``area`` [m^2] (at least
    ``min_area``), largest first.  ``groups`` (T,) int: the object of each triangle."""
    corners = np.asarray(corners, float)
    groups = np.asarray(groups, np.int64)
    if len(corners) == 0:
        return []
    plane, n, area, shared = _shared_planes(corners, groups)
    found: dict = {}
    rng = np.random.default_rng(0)
    members = np.argsort(plane, kind="stable")
    bounds = np.searchsorted(plane[members], np.stack([shared, shared + 1]))
    for lo, hi in bounds.T:
        tri = members[lo:hi]
        e1, e2 = orthonormal_basis(n[tri[0]])
        c2 = np.stack([corners[tri] @ e1, corners[tri] @ e2], axis=-1)                   # (P, 3, 2)
        near = _near_other_groups(c2, groups[tri])
        tri, c2 = tri[near], c2[near]
        g = groups[tri]
        if len(np.unique(g)) < 2:
            continue
        mine, scale = _sampled(g, area[tri], rng)
        pts = np.einsum("sk,pkx->psx", _SAMPLES, c2[mine]).reshape(-1, 2)                 # (4 m, 2)
        point_tri = np.repeat(mine, len(_SAMPLES))
        weight = area[tri][point_tri] * scale[point_tri] / len(_SAMPLES)
        ga, gb, covered = _covered_area(pts, g[point_tri], weight, c2, g)
        for a, b, s_ab in zip(ga.tolist(), gb.tolist(), covered.tolist()):
            key = (min(a, b), max(a, b))
            # each pair is measured from both sides: keep the larger estimate
            found[key] = max(found.get(key, 0.0), s_ab)
    out = [(a, b, s) for (a, b), s in found.items() if s > 0 and s >= min_area]
    return sorted(out, key=lambda x: -x[2])


def _shared_planes(corners, groups):
    """``(plane (T,), unit normals (T, 3), areas (T,), shared)``: each triangle's plane id (-1:
    no area; module docstring), and the ids of the planes holding triangles of two groups or more."""
    cross = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    area = 0.5 * np.linalg.norm(cross, axis=1)
    ok = area > 0
    n = np.zeros_like(cross)
    n[ok] = cross[ok] / (2.0 * area[ok, None])
    radius = float(np.linalg.norm(corners.reshape(-1, 3) - corners.reshape(-1, 3).mean(axis=0), axis=1).max())
    off = np.einsum("ij,ij->i", n, corners[:, 0])
    q = np.round(n * 1e4).astype(np.int64)
    plane = group_ids([q[:, 0], q[:, 1], q[:, 2], np.round(off / max(radius * 1e-6, 1e-12)).astype(np.int64)])
    plane[~ok] = -1
    sel = np.nonzero(ok)[0]
    first = np.unique(group_ids([plane[sel], groups[sel]]), return_index=True)[1]       # one per (plane, group)
    count = np.bincount(plane[sel][first])
    return plane, n, area, np.nonzero(count > 1)[0]


def covered_points(corners, groups, points, triangles):
    """(N,) bool: which ``points`` (N, 3) on ``triangles`` (N,) of ``corners`` (T, 3, 3) lie
    strictly inside a triangle of another of ``groups`` (T,) in the same plane, facing the same
    way: the points where Cycles z-fights (module docstring).  A point off every triangle
    (``triangles`` -1) is not covered."""
    corners = np.asarray(corners, float)
    groups = np.asarray(groups, np.int64)
    points, triangles = np.asarray(points, float), np.asarray(triangles, np.int64)
    out = np.zeros(len(points), bool)
    if len(corners) == 0 or len(points) == 0:
        return out
    plane, n, _, shared = _shared_planes(corners, groups)
    mine = np.where(triangles >= 0, plane[np.maximum(triangles, 0)], -1)
    members, by_point = np.argsort(plane, kind="stable"), np.argsort(mine, kind="stable")
    bounds = np.searchsorted(plane[members], np.stack([shared, shared + 1]))
    points_at = np.searchsorted(mine[by_point], np.stack([shared, shared + 1]))
    for (lo, hi), (p_lo, p_hi) in zip(bounds.T, points_at.T):
        at = by_point[p_lo:p_hi]
        if not len(at):
            continue
        tri = members[lo:hi]
        e1, e2 = orthonormal_basis(n[tri[0]])
        c2 = np.stack([corners[tri] @ e1, corners[tri] @ e2], axis=-1)
        near = _near_other_groups(c2, groups[tri])        # the others neither cover nor are covered
        at = at[np.isin(triangles[at], tri[near])]
        tri, c2 = tri[near], c2[near]
        if not len(at):
            continue
        p2 = np.stack([points[at] @ e1, points[at] @ e2], axis=-1)
        point_group = groups[triangles[at]]
        ga, _, _ = _covered_area(p2, np.arange(len(at)), np.ones(len(at)), c2, groups[tri], point_group)
        out[at[np.unique(ga)]] = True
    return out


def _near_other_groups(c2, g):
    """(P,) bool: which triangles ``c2`` (P, 3, 2) of a plane have a bounding box that meets
    the bounding box of another group's triangles (the others cannot overlap another group);
    in blocks of :data:`BLOCK` tests."""
    ids, gi = np.unique(g, return_inverse=True)
    lo, hi = c2.min(axis=1), c2.max(axis=1)
    glo, ghi = np.full((len(ids), 2), np.inf), np.full((len(ids), 2), -np.inf)
    np.minimum.at(glo, gi, lo)
    np.maximum.at(ghi, gi, hi)
    near = np.zeros(len(g), bool)
    step = max(1, BLOCK // len(ids))
    for s in range(0, len(g), step):
        meets = ((lo[s:s + step, None] <= ghi[None]) & (hi[s:s + step, None] >= glo[None])).all(axis=2)
        meets[np.arange(len(meets)), gi[s:s + step]] = False                     # its own group
        near[s:s + step] = meets.any(axis=1)
    return near


def _sampled(g, area, rng):
    """``(triangles tested, scale)``: every triangle of the plane, or, beyond :data:`MAX_TESTS`
    tests, a random subset of each group's (at least 16 of it); ``scale`` (P,): the group's area
    over the area of its triangles tested."""
    every = np.arange(len(g))
    keep = max(16, MAX_TESTS // (len(_SAMPLES) * len(g)))
    if len(g) > keep:
        order = np.lexsort((rng.random(len(g)), g))                    # each group's triangles, shuffled
        start = np.searchsorted(g[order], g[order])                       # first place of its group
        rank = np.arange(len(g)) - start
        count = np.bincount(g - g.min())[g[order] - g.min()]
        every = np.sort(order[rank < np.maximum(16, np.ceil(count * keep / len(g)))])
    total = np.bincount(g - g.min(), weights=area)
    tested = np.bincount(g[every] - g.min(), weights=area[every], minlength=len(total))
    scale = np.zeros(len(g))
    scale[every] = total[g[every] - g.min()] / tested[g[every] - g.min()]
    return every, scale


def _covered_area(points, point_group, weight, tris, tri_group, owner=None):
    """``(a, b, area)`` arrays: for each pair of groups, the summed ``weight`` of the points of
    group ``a`` that lie strictly inside some triangle of ``tris`` (M, 3, 2) of another group
    ``b``; a point counts once per covering group.  ``owner`` (N,): the group a point's cover
    must differ from, when ``point_group`` labels the points otherwise (default: their group).
    In blocks of :data:`BLOCK` tests."""
    owner = point_group if owner is None else owner
    a, b, c = tris[:, 0], tris[:, 1], tris[:, 2]
    det = (b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (c[:, 0] - a[:, 0])
    live = np.abs(det) > 0
    a, b, c, det, tri_group = a[live], b[live], c[live], det[live], tri_group[live]
    step = max(1, BLOCK // max(len(a), 1))
    hit_point, hit_group = [], []
    for lo in range(0, len(points), step):
        p = points[lo:lo + step, None, :]                                                # (n, 1, 2)
        u = ((p[..., 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (p[..., 1] - a[:, 1]) * (c[:, 0] - a[:, 0])) / det
        v = ((b[:, 0] - a[:, 0]) * (p[..., 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (p[..., 0] - a[:, 0])) / det
        pi, ti = np.nonzero((u > 1e-9) & (v > 1e-9) & (u + v < 1 - 1e-9))                 # (n, M) inside
        pi = pi + lo
        other = owner[pi] != tri_group[ti]
        hit_point.append(pi[other])
        hit_group.append(tri_group[ti[other]])
    pi, gb = np.concatenate(hit_point), np.concatenate(hit_group)
    pi, gb = np.unique(np.stack([pi, gb]), axis=1)                                       # once per covering group
    pairs, inverse = np.unique(np.stack([point_group[pi], gb]), axis=1, return_inverse=True)
    return pairs[0], pairs[1], np.bincount(inverse.ravel(), weights=weight[pi], minlength=pairs.shape[1])
