"""The lamps' per-point arithmetic, compiled: area-light samples, the shadow rays' geometry,
which points a lamp may light, its selection estimate and Lambert's outline sum.

Each function here is the kernel of a method whose NumPy path stays beside it, where the
kernels are on (:mod:`raybundle.util.compiled`): one loop over the points, each doing in
registers what the NumPy path does in whole-array steps.  The arithmetic is the NumPy path's,
in the same order, so both give the same values up to the last bits of their sums
(``tests/test_compiled_lights.py``):

* :func:`shape_sample`: :meth:`~raybundle.lights.sources.ShapeLight.sample` (by area, or
  uniform in the spherical rectangle's solid angle where the lamp may look large);
* :func:`shape_reach`: :func:`~raybundle.lights.direct.may_light` of an area light (a corner in
  front of the point's tangent plane, the point in front of the lamp);
* :func:`shape_selection_estimate`: :meth:`~raybundle.lights.sources.ShapeLight.selection_estimate`;
* :func:`outline_irradiance`: Lambert's sum of :func:`~raybundle.lights.polygon.clipped_edge_irradiance`
  over an outline wholly above a point's horizon, and which points' horizons cut it;
* :func:`shadow_geometry`: the direction, cosine and shadow ray of each light sample in
  :meth:`~raybundle.lights.direct.DirectLighting.shadowed`.
"""
from __future__ import annotations

import numpy as np

from ..util.compiled import helper, kernel

_V = np.ascontiguousarray


def _rows(a):
    return _V(np.asarray(a, float))


# ------------------------------------------------------------------------------- area lights
def shape_sample(light, points, u, min_solid_angle):
    """``(y (N, 3), e (N,))`` of :meth:`~raybundle.lights.sources.ShapeLight.sample` before its
    radiance: ``cos_l A / r^2`` by area, the solid angle O where it samples that."""
    n = len(points)
    y, e = np.empty((n, 3)), np.empty(n)
    lx, ly = 2.0 * np.linalg.norm(light.axis_u), 2.0 * np.linalg.norm(light.axis_v)
    ex, ey = light.axis_u / (0.5 * lx), light.axis_v / (0.5 * ly)
    radius = max(np.linalg.norm(light.axis_u + light.axis_v), np.linalg.norm(light.axis_u - light.axis_v))
    _shape_sample(_rows(points), _rows(u), _rows(light.center), _rows(light.axis_u), _rows(light.axis_v),
                  _rows(light.normal), bool(light.ellipse), float(light.area), float(radius), float(min_solid_angle),
                  float(lx), float(ly), _rows(ex), _rows(ey), _rows(np.cross(ex, ey)), y, e)
    return y, e


def shape_reach(light, points, normals):
    """(N,) bool: :func:`~raybundle.lights.direct.may_light` of area light ``light``."""
    out = np.empty(len(points), bool)
    _shape_reach(_rows(points), _rows(normals), _rows(light.corners()), _rows(light.center), _rows(light.normal), out)
    return out


def shape_selection_estimate(light, points, normals):
    """(N,) :meth:`~raybundle.lights.sources.ShapeLight.selection_estimate`."""
    out = np.empty(len(points))
    _shape_selection(_rows(points), _rows(normals), _rows(light.center), _rows(light.axis_u), _rows(light.axis_v),
                     _rows(light.normal), float(np.mean(light.radiance)), out)
    return out


# -------------------------------------------------------------------------------- polygons
def outline_irradiance(points, normals, verts, ends):
    """``(I (N,), cut (N,) bool)``: Lambert's ``|sum_e theta_e n . g_e| / 2`` over the outline
    edges ``ends`` (B, 2) (indices into ``verts`` (V, 3)) where every vertex lies on or above a
    point's horizon, 0 where none lies above it; ``cut`` marks the points whose horizon cuts the
    outline (``I`` is left 0 there for the caller's clipped sum)."""
    out, cut = np.empty(len(points)), np.empty(len(points), bool)
    _outline(_rows(points), _rows(normals), _rows(verts), _V(ends, np.int64), out, cut)
    return out, cut


