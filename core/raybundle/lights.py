"""Small lights and their direct illumination: the generalized (incoming) first shot.

Thesis 3.4: small and point lights are hard for bundles (a bundle hits a small
light with probability ~ its solid angle / 4 pi, and never hits a point light).
Their emission ``Le_s`` is therefore taken out of the iteration: the incoming
radiance they create is computed first, by shadow rays, and the iteration then
solves ``L~ = (Le_r + L1) + T L~`` with ``L1 = T Le_s`` as extra emission.

* Per patch (used inside the iteration), for every light l the patch-average
  irradiance ``E_{i,l}`` [W/m^2] and its mean travel direction ``w_{i,l}``, so the
  first-shot radiance is ``L1_i(w) = sum_l E_{i,l} f_i(w_{i,l}, w)`` (incoming
  first shot: only incoming values are stored, the BRDF is applied on the fly).
* Per pixel (for the image), the reflected direct radiance at the visible point
  is estimated with fresh shadow rays every image pass, so shadows and glossy
  highlights are sharp (:meth:`DirectLighting.reflected_radiance`).

Lights (each an object with ``sample(points, u)``, see :class:`MeshLight`):

* every emitting material whose emission is constant and whose area is at
  most ``small_fraction`` of the scene's area: a :class:`MeshLight`, a Lambertian
  emitter on its front (and, for two-sided triangles, on its back too), sampled
  by area where it looks small and by solid angle where it may look large, one
  planar part at a time when its parts have convex outlines (so a lamp modelled as
  a grid of many triangles is sampled as well as a single quad);
* point and spot lights (:class:`PointLight`): ``E = I s(w) cos / r^2`` with
  Cycles' spot attenuation s, and a disc of the light's radius for soft shadows;
* Blender area lights (:class:`ShapeLight`): one-sided rectangles and ellipses
  that are not geometry;
* suns (:class:`SunLight`): ``E = E_sun cos`` from a cone of the sun's angle.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .sampling import (frames_from_normals, orthonormal_basis, points_on_triangles, sample_spherical_triangle,
                       triangle_solid_angle)


@dataclass
class MeshLight:
    """Triangles of one emitting material: ``triangles`` (K,), area-CDF, area [m^2],
    radiance (3,), ``two_sided`` (K,) bool (the triangle emits from its back too)."""

    material: int
    triangles: np.ndarray
    cdf: np.ndarray
    area: float
    radiance: np.ndarray
    two_sided: np.ndarray
    scene: object = None

    #: triangles that may look larger than this [sr] are sampled by solid angle, others by area
    MIN_SOLID_ANGLE = 0.5

    def __post_init__(self):
        c = self.scene.triangle_corners[self.triangles]
        self._centroid = c.mean(axis=1)
        self._radius = np.linalg.norm(c - self._centroid[:, None], axis=2).max(axis=1)
        self.planes = light_planes(self)
        self._fans = plane_fans(self)

    def sample(self, points, u):
        """One sample of the light for each point (N, 3) from uniforms ``u`` (N, 3).

        Returns ``(y (N, 3), e (N, 3))``: the sampled point on the light and the
        unshadowed irradiance estimate on a plane facing it: the caller
        multiplies by ``cos_x`` (w = direction to y) and tests visibility.

        A light whose planar parts have convex outlines (:func:`plane_fans`: a lamp
        quad, a box, a lamp cut into a grid of many triangles) is sampled part by part:
        part g with probability ``p_g = A_g / A``; where it looks small, a point uniform
        on it (``e = Le cos_l A_g / (r^2 p_g)``); where it may look large, a direction
        uniform in its whole solid angle (a fan triangle of its outline by its solid
        angle, then Arvo's sampling in it: ``e = Le O_g / p_g``, bounded next to the
        light however finely it is meshed).  Other lights: triangle by triangle
        (:meth:`_sample_triangles`)."""
        if self._fans is None:
            return self._sample_triangles(points, u)
        f = self._fans
        g = np.minimum(np.searchsorted(f["cdf"], u[:, 0], side="right"), len(f["area"]) - 1)
        lo = f["cdf"][g] - f["p"][g]
        u0 = np.clip((u[:, 0] - lo) / f["p"][g], 0.0, 1.0 - 1e-12)
        normal = f["normal"][g]
        # far: a fan triangle by area, a point uniform on it
        j = np.minimum(np.searchsorted(f["fan_key"], g + u0, side="right"), len(f["fan_key"]) - 1)
        y = points_on_triangles(f["fan"][j], u[:, 1], u[:, 2])
        v = y - points
        r2 = np.maximum(np.einsum("ij,ij->i", v, v), 1e-300)
        cos_l = -np.einsum("ij,ij->i", normal, v) / np.sqrt(r2)
        e = cos_l * f["area"][g] / r2
        near = self._part_near(g, points)
        for gi in np.unique(g[near]):
            idx = np.nonzero(near & (g == gi))[0]
            rel, omega = self._fan_solid_angles(gi, points[idx])
            total = omega.sum(axis=1)
            cdf = np.cumsum(omega, axis=1) / np.maximum(total, 1e-300)[:, None]
            k = np.minimum((cdf <= u0[idx, None]).sum(axis=1), omega.shape[1] - 1)
            lo_k = np.where(k > 0, cdf[np.arange(len(idx)), np.maximum(k - 1, 0)], 0.0)
            w_k = np.maximum(cdf[np.arange(len(idx)), k] - lo_k, 1e-300)
            u1 = np.clip((u0[idx] - lo_k) / w_k, 0.0, 1.0)
            tri = rel[np.arange(len(idx)), k]
            d, _ = sample_spherical_triangle(tri[:, 0], tri[:, 1], tri[:, 2], u1, u[idx, 2])
            nd = np.einsum("ij,ij->i", normal[idx], d)
            t = np.einsum("ij,ij->i", normal[idx], tri[:, 0]) / np.where(nd != 0, nd, 1e-300)
            y[idx] = points[idx] + t[:, None] * d
            cos_l[idx] = -nd
            e[idx] = total
        lit = np.where(f["two_sided"][g], cos_l != 0, cos_l > 0)
        return y, (np.abs(e) * lit / f["p"][g])[:, None] * self.radiance

    def _part_near(self, g, points):
        """(N,) bool: planar part ``g`` (N,) may look large from ``points`` (its solid angle
        is not surely below :attr:`MIN_SOLID_ANGLE`): it is then sampled by solid angle."""
        f = self._fans
        gap = np.maximum(np.linalg.norm(f["centroid"][g] - points, axis=1) - f["radius"][g], 0.0)
        return f["area"][g] >= self.MIN_SOLID_ANGLE * gap * gap

    def _fan_solid_angles(self, gi, points):
        """Part ``gi``'s fan triangles relative to ``points`` (n, F, 3, 3) and their solid angles (n, F)."""
        f = self._fans
        rel = f["fan"][f["fan_group"] == gi][None] - points[:, None, None, :]
        return rel, triangle_solid_angle(rel[..., 0, :], rel[..., 1, :], rel[..., 2, :])

    def _sample_triangles(self, points, u):
        """:meth:`sample` triangle by triangle.  A triangle k is picked with probability p_k = A_k / A.  If it looks
        small from the point (its solid angle is surely below :attr:`MIN_SOLID_ANGLE`:
        ``A_k < MIN_SOLID_ANGLE d^2`` with d the distance to its bounding sphere) a point
        uniform on it gives ``e = Le cos_l A_k / (r^2 p_k)``; if it looks large, a
        direction uniform in its solid angle (Arvo's spherical triangle
        sampling) gives ``e = Le O_k / p_k``.  Both are unbiased; the second keeps
        the estimate bounded next to the light (a lamp 0.5 mm under a ceiling),
        where sampling by area has a heavy tail.  Emits from the back only where
        ``two_sided``."""
        from .sampling import sample_spherical_triangle

        sc = self.scene
        n_k = len(self.triangles)
        k = np.minimum(np.searchsorted(self.cdf, u[:, 0] * self.cdf[-1], side="right"), n_k - 1)
        tri = self.triangles[k]
        p_k = sc.triangle_area[tri] / self.area
        c = sc.triangle_corners[tri]
        y = points_on_triangles(c, u[:, 1], u[:, 2])
        normal = sc.triangle_normal[tri]
        v = y - points
        r2 = np.maximum(np.einsum("ij,ij->i", v, v), 1e-300)
        cos_l = -np.einsum("ij,ij->i", normal, v) / np.sqrt(r2)
        e = cos_l * sc.triangle_area[tri] / r2
        gap = np.maximum(np.linalg.norm(self._centroid[k] - points, axis=1) - self._radius[k], 0.0)
        near = np.nonzero(sc.triangle_area[tri] >= self.MIN_SOLID_ANGLE * gap * gap)[0]
        if len(near):
            rel = c[near] - points[near, None, :]
            d, omega = sample_spherical_triangle(rel[:, 0], rel[:, 1], rel[:, 2], u[near, 1], u[near, 2])
            nd = np.einsum("ij,ij->i", normal[near], d)
            t = np.einsum("ij,ij->i", normal[near], rel[:, 0]) / np.where(nd != 0, nd, 1e-300)
            y[near] = points[near] + t[:, None] * d
            cos_l[near] = -nd
            e[near] = omega
        lit = np.where(self.two_sided[k], cos_l != 0, cos_l > 0)
        return y, (np.abs(e) * lit / p_k)[:, None] * self.radiance

    def pdf(self, points, k, y):
        """Density [1/sr] with which :meth:`sample` draws, from ``points`` (N, 3), the
        direction to ``y`` (N, 3) on the light's triangle ``triangles[k]`` (k (N,)):
        ``p / O`` where the part (or triangle) looks large (solid-angle sampling), else
        ``p r^2 / (A_part |cos_l|) = r^2 / (A |cos_l|)`` (area sampling)."""
        sc = self.scene
        if self._fans is not None:
            f = self._fans
            g = f["tri_group"][k]
            v = y - points
            r2 = np.maximum(np.einsum("ij,ij->i", v, v), 1e-300)
            cos_l = np.abs(np.einsum("ij,ij->i", f["normal"][g], v)) / np.sqrt(r2)
            pdf = r2 / (np.maximum(cos_l, 1e-300) * self.area)
            near = self._part_near(g, points)
            for gi in np.unique(g[near]):
                idx = np.nonzero(near & (g == gi))[0]
                pdf[idx] = f["p"][gi] / np.maximum(self._fan_solid_angles(gi, points[idx])[1].sum(axis=1), 1e-300)
            return pdf
        tri = self.triangles[k]
        area_k = sc.triangle_area[tri]
        v = y - points
        r2 = np.maximum(np.einsum("ij,ij->i", v, v), 1e-300)
        cos_l = np.abs(np.einsum("ij,ij->i", sc.triangle_normal[tri], v)) / np.sqrt(r2)
        pdf = r2 / (np.maximum(cos_l, 1e-300) * self.area)
        gap = np.maximum(np.linalg.norm(self._centroid[k] - points, axis=1) - self._radius[k], 0.0)
        near = np.nonzero(area_k >= self.MIN_SOLID_ANGLE * gap * gap)[0]
        if len(near):
            rel = sc.triangle_corners[tri[near]] - points[near, None, :]
            omega = triangle_solid_angle(rel[:, 0], rel[:, 1], rel[:, 2])
            pdf[near] = (area_k[near] / self.area) / np.maximum(omega, 1e-300)
        return pdf

    def in_front(self, origin, normal):
        """(N,) bool: some point of the light lies in front of the planes (origin, normal) (N, 3)."""
        c = self.scene.triangle_corners[self.triangles].reshape(-1, 3)
        return _box_in_front(c.min(axis=0), c.max(axis=0), origin, normal)


