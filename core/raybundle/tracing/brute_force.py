"""The tracer's obviously-correct twin: every hit of parallel rays with every triangle, for
small scenes (the tests check :class:`~raybundle.tracing.visibility.RayTracer` against it)."""
from __future__ import annotations

import numpy as np

from .visibility import bundle_from_hits


def brute_force_hits(corners, origins, direction, eps):
    """All hits of parallel rays with every triangle, by Moller-Trumbore in NumPy.

    The obviously-correct twin of :meth:`~raybundle.tracing.visibility.RayTracer.all_hit_pairs` for small
    scenes.  Returns, per ray, a list of ``(t, triangle)`` sorted by t, with
    hits closer than ``eps`` merged (the first triangle index wins).
    """
    corners = np.asarray(corners, float)
    d = np.asarray(direction, float)
    e1 = corners[:, 1] - corners[:, 0]
    e2 = corners[:, 2] - corners[:, 0]
    p = np.cross(d, e2)                                   # (T, 3)
    det = np.einsum("ij,ij->i", e1, p)
    ok_tri = np.abs(det) > 1e-300
    inv = np.where(ok_tri, 1.0 / np.where(ok_tri, det, 1.0), 0.0)
    s = origins[:, None, :] - corners[None, :, 0]         # (N, T, 3)
    u = np.einsum("ntk,tk->nt", s, p) * inv
    q = np.cross(s, e1[None])
    v = (q @ d) * inv
    t = np.einsum("ntk,tk->nt", q, e2) * inv
    tol = 1e-12
    hit = ok_tri & (u >= -tol) & (v >= -tol) & (u + v <= 1 + tol) & (t > 0)
    out = []
    for n in range(len(origins)):
        idx = np.nonzero(hit[n])[0]
        order = np.lexsort((idx, t[n, idx]))
        seq = []
        for k in idx[order]:
            if seq and t[n, k] - seq[-1][0] < eps:
                continue
            seq.append((float(t[n, k]), int(k)))
        out.append(seq)
    return out


def brute_force_bundle(scene, origins, direction, delta, eps):
    """The :class:`~raybundle.tracing.visibility.Bundle` of the same rays computed with :func:`brute_force_hits`."""
    d = np.asarray(direction, float)
    up, down, first, last = [], [], [], []
    for seq in brute_force_hits(scene.triangle_corners, origins, d, eps):
        for (_, a), (_, b) in zip(seq[:-1], seq[1:]):
            up.append(a)
            down.append(b)
        if seq:
            first.append(seq[0][1])
            last.append(seq[-1][1])
    ends = [np.array(first, np.int64), np.array(last, np.int64)] if scene.world.emits else []
    return bundle_from_hits(scene, d, delta, np.array(up, np.int64), np.array(down, np.int64),
                            len(origins), 0, *ends)
