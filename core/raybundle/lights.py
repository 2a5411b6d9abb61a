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

Lights: every emitting material whose emission is constant and whose area is at
most ``small_fraction`` of the scene's area is one area light (sampled uniformly
by area, one-sided Lambertian emitter); every point light is one light with
``E = I cos / r^2``.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .sampling import points_on_triangles


@dataclass
class AreaLight:
    """Triangles of one emitting material: ``triangles`` (K,), area-CDF, area [m^2], radiance (3,)."""

    material: int
    triangles: np.ndarray
    cdf: np.ndarray
    area: float
    radiance: np.ndarray


class DirectLighting:
    """First-shot lights of a scene and the direct-illumination estimators."""

    def __init__(self, scene, tracer, first_shot="auto", small_fraction=0.1):
        if first_shot not in ("auto", "none"):
            raise ValueError("first_shot must be 'auto' or 'none'")
        self.scene = scene
        self.tracer = tracer
        self.rays = 0  # shadow rays traced so far
        mats = scene.materials
        self.first_shot_material = np.zeros(len(mats), bool)
        self.area_lights: list[AreaLight] = []
        total = scene.triangle_area.sum()
        if first_shot == "auto":
            constant = ~np.any(mats.emission_albedo_complement > 0, axis=1) & np.any(mats.emission > 0, axis=1)
            for m in np.nonzero(constant)[0]:
                tri = np.nonzero(scene.triangle_material == m)[0]
                area = scene.triangle_area[tri].sum()
                if len(tri) and area <= small_fraction * total:
                    self.first_shot_material[m] = True
                    cdf = np.cumsum(scene.triangle_area[tri])
                    self.area_lights.append(AreaLight(int(m), tri, cdf / cdf[-1], float(area),
                                                      mats.emission[m].astype(float)))
        pl = scene.point_lights
        self.point_lights = [(pl.position[k], pl.intensity[k]) for k in range(len(pl))
                             if np.any(pl.intensity[k] > 0)]

    @property
    def n_lights(self):
        return len(self.area_lights) + len(self.point_lights)

    def sample_area_light(self, light: AreaLight, u):
        """Points (N, 3) and normals (N, 3) on ``light`` from (N, 3) uniforms; pdf = 1 / area."""
        k = np.minimum(np.searchsorted(light.cdf, u[:, 0] * light.cdf[-1], side="right"), len(light.cdf) - 1)
        tri = light.triangles[k]
        p = points_on_triangles(self.scene.triangle_corners[tri], u[:, 1], u[:, 2])
        return p, self.scene.triangle_normal[tri]

    def _light_samples(self, points, normals, light, u):
        """One sample of every point's irradiance from one light.

        Returns ``(E (N,3) [W/m^2], travel (N,3), cos_x (N,))`` where E already
        includes visibility, so ``E f(travel, w_out)`` is the reflected radiance.
        """
        if isinstance(light, AreaLight):
            y, ny = self.sample_area_light(light, u)
        else:
            y, ny = np.broadcast_to(light[0], points.shape), None
        v = y - points
        r2 = np.einsum("ij,ij->i", v, v)
        r = np.sqrt(np.maximum(r2, 1e-300))
        w = v / r[:, None]                      # from the point towards the light
        cos_x = np.einsum("ij,ij->i", normals, w)
        if ny is not None:
            cos_l = -np.einsum("ij,ij->i", ny, w)
            geom = np.where((cos_x > 0) & (cos_l > 0), cos_x * cos_l * light.area / np.maximum(r2, 1e-300), 0.0)
            e = geom[:, None] * light.radiance
        else:
            geom = np.where(cos_x > 0, cos_x / np.maximum(r2, 1e-300), 0.0)
            e = geom[:, None] * light[1]
        live = geom > 0
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
        return e, -w, cos_x

    def light_list(self):
        return self.area_lights + self.point_lights

    def samples_per_pass(self, samples_per_light=1):
        """How many light samples :meth:`reflected_radiance` draws per point."""
        return samples_per_light * len(self.area_lights) + len(self.point_lights)

    def reflected_radiance(self, points, normals, mats, w_out, u, samples_per_light=1):
        """Direct radiance reflected towards ``w_out`` (N, 3) at surface points, RGB.

        Unbiased estimate with ``samples_per_light`` shadow rays per area light
        (one per point light): ``sum_l mean_s Le f(w_travel, w_out) cos_x cos_l A / r^2 V``.
        ``u``: uniforms (N, K, 3) with K = :meth:`samples_per_pass`, or a Generator.
        """
        out = np.zeros((len(points), 3))
        if isinstance(u, np.random.Generator):
            u = u.random((len(points), self.samples_per_pass(samples_per_light), 3))
        k = 0
        for light in self.light_list():
            n_s = samples_per_light if isinstance(light, AreaLight) else 1
            for _ in range(n_s):
                e, travel, _ = self._light_samples(points, normals, light, u[:, k])
                k += 1
                live = np.any(e > 0, axis=1)
                if live.any():
                    f = self.scene.materials.brdf(mats[live], normals[live], travel[live], w_out[live])
                    out[live] += e[live] * f / n_s
        return out


