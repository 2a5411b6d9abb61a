"""Light sources, each an object with ``sample(points, u)`` that returns light samples for
shadow rays (see :class:`MeshLight`):

* every emitting material whose emission is constant and whose area is at
  most ``small_fraction`` of the scene's area (:func:`small_emitters`): a :class:`MeshLight`, a
  Lambertian emitter on its front (and, for two-sided triangles, on its back too), sampled
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

from ..tracing.sampling import (
    frames_from_normals,
    orthonormal_basis,
    points_on_triangles,
    sample_spherical_triangle,
    triangle_solid_angle,
)
from ..util import compiled
from . import compiled_lights
from .light_planes import light_planes, plane_fans


class _Light:
    """What every light class shares: :meth:`selection_estimate`; :attr:`shadow`, whether
    anything blocks its direct light (False: Blender's Cast Shadow off); :attr:`link`, its link
    set (:mod:`raybundle.scene.linking`; 0: no linking)."""

    shadow = True
    link = 0

    def selection_estimate(self, points, normals):
        """Lamp selection's guess (N,) of the light's unoccluded irradiance [W/m^2, mean of
        RGB] at ``points`` (N, 3) with unit ``normals``: one unshadowed sample at the middle
        of the light's sample space."""
        y, e = self.sample(points, np.full((len(points), 3), 0.5))
        w = y - points
        cos_x = np.einsum("ij,ij->i", normals, w) / np.maximum(np.linalg.norm(w, axis=1), 1e-300)
        return e.mean(axis=1) * np.maximum(cos_x, 0.0)


@dataclass
class MeshLight(_Light):
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
    #: a curved light (no planar parts) whose area is at least this share of its bounding
    #: sphere's is compact (a sphere, a blob): sampled by its bounding cone (:meth:`_sample_cone`)
    COMPACT_SHARE = 0.5

    def __post_init__(self):
        c = self.scene.triangle_corners[self.triangles]
        self._centroid = c.mean(axis=1)
        self._radius = np.linalg.norm(c - self._centroid[:, None], axis=2).max(axis=1)
        self.planes = light_planes(self)
        self._fans = plane_fans(self)
        #: a compact light's bounding sphere (centre, radius) and its triangles to trace, or None
        self._cone = None
        if self._fans is None:
            centre = 0.5 * (c.reshape(-1, 3).min(axis=0) + c.reshape(-1, 3).max(axis=0))
            radius = float(np.linalg.norm(c.reshape(-1, 3) - centre, axis=1).max())
            if self.area >= self.COMPACT_SHARE * 4.0 * np.pi * radius * radius:
                from ..tracing.triangle_set import TriangleSet

                self._cone = (centre, radius, TriangleSet(c))
        #: points closer than this to the plane of the part sampled lie in it (the light itself, or
        #: a surface flush with it): it sends them nothing, as a plane sends nothing along itself
        #: (sampled by solid angle from a point of the light, its outline looked like a hemisphere)
        self.plane_tol = 1e-5 * self.scene.bounding_sphere[1]

    def sample(self, points, u):
        """One sample of the light for each point (N, 3) from uniforms ``u`` (N, 3).

        Returns ``(y (N, 3), e (N, 3))``: the sampled point on the light and the
        unshadowed irradiance estimate on a plane facing it: the caller
        multiplies by ``cos_x`` (w = direction to y) and tests visibility.

        A light whose planar parts have convex outlines (:func:`~raybundle.lights.light_planes.plane_fans`: a lamp
        quad, a box, a lamp cut into a grid of many triangles) is sampled part by part:
        part g with probability ``p_g = A_g / A``; where it looks small, a point uniform
        on it (``e = Le cos_l A_g / (r^2 p_g)``); where it may look large, a direction
        uniform in its whole solid angle (a fan triangle of its outline by its solid
        angle, then Arvo's sampling in it: ``e = Le O_g / p_g``, bounded next to the
        light however finely it is meshed).  A compact light (a sphere), from outside its bounding
        sphere: by the sphere's cone (:meth:`_sample_cone`).  Other lights: triangle by triangle
        (:meth:`_sample_triangles`)."""
        if self._cone is not None:
            out = self._outside(points)
            if out.all():
                return self._sample_cone(points, u)
            y, e = np.empty((len(points), 3)), np.empty((len(points), 3))
            y[~out], e[~out] = self._sample_triangles(points[~out], u[~out])     # inside its bounding sphere
            if out.any():
                y[out], e[out] = self._sample_cone(points[out], u[out])
            return y, e
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
        for idx in self._fan_chunks(g, self._part_near(g, points)):
            rel, omega, count = self._fan_solid_angles(g[idx], points[idx])
            total = omega.sum(axis=1)
            cdf = np.cumsum(omega, axis=1) / np.maximum(total, 1e-300)[:, None]
            k = np.minimum((cdf <= u0[idx, None]).sum(axis=1), count - 1)
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
        lit = np.where(f["two_sided"][g], cos_l != 0, cos_l > 0) & self._off_plane(normal, y, points)
        return y, (np.abs(e) * lit / f["p"][g])[:, None] * self.radiance

    def selection_estimate(self, points, normals):
        """As :meth:`_Light.selection_estimate`; for a compact light, from outside its bounding
        sphere, the bound ``Le O cos(max(theta_i - theta_u, 0))`` (O and theta_u the sphere's
        solid angle and half-angle, theta_i the angle of its centre from the normal), with no
        ray traced."""
        if self._cone is None:
            return super().selection_estimate(points, normals)
        if compiled.use():
            return compiled_lights.cone_selection_estimate(self._cone[0], self._cone[1], np.mean(self.radiance),
                                                           points, normals)
        out = self._outside(points)
        est = np.full(len(points), float(np.mean(self.radiance)) * 2.0 * np.pi)    # inside: a hemisphere
        if out.any():
            w, cos_u, omega = self._cone_solid_angle(points[out])
            cos_i = np.einsum("ij,ij->i", normals[out], w)
            sin_i, sin_u = np.sqrt(np.maximum(1 - cos_i * cos_i, 0)), np.sqrt(np.maximum(1 - cos_u * cos_u, 0))
            cos_near = np.where(cos_i >= cos_u, 1.0, cos_i * cos_u + sin_i * sin_u)
            est[out] = float(np.mean(self.radiance)) * omega * np.maximum(cos_near, 0.0)
        return est

    def _outside(self, points):
        """(N,) bool: ``points`` lie outside a compact light's bounding sphere."""
        centre, radius, _ = self._cone
        return np.linalg.norm(points - centre, axis=1) > radius * (1.0 + 1e-9)

    def _cone_solid_angle(self, points):
        """The bounding sphere's direction (N, 3), cos of its half-angle and solid angle (N,) [sr]
        from ``points`` outside it."""
        centre, radius, _ = self._cone
        v = centre - points
        d = np.linalg.norm(v, axis=1)
        cos_max = np.sqrt(np.maximum(1.0 - (radius / d) ** 2, 0.0))
        return v / d[:, None], cos_max, 2.0 * np.pi * (1.0 - cos_max)

    def _sample_cone(self, points, u):
        """:meth:`sample` of a compact light from ``points`` outside its bounding sphere: a
        direction uniform in the cone the sphere fills (solid angle O), traced to the light's own
        triangles; where it meets one on an emitting side, ``e = Le O``, else 0.  Unbiased for any
        shape inside the sphere; for a sphere, no sample falls on its far side (by area, half
        did, and its own front hid them), and what remains random is only ``cos_x``."""
        if compiled.use():
            d, omega = compiled_lights.cone_directions(self._cone[0], self._cone[1], points, u)
        else:
            w, cos_max, omega = self._cone_solid_angle(points)
            cos_t = 1.0 - u[:, 1] * (1.0 - cos_max)
            sin_t = np.sqrt(np.maximum(1.0 - cos_t * cos_t, 0.0))
            phi = 2.0 * np.pi * u[:, 2]
            a, b = frames_from_normals(w)
            d = cos_t[:, None] * w + (sin_t * np.cos(phi))[:, None] * a + (sin_t * np.sin(phi))[:, None] * b
        k, t = self._cone[2].first_hit(points, d)
        hit = k >= 0
        kk = np.maximum(k, 0)
        cos_l = -np.einsum("ij,ij->i", self.scene.triangle_normal[self.triangles[kk]], d)
        lit = hit & np.where(self.two_sided[kk], cos_l != 0, cos_l > 0)
        y = np.where(hit[:, None], points + np.where(hit, t, 0.0)[:, None] * d, self._cone[0])
        return y, (omega * lit)[:, None] * self.radiance

    def _off_plane(self, normal, y, points):
        """(N,) bool: ``points`` lie off the plane through ``y`` of ``normal`` (N, 3) each."""
        return np.abs(np.einsum("ij,ij->i", normal, y - points)) > self.plane_tol

    def _part_near(self, g, points):
        """(N,) bool: planar part ``g`` (N,) may look large from ``points`` (its solid angle
        is not surely below :attr:`MIN_SOLID_ANGLE`): it is then sampled by solid angle."""
        f = self._fans
        gap = np.maximum(np.linalg.norm(f["centroid"][g] - points, axis=1) - f["radius"][g], 0.0)
        return f["area"][g] >= self.MIN_SOLID_ANGLE * gap * gap

    #: fan triangles (points times the most fan triangles of their parts) measured at once
    FAN_CHUNK = 1 << 16

    def _fan_chunks(self, g, near):
        """The indices of the ``near`` points (N,) bool, in chunks of at most :data:`FAN_CHUNK`
        fan triangles of their parts ``g`` (N,)."""
        idx = np.nonzero(near)[0]
        if len(idx) == 0:
            return []
        step = max(1, self.FAN_CHUNK // int(self._fans["fan_count"][g[idx]].max()))
        return [idx[lo:lo + step] for lo in range(0, len(idx), step)]

    def _fan_solid_angles(self, g, points):
        """The fan triangles of parts ``g`` (n,) relative to ``points`` (n, 3), padded to the most
        any of them has, ``(n, F, 3, 3)``, their solid angles (n, F) (0 where padded) and each
        part's count of them (n,)."""
        f = self._fans
        count = f["fan_count"][g]
        j = np.arange(int(count.max()))
        real = j[None, :] < count[:, None]
        rel = f["fan"][f["fan_start"][g][:, None] + np.where(real, j[None, :], 0)] - points[:, None, None, :]
        omega = triangle_solid_angle(rel[..., 0, :], rel[..., 1, :], rel[..., 2, :])
        return rel, np.where(real, omega, 0.0), count

    def _sample_triangles(self, points, u):
        """:meth:`sample` triangle by triangle: triangle k picked with probability
        ``p_k = A_k / A``, then sampled by :meth:`sample_triangle`."""
        n_k = len(self.triangles)
        k = np.minimum(np.searchsorted(self.cdf, u[:, 0] * self.cdf[-1], side="right"), n_k - 1)
        y, e = self.sample_triangle(points, k, u[:, 1], u[:, 2])
        return y, e * (self.area / self.scene.triangle_area[self.triangles[k]])[:, None]

    def sample_triangle(self, points, k, u1, u2):
        """One sample of the light's triangle ``triangles[k]`` (k (N,)) for each point (N, 3),
        from uniforms ``u1``, ``u2`` (N,): ``(y (N, 3), e (N, 3))`` as :meth:`sample` returns
        them, for that triangle alone.  If it looks small from the point (its solid angle is
        surely below :attr:`MIN_SOLID_ANGLE`: ``A_k < MIN_SOLID_ANGLE d^2`` with d the
        distance to its bounding sphere) a point uniform on it gives ``e = Le cos_l A_k / r^2``;
        if it may look large, a direction uniform in its solid angle (Arvo's spherical
        triangle sampling) gives ``e = Le O_k``.  Both are unbiased; the second keeps the
        estimate bounded next to the light (a lamp 0.5 mm under a ceiling), where sampling
        by area has a heavy tail.  Emits from the back only where ``two_sided``."""
        from ..tracing.sampling import sample_spherical_triangle

        sc = self.scene
        tri = self.triangles[k]
        c = sc.triangle_corners[tri]
        y = points_on_triangles(c, u1, u2)
        normal = sc.triangle_normal[tri]
        v = y - points
        r2 = np.maximum(np.einsum("ij,ij->i", v, v), 1e-300)
        cos_l = -np.einsum("ij,ij->i", normal, v) / np.sqrt(r2)
        e = cos_l * sc.triangle_area[tri] / r2
        near = np.nonzero(self._triangle_near(k, points))[0]
        if len(near):
            rel = c[near] - points[near, None, :]
            d, omega = sample_spherical_triangle(rel[:, 0], rel[:, 1], rel[:, 2], u1[near], u2[near])
            nd = np.einsum("ij,ij->i", normal[near], d)
            t = np.einsum("ij,ij->i", normal[near], rel[:, 0]) / np.where(nd != 0, nd, 1e-300)
            y[near] = points[near] + t[:, None] * d
            cos_l[near] = -nd
            e[near] = omega
        lit = np.where(self.two_sided[k], cos_l != 0, cos_l > 0) & self._off_plane(normal, y, points)
        return y, (np.abs(e) * lit)[:, None] * self.radiance

    def _triangle_near(self, k, points):
        """(N,) bool: triangle ``triangles[k]`` may look large from ``points`` (it is then
        sampled by solid angle; :meth:`sample_triangle`)."""
        gap = np.maximum(np.linalg.norm(self._centroid[k] - points, axis=1) - self._radius[k], 0.0)
        return self.scene.triangle_area[self.triangles[k]] >= self.MIN_SOLID_ANGLE * gap * gap

    def triangle_pdf(self, points, k, y):
        """Density [1/sr] with which :meth:`sample_triangle` draws, from ``points`` (N, 3), the
        direction to ``y`` (N, 3) on triangle ``triangles[k]``: ``1 / O_k`` where it samples
        the solid angle, else ``r^2 / (A_k |cos_l|)``."""
        sc = self.scene
        tri = self.triangles[k]
        v = y - points
        r2 = np.maximum(np.einsum("ij,ij->i", v, v), 1e-300)
        cos_l = np.abs(np.einsum("ij,ij->i", sc.triangle_normal[tri], v)) / np.sqrt(r2)
        pdf = r2 / (np.maximum(cos_l, 1e-300) * sc.triangle_area[tri])
        near = np.nonzero(self._triangle_near(k, points))[0]
        if len(near):
            rel = sc.triangle_corners[tri[near]] - points[near, None, :]
            pdf[near] = 1.0 / np.maximum(triangle_solid_angle(rel[:, 0], rel[:, 1], rel[:, 2]), 1e-300)
        return pdf

    def pdf(self, points, k, y):
        """Density [1/sr] with which :meth:`sample` draws, from ``points`` (N, 3), the
        direction to ``y`` (N, 3) on the light's triangle ``triangles[k]`` (k (N,)):
        ``p / O`` where the part (or triangle) looks large (solid-angle sampling), else
        ``p r^2 / (A_part |cos_l|) = r^2 / (A |cos_l|)`` (area sampling)."""
        sc = self.scene
        if self._cone is not None:
            out = self._outside(points)
            pdf = np.empty(len(points))
            if (~out).any():
                i = ~out
                pdf[i] = self.triangle_pdf(points[i], k[i], y[i]) * (sc.triangle_area[self.triangles[k[i]]] / self.area)
            if out.any():
                pdf[out] = 1.0 / np.maximum(self._cone_solid_angle(points[out])[2], 1e-300)
            return pdf
        if self._fans is not None:
            f = self._fans
            g = f["tri_group"][k]
            v = y - points
            r2 = np.maximum(np.einsum("ij,ij->i", v, v), 1e-300)
            cos_l = np.abs(np.einsum("ij,ij->i", f["normal"][g], v)) / np.sqrt(r2)
            pdf = r2 / (np.maximum(cos_l, 1e-300) * self.area)
            for idx in self._fan_chunks(g, self._part_near(g, points)):
                omega = self._fan_solid_angles(g[idx], points[idx])[1]
                pdf[idx] = f["p"][g[idx]] / np.maximum(omega.sum(axis=1), 1e-300)
            return pdf
        return self.triangle_pdf(points, k, y) * (sc.triangle_area[self.triangles[k]] / self.area)

    def in_front(self, origin, normal):
        """(N,) bool: some point of the light lies in front of the planes (origin, normal) (N, 3)."""
        c = self.scene.triangle_corners[self.triangles].reshape(-1, 3)
        return _box_in_front(c.min(axis=0), c.max(axis=0), origin, normal)


@dataclass
class PointLight(_Light):
    """A point or spot light (``PointLights`` row ``k``); see :meth:`MeshLight.sample`.

    ``e = I s(travel) / r^2`` with ``s`` Cycles' spot attenuation.  A light with
    a radius is sampled on the disc of that radius facing the point (soft
    shadows; exact far from the light, where a sphere looks like that disc)."""

    position: np.ndarray
    intensity: np.ndarray
    lights: object
    k: int

    @property
    def shadow(self):
        return bool(self.lights.shadow[self.k] > 0)

    @property
    def link(self):
        return int(self.lights.link[self.k])

    def sample(self, points, u):
        return sample_point_lights(self.lights, np.full(len(points), self.k), points, u)

    def in_front(self, origin, normal):
        r = float(self.lights.radius[self.k])
        return np.einsum("ij,ij->i", self.position - origin, normal) > -r


def sample_point_lights(lights, k, points, u):
    """One sample of point lights ``k`` (N,) (rows of ``lights``, a
    :class:`~raybundle.scene.model.PointLights`) for each point (N, 3) from uniforms ``u``
    (N, >= 2): ``(y (N, 3), e (N, 3))`` as :meth:`MeshLight.sample` returns them, ``e = I s / r^2``
    with ``s`` Cycles' spot attenuation; a light with a radius is sampled on the disc of
    that radius facing the point."""
    to_light = lights.position[k] - points
    dist = np.maximum(np.linalg.norm(to_light, axis=1), 1e-300)
    travel = -to_light / dist[:, None]
    y = lights.position[k].astype(float)
    radius = lights.radius[k]
    soft = np.nonzero(radius > 0)[0]
    if len(soft):
        a, b = frames_from_normals(travel[soft])
        r = radius[soft] * np.sqrt(u[soft, 0])
        phi = 2 * np.pi * u[soft, 1]
        y[soft] += (r * np.cos(phi))[:, None] * a + (r * np.sin(phi))[:, None] * b
    v = y - points
    r2 = np.maximum(np.einsum("ij,ij->i", v, v), 1e-300)
    return y, (lights.spot_factor(k, travel) / r2)[:, None] * lights.intensity[k]


@dataclass
class ShapeLight(_Light):
    """A Blender area light (``AreaLights`` row): a one-sided Lambertian rectangle
    or ellipse that is not geometry.  Sampled by area, ``e = Le cos_l A / r^2`` (pdf 1/A),
    except a rectangle where it may look large (as :class:`MeshLight`'s parts: area at
    least ``MeshLight.MIN_SOLID_ANGLE`` times the squared distance to its bounding sphere):
    there a direction uniform in its solid angle O (:meth:`_sample_solid_angle`),
    ``e = Le O``, bounded however close the point is.
    By area, a point a few centimetres from a 40 m^2 panel drew ``1 / r^2`` fireflies,
    negative ones through the control variate of :func:`~raybundle.lights.reflected_direct.reflected_radiance`."""

    center: np.ndarray
    axis_u: np.ndarray
    axis_v: np.ndarray
    normal: np.ndarray
    ellipse: bool
    area: float
    radiance: np.ndarray
    shadow: bool = True
    link: int = 0

    def sample(self, points, u):
        if compiled.use():
            y, e = compiled_lights.shape_sample(self, points, u, MeshLight.MIN_SOLID_ANGLE)
            return y, e[:, None] * self.radiance
        if self.ellipse:
            r, phi = np.sqrt(u[:, 0]), 2 * np.pi * u[:, 1]
            y, e = self._by_area(points, r * np.cos(phi), r * np.sin(phi))
            return y, e[:, None] * self.radiance
        radius = max(np.linalg.norm(self.axis_u + self.axis_v), np.linalg.norm(self.axis_u - self.axis_v))
        gap = np.maximum(np.linalg.norm(points - self.center, axis=1) - radius, 0.0)
        near = (self.area >= MeshLight.MIN_SOLID_ANGLE * gap * gap) & ((points - self.center) @ self.normal > 0)
        if near.all():
            y, e = self._sample_solid_angle(points, u)
        else:
            y, e = self._by_area(points, 2 * u[:, 0] - 1, 2 * u[:, 1] - 1)
            if near.any():
                y[near], e[near] = self._sample_solid_angle(points[near], u[near])
        return y, e[:, None] * self.radiance

    def selection_estimate(self, points, normals):
        """An upper bound (N,) of the unoccluded irradiance [W/m^2, mean of RGB] (the
        ellipse's by its rectangle): with ``r`` the distance from the point to the
        rectangle, ``d`` its height above the light's plane and ``m`` the largest
        ``n . (corner - x)``, ``cos_x <= m / r`` and ``cos_l = d / |y - x| <= d / r``, so
        ``E <= Le min(pi, A m d / r^4)``.  A guess at the centre could be far below the
        truth (a point near the plane of a lamp whose centre is below its horizon, part of
        it above): picked with probability 1/16 and weighted 16, it made fireflies."""
        if compiled.use():
            return compiled_lights.shape_selection_estimate(self, points, normals)
        p = points - self.center
        uu, vv = self.axis_u @ self.axis_u, self.axis_v @ self.axis_v
        a = np.clip(p @ self.axis_u / uu, -1.0, 1.0)
        b = np.clip(p @ self.axis_v / vv, -1.0, 1.0)
        r2 = np.einsum("ij,ij->i", *(2 * [p - a[:, None] * self.axis_u - b[:, None] * self.axis_v]))
        d = np.maximum(p @ self.normal, 0.0)
        m = np.maximum(-np.einsum("ij,ij->i", normals, p) + np.abs(normals @ self.axis_u)
                       + np.abs(normals @ self.axis_v), 0.0)
        area = 4.0 * np.sqrt(uu * vv)
        return float(np.mean(self.radiance)) * np.minimum(np.pi, area * m * d / np.maximum(r2 * r2, 1e-300))

    def _by_area(self, points, a, b):
        """The point ``center + a axis_u + b axis_v`` (N, 3) and ``cos_l A / r^2`` (N,)."""
        y = self.center + a[:, None] * self.axis_u + b[:, None] * self.axis_v
        v = y - points
        r2 = np.maximum(np.einsum("ij,ij->i", v, v), 1e-300)
        return y, np.maximum(-(v @ self.normal) / np.sqrt(r2), 0.0) * self.area / r2

    def _sample_solid_angle(self, points, u):
        """Points on the rectangle (N, 3) along directions uniform in its solid angle seen
        from ``points`` (N, 3) in front of it, and that solid angle O (N,) [sr]: the
        area-preserving map of the unit square onto the spherical rectangle (Urena, Fajardo
        and King, "An area-preserving parametrization for spherical rectangles", EGSR 2013),
        from ``u[:, 0]`` and ``u[:, 1]``."""
        lx, ly = 2.0 * np.linalg.norm(self.axis_u), 2.0 * np.linalg.norm(self.axis_v)
        ex, ey = self.axis_u / (0.5 * lx), self.axis_v / (0.5 * ly)
        ez = np.cross(ex, ey)
        # what depends on the point only, once per run of equal points (a penumbra's samples)
        new = np.ones(len(points), bool)
        new[1:] = np.any(points[1:] != points[:-1], axis=1)
        d = (self.center - self.axis_u - self.axis_v) - points[new]      # to the corner, (N', 3)
        x0, y0, z0 = d @ ex, d @ ey, d @ ez
        flip = z0 > 0                                                     # the frame's z away from the light
        z0 = np.where(flip, -z0, z0)
        x1, y1 = x0 + lx, y0 + ly
        # the z components of the unit normals of the four great circles through the edges
        n0, n1 = -y0 / np.sqrt(z0 * z0 + y0 * y0), x1 / np.sqrt(z0 * z0 + x1 * x1)
        n2, n3 = y1 / np.sqrt(z0 * z0 + y1 * y1), -x0 / np.sqrt(z0 * z0 + x0 * x0)
        g0, g1 = np.arccos(np.clip(-n0 * n1, -1, 1)), np.arccos(np.clip(-n1 * n2, -1, 1))
        g2, g3 = np.arccos(np.clip(-n2 * n3, -1, 1)), np.arccos(np.clip(-n3 * n0, -1, 1))
        k = 2.0 * np.pi - g2 - g3
        omega = np.maximum(g0 + g1 - k, 0.0)
        if not new.all():
            run = np.cumsum(new) - 1
            x0, y0, z0, x1, y1, n0, n2, k, omega, flip = (
                a[run] for a in (x0, y0, z0, x1, y1, n0, n2, k, omega, flip))
        au = u[:, 0] * omega + k
        sin_au = np.sin(au)
        fu = (np.cos(au) * n0 - n2) / np.where(sin_au != 0, sin_au, 1e-300)
        cu = np.clip(np.sign(fu) / np.sqrt(fu * fu + n0 * n0), -1.0, 1.0)
        xu = np.clip(-(cu * z0) / np.maximum(np.sqrt(1.0 - cu * cu), 1e-300), x0, x1)
        dd = np.sqrt(xu * xu + z0 * z0)
        h0, h1 = y0 / np.sqrt(dd * dd + y0 * y0), y1 / np.sqrt(dd * dd + y1 * y1)
        hv = h0 + u[:, 1] * (h1 - h0)
        yv = np.where(hv * hv < 1.0 - 1e-12, hv * dd / np.sqrt(np.maximum(1.0 - hv * hv, 1e-300)), y1)
        zdir = np.where(flip[:, None], -ez, ez)
        return points + xu[:, None] * ex + yv[:, None] * ey + z0[:, None] * zdir, omega

    def hit(self, origins, directions, t_max):
        """(N,) bool: rays from ``origins`` along unit ``directions`` (N, 3) meet the light's
        emitting side before ``t_max`` (N,) [m], and the points they meet (N, 3)."""
        denom = directions @ self.normal
        t = ((self.center - origins) @ self.normal) / np.where(denom < 0, denom, -1.0)
        y = origins + t[:, None] * directions
        a = (y - self.center) @ self.axis_u / (self.axis_u @ self.axis_u)
        b = (y - self.center) @ self.axis_v / (self.axis_v @ self.axis_v)
        inside = (a * a + b * b <= 1.0) if self.ellipse else ((np.abs(a) <= 1.0) & (np.abs(b) <= 1.0))
        return (denom < 0) & (t > 0) & (t < t_max) & inside, y

    def pdf(self, points, y):
        """Density [1/sr] with which :meth:`sample` draws, from ``points`` (N, 3), the direction
        to ``y`` (N, 3) on the light: ``1 / O`` where it samples the solid angle O, else
        ``r^2 / (A cos_l)``."""
        v = y - points
        r2 = np.einsum("ij,ij->i", v, v)
        cos_l = np.maximum(-(v @ self.normal) / np.sqrt(np.maximum(r2, 1e-300)), 1e-300)
        out = r2 / (self.area * cos_l)
        if not self.ellipse:
            radius = max(np.linalg.norm(self.axis_u + self.axis_v), np.linalg.norm(self.axis_u - self.axis_v))
            gap = np.maximum(np.linalg.norm(points - self.center, axis=1) - radius, 0.0)
            near = np.nonzero((self.area >= MeshLight.MIN_SOLID_ANGLE * gap * gap)
                              & ((points - self.center) @ self.normal > 0))[0]
            if len(near):
                _, omega = self._sample_solid_angle(points[near], np.zeros((len(near), 2)))
                out[near] = 1.0 / np.maximum(omega, 1e-300)
        return out

    def corners(self):
        """(4, 3) the rectangle's corners [m] in order around its outline (an ellipse's box)."""
        return np.array([self.center + a * self.axis_u + b * self.axis_v
                         for a, b in ((-1, -1), (1, -1), (1, 1), (-1, 1))])

    def in_front(self, origin, normal):
        return np.any([np.einsum("ij,ij->i", c - origin, normal) > 0 for c in self.corners()], axis=0)


@dataclass
class SunLight(_Light):
    """A distant light: travel directions uniform in the cone of half-angle
    ``angle / 2`` around ``direction``; ``e = irradiance`` (no fall-off).  The
    sample point lies ``far`` [m] away towards the sun (beyond the scene)."""

    direction: np.ndarray
    irradiance: np.ndarray
    angle: float
    far: float
    shadow: bool = True
    link: int = 0

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


def small_emitters(scene, small_fraction=0.1):
    """Material ids (list) of the mesh emitters the first shot takes: constant emission (not
    the furnaces' ``c (1 - a(w))``) over at most ``small_fraction`` of the scene's area, and
    no cut-out (a cut-out emits where it is covered only: the iteration's bundles take it)."""
    mats = scene.materials
    total = scene.triangle_area.sum()
    constant = ~np.any(mats.emission_albedo_complement > 0, axis=1) & np.any(mats.emission > 0, axis=1)
    cut = np.zeros(len(scene.triangles), bool)
    if scene.texture is not None and scene.texture.has_cutouts:
        cut = scene.texture.cutout_faces[scene.triangle_source]
    out = []
    for m in np.nonzero(constant)[0]:
        tri = scene.triangle_material == m
        if tri.any() and not cut[tri].any() and scene.triangle_area[tri].sum() <= small_fraction * total:
            out.append(int(m))
    return out