@dataclass
class PointLight:
    """A point or spot light (``PointLights`` row ``k``); see :meth:`MeshLight.sample`.

    ``e = I s(travel) / r^2`` with ``s`` Cycles' spot attenuation.  A light with
    a radius is sampled on the disc of that radius facing the point (soft
    shadows; exact far from the light, where a sphere looks like that disc)."""

    position: np.ndarray
    intensity: np.ndarray
    lights: object
    k: int

    def sample(self, points, u):
        to_light = self.position - points
        dist = np.maximum(np.linalg.norm(to_light, axis=1), 1e-300)
        travel = -to_light / dist[:, None]
        y = np.broadcast_to(self.position, points.shape)
        radius = float(self.lights.radius[self.k])
        if radius > 0:
            a, b = frames_from_normals(travel)
            r = radius * np.sqrt(u[:, 0])
            phi = 2 * np.pi * u[:, 1]
            y = y + (r * np.cos(phi))[:, None] * a + (r * np.sin(phi))[:, None] * b
        v = y - points
        r2 = np.maximum(np.einsum("ij,ij->i", v, v), 1e-300)
        s = self.lights.spot_factor(self.k, travel)
        return y, (s / r2)[:, None] * self.intensity

    def in_front(self, origin, normal):
        r = float(self.lights.radius[self.k])
        return np.einsum("ij,ij->i", self.position - origin, normal) > -r