class PatchFirstShot:
    """Incoming first shot per patch, refined progressively while the solver iterates.

    For every patch i and light l it keeps running sums over uniformly random
    points of the patch and light samples of the irradiance
    ``Le cos_x cos_l A / r^2 V`` (area light) or ``I cos_x / r^2 V`` (point light)
    and of the irradiance-weighted travel direction, divided by the patch's
    receiving area (``receiving_area``; buried parts receive nothing).  ``E`` (P, L, 3) [W/m^2] is
    the patch-average irradiance, ``direction`` (P, L, 3) the mean travel direction.

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
        self.receiving_area = direct.scene.patch_area if receiving_area is None else receiving_area
        self.rng = rng
        sc = direct.scene
        self.scene = sc
        self.lights = direct.light_list()
        n_t, n_l = len(sc.triangles), len(self.lights)
        self._e_sum = np.zeros((n_t, n_l, 3))
        self._d_sum = np.zeros((n_t, n_l, 3))
        self._count = np.zeros(n_t)
        self._next = 0
        self.E = np.zeros((sc.n_patches, n_l, 3))
        self._d_patch = np.zeros((sc.n_patches, n_l, 3))
        self.direction = np.zeros((sc.n_patches, n_l, 3))
        if n_l:
            for _ in range(initial_samples):
                self._add(np.arange(n_t))

    @property
    def n_lights(self):
        return len(self.lights)

    def _add(self, tri):
        """One new sample on each triangle in ``tri`` (distinct ids); updates E and direction."""
        sc = self.scene
        u = self.rng.random((len(tri), 2))
        pts = points_on_triangles(sc.triangle_corners[tri], u[:, 0], u[:, 1])
        nrm = sc.triangle_normal[tri]
        old = self._e_sum[tri] / np.maximum(self._count[tri], 1)[:, None, None]
        old_d = self._d_sum[tri] / np.maximum(self._count[tri], 1)[:, None, None]
        for li, light in enumerate(self.lights):
            e, travel, _ = self.direct._light_samples(pts, nrm, light, self.rng.random((len(tri), 3)))
            self._e_sum[tri, li] += e
            self._d_sum[tri, li] += e.sum(axis=1, keepdims=True) * travel
        self._count[tri] += 1
        # patch average = sum over its triangles of area * (triangle mean) / patch area
        w = (sc.triangle_area[tri] / self.receiving_area[sc.triangle_patch[tri]])[:, None, None]
        new = self._e_sum[tri] / self._count[tri][:, None, None]
        new_d = self._d_sum[tri] / self._count[tri][:, None, None]
        np.add.at(self.E, sc.triangle_patch[tri], w * (new - old))
        np.add.at(self._d_patch, sc.triangle_patch[tri], w * (new_d - old_d))
        p = np.unique(sc.triangle_patch[tri])
        norm = np.linalg.norm(self._d_patch[p], axis=2, keepdims=True)
        self.direction[p] = np.where(norm > 0, self._d_patch[p] / np.maximum(norm, 1e-300), 0.0)

    def refine(self, n_triangles):
        """One more sample on the next ``n_triangles`` triangles (round robin)."""
        if not self.lights or n_triangles <= 0:
            return
        n_t = len(self.scene.triangles)
        tri = (self._next + np.arange(min(n_triangles, n_t))) % n_t
        self._next = int((self._next + len(tri)) % n_t)
        self._add(tri)