# ---------------------------------------------------------------------------- shadow rays
def shadow_geometry(points, normals, y, e, eps):
    """For light samples at ``y`` (N, 3) with unshadowed estimates ``e`` (N, 3) (scaled by
    ``max(cos_x, 0)`` in place) at ``points`` with unit ``normals``: ``(w (N, 3) towards the
    light, cos_x (N,), live (N,) bool (some channel of e above 0), origin (N, 3), direction
    (N, 3), t_max (N,), e)``, the shadow ray from ``eps`` above the surface to the sample itself
    (``e`` is a copy where it was not a C-ordered float array)."""
    n = len(points)
    e = np.require(e, float, "C")
    w, cos_x, live = np.empty((n, 3)), np.empty(n), np.empty(n, bool)
    org, d, t = np.empty((n, 3)), np.empty((n, 3)), np.empty(n)
    _shadow_geometry(_rows(points), _rows(normals), _rows(y), e, float(eps), w, cos_x, live, org, d, t)
    return w, cos_x, live, org, d, t, e


# --------------------------------------------------------------------------------- kernels
@helper
def _dot(a0, a1, a2, b0, b1, b2):
    """a.b summed as ``np.einsum("ij,ij->i", a, b)`` sums three terms."""
    return (a0 * b0 + a2 * b2) + a1 * b1


@helper
def _clip(x, lo, hi):
    return min(max(x, lo), hi)


@helper
def _by_area(p0, p1, p2, a, b, c, au, av, nl, area, y, e, i):
    """``y[i] = c + a au + b av`` and ``e[i] = cos_l A / r^2`` (ShapeLight._by_area)."""
    y0, y1, y2 = c[0] + a * au[0] + b * av[0], c[1] + a * au[1] + b * av[1], c[2] + a * au[2] + b * av[2]
    v0, v1, v2 = y0 - p0, y1 - p1, y2 - p2
    r2 = max(_dot(v0, v1, v2, v0, v1, v2), 1e-300)
    e[i] = max(-(v0 * nl[0] + v1 * nl[1] + v2 * nl[2]) / np.sqrt(r2), 0.0) * area / r2
    y[i, 0], y[i, 1], y[i, 2] = y0, y1, y2


@helper
def _solid_angle(p0, p1, p2, u0, u1, c, au, av, lx, ly, ex, ey, ez, y, e, i):
    """A point on the rectangle along a direction uniform in its solid angle O from p, and O
    (Urena, Fajardo and King 2013; ShapeLight._sample_solid_angle)."""
    d0, d1, d2 = (c[0] - au[0] - av[0]) - p0, (c[1] - au[1] - av[1]) - p1, (c[2] - au[2] - av[2]) - p2
    x0 = d0 * ex[0] + d1 * ex[1] + d2 * ex[2]
    y0 = d0 * ey[0] + d1 * ey[1] + d2 * ey[2]
    z0 = d0 * ez[0] + d1 * ez[1] + d2 * ez[2]
    flip = z0 > 0
    if flip:
        z0 = -z0
    x1, y1 = x0 + lx, y0 + ly
    n0, n1 = -y0 / np.sqrt(z0 * z0 + y0 * y0), x1 / np.sqrt(z0 * z0 + x1 * x1)
    n2, n3 = y1 / np.sqrt(z0 * z0 + y1 * y1), -x0 / np.sqrt(z0 * z0 + x0 * x0)
    g0, g1 = np.arccos(_clip(-n0 * n1, -1.0, 1.0)), np.arccos(_clip(-n1 * n2, -1.0, 1.0))
    g2, g3 = np.arccos(_clip(-n2 * n3, -1.0, 1.0)), np.arccos(_clip(-n3 * n0, -1.0, 1.0))
    k = 2.0 * np.pi - g2 - g3
    omega = max(g0 + g1 - k, 0.0)
    a_u = u0 * omega + k
    sin_au = np.sin(a_u)
    fu = (np.cos(a_u) * n0 - n2) / (sin_au if sin_au != 0 else 1e-300)
    sign = 1.0 if fu > 0 else (-1.0 if fu < 0 else 0.0)
    cu = _clip(sign / np.sqrt(fu * fu + n0 * n0), -1.0, 1.0)
    xu = _clip(-(cu * z0) / max(np.sqrt(1.0 - cu * cu), 1e-300), x0, x1)
    dd = np.sqrt(xu * xu + z0 * z0)
    h0, h1 = y0 / np.sqrt(dd * dd + y0 * y0), y1 / np.sqrt(dd * dd + y1 * y1)
    hv = h0 + u1 * (h1 - h0)
    yv = hv * dd / np.sqrt(max(1.0 - hv * hv, 1e-300)) if hv * hv < 1.0 - 1e-12 else y1
    zs = -z0 if flip else z0
    y[i, 0] = p0 + xu * ex[0] + yv * ey[0] + zs * ez[0]
    y[i, 1] = p1 + xu * ex[1] + yv * ey[1] + zs * ez[1]
    y[i, 2] = p2 + xu * ex[2] + yv * ey[2] + zs * ez[2]
    e[i] = omega


