"""The image's parts, apart: what each of the renderer's estimators adds to the pixels.

A pixel of :class:`~raybundle.imaging.renderer.Renderer` is a sum of parts, each estimated on
its own (the renderer's module docstring).  With ``RenderSettings.components`` the renderer
keeps them apart, so that each can be compared with what a path tracer's light passes say of
the same light (the interior bench's breakdown against Cycles' Emission, Diffuse Direct and
Indirect, and Glossy passes):

* ``emission``: emission and the world seen (Cycles: Emission + Environment);
* ``lamps``: the first-shot lights' direct light on the diffuse lobe (and through translucent
  surfaces), per pixel;
* ``world``: the world's direct light on the diffuse lobe, where it is sampled per pixel
  (``world_samples``); elsewhere the patches carry it, in ``diffuse indirect``;
* ``glossy``: the glossy lobe, all of it: its share of the lights' and the world's samples,
  the glossy eye paths and the per-iteration glossy iterates;
* ``diffuse indirect``: the diffuse lobe's light from the patches (the running average
  resolved, with its final gather), lights the first shot left to the bundles included;
* ``caustics``: the caustic first shot light-traced into the pixels (``caustic_splats``).

They sum to the image.  A part of a sample whose eye path glass or a mirror turned stays the
part of the surface the path ends on; :attr:`ImageComponents.glass` says which pixels hold such
samples (a path tracer's passes count them as transmission or glossy).
"""
from __future__ import annotations

import numpy as np

#: the parts, in the order they are summed
PARTS = ("emission", "lamps", "world", "glossy", "diffuse indirect", "caustics")
#: the parts each image pass estimates per sample (the others have sums of their own)
PASS_PARTS = ("lamps", "world", "glossy")


class ImageComponents:
    """The image passes' parts per pixel (``pixels`` of them): for each of
    :data:`PASS_PARTS` the sum of its per-pass estimates times their samples (the weights of
    the renderer's ``pass_sum``), and per pixel the passes whose primary sample an interface
    turned (``glass``)."""

    def __init__(self, pixels):
        self.sum = {p: np.zeros((pixels, 3)) for p in PASS_PARTS}
        self.glass = np.zeros(pixels)
        self.passes = 0

    @staticmethod
    def split(out, lamps, world):
        """The pass parts of per-sample radiance ``out`` (N, 3), of which ``lamps`` and
        ``world`` (N, 3) are the diffuse lobe's direct light: the glossy lobe is the rest."""
        return {"lamps": lamps, "world": world, "glossy": out - lamps - world}

    def add_pass(self, parts, count, bounced):
        """Add one pass's parts (N, 3) each, weighted by its samples per pixel ``count``
        (N,); ``bounced`` (N,) bool or None: whether an interface turned the pixel's primary
        sample."""
        for p in PASS_PARTS:
            self.sum[p] += parts[p] * count[:, None]
        if bounced is not None:
            self.glass += bounced
        self.passes += 1

    def images(self, samples, emission, glossy_more, diffuse, caustics, shape):
        """The parts as images (``shape`` (H, W)), by name in :data:`PARTS` order, and
        ``glass`` (H, W): the share of each pixel's passes that an interface turned.
        ``samples`` (N,) the pass samples per pixel; ``emission``, ``diffuse``, ``caustics``
        (N, 3) or None the parts with sums of their own; ``glossy_more`` (N, 3) the glossy light
        read outside the pass sums (the eye paths' reading of the solver, the iterates)."""
        per = {p: self.sum[p] / np.maximum(samples, 1)[:, None] for p in PASS_PARTS}
        per["glossy"] = per["glossy"] + glossy_more
        per.update({"emission": emission, "diffuse indirect": diffuse, "caustics": caustics})
        out = {p: (np.zeros_like(per["lamps"]) if per[p] is None else per[p]).reshape(*shape, 3).astype(np.float32)
               for p in PARTS}
        out["glass"] = (self.glass / max(self.passes, 1)).reshape(shape).astype(np.float32)
        return out
