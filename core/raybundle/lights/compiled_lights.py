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
* :func:`cone_directions`, :func:`cone_selection_estimate`: a compact mesh light's directions
  uniform in the cone of its bounding sphere, and its selection bound
  (:meth:`~raybundle.lights.sources.MeshLight.selection_estimate`);
* :func:`outline_irradiance`: Lambert's sum of :func:`~raybundle.lights.polygon.clipped_edge_irradiance`
  over an outline wholly above a point's horizon, and which points' horizons cut it;
* :func:`shadow_geometry`: the direction, cosine and shadow ray of each light sample in
  :meth:`~raybundle.lights.direct.DirectLighting.shadowed`;
* :func:`lamp_accumulate`: what a shadowed light sample adds to its point in
  :func:`~raybundle.lights.reflected_direct.reflected_radiance`: the BRDF, the control variate's
  correction and the glossy lobe's MIS share, with the BRDF's own kernels
  (:mod:`raybundle.scene.compiled_bsdf`).
"""
from __future__ import annotations

import numpy as np

from ..scene import compiled_bsdf
from ..scene.compiled_bsdf import glossy_pdf_at
from ..scene.compiled_microfacet import dot3
from ..util.compiled import helper, kernel

def _V(a, dtype=None):
    """``a`` contiguous and writeable, the kernels' compiled signature (a read-only view, as
    ``broadcast_to`` gives, would compile them again during the run)."""
    a = np.ascontiguousarray(a, dtype)
    return a if a.flags.writeable else a.copy()


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
    frame = _rows([light.center, light.axis_u, light.axis_v, light.normal, ex, ey, np.cross(ex, ey)])
    _shape_sample(_rows(points), _rows(u), frame, bool(light.ellipse), float(light.area), float(radius),
                  float(min_solid_angle), float(lx), float(ly), y, e)
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


# ----------------------------------------------------------------------- compact mesh lights
def cone_directions(centre, radius, points, u):
    """``(d (N, 3), O (N,))``: of :meth:`~raybundle.lights.sources.MeshLight._sample_cone`, the
    directions uniform (by ``u[:, 1:]``) in the cone a sphere (``centre``, ``radius``) fills
    seen from ``points`` outside it, and that cone's solid angle."""
    n = len(points)
    d, omega = np.empty((n, 3)), np.empty(n)
    _cone_directions(_rows(points), _rows(u), _rows(centre), float(radius), d, omega)
    return d, omega


def cone_selection_estimate(centre, radius, le, points, normals):
    """(N,) :meth:`~raybundle.lights.sources.MeshLight.selection_estimate` of a compact light
    of mean radiance ``le`` in the sphere (``centre``, ``radius``)."""
    out = np.empty(len(points))
    _cone_selection(_rows(points), _rows(normals), _rows(centre), float(radius), float(le), out)
    return out


# -------------------------------------------------------------------------------- polygons
def outline_irradiance(points, normals, verts, ends, edges, plane_normal):
    """:func:`~raybundle.lights.polygon.clipped_edge_irradiance`: Lambert's
    ``|sum_e theta_e n . g_e| / 2`` over the outline edges ``ends`` (B, 2) (indices into
    ``verts`` (V, 3), the edges ``edges`` (B, 2, 3) themselves) where every vertex lies on or above a
    point's horizon, the clipped sum where the horizon cuts the outline (whose plane has the unit
    normal ``plane_normal``), 0 where it lies wholly below."""
    out = np.empty(len(points))
    _outline(_rows(points), _rows(normals), _rows(verts), _V(ends, np.int64), _rows(edges), _rows(plane_normal), out)
    return out


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