def _sample_shape():
    v, p = np.array([0.0, 0.0, 1.0]), np.array([[0.1, 0.2, 0.0], [0.0, 0.0, -3.0]])
    a, b = np.array([0.5, 0.0, 0.0]), np.array([0.0, 0.5, 0.0])
    return (p, np.full((2, 2), 0.5), v, a, b, -v, False, 1.0, 0.8, 0.5, 1.0, 1.0, a * 2, b * 2,
            np.array([0.0, 0.0, 1.0]), np.empty((2, 3)), np.empty(2))


@kernel(_sample_shape)
def _shape_sample(points, u, c, au, av, nl, ellipse, area, radius, min_sa, lx, ly, ex, ey, ez, y, e):
    for i in range(len(points)):
        p0, p1, p2 = points[i, 0], points[i, 1], points[i, 2]
        if ellipse:
            r, phi = np.sqrt(u[i, 0]), 2 * np.pi * u[i, 1]
            _by_area(p0, p1, p2, r * np.cos(phi), r * np.sin(phi), c, au, av, nl, area, y, e, i)
            continue
        q0, q1, q2 = p0 - c[0], p1 - c[1], p2 - c[2]
        gap = max(np.sqrt(q0 * q0 + q1 * q1 + q2 * q2) - radius, 0.0)
        if area >= min_sa * gap * gap and q0 * nl[0] + q1 * nl[1] + q2 * nl[2] > 0:
            _solid_angle(p0, p1, p2, u[i, 0], u[i, 1], c, au, av, lx, ly, ex, ey, ez, y, e, i)
        else:
            _by_area(p0, p1, p2, 2 * u[i, 0] - 1, 2 * u[i, 1] - 1, c, au, av, nl, area, y, e, i)


def _sample_reach():
    p = np.zeros((2, 3))
    return p, p + np.array([0.0, 0.0, 1.0]), np.ones((4, 3)), np.ones(3), np.array([0.0, 0.0, -1.0]), np.empty(2, bool)


@kernel(_sample_reach)
def _shape_reach(points, normals, corners, c, nl, out):
    for i in range(len(points)):
        p0, p1, p2 = points[i, 0], points[i, 1], points[i, 2]
        n0, n1, n2 = normals[i, 0], normals[i, 1], normals[i, 2]
        front = False
        for j in range(corners.shape[0]):
            if _dot(corners[j, 0] - p0, corners[j, 1] - p1, corners[j, 2] - p2, n0, n1, n2) > 0:
                front = True
        out[i] = front and (p0 - c[0]) * nl[0] + (p1 - c[1]) * nl[1] + (p2 - c[2]) * nl[2] > 0


def _sample_selection():
    p = np.zeros((2, 3))
    a, b = np.array([0.5, 0.0, 0.0]), np.array([0.0, 0.5, 0.0])
    return p, p + np.array([0.0, 0.0, 1.0]), np.ones(3), a, b, np.array([0.0, 0.0, -1.0]), 1.0, np.empty(2)


@kernel(_sample_selection)
def _shape_selection(points, normals, c, au, av, nl, le, out):
    uu, vv = au[0] * au[0] + au[1] * au[1] + au[2] * au[2], av[0] * av[0] + av[1] * av[1] + av[2] * av[2]
    area = 4.0 * np.sqrt(uu * vv)
    for i in range(len(points)):
        q0, q1, q2 = points[i, 0] - c[0], points[i, 1] - c[1], points[i, 2] - c[2]
        n0, n1, n2 = normals[i, 0], normals[i, 1], normals[i, 2]
        a = _clip((q0 * au[0] + q1 * au[1] + q2 * au[2]) / uu, -1.0, 1.0)
        b = _clip((q0 * av[0] + q1 * av[1] + q2 * av[2]) / vv, -1.0, 1.0)
        s0, s1, s2 = q0 - a * au[0] - b * av[0], q1 - a * au[1] - b * av[1], q2 - a * au[2] - b * av[2]
        r2 = _dot(s0, s1, s2, s0, s1, s2)
        d = max(q0 * nl[0] + q1 * nl[1] + q2 * nl[2], 0.0)
        m = max(-_dot(n0, n1, n2, q0, q1, q2) + abs(n0 * au[0] + n1 * au[1] + n2 * au[2])
                + abs(n0 * av[0] + n1 * av[1] + n2 * av[2]), 0.0)
        out[i] = le * min(np.pi, area * m * d / max(r2 * r2, 1e-300))


