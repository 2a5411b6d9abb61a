"""Gaps: where another surface lies within a contact's width of a surface.

A point in such a gap (the ceiling over a lamp hanging 0.5 mm under it, the floor under a
rug) sees only that surface on that side, a world apart from its neighbours outside the gap,
so a patch must not hold both (:mod:`raybundle.patches.contacts`).  :func:`gap_sides` probes
points on both sides; :func:`straddling` finds the triangles part of which lies in a gap and
part not, the triangles the contact cuts must cut.
"""
from __future__ import annotations

import numpy as np


#: gaps narrower than this share of the patch size count as contact
#: (:func:`~raybundle.patches.layout.cut_at_contacts`, :func:`~raybundle.patches.clusters.make_patches`):
#: a point under a cabinet's base a quarter patch up sees the base over most of its
#: hemisphere, so its light changes within the patch as at a contact; counted only up to 5%,
#: the floor beside the base shared clusters with the floor under it, and the lit part the
#: dark part's average (the interior bench's bathrooms read 2-4% dark where the camera looks)
CONTACT_SHARE = 0.25
#: probe rays per chunk in :func:`gap_sides` (memory: about 100 bytes a ray)
PROBE_CHUNK = 1 << 20


def gap_sides(tracer, points, normals, tol):
    """(N, 2) bool: another surface lies within ``tol`` [m] of ``points`` (N, 3) along
    their unit ``normals`` (column 0) and against them (column 1).

    A point in such a gap (the ceiling over a lamp hanging 0.5 mm under it, the floor
    under a rug) sees only that surface on that side, a world apart from its neighbours
    outside the gap: a patch must not hold both (module docstring)."""
    points, normals = np.asarray(points, float), np.asarray(normals, float)
    out = np.zeros((len(points), 2), bool)
    eps = tracer.eps
    for lo in range(0, len(points), PROBE_CHUNK // 2):
        p, n = points[lo:lo + PROBE_CHUNK // 2], normals[lo:lo + PROBE_CHUNK // 2]
        for col, sign in ((0, 1.0), (1, -1.0)):
            d = sign * n
            out[lo:lo + len(p), col] = tracer.occluded(p + eps * d, d, np.full(len(p), max(tol - eps, eps)))
    return out


def straddling(tracer, scene, faces, tol):
    """(F,) bool: triangles ``faces`` part of which lies in a gap narrower than ``tol`` [m]
    and part not: the triangles :func:`~raybundle.patches.contacts.split_at_contacts` must cut.  :func:`gap_sides` at
    every centroid first; where a triangle's flags differ from those of a triangle it shares
    a corner with (or it shares none), at its three corners pulled 1% towards the centroid
    too, and the triangle straddles where its four points disagree."""
    faces = np.asarray(faces, np.int64)
    if len(faces) == 0:
        return np.zeros(0, bool)
    c = scene.triangle_corners[faces]
    flags = gap_sides(tracer, c.mean(axis=1), scene.triangle_normal[faces], tol)
    code = flags[:, 0] * 2 + flags[:, 1]
    corner = scene.triangles[faces]
    lo = np.full(len(scene.vertices), 4)
    hi = np.full(len(scene.vertices), -1)
    users = np.zeros(len(scene.vertices), np.int64)
    np.minimum.at(lo, corner, code[:, None])
    np.maximum.at(hi, corner, code[:, None])
    np.add.at(users, corner, 1)
    near = np.any(lo[corner] != hi[corner], axis=1) | np.all(users[corner] == 1, axis=1)
    out = np.zeros(len(faces), bool)
    sel = np.nonzero(near)[0]
    step = max(1, PROBE_CHUNK // 8)
    for start in range(0, len(sel), step):
        f = sel[start:start + step]
        mid = c[f].mean(axis=1, keepdims=True)
        pts = mid + 0.99 * (c[f] - mid)                                           # (F, 3, 3)
        n = np.repeat(scene.triangle_normal[faces[f]], 3, axis=0)
        at = gap_sides(tracer, pts.reshape(-1, 3), n, tol).reshape(len(f), 3, 2)
        out[f] = (at != flags[f, None, :]).any(axis=(1, 2))
    return out
