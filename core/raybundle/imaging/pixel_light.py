"""Direct light per pixel: the first-shot lights and the world at the points the eye sees.

Every image pass estimates, at each visible point, the light of the first-shot lights with
shadow rays (:func:`~raybundle.lights.reflected_direct.reflected_radiance`), what a
translucent surface lets through from its far side, and the world's light on the diffuse
lobe where the world is sampled per pixel.

**Penumbrae.**  The diffuse lobe of polygonal lights takes their exact unoccluded irradiance as
a control variate, so only the shadow rays' outcome is random, in pixels where an earlier
shadow ray reached that light (elsewhere, in an umbra or on the first pass, the plain estimate
is exact or at least never negative).  Pixels whose earlier shadow rays both reached and
missed a light (a penumbra, where then most of the noise is) get ``penumbra_samples`` shadow
rays for that light, a randomly shifted Kronecker set, and one for the others: the flags are
kept per pixel and light (:func:`~raybundle.lights.direct.light_bits`), so a hall of many
lamps spends its penumbra rays on the lamps whose shadow edges cross the pixel.  Those lamps
share the pixel's ``penumbra_samples`` (rounded up, at least one each), so a pixel's penumbra
costs the same however many lamps cross it.  Both choices use earlier passes only, so every
pass stays unbiased.  The first pass, with no earlier samples, treats every pixel as a
penumbra (with the control variate), so single lit pixels are not left to a plain one-ray
estimate.

**Light sequences.**  A pass's own samples (one per pixel) continue, light by light, one
randomly shifted R_3 sequence per pixel over the passes, the penumbra samples of pass p taking
indices p c .. p c + c - 1 (c = ``penumbra_samples``), the others the first of those: a
penumbra's shadow rays stay stratified over the light across passes.
"""
from __future__ import annotations

import numpy as np

from ..lights.direct import ALL_LIGHTS
from ..lights.reflected_direct import reflected_radiance
from ..scene.shading import ShadowTerminator
from ..tracing.sampling import Stream, stream