@dataclass
class ShapeLight:
    """A Blender area light (``AreaLights`` row): a one-sided Lambertian rectangle
    or ellipse that is not geometry.  ``e = Le cos_l A / r^2`` (pdf 1/A)."""

    center: np.ndarray
    axis_u: np.ndarray
    axis_v: np.ndarray
    normal: np.ndarray
    ellipse: bool
    area: float
    radiance: np.ndarray

    def sample(self, points, u):
        if self.ellipse:
            r, phi = np.sqrt(u[:, 0]), 2 * np.pi * u[:, 1]
            a, b = r * np.cos(phi), r * np.sin(phi)
        else:
            a, b = 2 * u[:, 0] - 1, 2 * u[:, 1] - 1
        y = self.center + a[:, None] * self.axis_u + b[:, None] * self.axis_v
        v = y - points
        r2 = np.maximum(np.einsum("ij,ij->i", v, v), 1e-300)
        cos_l = np.maximum(-(v @ self.normal) / np.sqrt(r2), 0.0)
        return y, (cos_l * self.area / r2)[:, None] * self.radiance

    def in_front(self, origin, normal):
        corners = [self.center + a * self.axis_u + b * self.axis_v for a in (-1, 1) for b in (-1, 1)]
        return np.any([np.einsum("ij,ij->i", c - origin, normal) > 0 for c in corners], axis=0)


@dataclass
class SunLight:
    """A distant light: travel directions uniform in the cone of half-angle
    ``angle / 2`` around ``direction``; ``e = irradiance`` (no fall-off).  The
    sample point lies ``far`` [m] away towards the sun (beyond the scene)."""

    direction: np.ndarray
    irradiance: np.ndarray
    angle: float
    far: float

    def sample(self, points, u):
        cos_max = np.cos(0.5 * self.angle)
        cos_t = 1.0 - u[:, 0] * (1.0 - cos_max)
        sin_t = np.sqrt(np.maximum(0.0, 1.0 - cos_t * cos_t))
        a, b = orthonormal_basis(self.direction)
        phi = 2 * np.pi * u[:, 1]
        travel = (cos_t[:, None] * self.direction + (sin_t * np.cos(phi))[:, None] * a
                  + (sin_t * np.sin(phi))[:, None] * b)
        return points - self.far * travel, np.broadcast_to(self.irradiance, points.shape).copy()

    def in_front(self, origin, normal):
        return -(normal @ self.direction) > -np.sin(0.5 * self.angle)


def _box_in_front(lo, hi, origin, normal):
    """(N,) bool: a corner of the box [lo, hi] lies in front of the planes (origin, normal)."""
    corner = np.where(normal > 0, hi, lo)            # the corner furthest along each normal
    return np.einsum("ij,ij->i", corner - origin, normal) > 0


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


def _merge_collinear(vertices, directed):
    """Directed boundary edges (B, 2) (vertex ids) -> edge end points (B', 2, 3), chains of
    collinear edges merged into one (the outline of a light cut into a grid of triangles
    has 4 edges, not 4 n: Lambert's sum over a straight edge does not depend on how it is
    split).  Outlines whose loops cannot be walked (a vertex with two outgoing edges) stay as they are."""
    nxt = {}
    for a, b in directed.tolist():
        if a in nxt:
            return vertices[directed]
        nxt[a] = b
    out, seen = [], set()
    for start in list(nxt):
        if start in seen:
            continue
        loop = [start]
        seen.add(start)
        v = nxt[start]
        while v != start and v in nxt and v not in seen:
            loop.append(v)
            seen.add(v)
            v = nxt[v]
        pts = vertices[loop]
        d_in = pts - np.roll(pts, 1, axis=0)
        d_out = np.roll(pts, -1, axis=0) - pts
        cross = np.linalg.norm(np.cross(d_in, d_out), axis=1)
        scale = np.linalg.norm(d_in, axis=1) * np.linalg.norm(d_out, axis=1)
        corner = (cross > 1e-9 * scale) | (np.einsum("ij,ij->i", d_in, d_out) < 0)
        keep = pts[corner] if corner.sum() >= 3 else pts
        out.append(np.stack([keep, np.roll(keep, -1, axis=0)], axis=1))
    return np.concatenate(out) if out else vertices[directed]


