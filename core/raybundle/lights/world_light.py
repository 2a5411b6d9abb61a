"""Direct light of the world at surface points, importance-sampled by the world's brightness.

The irradiance the world gives a point ``x`` with normal ``n`` directly (along unblocked
directions) is

    E_w(x) = integral L_w(w) max(0, n.w) V(x, w) dw                      [W/m^2]

estimated with directions drawn from the world's image (:mod:`raybundle.scene.world`): a
pixel with probability proportional to its brightest channel times its solid angle, then
a direction uniform in solid angle inside the pixel, so that ``pdf(w) = P_pixel / Omega_pixel``
[1/sr] and ``E_w ~ (1/K) sum_k L_w(w_k) max(0, n.w_k) V(x, w_k) / pdf(w_k)`` with one
shadow ray per sample.  Every pixel that sends light can be drawn, so the estimate is
unbiased.  Bright skies and suns seen through windows are found at once, where cosine
sampling or the patch solution meet them by chance or smear them over a patch.
"""
from __future__ import annotations

import numpy as np

from ..scene.world import World, pixel_of


class WorldLight:
    """The world as a light to sample (module docstring), over a ray tracer of the scene."""

    def __init__(self, world: World, tracer):
        self.world, self.tracer = world, tracer
        img = world.image
        h, w = img.shape[:2]
        self.h, self.w = h, w
        self.omega = world.pixel_solid_angles()[:, 0]                       # (H,) sr per pixel of a row
        weight = (img.max(axis=2) * self.omega[:, None]).reshape(-1)
        total = weight.sum()
        self.emits = total > 0
        self.p = weight / total if self.emits else weight
        self.cdf = np.cumsum(self.p)
        self.z_edges = np.cos(np.linspace(0.0, np.pi, h + 1))
        _, radius = tracer.scene.bounding_sphere
        self.far = 4.0 * radius + 1.0
        self.rays = 0

    def sample(self, u):
        """``(directions (N, 3), pdf (N,) [1/sr], radiance (N, 3))`` for uniforms ``u`` (N, 3)."""
        u = np.asarray(u, float)
        k = np.minimum(np.searchsorted(self.cdf, u[:, 0] * self.cdf[-1], side="right"), len(self.p) - 1)
        row, col = np.divmod(k, self.w)
        z = self.z_edges[row] + (self.z_edges[row + 1] - self.z_edges[row]) * u[:, 1]
        phi = np.pi * (1.0 - 2.0 * (col + u[:, 2]) / self.w)
        s = np.sqrt(np.maximum(0.0, 1.0 - z * z))
        d = np.stack([s * np.cos(phi), s * np.sin(phi), z], axis=1)
        pdf = self.p[k] / self.omega[row]
        return d, pdf, self.world.image[row, col]

    def pdf(self, directions):
        """(N,) [1/sr] the density :meth:`sample` draws ``directions`` (N, 3) with."""
        row, col = pixel_of(np.asarray(directions, float), self.h, self.w)
        return self.p[row * self.w + col] / self.omega[row]

    def irradiance(self, points, normals, u):
        """(N, 3) [W/m^2] estimate of the direct irradiance from the world at ``points``
        (N, 3) with unit ``normals`` (N, 3), with ``u`` (N, K, 3) uniforms: K samples each."""
        points, normals = np.asarray(points, float), np.asarray(normals, float)
        n, k = u.shape[:2]
        out = np.zeros((n, 3))
        if not self.emits or n == 0:
            return out
        d, pdf, L = self.sample(u.reshape(-1, 3))
        rep = np.repeat(np.arange(n), k)
        cos = np.einsum("ij,ij->i", normals[rep], d)
        live = np.nonzero((cos > 0) & (pdf > 0))[0]
        if len(live):
            origin = points[rep[live]] + normals[rep[live]] * self.tracer.eps
            blocked = self.tracer.occluded(origin, d[live], np.full(len(live), self.far))
            self.rays += len(live)
            ok = live[~blocked]
            contrib = L[ok] * (cos[ok] / pdf[ok])[:, None]
            for c in range(3):
                out[:, c] = np.bincount(rep[ok], contrib[:, c], minlength=n)
        return out / k
