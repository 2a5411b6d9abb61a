"""Emission seen: what the eye sees directly (emitting surfaces, the world), averaged per pixel.

Its own per-pixel average with its own sample count: every image pass's primary ray, plus
extra samples where a pixel's samples disagree (the edge of a visible light, a window bar
against the sky), so light edges antialias long before the rest has converged.  Which pixels
get extra samples depends on earlier samples only: the average is consistent, its bias
falling as 1/passes.
"""
from __future__ import annotations

import numpy as np


class EmissionSeen:
    """The emission seen through ``camera`` in ``scene``: per pixel, ``sum`` (pixels, 3) and
    ``count`` (pixels,) of the samples, and ``range`` (2, pixels), the least and most
    luminance seen (a pixel whose samples differ is on an edge)."""

    def __init__(self, scene, camera):
        self.scene = scene
        n = camera.width * camera.height
        #: (pixels, 3) the mean of the world's view over each pixel, or None (no view through this
        #: camera: the world by direction); where an earlier sample of a pixel hit geometry
        #: (``hit_seen``), camera rays that miss read the view's sub-pixel they pass (:meth:`radiance`)
        self.view_means = scene.world.view_pixel_means(camera) if scene.world.view_for(camera) else None
        self.hit_seen = np.zeros(n, bool)
        self.sum = np.zeros((n, 3))
        self.count = np.zeros(n)
        self.range = np.stack([np.full(n, np.inf), np.full(n, -np.inf)])

    def radiance(self, g):
        """Radiance (N, 3) that reaches the eye directly: emission of the surfaces
        seen, the world's radiance where nothing is hit; and (N,) bool, the
        pixels whose sample saw an emitting surface.

        The world comes from its view through this camera where there is one
        (:attr:`~raybundle.scene.world.World.view`): the pixel's mean, or in a pixel an earlier
        sample found partly covered (a window bar), the view's sub-pixel the ray passes
        (:meth:`~raybundle.scene.world.World.view_radiance`): the sky beside the bar, not the
        mean of the sky behind it too.  Which one depends on earlier samples only: consistent,
        the pixel's first samples aside; exact in pixels that see only the world."""
        out = np.zeros((len(g.triangle), 3))
        miss = np.nonzero(~g.hit)[0]
        world = self.scene.world
        if g.bounced is not None and len(miss):     # turned by glass: the world as light, no longer the camera's view
            turned = miss[g.bounced[miss]]
            out[turned] = world.radiance(-g.w_eye[turned])
            miss = miss[~g.bounced[miss]]
        if len(miss) and self.view_means is None:
            out[miss] = world.radiance(-g.w_eye[miss], camera=True)
        elif len(miss):
            fine = self.hit_seen[g.pixel[miss]]
            out[miss[~fine]] = self.view_means[g.pixel[miss[~fine]]]
            out[miss[fine]] = world.view_radiance(-g.w_eye[miss[fine]])
        self.hit_seen[g.pixel[g.hit]] = True
        h = np.nonzero(g.hit)[0]
        # the side seen is the flat normal's (a diffuse lobe's smooth normal may face away from
        # the eye); a layered material's view angle is its shading normal's
        front = np.einsum("ij,ij->i", self.scene.tside_normal[g.tside[h]], g.w_eye[h]) > 0
        cos_eye = np.where(front, np.maximum(np.einsum("ij,ij->i", g.normal[h], g.w_eye[h]), 1e-6), 0.0)
        out[h] = self.scene.materials.emitted_radiance(g.material[h], cos_eye)
        emitter = np.zeros(len(out), bool)
        emitter[h] = np.any(out[h] > 0, axis=1)
        out = g.weighted(out)
        if g.lamps is not None:
            out += g.lamps
        return out, emitter

    def add(self, pixels, le):
        """Add emission samples ``le`` (N, 3) seen in ``pixels`` (N,) (repeats allowed)."""
        for k in range(3):
            self.sum[:, k] += np.bincount(pixels, le[:, k], minlength=len(self.sum))
        self.count += np.bincount(pixels, minlength=len(self.count))
        y = le.sum(axis=1)
        np.minimum.at(self.range[0], pixels, y)
        np.maximum.at(self.range[1], pixels, y)

    def edges(self):
        """The pixels whose samples so far differ: the edges of what is seen emitting."""
        return np.nonzero(self.range[0] < self.range[1])[0]

    def mean(self):
        """(pixels, 3) the average emission seen per pixel."""
        return self.sum / np.maximum(self.count, 1)[:, None]