def _sample_outline():
    v = np.array([[0.0, 0.0, 1.0], [1.0, 0.0, 1.0], [0.0, 1.0, 1.0]])
    p = np.zeros((2, 3))
    return (p, p + np.array([0.0, 0.0, 1.0]), v, np.array([[0, 1], [1, 2], [2, 0]], np.int64), np.empty(2),
            np.empty(2, bool))


@kernel(_sample_outline)
def _outline(points, normals, verts, ends, out, cut):
    nv = verts.shape[0]
    dirs = np.empty((nv, 3))
    for i in range(len(points)):
        p0, p1, p2 = points[i, 0], points[i, 1], points[i, 2]
        n0, n1, n2 = normals[i, 0], normals[i, 1], normals[i, 2]
        base = _dot(n0, n1, n2, p0, p1, p2)
        below = above = False
        for j in range(nv):
            h = (n0 * verts[j, 0] + n1 * verts[j, 1] + n2 * verts[j, 2]) - base
            below = below or not h >= 0
            above = above or h > 0
        out[i] = 0.0
        cut[i] = below and above
        if below:
            continue
        for j in range(nv):
            x0, x1, x2 = verts[j, 0] - p0, verts[j, 1] - p1, verts[j, 2] - p2
            r = max(np.sqrt(_dot(x0, x1, x2, x0, x1, x2)), 1e-300)
            dirs[j, 0], dirs[j, 1], dirs[j, 2] = x0 / r, x1 / r, x2 / r
        total = 0.0
        for k in range(ends.shape[0]):
            a, b = ends[k, 0], ends[k, 1]
            v0, v1, v2 = dirs[a, 0], dirs[a, 1], dirs[a, 2]
            w0, w1, w2 = dirs[b, 0], dirs[b, 1], dirs[b, 2]
            c0, c1, c2 = v1 * w2 - v2 * w1, v2 * w0 - v0 * w2, v0 * w1 - v1 * w0
            sin = np.sqrt(c0 * c0 + c1 * c1 + c2 * c2)
            theta = np.arctan2(sin, v0 * w0 + v1 * w1 + v2 * w2)
            total += theta * (c0 * n0 + c1 * n1 + c2 * n2) / max(sin, 1e-300)
        out[i] = abs(total) / 2


def _sample_shadow():
    p = np.zeros((2, 3))
    return (p, p + np.array([0.0, 0.0, 1.0]), p + 1.0, np.ones((2, 3)), 1e-5, np.empty((2, 3)), np.empty(2),
            np.empty(2, bool), np.empty((2, 3)), np.empty((2, 3)), np.empty(2))


@kernel(_sample_shadow)
def _shadow_geometry(points, normals, y, e, eps, w, cos_x, live, org, d, t):
    for i in range(len(points)):
        p0, p1, p2 = points[i, 0], points[i, 1], points[i, 2]
        n0, n1, n2 = normals[i, 0], normals[i, 1], normals[i, 2]
        v0, v1, v2 = y[i, 0] - p0, y[i, 1] - p1, y[i, 2] - p2
        r = np.sqrt(max(_dot(v0, v1, v2, v0, v1, v2), 1e-300))
        w0, w1, w2 = v0 / r, v1 / r, v2 / r
        w[i, 0], w[i, 1], w[i, 2] = w0, w1, w2
        c = _dot(n0, n1, n2, w0, w1, w2)
        cos_x[i] = c
        cp = max(c, 0.0)
        e[i, 0], e[i, 1], e[i, 2] = e[i, 0] * cp, e[i, 1] * cp, e[i, 2] * cp
        live[i] = e[i, 0] > 0 or e[i, 1] > 0 or e[i, 2] > 0
        o0, o1, o2 = p0 + n0 * eps, p1 + n1 * eps, p2 + n2 * eps
        s0, s1, s2 = y[i, 0] - o0, y[i, 1] - o1, y[i, 2] - o2
        dist = np.sqrt((s0 * s0 + s1 * s1) + s2 * s2)
        q = max(dist, 1e-300)
        org[i, 0], org[i, 1], org[i, 2] = o0, o1, o2
        d[i, 0], d[i, 1], d[i, 2] = s0 / q, s1 / q, s2 / q
        t[i] = max(dist - 2 * eps, 0.0)
