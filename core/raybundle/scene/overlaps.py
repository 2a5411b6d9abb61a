"""Coplanar overlaps: two objects with faces in one plane, facing the same way, over the
same area (a floor strip of the walls' mesh lying on the floor's own mesh).

Such faces *z-fight*: Cycles starts each bounce and shadow ray on one of them and meets the
other at a distance of about zero, which it counts as a hit, so the overlap comes out darker
than either surface alone (a sunlit strip black: ``tests/test_addon_export.py``).  Raybundle's tracer merges hits
closer than ``eps`` (:mod:`raybundle.tracing.visibility`) and lights the overlap as one
surface.  Neither is modelled as the other: the export warns, naming the objects.

Faces are grouped by plane (their unit normal rounded to 1e-4 and their offset to 1e-6 of
the scene radius, not canonicalised: a box's bottom on a floor faces the other way and is a
contact, not an overlap); in each plane holding faces of two groups, points of one group's
triangles (centroid and three points halfway to the corners) are tested against the other
group's triangles, vectorised in blocks.
"""
from __future__ import annotations

import numpy as np

from ..tracing.sampling import orthonormal_basis
from ..util.arrays import group_ids

#: points x triangles tested at a time (memory: about 50 bytes each)
BLOCK = 1 << 22
#: at most this many point-in-triangle tests per plane and group: beyond, a random subset of the
#: group's triangles is tested and the covered area scaled up by the area sampled
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
    # planes holding triangles of two groups or more
    sel = np.nonzero(ok)[0]
    first = np.unique(group_ids([plane[sel], groups[sel]]), return_index=True)[1]       # one per (plane, group)
    count = np.bincount(plane[sel][first])
    shared = np.nonzero(count > 1)[0]
    found: dict = {}
    rng = np.random.default_rng(0)
    members = np.argsort(plane, kind="stable")
    bounds = np.searchsorted(plane[members], np.stack([shared, shared + 1]))
    for lo, hi in bounds.T:
        tri = members[lo:hi]
        e1, e2 = orthonormal_basis(n[tri[0]])
        c2 = np.stack([corners[tri] @ e1, corners[tri] @ e2], axis=-1)                   # (P, 3, 2)
        pts = np.einsum("sk,pkx->psx", _SAMPLES, c2)                                      # (P, 4, 2)
        g = groups[tri]
        for a in np.unique(g):
            every, theirs = np.nonzero(g == a)[0], np.nonzero(g != a)[0]
            keep = max(16, MAX_TESTS // (len(_SAMPLES) * len(theirs)))
            mine = every if len(every) <= keep else np.sort(rng.choice(every, keep, replace=False))
            scale = area[tri[every]].sum() / area[tri[mine]].sum()
            covered = _covered(pts[mine].reshape(-1, 2), c2[theirs], g[theirs])
            for b, hits in covered.items():
                share = hits.reshape(len(mine), len(_SAMPLES)).mean(axis=1)
                key = (min(a, b), max(a, b))
                # each pair is measured from both sides: keep the larger estimate
                found[key] = max(found.get(key, 0.0), scale * float((share * area[tri[mine]]).sum()))
    out = [(a, b, s) for (a, b), s in found.items() if s > 0 and s >= min_area]
    return sorted(out, key=lambda x: -x[2])


def _covered(points, tris, tri_group):
    """``{group: (N,) bool}``: which ``points`` (N, 2) lie strictly inside some triangle of
    ``tris`` (M, 3, 2) of each group ``tri_group`` (M,), in blocks of :data:`BLOCK` tests."""
    out = {}
    a, b, c = tris[:, 0], tris[:, 1], tris[:, 2]
    det = (b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (c[:, 0] - a[:, 0])
    live = np.abs(det) > 0
    a, b, c, det, tri_group = a[live], b[live], c[live], det[live], tri_group[live]
    step = max(1, BLOCK // max(len(a), 1))
    for g in np.unique(tri_group):
        out[int(g)] = np.zeros(len(points), bool)
    for lo in range(0, len(points), step):
        p = points[lo:lo + step, None, :]                                                # (n, 1, 2)
        u = ((p[..., 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (p[..., 1] - a[:, 1]) * (c[:, 0] - a[:, 0])) / det
        v = ((b[:, 0] - a[:, 0]) * (p[..., 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (p[..., 0] - a[:, 0])) / det
        inside = (u > 1e-9) & (v > 1e-9) & (u + v < 1 - 1e-9)                            # (n, M)
        for g in out:
            out[g][lo:lo + step] = inside[:, tri_group == g].any(axis=1)
    return out