# ----------------------------------------------------------------------- a sample's light
def lamp_accumulate(mt, mats, normals, w_out, travel, e, free, cos_x, weight, f_d, scale, mis, le, n_s, acc):
    """Add to ``acc`` (S, 3), or (S, 6) with the glossy lobe's part in columns 3-5, what each
    light sample adds at its point (``_one_sample`` of :mod:`~raybundle.lights.reflected_direct`):
    ``- w f_d (free - e)`` where ``f_d`` (S, 3) is given (the control variate), and where the
    sample reached its light, ``w e (f - f_d)`` with the glossy part of ``f`` at the points
    ``mis`` (S,) bool (or None) weighted by the power heuristic against the lobe's own ray
    (``w_l = 1 - p_g^2 / (p_g^2 + (n_s p_l)^2)``, ``p_l = mean(le) cos_x / mean(e)``).  ``mt``
    a material table; per sample its material, unit normal, ``w_out``, ``travel`` (towards
    the point), shadowed ``e`` and unshadowed ``free`` (or None), ``cos_x``, weight ``weight``
    (S, 1), texture ``scale`` (S, 3) or None and its light's radiance ``le`` (S, 3).  Returns
    ``(live, blocked)`` (S,) bool: the samples that reached their light, and those that faced
    it but were blocked (all False without ``free``)."""
    k = len(mats)
    live, blocked = np.empty(k, bool), np.empty(k, bool)
    none3 = np.zeros((0, 3))
    e, w_out = _rows(e), _rows(w_out)
    w_in = -_rows(travel)                                     # towards the light
    # the BRDF where a sample reached its light: its glossy lobe apart where MIS or the glossy part
    # asks for it, the diffuse lobe then added (the same sum the whole BRDF makes)
    i = np.nonzero(np.any(e > 0, axis=1))[0]
    at = (mats[i], normals[i], w_in[i], w_out[i])
    sc = None if scale is None else scale[i]
    if acc.shape[1] == 3 and (mis is None or not mis[i].any()):
        f, lobe = compiled_bsdf.brdf(mt, *at, True, True, sc), none3
    else:
        lobe = compiled_bsdf.brdf(mt, *at, False, True, None)
        f = compiled_bsdf.brdf(mt, *at, True, False, sc) + lobe
    _accumulate(_V(mats, np.int64), _rows(normals), w_out, w_in, e, none3 if free is None else _rows(free),
                _rows(cos_x), _rows(np.broadcast_to(weight, (k, 1))[:, 0]), none3 if f_d is None else _rows(f_d), f,
                lobe, np.zeros(0, bool) if mis is None else _V(mis, bool), _rows(np.broadcast_to(le, (k, 3))),
                float(n_s), compiled_bsdf.packed(mt).alpha, acc, live, blocked)
    return live, blocked


# --------------------------------------------------------------------------------- kernels
@helper
def _clip(x, lo, hi):
    return min(max(x, lo), hi)


@helper
def _by_area(p0, p1, p2, a, b, c, au, av, nl, area):
    """``(y = c + a au + b av, cos_l A / r^2)`` (ShapeLight._by_area; vectors as 3-tuples)."""
    y0, y1, y2 = c[0] + a * au[0] + b * av[0], c[1] + a * au[1] + b * av[1], c[2] + a * au[2] + b * av[2]
    v0, v1, v2 = y0 - p0, y1 - p1, y2 - p2
    r2 = max(dot3(v0, v1, v2, v0, v1, v2), 1e-300)
    return y0, y1, y2, max(-(v0 * nl[0] + v1 * nl[1] + v2 * nl[2]) / np.sqrt(r2), 0.0) * area / r2


@helper
def _solid_angle(p0, p1, p2, u0, u1, c, au, av, lx, ly, ex, ey, ez):
    """A point on the rectangle along a direction uniform in its solid angle O from p, and O
    (Urena, Fajardo and King 2013; ShapeLight._sample_solid_angle; vectors as 3-tuples)."""
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
    return (p0 + xu * ex[0] + yv * ey[0] + zs * ez[0], p1 + xu * ex[1] + yv * ey[1] + zs * ez[1],
            p2 + xu * ex[2] + yv * ey[2] + zs * ez[2], omega)


