"""Caustic splats: the caustic first shot light-traced into the pixels.

The first shot's glossy reflections (:class:`~raybundle.lights.caustics.CausticShot`: light ->
glossy side -> surface) are sampled and each sample's diffuse reflection towards the eye is
splatted into the pixel it lands in (:func:`~raybundle.imaging.splat.splat_to_camera`),
averaged over all samples drawn [W m^-2 sr^-1]; read from the patches instead, a sharp caustic
is a side average, blurred over a patch or two.
"""
from __future__ import annotations

import numpy as np

from ..tracing.sampling import Stream, stream
from .splat import splat_to_camera


class CausticSplats:
    """The caustic splats of a renderer: per pixel their ``sum`` (N, 3) and the ``samples``
    drawn.  ``pixel`` (N, 2): the pixels' corners; ``trace_centres()``: the G-buffer through
    the pixel centres (for the filter's same-surface test); ``rays`` counts the rays traced."""

    #: :meth:`image` filters the splats until they average this many per pixel
    FILTER_SAMPLES = 1024

    def __init__(self, scene, camera, tracer, direct, caustic, seed, pixel, trace_centres):
        self.scene, self.camera, self.tracer, self.direct, self.caustic = scene, camera, tracer, direct, caustic
        self.pixel, self.trace_centres = pixel, trace_centres
        self.rng = stream(seed, Stream.CAUSTIC_SPLATS)
        self.sum = np.zeros((len(pixel), 3))
        self.samples = 0
        self.rays = 0
        self._pixel_surface = None                        # the filter's same-surface test

    def splat(self, n_samples):
        """Light-trace ``n_samples`` samples of the caustic first shot (light -> glossy side
        -> surface, :meth:`~raybundle.lights.caustics.CausticShot.sample`) into the pixels: the
        diffuse lobe of the surface they reach, towards the eye (:func:`splat_to_camera`),
        averaged over all samples drawn.  Read from the patches, the caustic is a side
        average, interpolated: sharp caustics (a glossy floor throwing the lamp onto the
        walls, with the shadow of a block in it) came out blurred over a patch or two,
        most of the glossy box's bias, which the splats measured to cut (docs/benchmarks.md, 'Measured
        choices behind the defaults').  The samples are drawn in pieces run in parallel, each
        with random numbers of its own (:meth:`~raybundle.tracing.visibility.RayTracer.each_piece`)
        and summed in order as they end: a piece gives its samples' pixels and values, not an
        image, so a draw holds a few pieces' samples and one image, whatever its size."""
        cs, sc = self.caustic, self.scene
        before = self.direct.rays

        def piece(a, b, rng):
            h = cs.sample(b - a, rng)
            normals = sc.tside_normal[sc.seen_tside(h.triangles, h.travel)]
            pix, value, rays = splat_to_camera(sc, self.camera, self.tracer, h.points, normals, h.triangles,
                                               h.travel, h.power, glossy=False)
            return pix, value, h.rays + rays

        for pix, value, rays in self.tracer.each_piece(piece, n_samples, self.rng):
            for k in range(3):
                self.sum[:, k] += np.bincount(pix, value[:, k], minlength=len(self.sum))
            self.rays += rays
        self.samples += n_samples
        self.rays += self.direct.rays - before

    def image(self):
        """(N, 3) the caustic splats' average per pixel [W m^-2 sr^-1], filtered, until the
        splats average ``FILTER_SAMPLES`` per pixel, by a tent one pixel wide,
        (1, 2, 1) x (1, 2, 1), over the neighbours that see the same surface (material,
        normal, plane) through their centres, normalised by the weights used: a density
        estimate whose kernel shrinks to a pixel once the samples are many (consistent).
        A photon lands in one pixel, so unfiltered the splats are a pixel-sized Poisson
        count, which measured worse than filtered on ``cornell-glossy`` (docs/benchmarks.md, 'Measured
        choices behind the defaults')."""
        n = len(self.pixel)
        img = self.sum / max(self.samples, 1)
        if self.samples >= self.FILTER_SAMPLES * n:
            return img
        if self._pixel_surface is None:
            g = self.trace_centres()
            depth = np.where(g.hit, np.linalg.norm(g.point - self.camera.position, axis=1), 0.0)
            self._pixel_surface = (np.where(g.hit, g.material, -1), g.normal, g.point, depth)
        mat, nrm, pts, depth = self._pixel_surface
        w_img, h_img = self.camera.width, self.camera.height
        py, px = self.pixel[:, 1].astype(np.int64), self.pixel[:, 0].astype(np.int64)
        num, den = np.zeros_like(img), np.zeros(n)
        for dy in (-1, 0, 1):
            for dx in (-1, 0, 1):
                ok = (px + dx >= 0) & (px + dx < w_img) & (py + dy >= 0) & (py + dy < h_img)
                p = np.nonzero(ok)[0]
                q = p + dy * w_img + dx
                same = ((mat[q] == mat[p]) & (np.einsum("ij,ij->i", nrm[q], nrm[p]) > 0.99)
                        & (np.abs(np.einsum("ij,ij->i", pts[q] - pts[p], nrm[p])) <= 0.01 * depth[p]))
                w = (2 - abs(dx)) * (2 - abs(dy)) * same
                num[p] += w[:, None] * img[q]
                den[p] += w
        return num / np.maximum(den, 1)[:, None]