#: mesh lights with more planar parts than this (a tessellated sphere) are sampled and
#: integrated triangle by triangle
MAX_PLANES = 64


def light_planes(light):
    """The planar parts of a mesh light: a list of (triangle rows into ``light.triangles``,
    unit normal, a point of the plane, two-sided, bounding-box corners (8, 3), directed
    boundary edges (B, 2, 3) or None when the triangles do not form a consistently
    oriented, T-junction-free surface, whose outline cannot stand for them); None for a
    light of more than :data:`MAX_PLANES` parts."""
    sc = light.scene
    tri = light.triangles
    nrm = sc.triangle_normal[tri]
    p0 = sc.triangle_corners[tri, 0]
    _, r = sc.bounding_sphere
    key = np.concatenate([np.round(nrm * 1e5), np.round((nrm * p0).sum(axis=1) / max(r * 1e-7, 1e-12))[:, None],
                          light.two_sided[:, None]], axis=1).astype(np.int64)
    _, label = np.unique(key, axis=0, return_inverse=True)
    n_planes = int(label.max()) + 1 if len(label) else 0
    if n_planes > MAX_PLANES:
        return None
    planes = []
    for g in range(n_planes):
        rows = np.nonzero(label.reshape(-1) == g)[0]
        ids = sc.triangles[tri[rows]]
        corners = sc.triangle_corners[tri[rows]]
        lo, hi = corners.reshape(-1, 3).min(axis=0), corners.reshape(-1, 3).max(axis=0)
        box = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])
        e = np.concatenate([ids[:, [0, 1]], ids[:, [1, 2]], ids[:, [2, 0]]])
        und = np.sort(e, axis=1)
        uniq, inv, cnt = np.unique(und, axis=0, return_inverse=True, return_counts=True)
        inv = inv.reshape(-1)
        edges = None
        once = cnt[inv] == 1
        twice_ok = np.all(cnt <= 2)
        if twice_ok:
            # interior edges must be traversed both ways (consistent winding)
            fwd = (e[:, 0] == und[:, 0]).astype(int)
            per = np.bincount(inv, fwd, minlength=len(uniq))
            if np.all(per[cnt == 2] == 1):
                edges = _merge_collinear(sc.vertices, e[once])      # (B, 2, 3)
                # the outline's area vector must equal the triangles' total area (no T-junctions)
                area_vec = 0.5 * np.cross(edges[:, 0], edges[:, 1]).sum(axis=0)
                total = sc.triangle_area[tri[rows]].sum()
                if abs(area_vec @ nrm[rows[0]] - total) > 1e-6 * total:
                    edges = None
        planes.append((rows, nrm[rows[0]], p0[rows[0]], bool(light.two_sided[rows[0]]), box, edges))
    return planes


def plane_fans(light):
    """Sampling tables of a mesh light whose planar parts (``light.planes``) each
    have one convex outline: per part its area, probability ``A_g / A`` and CDF, normal,
    sidedness, bounding sphere, and the fan triangles of its outline (``fan`` (F, 3, 3),
    ``fan_group``, ``fan_key`` = group + area CDF within it); ``tri_group`` maps the
    light's triangles to parts.  None when a part's outline is not one convex loop (or
    there are more than :data:`MAX_PLANES` parts): the light is then sampled triangle by triangle."""
    planes = light.planes
    if not planes:
        return None
    sc = light.scene
    fans, fan_group, areas, normals, two, cents, radii = [], [], [], [], [], [], []
    tri_group = np.zeros(len(light.triangles), np.int64)
    for gi, (rows, nrm, _, two_sided, _, edges) in enumerate(planes):
        if edges is None or len(edges) < 3 or not np.allclose(edges[:, 1], np.roll(edges[:, 0], -1, axis=0)):
            return None
        pts = edges[:, 0]
        d = np.roll(pts, -1, axis=0) - pts
        turn = np.cross(d, np.roll(d, -1, axis=0)) @ nrm
        scale = np.linalg.norm(d, axis=1) * np.linalg.norm(np.roll(d, -1, axis=0), axis=1)
        if not (np.all(turn >= -1e-9 * scale) or np.all(turn <= 1e-9 * scale)):
            return None                                    # not convex
        fan = np.stack([np.broadcast_to(pts[0], (len(pts) - 2, 3)), pts[1:-1], pts[2:]], axis=1)
        fa = 0.5 * np.linalg.norm(np.cross(fan[:, 1] - fan[:, 0], fan[:, 2] - fan[:, 0]), axis=1)
        area = float(sc.triangle_area[light.triangles[rows]].sum())
        if abs(fa.sum() - area) > 1e-6 * area:
            return None
        fans.append(fan)
        fan_group.append(np.full(len(fan), gi))
        areas.append(area)
        normals.append(nrm)
        two.append(two_sided)
        c = pts.mean(axis=0)
        cents.append(c)
        radii.append(float(np.linalg.norm(pts - c, axis=1).max()))
        tri_group[rows] = gi
    fan = np.concatenate(fans)
    fan_group = np.concatenate(fan_group)
    fa = 0.5 * np.linalg.norm(np.cross(fan[:, 1] - fan[:, 0], fan[:, 2] - fan[:, 0]), axis=1)
    areas = np.array(areas)
    within = np.zeros(len(fan))
    for gi in range(len(areas)):
        sel = fan_group == gi
        within[sel] = np.cumsum(fa[sel]) / fa[sel].sum()
    p = areas / areas.sum()
    return {"area": areas, "p": p, "cdf": np.cumsum(p), "normal": np.array(normals), "two_sided": np.array(two),
            "centroid": np.array(cents), "radius": np.array(radii), "fan": fan, "fan_group": fan_group,
            "fan_key": fan_group + within, "tri_group": tri_group}