def _sample_shape():
    frame = np.array([[0.0, 0.0, 1.0], [0.5, 0.0, 0.0], [0.0, 0.5, 0.0], [0.0, 0.0, -1.0], [1.0, 0.0, 0.0],
                      [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])
    return (np.array([[0.1, 0.2, 0.0], [0.0, 0.0, -3.0]]), np.full((2, 2), 0.5), frame, False, 1.0, 0.8, 0.5, 1.0,
            1.0, np.empty((2, 3)), np.empty(2))


@helper
def _row(a, k):
    return a[k, 0], a[k, 1], a[k, 2]


@kernel(_sample_shape)
def _shape_sample(points, u, frame, ellipse, area, radius, min_sa, lx, ly, y, e):
    """``frame`` (7, 3): the lamp's centre, axes u and v, normal, and the unit frame ex, ey, ez."""
    c, au, av, nl = _row(frame, 0), _row(frame, 1), _row(frame, 2), _row(frame, 3)
    ex, ey, ez = _row(frame, 4), _row(frame, 5), _row(frame, 6)
    for i in range(len(points)):
        p0, p1, p2 = points[i, 0], points[i, 1], points[i, 2]
        if ellipse:
            r, phi = np.sqrt(u[i, 0]), 2 * np.pi * u[i, 1]
            y0, y1, y2, ei = _by_area(p0, p1, p2, r * np.cos(phi), r * np.sin(phi), c, au, av, nl, area)
        else:
            q0, q1, q2 = p0 - c[0], p1 - c[1], p2 - c[2]
            gap = max(np.sqrt(q0 * q0 + q1 * q1 + q2 * q2) - radius, 0.0)
            if area >= min_sa * gap * gap and q0 * nl[0] + q1 * nl[1] + q2 * nl[2] > 0:
                y0, y1, y2, ei = _solid_angle(p0, p1, p2, u[i, 0], u[i, 1], c, au, av, lx, ly, ex, ey, ez)
            else:
                y0, y1, y2, ei = _by_area(p0, p1, p2, 2 * u[i, 0] - 1, 2 * u[i, 1] - 1, c, au, av, nl, area)
        y[i, 0], y[i, 1], y[i, 2], e[i] = y0, y1, y2, ei


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
            if dot3(corners[j, 0] - p0, corners[j, 1] - p1, corners[j, 2] - p2, n0, n1, n2) > 0:
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
        r2 = dot3(s0, s1, s2, s0, s1, s2)
        d = max(q0 * nl[0] + q1 * nl[1] + q2 * nl[2], 0.0)
        m = max(-dot3(n0, n1, n2, q0, q1, q2) + abs(n0 * au[0] + n1 * au[1] + n2 * au[2])
                + abs(n0 * av[0] + n1 * av[1] + n2 * av[2]), 0.0)
        out[i] = le * min(np.pi, area * m * d / max(r2 * r2, 1e-300))


def _sample_outline():
    v = np.array([[0.0, 0.0, 1.0], [1.0, 0.0, 1.0], [0.0, 1.0, 1.0]])
    p = np.zeros((2, 3))
    ends = np.array([[0, 1], [1, 2], [2, 0]], np.int64)
    return p, p + np.array([0.0, 0.0, 1.0]), v, ends, v[ends], np.array([0.0, 0.0, 1.0]), np.empty(2)


@helper
def _edge_term(v0, v1, v2, w0, w1, w2, n0, n1, n2):
    """Lambert's ``theta n . g`` of the edge between unit directions v and w (polygon._edge_terms)."""
    c0, c1, c2 = v1 * w2 - v2 * w1, v2 * w0 - v0 * w2, v0 * w1 - v1 * w0
    sin = np.sqrt(c0 * c0 + c1 * c1 + c2 * c2)
    theta = np.arctan2(sin, v0 * w0 + v1 * w1 + v2 * w2)
    return theta * (c0 * n0 + c1 * n1 + c2 * n2) / max(sin, 1e-300)


@helper
def _unit3(x0, x1, x2):
    r = max(np.sqrt(dot3(x0, x1, x2, x0, x1, x2)), 1e-300)
    return x0 / r, x1 / r, x2 / r


@kernel(_sample_outline)
def _outline(points, normals, verts, ends, edges, m, out):
    nv = verts.shape[0]
    dirs = np.empty((nv, 3))
    for i in range(len(points)):
        p0, p1, p2 = points[i, 0], points[i, 1], points[i, 2]
        n0, n1, n2 = normals[i, 0], normals[i, 1], normals[i, 2]
        base = dot3(n0, n1, n2, p0, p1, p2)
        below = above = False
        for j in range(nv):
            h = (n0 * verts[j, 0] + n1 * verts[j, 1] + n2 * verts[j, 2]) - base
            below = below or not h >= 0
            above = above or h > 0
        if below:
            out[i] = _cut_outline(p0, p1, p2, n0, n1, n2, edges, m) if above else 0.0
            continue
        for j in range(nv):
            dirs[j, 0], dirs[j, 1], dirs[j, 2] = _unit3(verts[j, 0] - p0, verts[j, 1] - p1, verts[j, 2] - p2)
        total = 0.0
        for k in range(ends.shape[0]):
            a, b = ends[k, 0], ends[k, 1]
            total += _edge_term(dirs[a, 0], dirs[a, 1], dirs[a, 2], dirs[b, 0], dirs[b, 1], dirs[b, 2], n0, n1, n2)
        out[i] = abs(total) / 2


@helper
def _cut_outline(p0, p1, p2, n0, n1, n2, edges, m):
    """polygon._cut_outline_irradiance at one point: the edges clipped to its upper half-space,
    and the horizon's pieces by their angles psi about n."""
    l0, l1, l2 = _unit3(n1 * m[2] - n2 * m[1], n2 * m[0] - n0 * m[2], n0 * m[1] - n1 * m[0])
    r0, r1, r2 = l1 * n2 - l2 * n1, l2 * n0 - l0 * n2, l0 * n1 - l1 * n0
    if ((edges[0, 0, 0] - p0) * m[0] + (edges[0, 0, 1] - p1) * m[1] + (edges[0, 0, 2] - p2) * m[2]) * \
            (r0 * m[0] + r1 * m[1] + r2 * m[2]) < 0:
        r0, r1, r2 = -r0, -r1, -r2
    terms = entered = left = 0.0
    for k in range(edges.shape[0]):
        a0, a1, a2 = edges[k, 0, 0] - p0, edges[k, 0, 1] - p1, edges[k, 0, 2] - p2
        b0, b1, b2 = edges[k, 1, 0] - p0, edges[k, 1, 1] - p1, edges[k, 1, 2] - p2
        da, db = dot3(a0, a1, a2, n0, n1, n2), dot3(b0, b1, b2, n0, n1, n2)
        t = da / (da - db) if da != db else 0.0
        x0, x1, x2 = a0 + t * (b0 - a0), a1 + t * (b1 - a1), a2 + t * (b2 - a2)
        exits, entries = da >= 0 and db < 0, da < 0 and db >= 0
        v0, v1, v2 = _unit3(x0, x1, x2) if entries else _unit3(a0, a1, a2)
        w0, w1, w2 = _unit3(x0, x1, x2) if exits else _unit3(b0, b1, b2)
        if da >= 0 or db >= 0:
            terms += _edge_term(v0, v1, v2, w0, w1, w2, n0, n1, n2)
        c0, c1, c2 = r1 * x2 - r2 * x1, r2 * x0 - r0 * x2, r0 * x1 - r1 * x0
        psi = np.arctan2(dot3(c0, c1, c2, n0, n1, n2), dot3(x0, x1, x2, r0, r1, r2))
        if entries:
            entered += psi
        if exits:
            left += psi
    return abs(terms + (entered - left)) / 2


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
        r = np.sqrt(max(dot3(v0, v1, v2, v0, v1, v2), 1e-300))
        w0, w1, w2 = v0 / r, v1 / r, v2 / r
        w[i, 0], w[i, 1], w[i, 2] = w0, w1, w2
        c = dot3(n0, n1, n2, w0, w1, w2)
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


def _sample_accumulate():
    v = np.tile([[0.0, 0.0, 1.0]], (2, 1))
    z = np.zeros((0, 3))
    return (np.zeros(2, np.int64), v, v, v, np.ones((2, 3)), np.ones((2, 3)), np.ones(2), np.ones(2), z,
            np.ones((2, 3)), z, np.zeros(2, bool), np.ones((2, 3)), 1.0, np.full(1, 0.25), np.zeros((2, 6)),
            np.empty(2, bool), np.empty(2, bool))


@kernel(_sample_accumulate)
def _accumulate(mats, normals, w_out, w_in, e, free, cos_x, weight, f_d, f, lobe, mis, le, n_s, alpha, acc, live,
                blocked):
    """``lamp_accumulate`` with the BRDF ``f`` (L, 3) and its glossy lobe ``lobe`` (L, 3, or (0, 3)
    where neither the glossy part nor MIS is asked for) evaluated already at the L samples that
    reached their light, in order."""
    has_free, has_fd, has_mis = free.shape[0] > 0, f_d.shape[0] > 0, mis.shape[0] > 0
    glossy = acc.shape[1] == 6
    fr, gl = np.empty(3), np.empty(3)
    j = -1                      # the row of f and lobe
    for r in range(len(mats)):
        w = weight[r]
        if has_fd:
            for c in range(3):
                acc[r, c] -= w * f_d[r, c] * (free[r, c] - e[r, c])
        seen = e[r, 0] > 0 or e[r, 1] > 0 or e[r, 2] > 0
        live[r] = seen
        blocked[r] = has_free and not seen and (free[r, 0] > 0 or free[r, 1] > 0 or free[r, 2] > 0)
        if not seen:
            continue
        j += 1
        for c in range(3):
            fr[c] = f[j, c] - f_d[r, c] if has_fd else f[j, c]
            if glossy:
                gl[c] = lobe[j, c]
        if has_mis and mis[r]:
            n0, n1, n2 = normals[r, 0], normals[r, 1], normals[r, 2]
            p_l = (le[r, 0] + le[r, 1] + le[r, 2]) / 3.0 * cos_x[r] / ((e[r, 0] + e[r, 1] + e[r, 2]) / 3.0)
            p_g = glossy_pdf_at(alpha[mats[r]], n0, n1, n2, w_in[r, 0], w_in[r, 1], w_in[r, 2], w_out[r, 0],
                                w_out[r, 1], w_out[r, 2])
            a2, b = p_g * p_g, n_s * p_l
            b2 = b * b
            w_l = 1.0 - (a2 / max(a2 + b2, 1e-300) if a2 > 0 else 0.0)
            for c in range(3):
                before = fr[c]
                fr[c] = fr[c] - (1.0 - w_l) * lobe[j, c]
                if glossy:
                    gl[c] = gl[c] - (before - fr[c])
        for c in range(3):
            we = w * e[r, c]
            acc[r, c] += we * fr[c]
            if glossy:
                acc[r, 3 + c] += we * gl[c]


@helper
def _cone(p0, p1, p2, c, radius):
    """The unit direction to the sphere's centre, the distance to it, and the cos of the cone's
    half-angle and its solid angle (MeshLight._cone_solid_angle)."""
    v0, v1, v2 = c[0] - p0, c[1] - p1, c[2] - p2
    dist = np.sqrt((v0 * v0 + v1 * v1) + v2 * v2)
    q = radius / dist
    cos_max = np.sqrt(max(1.0 - q * q, 0.0))
    return v0 / dist, v1 / dist, v2 / dist, dist, cos_max, 2.0 * np.pi * (1.0 - cos_max)


def _sample_cone():
    p = np.zeros((2, 3))
    return p, np.full((2, 3), 0.5), np.array([0.0, 0.0, 3.0]), 1.0, np.empty((2, 3)), np.empty(2)


@kernel(_sample_cone)
def _cone_directions(points, u, centre, radius, d, omega):
    c = (centre[0], centre[1], centre[2])
    for i in range(len(points)):
        w0, w1, w2, _, cos_max, om = _cone(points[i, 0], points[i, 1], points[i, 2], c, radius)
        cos_t = 1.0 - u[i, 1] * (1.0 - cos_max)
        sin_t = np.sqrt(max(1.0 - cos_t * cos_t, 0.0))
        phi = 2.0 * np.pi * u[i, 2]
        sign = 1.0 if w2 >= 0 else -1.0                 # sampling.frames_from_normals
        a = -1.0 / (sign + w2)
        b = w0 * w1 * a
        t0, t1, t2 = 1 + sign * (w0 * w0) * a, sign * b, -sign * w0
        b0, b1, b2 = b, sign + (w1 * w1) * a, -w1
        sc, ss = sin_t * np.cos(phi), sin_t * np.sin(phi)
        d[i, 0] = cos_t * w0 + sc * t0 + ss * b0
        d[i, 1] = cos_t * w1 + sc * t1 + ss * b1
        d[i, 2] = cos_t * w2 + sc * t2 + ss * b2
        omega[i] = om


def _sample_cone_selection():
    p = np.zeros((2, 3))
    return p, p + np.array([0.0, 0.0, 1.0]), np.array([0.0, 0.0, 3.0]), 1.0, 1.0, np.empty(2)


@kernel(_sample_cone_selection)
def _cone_selection(points, normals, centre, radius, le, out):
    c = (centre[0], centre[1], centre[2])
    for i in range(len(points)):
        w0, w1, w2, dist, cos_u, om = _cone(points[i, 0], points[i, 1], points[i, 2], c, radius)
        if not dist > radius * (1.0 + 1e-9):         # inside: a hemisphere
            out[i] = le * 2.0 * np.pi
            continue
        cos_i = dot3(normals[i, 0], normals[i, 1], normals[i, 2], w0, w1, w2)
        sin_i, sin_u = np.sqrt(max(1 - cos_i * cos_i, 0.0)), np.sqrt(max(1 - cos_u * cos_u, 0.0))
        cos_near = 1.0 if cos_i >= cos_u else cos_i * cos_u + sin_i * sin_u
        out[i] = le * om * max(cos_near, 0.0)
