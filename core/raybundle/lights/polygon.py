"""Analytic irradiance from polygonal lights: the cosine-weighted solid angle
``I = int cos_x dw`` [sr] of a polygon clipped to the receiver's upper hemisphere, by
Lambert's formula ``I = |sum_i theta_i n . g_i| / 2``, so a Lambertian emitter of radiance
``Le`` gives ``E = Le I`` [W/m^2] (no occlusion); lights of many triangles are taken plane by
plane and outline by outline.  The direct-lighting estimator uses it as a control variate."""
from __future__ import annotations

import numpy as np

from ..util import compiled
from . import compiled_lights
from .sources import MeshLight, ShapeLight

#: a mesh light's plane cut by a point's horizon is integrated triangle by triangle
#: (each clipped) only when it has at most this many triangles
ANALYTIC_MAX_TRIANGLES = 64


def polygon_irradiance(points, normals, polygons):
    """Cosine-weighted solid angle (N,) [sr] of planar polygons ``polygons`` (N, M, 3)
    seen from ``points`` (N, 3) with unit ``normals`` (N, 3), clipped to the points'
    upper hemispheres: ``I = int cos_x dw``, so a Lambertian emitter of radiance Le
    gives the irradiance ``E = Le I`` [W/m^2] (no occlusion).

    Lambert's formula on the clipped polygon (Sutherland-Hodgman against the tangent
    plane; vertices repeated to pad a row, whose zero-length edges add nothing):
    ``I = |sum_i theta_i n . g_i| / 2``, ``theta_i`` the angle between the directions to
    vertices i and i+1 and ``g_i`` the unit normal of the plane through them and the point.
    """
    pts = np.asarray(points, float)
    poly = np.asarray(polygons, float)
    n_pts, m = poly.shape[:2]
    d = np.einsum("nmk,nk->nm", poly - pts[:, None], normals)
    a, b = poly, np.roll(poly, -1, axis=1)
    da, db = d, np.roll(d, -1, axis=1)
    inside_a, inside_b = da >= 0, db >= 0
    t = np.where(inside_a != inside_b, da / np.where(da != db, da - db, 1.0), 0.0)
    cut = a + t[..., None] * (b - a)
    cand = np.stack([a, cut], axis=2).reshape(n_pts, 2 * m, 3)
    valid = np.stack([inside_a, inside_a != inside_b], axis=2).reshape(n_pts, 2 * m)
    order = np.argsort(~valid, axis=1, kind="stable")
    cand = np.take_along_axis(cand, order[..., None], axis=1)
    count = valid.sum(axis=1)
    last = np.take_along_axis(cand, np.maximum(count - 1, 0)[:, None, None], axis=1)
    cand = np.where((np.arange(2 * m)[None, :] < count[:, None])[..., None], cand, last)
    v = _unit(cand - pts[:, None])
    return np.where(count >= 3, np.abs(_edge_terms(v, np.roll(v, -1, axis=1), normals).sum(axis=1)) / 2, 0.0)


def _unit(x):
    return x / np.maximum(np.sqrt(np.einsum("...k,...k->...", x, x)), 1e-300)[..., None]


def _edge_terms(v, w, normals):
    """Lambert's per-edge terms ``theta_e n . g_e`` (N, B) of edges from unit directions
    ``v`` to ``w`` (N, B, 3) seen from points with unit ``normals`` (N, 3)."""
    vx, vy, vz = v[..., 0], v[..., 1], v[..., 2]
    wx, wy, wz = w[..., 0], w[..., 1], w[..., 2]
    cx, cy, cz = vy * wz - vz * wy, vz * wx - vx * wz, vx * wy - vy * wx       # v x w
    sin = np.sqrt(cx * cx + cy * cy + cz * cz)
    theta = np.arctan2(sin, vx * wx + vy * wy + vz * wz)
    n = normals[:, None]
    return theta * (cx * n[..., 0] + cy * n[..., 1] + cz * n[..., 2]) / np.maximum(sin, 1e-300)