def light_polygon_irradiance(light, points, normals):
    """``I(x)`` (N,) of :func:`polygon_irradiance` for a polygonal light seen from its
    emitting side (a :class:`MeshLight` of at most :data:`MAX_PLANES` planar parts, a
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
            front = (points - p0) @ nrm
            lit = np.nonzero(front != 0 if two else front > 0)[0]
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
        corners = np.array([light.center + a * light.axis_u + b * light.axis_v
                            for a, b in ((-1, -1), (1, -1), (1, 1), (-1, 1))])
        lit = (points - light.center) @ light.normal > 0
        out = np.zeros(len(points))
        if lit.any():
            out[lit] = polygon_irradiance(points[lit], normals[lit], np.broadcast_to(corners, (int(lit.sum()), 4, 3)))
        return out, np.ones(len(points), bool)
    return None


def small_emitters(scene, small_fraction=0.1):
    """Material ids (list) of the mesh emitters the first shot takes: constant emission (not
    the furnaces' ``c (1 - a(w))``) over at most ``small_fraction`` of the scene's area."""
    mats = scene.materials
    total = scene.triangle_area.sum()
    constant = ~np.any(mats.emission_albedo_complement > 0, axis=1) & np.any(mats.emission > 0, axis=1)
    out = []
    for m in np.nonzero(constant)[0]:
        tri = scene.triangle_material == m
        if tri.any() and scene.triangle_area[tri].sum() <= small_fraction * total:
            out.append(int(m))
    return out


class DirectLighting:
    """First-shot lights of a scene and the direct-illumination estimators."""

    def __init__(self, scene, tracer, first_shot="auto", small_fraction=0.1):
        if first_shot not in ("auto", "none"):
            raise ValueError("first_shot must be 'auto' or 'none'")
        self.scene = scene
        self.tracer = tracer
        self.rays = 0  # shadow rays traced so far
        # area_lights: sampled ``samples_per_light`` times per point (mesh and shape lights);
        # point_lights: one sample per point (point, spot and sun lights)
        mats = scene.materials
        self.first_shot_material = np.zeros(len(mats), bool)
        self.area_lights: list[MeshLight] = []
        if first_shot == "auto":
            for m in small_emitters(scene, small_fraction):
                tri = np.nonzero(scene.triangle_material == m)[0]
                self.first_shot_material[m] = True
                cdf = np.cumsum(scene.triangle_area[tri])
                self.area_lights.append(MeshLight(int(m), tri, cdf / cdf[-1], float(scene.triangle_area[tri].sum()),
                                                  mats.emission[m].astype(float),
                                                  scene.triangle_two_sided[tri], scene))
        pl = scene.point_lights
        self.point_lights = [PointLight(pl.position[k], pl.intensity[k], pl, k) for k in range(len(pl))
                             if np.any(pl.intensity[k] > 0)]
        al = scene.area_lights
        self.area_lights += [ShapeLight(al.center[k], al.axis_u[k], al.axis_v[k], al.normal[k], bool(al.shape[k] == 1),
                                        float(al.area[k]), al.radiance[k]) for k in range(len(al))
                             if np.any(al.radiance[k] > 0)]
        # mesh-light triangles: which light (index into light_list()) and which of its triangles
        self.triangle_light = np.full(len(scene.triangles), -1, np.int64)
        self.triangle_light_k = np.zeros(len(scene.triangles), np.int64)
        for li, light in enumerate(self.area_lights):
            if isinstance(light, MeshLight):
                self.triangle_light[light.triangles] = li
                self.triangle_light_k[light.triangles] = np.arange(len(light.triangles))
        sl = scene.sun_lights
        far = 4.0 * tracer.radius + 1.0
        self.point_lights += [SunLight(sl.direction[k], sl.irradiance[k], float(sl.angle[k]), far)
                              for k in range(len(sl)) if np.any(sl.irradiance[k] > 0)]

    @property
    def n_lights(self):
        return len(self.area_lights) + len(self.point_lights)

    def light_samples_at(self, points, normals, light, u, unshadowed=False):
        """One sample of every point's irradiance from one light.

        Returns ``(E (N,3) [W/m^2], travel (N,3), cos_x (N,))`` where E already
        includes visibility, so ``E f(travel, w_out)`` is the reflected radiance;
        with ``unshadowed``, also E without the visibility test (4th item).
        """
        y, e = light.sample(points, u)
        v = y - points
        r = np.sqrt(np.maximum(np.einsum("ij,ij->i", v, v), 1e-300))
        w = v / r[:, None]                      # from the point towards the light
        cos_x = np.einsum("ij,ij->i", normals, w)
        e *= np.maximum(cos_x, 0.0)[:, None]
        free = e.copy() if unshadowed else None
        live = np.any(e > 0, axis=1)
        if live.any():
            eps = self.tracer.eps
            # shadow ray from just above the surface *to the light sample itself*
            # (a ray shifted parallel would meet a grazing light plane early)
            org = points[live] + normals[live] * eps
            seg = y[live] - org
            dist = np.linalg.norm(seg, axis=1)
            self.rays += int(live.sum())
            blocked = self.tracer.occluded(org, seg / np.maximum(dist, 1e-300)[:, None],
                                           np.maximum(dist - 2 * eps, 0.0))
            idx = np.nonzero(live)[0][blocked]
            e[idx] = 0.0
        return (e, -w, cos_x, free) if unshadowed else (e, -w, cos_x)

    def light_list(self):
        return self.area_lights + self.point_lights

    @staticmethod
    def _seen_blocked(e, free):
        """(N,) bool each: the sample reached its light (``e`` (N, 3), shadowed estimate);
        it faced the light but was blocked (``free``, the unshadowed estimate)."""
        seen = np.any(e > 0, axis=1)
        return seen, np.any(free > 0, axis=1) & ~seen

    def samples_per_pass(self, samples_per_light=1):
        """How many light samples :meth:`reflected_radiance` draws per point."""
        return samples_per_light * len(self.area_lights) + len(self.point_lights)

    def reflected_radiance(self, points, normals, mats, w_out, u, samples_per_light=1, mis=None, diffuse_scale=None,
                           shadow_flags=None, analytic=False):
        """Direct radiance reflected towards ``w_out`` (N, 3) at surface points, RGB.

        Unbiased estimate with ``samples_per_light`` shadow rays per area light
        (one per point light or sun): ``sum_l mean_s e_l cos_x f(w_travel, w_out) V``.
        ``u``: uniforms (N, K, 3) with K = :meth:`samples_per_pass`, or a Generator.
        ``mis`` (N,) bool: points whose glossy lobe also gets one lobe-sampled ray that
        counts the mesh lights it meets (:meth:`mis_weight`); the glossy part of their
        mesh-light samples is weighted by ``w_l = (n p_l)^2 / ((n p_l)^2 + p_g^2)`` (power
        heuristic; n = ``samples_per_light``, p_l and p_g the light's and the lobe's
        densities of the sampled direction), so a sharp lobe reflecting a lamp is found by
        the lobe's ray, not by rare light samples with a huge BRDF value.
        ``diffuse_scale`` (N, 3): texture modulation of the diffuse reflectance.
        ``shadow_flags`` (N, 2) bool, updated in place: column 0 set where a sample
        reached its light, column 1 where one facing the point was blocked.

        ``analytic`` (bool or (N,) bool): the diffuse lobe of polygonal lights
        (:func:`light_polygon_irradiance`) with the exact unoccluded irradiance as a control variate,
        ``f_d (Le I(x) - mean_s (e_s - e_s V_s))``, ``e_s`` the sample's unshadowed
        estimate: still unbiased, and exact wherever the light is wholly seen or wholly
        hidden from the point's upper side (only which samples are blocked is random,
        not where on the light they land: the Cornell back wall's per-pass noise).  In
        an umbra the plain estimate is exact (0) and the control variate is not, so a
        caller that knows where earlier samples were all blocked passes a mask.
        """
        out = np.zeros((len(points), 3))
        if isinstance(u, np.random.Generator):
            u = u.random((len(points), self.samples_per_pass(samples_per_light), 3))
        mt = self.scene.materials
        k = 0
        for light in self.light_list():
            n_s = samples_per_light if isinstance(light, (MeshLight, ShapeLight)) else 1
            cv = np.nonzero(np.broadcast_to(analytic, len(points)))[0]
            exact = light_polygon_irradiance(light, points[cv], normals[cv]) if len(cv) else None
            if exact is not None:
                # f_d does not depend on the incoming direction (any w_in gives it)
                f_d = np.zeros((len(points), 3))
                f_d[cv] = mt.brdf(mats[cv], normals[cv], -normals[cv], w_out[cv], glossy=False,
                                  diffuse_scale=None if diffuse_scale is None else diffuse_scale[cv])
                f_d[cv] *= exact[1][:, None]
                out[cv] += f_d[cv] * exact[0][:, None] * np.asarray(light.radiance, float)
            for _ in range(n_s):
                if shadow_flags is None and exact is None:
                    e, travel, cos_x = self.light_samples_at(points, normals, light, u[:, k])
                    live = np.any(e > 0, axis=1)
                else:
                    e, travel, cos_x, free = self.light_samples_at(points, normals, light, u[:, k], unshadowed=True)
                    live, blocked = self._seen_blocked(e, free)
                    if shadow_flags is not None:
                        shadow_flags[:, 0] |= live
                        shadow_flags[:, 1] |= blocked
                    if exact is not None:
                        out -= f_d * (free - e) / n_s
                k += 1
                if live.any():
                    f = mt.brdf(mats[live], normals[live], travel[live], w_out[live],
                                diffuse_scale=None if diffuse_scale is None else diffuse_scale[live])
                    if exact is not None:                # the control variate took the diffuse part
                        f -= f_d[live]
                    if mis is not None and isinstance(light, MeshLight):
                        sel = np.nonzero(mis[live])[0]
                        if len(sel):
                            i = np.nonzero(live)[0][sel]
                            c = int(np.argmax(light.radiance))
                            # e = Le cos_x / p_l for an unblocked sample (MeshLight.sample)
                            p_l = light.radiance[c] * cos_x[i] / e[i, c]
                            p_g = mt.glossy_pdf(mats[i], normals[i], -travel[i], w_out[i])
                            w_l = 1.0 - self.mis_weight(p_g, n_s * p_l)
                            f[sel] -= (1.0 - w_l)[:, None] * mt.brdf(mats[i], normals[i], travel[i], w_out[i],
                                                                     diffuse=False)
                    out[live] += e[live] * f / n_s
        return out

    def irradiance(self, points, normals, rng, samples_per_light=16, penumbra_samples=None):
        """Direct irradiance (N, 3) [W/m^2] of the first-shot lights at surface points
        with unit ``normals`` (N, 3), for bakes, where a point's value is final.

        Polygonal lights (mesh lights, rectangular area lights;
        :func:`light_polygon_irradiance`) use the ratio estimator of analytic
        direct light and stochastic shadows (Heitz, Hill & McGuire 2018):
        ``E = Le I(x) sum_s e_s V_s / sum_s e_s``, ``I(x)`` the exact unoccluded
        cosine-weighted solid angle of the light (:func:`polygon_irradiance`) and
        ``e_s`` the unshadowed sample estimates: exact where no sample is blocked,
        0 where all are, and consistent in between (its bias in a penumbra falls as
        1 / samples).  Other lights: the mean of the samples.  ``samples_per_light``
        shadow rays per light with an extent, one per point light of radius 0 and
        per sun of angle 0 (exact with one).  Points in a penumbra (some of their
        samples blocked, some not) get ``penumbra_samples`` in all (default 16 times
        ``samples_per_light``): there the shadow
        ratio is a binomial proportion whose error (up to 1 / (2 sqrt(n))) dominated
        the bake's error (Cornell bake: 2.3% -> 1.5% at 10 s), and few points are
        in a penumbra.  A point's samples are a randomly shifted Kronecker (R_3) set,
        stratified over the light's triangles and their areas.  ``rng``: a Generator."""
        from .sampling import kronecker_alpha

        out = np.zeros((len(points), 3))
        alpha = kronecker_alpha(3)
        for light in self.light_list():
            sharp = (isinstance(light, PointLight) and float(light.lights.radius[light.k]) == 0.0) or \
                (isinstance(light, SunLight) and light.angle == 0.0)
            n_s = 1 if sharp else max(1, int(samples_per_light))
            shift = rng.random((len(points), 3))
            analytic = None if sharp else light_polygon_irradiance(light, points, normals)

            def shadow_sums(p, nrm, sh, first, last):
                """Sums of the shadowed and unshadowed estimates of samples first..last-1,
                and whether some sample was seen and some blocked."""
                seen, total = np.zeros((len(p), 3)), np.zeros((len(p), 3))
                lit, shade = np.zeros(len(p), bool), np.zeros(len(p), bool)
                for s in range(first, last):
                    e, _, _, free = self.light_samples_at(p, nrm, light, (sh + s * alpha) % 1.0, unshadowed=True)
                    seen += e
                    total += free
                    reached, blocked = self._seen_blocked(e, free)
                    lit |= reached
                    shade |= blocked
                return seen, total, lit & shade

            seen, total, penumbra = shadow_sums(points, normals, shift, 0, n_s)
            n_pts = np.full(len(points), n_s)
            more = np.nonzero(penumbra)[0]
            n_penumbra = 16 * n_s if penumbra_samples is None else int(penumbra_samples)
            if len(more) and n_penumbra > n_s:
                n_pts[more] = n_penumbra
                s_more, t_more, _ = shadow_sums(points[more], normals[more], shift[more], n_s, n_penumbra)
                seen[more] += s_more
                total[more] += t_more
            if analytic is None:
                out += seen / n_pts[:, None]
            else:
                exact_i, ok = analytic
                ratio = np.where(total > 0, seen / np.maximum(total, 1e-300), 0.0)
                out += np.where(ok[:, None], exact_i[:, None] * np.asarray(light.radiance, float) * ratio,
                                seen / n_pts[:, None])
        return out

    @staticmethod
    def mis_weight(p_a, p_b):
        """Power-heuristic weight of strategy a against b: ``p_a^2 / (p_a^2 + p_b^2)``."""
        a2, b2 = p_a * p_a, p_b * p_b
        return np.where(a2 > 0, a2 / np.maximum(a2 + b2, 1e-300), 0.0)

    def lobe_hits_light(self, origins, mats, normals, w_out, w_in, triangles, hits, samples_per_light=1):
        """Emitted radiance (N, 3) of first-shot mesh lights met by lobe-sampled rays,
        MIS-weighted against light sampling (:meth:`reflected_radiance` with ``mis``):
        ``Le w_g``, ``w_g = p_g^2 / (p_g^2 + (n p_l)^2)``.  ``origins``, ``normals``,
        ``w_out``, ``w_in`` (N, 3) at the surface the rays leave along ``w_in``;
        ``triangles`` (N,) the triangles met (-1 none) at points ``hits`` (N, 3)."""
        out = np.zeros((len(origins), 3))
        li = np.where(triangles >= 0, self.triangle_light[np.maximum(triangles, 0)], -1)
        for l_id in np.unique(li[li >= 0]):
            light = self.area_lights[l_id]
            i = np.nonzero(li == l_id)[0]
            tri = triangles[i]
            cos_l = np.einsum("ij,ij->i", self.scene.triangle_normal[tri], -w_in[i])
            lit = np.where(light.two_sided[self.triangle_light_k[tri]], cos_l != 0, cos_l > 0)
            p_l = samples_per_light * light.pdf(origins[i], self.triangle_light_k[tri], hits[i])
            p_g = self.scene.materials.glossy_pdf(mats[i], normals[i], w_in[i], w_out[i])
            out[i] = (lit * self.mis_weight(p_g, p_l))[:, None] * light.radiance
        return out


class PatchFirstShot:
    """Incoming first shot per patch, refined progressively while the solver iterates.

    For every side i (:mod:`raybundle.scene`) and light l it keeps running sums
    over uniformly random points of the side and light samples of the
    irradiance ``e cos_x V`` (:meth:`DirectLighting.light_samples_at`) and of the
    irradiance-weighted travel direction, divided by the side's receiving area
    (``receiving_area`` (S,); buried parts receive nothing).  ``E`` (S, L, 3)
    [W/m^2] is the side-average irradiance, ``direction`` (S, L, 3) the mean
    travel direction.  Samples are kept per triangle side (tside).

    A fixed first shot would freeze its Monte Carlo noise into the solution (a
    bias that no number of iterations removes); refining it with a few shadow
    rays per iteration (:meth:`refine`) keeps E a running average of unbiased
    samples.  For glossy patches the reflected first shot uses one mean
    direction per light, ``E f(w_mean, w)``: an approximation (exact for point
    lights, close for lights small as seen from the patch), used only inside
    the iteration; the image's direct light is per pixel and exact.
    """

    def __init__(self, direct: DirectLighting, rng, initial_samples=16, receiving_area=None):
        self.direct = direct
        # average over the area that can receive light (see RayTracer.open_fraction)
        sc = direct.scene
        self.receiving_area = sc.patch_area[sc.side_patch] if receiving_area is None else receiving_area
        self.rng = rng
        self.scene = sc
        self.lights = direct.light_list()
        n_t, n_l = len(sc.tside_triangle), len(self.lights)
        self._e_sum = np.zeros((n_t, n_l, 3))
        self._d_sum = np.zeros((n_t, n_l, 3))
        self._count = np.zeros(n_t)
        self._next = 0
        self.E = np.zeros((sc.n_sides, n_l, 3))
        self._d_patch = np.zeros((sc.n_sides, n_l, 3))
        self.direction = np.zeros((sc.n_sides, n_l, 3))
        # tsides that no light is in front of receive nothing: they cost no samples
        origin = sc.triangle_corners[sc.tside_triangle, 0]
        self.receiving_tsides = np.nonzero(np.any([light.in_front(origin, sc.tside_normal) for light in self.lights],
                                            axis=0))[0] if n_l else np.zeros(0, np.int64)
        # initial_samples per side, shared out over a cluster's triangles by area
        counts = sc.tside_samples(initial_samples)[self.receiving_tsides]
        for r in range(initial_samples if len(self.receiving_tsides) else 0):
            todo = self.receiving_tsides[counts > r]
            step = 1 << 18                                # bounded temporaries on big scenes
            for lo in range(0, len(todo), step):
                self._add(todo[lo:lo + step])

    @property
    def n_lights(self):
        return len(self.lights)

    def _add(self, tri):
        """One new sample on each tside in ``tri`` (distinct ids); updates E and direction."""
        sc = self.scene
        u = self.rng.random((len(tri), 2))
        pts = points_on_triangles(sc.triangle_corners[sc.tside_triangle[tri]], u[:, 0], u[:, 1])
        nrm = sc.tside_normal[tri]
        old = self._e_sum[tri] / np.maximum(self._count[tri], 1)[:, None, None]
        old_d = self._d_sum[tri] / np.maximum(self._count[tri], 1)[:, None, None]
        for li, light in enumerate(self.lights):
            e, travel, _ = self.direct.light_samples_at(pts, nrm, light, self.rng.random((len(tri), 3)))
            self._e_sum[tri, li] += e
            self._d_sum[tri, li] += e.sum(axis=1, keepdims=True) * travel
        self._count[tri] += 1
        # side average = sum over its tsides of area * (tside mean) / side area
        side = sc.tside_side[tri]
        w = (sc.triangle_area[sc.tside_triangle[tri]] / self.receiving_area[side])[:, None, None]
        new = self._e_sum[tri] / self._count[tri][:, None, None]
        new_d = self._d_sum[tri] / self._count[tri][:, None, None]
        np.add.at(self.E, side, w * (new - old))
        np.add.at(self._d_patch, side, w * (new_d - old_d))
        p = np.unique(side)
        norm = np.linalg.norm(self._d_patch[p], axis=2, keepdims=True)
        self.direction[p] = np.where(norm > 0, self._d_patch[p] / np.maximum(norm, 1e-300), 0.0)

    def sums(self):
        """Copies of the per-tside sums and counts ``(e_sum, d_sum, count)`` that ``E`` and
        ``direction`` are formed from (what chains pool, :mod:`raybundle.chains`)."""
        return self._e_sum.copy(), self._d_sum.copy(), self._count.copy()

    def set_sums(self, e_sum, d_sum, count):
        """Replace the per-tside sums and counts (e.g. those of several chains pooled,
        :mod:`raybundle.chains`) and recompute ``E`` and ``direction`` from them."""
        sc = self.scene
        self._e_sum, self._d_sum, self._count = e_sum.copy(), d_sum.copy(), count.copy()
        c = np.maximum(self._count, 1)[:, None, None]
        a = sc.triangle_area[sc.tside_triangle]
        w = (a / np.maximum(self.receiving_area[sc.tside_side], 1e-300))[:, None, None]
        self.E = np.zeros_like(self.E)
        self._d_patch = np.zeros_like(self._d_patch)
        np.add.at(self.E, sc.tside_side, w * self._e_sum / c)
        np.add.at(self._d_patch, sc.tside_side, w * self._d_sum / c)
        norm = np.linalg.norm(self._d_patch, axis=2, keepdims=True)
        self.direction = np.where(norm > 0, self._d_patch / np.maximum(norm, 1e-300), 0.0)

    def refine(self, n_triangles):
        """One more sample on the next ``n_triangles`` receiving tsides (round robin)."""
        n_t = len(self.receiving_tsides)
        if n_t == 0 or n_triangles <= 0:
            return
        k = (self._next + np.arange(min(n_triangles, n_t))) % n_t
        self._next = int((self._next + len(k)) % n_t)
        self._add(self.receiving_tsides[k])
