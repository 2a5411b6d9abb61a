"""Convex polygons cut by lines: the pieces of a triangle cut along the contact lines that cross
it (:mod:`raybundle.patches.contacts`), and which lines are worth cutting along.

Polygons are plain lists of [x, y] corners while they are cut: NumPy's cost per call on polygons
of three to six corners is larger than their arithmetic.
"""
from __future__ import annotations

import math

import numpy as np

from ..util.arrays import unique_rows


def split_polygon(poly, a, b, eps):
    """Split the convex polygon ``poly`` (M corners [x, y], a list) by the line through the
    points a, b: (left, right) polygons (lists), either None when the line misses the interior."""
    # Python floats: the same IEEE arithmetic as on arrays, without numpy's cost per call on
    # polygons of three to six corners (called once per piece and line: 95k times for 270k triangles)
    ax, ay = float(a[0]), float(a[1])
    dx, dy = float(b[0]) - ax, float(b[1]) - ay
    h = math.hypot(dx, dy)
    if not h > 0:                                # a point, not a line (on arrays: NaN, no split)
        return None, None
    ux, uy = dx / h, dy / h
    pts = poly
    s = [ux * (p[1] - ay) - uy * (p[0] - ax) for p in pts]                     # signed distance [m]
    s = [0.0 if abs(v) <= eps else v for v in s]
    if not any(v > 0 for v in s) or not any(v < 0 for v in s):
        return None, None
    left, right = [], []
    m = len(pts)
    for i in range(m):
        j = (i + 1) % m
        p, q, sp, sq = pts[i], pts[j], s[i], s[j]
        if sp >= 0:
            left.append(p)
        if sp <= 0:
            right.append(p)
        if sp * sq < 0:
            t = sp / (sp - sq)
            x = [p[0] + t * (q[0] - p[0]), p[1] + t * (q[1] - p[1])]
            left.append(x)
            right.append(x)
    return left, right


def without_collinear(poly, eps):
    """The convex polygon ``poly`` (a list of [x, y], as :func:`split_polygon` makes) as an (M, 2)
    array without the corners lying on the line through their neighbours (they would give
    zero-area fan triangles)."""
    keep = []
    m = len(poly)
    for i in range(m):
        (ax, ay), (px, py), (bx, by) = poly[i - 1], poly[i], poly[(i + 1) % m]
        length = math.hypot(bx - ax, by - ay)
        if length > 0 and abs((bx - ax) * (py - ay) - (by - ay) * (px - ax)) / length > eps:
            keep.append(poly[i])
    return np.array(keep, float).reshape(-1, 2)


def polygon_area(poly):
    """The area of the polygon ``poly`` (M corners [x, y], a list): the shoelace formula."""
    m = len(poly)
    return 0.5 * abs(sum(poly[i][0] * poly[(i + 1) % m][1] - poly[i][1] * poly[(i + 1) % m][0] for i in range(m)))


#: a patch is cut along a contact line whose segments in the plane reach this share of its longest
#: edge, along at most this many such lines, the longest
CUT_SHARE, MAX_CUTS = 0.05, 16


def worth_cutting(tri2d, f, k, crosses, seg, key):
    """(P,) bool: the pairs ``(f, k)`` (triangle ``tri2d[f]`` (F, 3, 2), segment ``seg[k]``
    (K, 2, 2) on line ``key[k]`` (K, 3) int: collinear segments share a key) whose line cuts the
    triangle (``crosses``) and is worth cutting along: the segments of its line in the plane add up to
    :data:`CUT_SHARE` of the triangle's longest edge, and the line is among the :data:`MAX_CUTS`
    longest that cut it."""
    out = np.zeros(len(f), bool)
    sel = np.nonzero(crosses)[0]
    if len(sel) == 0:
        return out
    line = unique_rows(key)[1]
    length = np.bincount(line, np.linalg.norm(seg[:, 1] - seg[:, 0], axis=1))            # each line's
    pairs = np.stack([f[sel], line[k[sel]]], axis=1)
    first, inverse = unique_rows(pairs)
    pair = pairs[first]
    total = length[pair[:, 1]]
    edges = np.linalg.norm(tri2d - np.roll(tri2d, 1, axis=1), axis=2).max(axis=1)           # (F,)
    long_enough = total >= CUT_SHARE * edges[pair[:, 0]]
    order = np.lexsort((-total, pair[:, 0]))                          # each triangle's lines, longest first
    rank = np.empty(len(pair), np.int64)
    first = np.searchsorted(pair[order, 0], pair[order, 0])
    rank[order] = np.arange(len(pair)) - first
    out[sel] = (long_enough & (rank < MAX_CUTS))[inverse]
    return out


def cut_triangles(c2, cut, start, count, seg_k, crosses, eps, min_fraction, whole=None):
    """``(pieces, kept)``: the convex pieces (lists of (M, 2) arrays) of each triangle ``cut`` (ids
    into ``c2`` (F, 3, 2)), cut along the lines of the segments that cross it (``seg_k``,
    ``crosses`` from ``start`` for ``count`` pairs), and per piece the lines it was not cut along
    (lists like ``pieces`` of lists of ``(a, b, left)``: the segment's ends and whether the sliver
    it would have cut off lies on its left, as :func:`split_polygon` names the sides).  A cut that
    would leave a piece under ``min_fraction`` of the triangle is not made; the corners of that
    sliver lie on the line for their weld tags (:func:`~raybundle.patches.contacts.split_at_contacts`).
    Triangles ``whole`` (F,) bool (None: none) are never cut, only their slivers' lines kept.
    Corners are plain lists while cutting (NumPy's cost per call on 3-6 corners)."""
    pieces, kept_lines = [], []
    for fi, lo, n in zip(cut.tolist(), start.tolist(), count.tolist()):
        polys = [(c2[fi].tolist(), [])]                  # a piece and the lines it was not cut along
        least = min_fraction * polygon_area(polys[0][0])
        fixed = whole is not None and whole[fi]
        # a line that leaves the triangle's corners on one side misses every piece of it
        for a, b in seg_k[lo:lo + n][crosses[lo:lo + n]].tolist():
            nxt = []
            for poly, kept in polys:
                lft, rgt = split_polygon(poly, a, b, eps)
                areas = (polygon_area(lft), polygon_area(rgt)) if lft is not None else None
                if areas is None:
                    nxt.append((poly, kept))
                elif min(areas) < least:
                    nxt.append((poly, kept + [(a, b, areas[0] < areas[1])]))
                elif fixed:
                    nxt.append((poly, kept))
                else:
                    nxt += [(lft, kept), (rgt, kept)]
            polys = nxt
        pieces.append([without_collinear(poly, eps) for poly, _ in polys])
        kept_lines.append([kept for _, kept in polys])
    return pieces, kept_lines