def clipped_edge_irradiance(points, normals, edges, plane_normal, chunk=16384):
    """``I`` (N,) of a planar polygon (any outline: concave, with holes) given by its
    directed boundary edges ``edges`` (B, 2, 3) [m] in the plane of unit normal
    ``plane_normal``, clipped to the points' upper hemispheres.

    Lambert's sum over the boundary of the clipped polygon: each edge clipped to the
    half-space ``n . (y - x) >= 0``, plus the new boundary along the horizon line, whose
    pieces run from where an edge leaves the half-space to where one enters it.  Those
    lie in the tangent plane, so each adds its signed angle about ``n``, and together
    they add ``sum_entries psi - sum_exits psi`` (``psi`` the angle about ``n`` from a
    fixed direction in the tangent plane), however the exits and entries pair up.  So a
    light cut into many triangles costs its outline even where the horizon cuts it.
    Points that see the whole outline above their horizon (most) take Lambert's sum
    over the outline's vertices' directions, computed once per vertex."""
    out = np.zeros(len(points))
    m = np.asarray(plane_normal, float)
    verts, ends = np.unique(edges.reshape(-1, 3), axis=0, return_inverse=True)
    ends = ends.reshape(-1, 2)
    if compiled.use():
        return compiled_lights.outline_irradiance(points, normals, verts, ends, edges, m)
    height = normals @ verts.T - np.einsum("ij,ij->i", normals, points)[:, None]     # (N, V)
    whole = np.all(height >= 0, axis=1)
    cut = ~whole & np.any(height > 0, axis=1)              # the rest lies wholly below the horizon
    for idx in (np.nonzero(whole)[0], np.nonzero(cut)[0]):
        for lo in range(0, len(idx), chunk):
            i = idx[lo:lo + chunk]
            if whole[i[0]]:
                dirs = _unit(verts[None] - points[i, None])                          # (n, V, 3)
                total = _edge_terms(dirs[:, ends[:, 0]], dirs[:, ends[:, 1]], normals[i]).sum(axis=1)
                out[i] = np.abs(total) / 2
            else:
                out[i] = _cut_outline_irradiance(points[i], normals[i], edges, m)
    return out


def _cut_outline_irradiance(x, n, edges, m):
    """:func:`clipped_edge_irradiance` for points whose horizon cuts the outline."""
    a, b = edges[None, :, 0] - x[:, None], edges[None, :, 1] - x[:, None]     # (N, B, 3)
    da, db = np.einsum("nbk,nk->nb", a, n), np.einsum("nbk,nk->nb", b, n)
    t = np.where(da != db, da / np.where(da != db, da - db, 1.0), 0.0)[..., None]
    cross = a + t * (b - a)
    exits, entries = (da >= 0) & (db < 0), (da < 0) & (db >= 0)
    v = _unit(np.where(entries[..., None], cross, a))
    w = _unit(np.where(exits[..., None], cross, b))
    total = np.where((da >= 0) | (db >= 0), _edge_terms(v, w, n), 0.0).sum(axis=1)
    # psi about n from r, the direction to the horizon line's nearest point
    ell = _unit(np.cross(n, m))
    wdir = np.cross(ell, n)
    r = wdir * np.where((edges[0, 0] - x) @ m * (wdir @ m) < 0, -1.0, 1.0)[:, None]
    psi = np.arctan2(np.einsum("nbk,nk->nb", np.cross(r[:, None], cross), n), np.einsum("nbk,nk->nb", cross, r))
    total += np.where(entries, psi, 0.0).sum(axis=1) - np.where(exits, psi, 0.0).sum(axis=1)
    return np.abs(total) / 2


def light_polygon_irradiance(light, points, normals):
    """``I(x)`` (N,) of :func:`polygon_irradiance` for a polygonal light seen from its
    emitting side (a :class:`MeshLight` of at most :data:`~raybundle.lights.light_planes.MAX_PLANES` planar parts, a
    rectangular :class:`ShapeLight`), and (N,) bool: where it is exact.  ``None`` for other lights.

    A mesh light is integrated plane by plane: by its outline
    (:func:`clipped_edge_irradiance`, exact wherever the horizon cuts it too); a plane
    whose triangles have no consistent outline, by its triangles, each clipped, when it
    has at most :data:`ANALYTIC_MAX_TRIANGLES` of them (otherwise the points whose horizon
    cuts it are not exact, and the caller samples them instead)."""
    if isinstance(light, MeshLight) and light.planes is not None:
        sc = light.scene
        out = np.zeros(len(points))
        exact = np.ones(len(points), bool)
        for rows, nrm, p0, two, box, edges in light.planes:
            front = (points - p0) @ nrm       # the light's own points (in its plane) get nothing from it
            lit = np.nonzero(np.abs(front) > light.plane_tol if two else front > light.plane_tol)[0]
            if len(lit) == 0:
                continue
            if edges is not None:             # (which also drops the points it lies wholly below)
                out[lit] += clipped_edge_irradiance(points[lit], normals[lit], edges, nrm)
                continue
            d = normals[lit] @ box.T - np.einsum("nk,nk->n", normals[lit], points[lit])[:, None]
            lit = lit[~np.all(d <= 0, axis=1)]                 # not wholly below the horizon
            if len(rows) <= ANALYTIC_MAX_TRIANGLES:
                for k in rows:
                    c = sc.triangle_corners[light.triangles[k]]
                    out[lit] += polygon_irradiance(points[lit], normals[lit], np.broadcast_to(c, (len(lit), 3, 3)))
            else:
                exact[lit] = False
        return out, exact
    if isinstance(light, ShapeLight) and not light.ellipse:
        corners = light.corners()
        lit = (points - light.center) @ light.normal > 0
        out = np.zeros(len(points))
        if lit.any():        # by its outline: most points see it whole, Lambert's sum over 4 corners
            out[lit] = clipped_edge_irradiance(points[lit], normals[lit],
                                               np.stack([corners, np.roll(corners, -1, axis=0)], axis=1), light.normal)
        return out, np.ones(len(points), bool)
    return None