class PixelLight:
    """The direct light at the points the eye sees through ``camera``: of the first-shot lights
    of ``direct`` and, with ``world_light`` (:class:`~raybundle.lights.world_light.WorldLight` or
    None) and ``world_samples`` per point, of the world.  ``rng`` (the renderer's pass stream)
    draws the light choices and the world samples; ``rays`` counts the rays traced."""

    def __init__(self, scene, camera, solver, direct, settings, rng, world_light, world_samples):
        self.scene, self.camera, self.solver, self.direct, self.settings = scene, camera, solver, direct, settings
        self.rng, self.world_light, self.world_samples = rng, world_light, world_samples
        n = camera.width * camera.height
        #: per pixel: some earlier shadow ray reached a light / was blocked (both: a penumbra)
        self.shadow_flags = np.zeros((n, 2), np.uint64)     # per-light masks (light_bits)
        # each pixel's shift of its R_3 light sequences (module docstring)
        self._light_shift = stream(settings.seed, Stream.LIGHT_SHIFT).random((n, 3))
        self.rays = 0

    def penumbrae(self):
        """(pixels,) uint64: per pixel, the lights whose earlier shadow rays there or in one of
        its four neighbours both reached and missed the light.  A light that a small blocker
        hides from 1% of a pixel's view is found blocked by one pass in a hundred, whose
        estimate then drops to nothing: the neighbours' flags find such pixels sooner."""
        f = self.shadow_flags
        pen = (f[:, 0] & f[:, 1]).reshape(self.camera.height, self.camera.width)
        out = pen.copy()
        out[1:] |= pen[:-1]
        out[:-1] |= pen[1:]
        out[:, 1:] |= pen[:, :-1]
        out[:, :-1] |= pen[:, 1:]
        return out.ravel()

    def lamps(self, g, hf, pixels, u_light, passes, mis, scale, glossy_part=None):
        """(len(hf), 3) the first-shot lights' light reflected at the front-facing points ``hf``
        of G-buffer ``g`` (``scale``: their texture's modulation of the diffuse reflectance, the
        scene's ``albedo_at``), seen in ``pixels``; ``u_light`` a Generator for the light samples, or
        None for a pass's own (the module docstring's sequences, ``passes`` so far); ``mis``
        (len(hf),) bool the points whose glossy lobe's MIS counts these light samples, or None;
        ``glossy_part`` (len(hf), 3) or None: the glossy lobe's share is added to it."""
        direct = self.direct
        before = direct.rays
        flags = self.shadow_flags[pixels[hf]]
        start = passes == 0          # no earlier samples: every point is treated as a penumbra
        # per point, the lights whose earlier samples were both seen and blocked
        pen_lights = np.full(len(hf), ALL_LIGHTS) if start else self.penumbrae()[pixels[hf]]
        if mis is not None:       # the lobe's MIS weight assumes light_samples light samples
            pen_lights[mis] = 0
        # penumbra_samples / light_samples sets of samples for the lights in a point's
        # penumbra, on one randomly shifted Kronecker sequence per point and light
        n_s = int(self.settings.light_samples)
        f = flags.copy()
        more = -(-int(self.settings.penumbra_samples) // n_s)
        # the pixel's penumbra samples shared by the lights whose shadow edges cross it
        crossing = np.zeros(len(hf), np.int64)
        for bits in direct.sampled_apart():
            crossing += (pen_lights & bits) != 0
        share = -(-more // np.maximum(crossing, 1))
        if u_light is None:       # the pass's own: each pixel's sequences continue over the passes
            u, sequence = None, (self._light_shift[pixels[hf]], np.full(len(hf), passes * more * n_s))
        else:
            u, sequence = u_light, (self.rng.random((len(hf), 3)), None)
        value = reflected_radiance(direct, 
            g.point[hf], g.normal[hf], g.material[hf], g.w_eye[hf], u, n_s,
            mis=mis, diffuse_scale=scale, shadow_flags=f,
            analytic=np.full(len(hf), ALL_LIGHTS) if start else flags[:, 0],
            penumbra=(pen_lights, share) + sequence, select=self.rng.random(len(hf)),
            receivers=self.scene.link_groups(g.triangle[hf]), glossy_part=glossy_part,
            terminator=self.terminator(g, hf))
        np.bitwise_or.at(self.shadow_flags, pixels[hf], f)
        self.rays += direct.rays - before
        return value

    def terminator(self, g, points, far_side=False):
        """The :class:`~raybundle.scene.shading.ShadowTerminator` at ``points`` (indices into
        G-buffer ``g``) for light on the side they are seen from (``far_side``: on the other), or
        None in a scene without smooth shading."""
        sc = self.scene
        if sc.shading is None or len(points) == 0:
            return None
        return ShadowTerminator(sc.shading, sc.triangle_source[g.triangle[points]], g.point[points],
                                sc.tside_normal[g.tside[points]] * (-1.0 if far_side else 1.0))

    def far_side(self, g, points):
        """(len(points), 3) the first-shot lights on the far side of the translucent surfaces
        among ``points`` (indices into G-buffer ``g``) let through (zero elsewhere)."""
        out = np.zeros((len(points), 3))
        kt = self.scene.materials.translucent[g.material[points]]
        far = np.nonzero(np.any(kt > 0, axis=1))[0] if self.direct.n_lights else []
        if len(far):
            t = points[far]
            out[far] = kt[far] / np.pi * self.direct.far_side_irradiance(g.point[t], g.normal[t], self.rng,
                                                                        self.scene.link_groups(g.triangle[t]),
                                                                        self.terminator(g, t, far_side=True))
        return out

    def world(self, g, hf, scale, lobe=None):
        """The world's light at the front-facing points ``hf`` of G-buffer ``g`` (``scale`` as
        for :meth:`lamps`): (len(hf), 3)
        on their diffuse lobe, and with ``lobe`` (positions in ``hf`` of glossy points whose
        lobes share these samples) also the lobes' part, (len(lobe), 3), and the guide the
        samples were drawn by (for the lobes' MIS); else None for both.  The unblocked samples
        teach the sides' guide for the next passes."""
        before = self.world_light.rays
        sides = self.scene.tside_side[g.tside[hf]]
        guide = self.world_light.guide_at(self.solver.world_guide, sides)
        lobes = None if lobe is None else (self.scene.materials, lobe, g.material[hf[lobe]], g.w_eye[hf[lobe]])
        e = self.world_light.irradiance(g.point[hf], g.normal[hf], self.rng.random((len(hf), self.world_samples, 3)),
                                        guide, lobe=lobes, learn=sides, terminator=self.terminator(g, hf))
        sky = lobe_guide = None
        if lobe is not None:
            e, sky = e
            lobe_guide = (guide[0], guide[1][lobe])
        m = g.material[hf]
        mats = self.scene.materials
        w_d = mats.diffuse_weight(m, np.einsum("ij,ij->i", g.normal[hf], g.w_eye[hf]))
        self.rays += self.world_light.rays - before
        return w_d * mats.diffuse_reflectance[m] / np.pi * e * (1.0 if scale is None else scale), sky, lobe_guide
