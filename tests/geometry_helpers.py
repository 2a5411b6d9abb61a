"""Exact plane geometry for the tests."""
import numpy as np


def clipped_area(polygon, poly):
    """Area of the convex ``polygon`` (M, 2) inside the convex ccw polygon ``poly`` (Sutherland-Hodgman)."""
    pts = list(np.asarray(polygon, float))
    for i in range(len(poly)):
        a, b = poly[i], poly[(i + 1) % len(poly)]
        side = [(b[0] - a[0]) * (p[1] - a[1]) - (b[1] - a[1]) * (p[0] - a[0]) for p in pts]
        out = []
        for k in range(len(pts)):
            p, q, sp, sq = pts[k], pts[(k + 1) % len(pts)], side[k], side[(k + 1) % len(pts)]
            if sp >= 0:
                out.append(p)
            if sp * sq < 0:
                out.append(p + sp / (sp - sq) * (q - p))
        pts = out
        if not pts:
            return 0.0
    x, y = np.array(pts).T
    return 0.5 * abs(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1)))
