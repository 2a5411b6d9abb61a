"""Caustic first shot: the first shot's glossy reflection, shot along lobe-sampled rays.

A glossy side j lit by the first shot of light l reflects ``E1_jl f_g(w_l, s)``
into direction s (:class:`~raybundle.lights.first_shot.PatchFirstShot`: side-average
irradiance ``E1_jl`` [W/m^2] arriving along the mean travel direction ``w_l``).
Carried by the bundles, that sharp lobe is met only when a random global
direction falls into it (probability ~ alpha^2 for a lobe of roughness alpha)
and then with a value ~ 1/alpha^2: the heavy tail that makes glossy boxes
blotchy (bright streaks on a ceiling above a glossy floor).

Instead, rays leave points of the lit glossy sides in directions drawn from the
lobe itself (:meth:`~raybundle.scene.materials.MaterialTable.sample_glossy`, pdf
~ f cos), and deposit what they carry on the side they hit: a light-tracing
estimate of the incoming radiance of every receiving side i::

    E_c,i = sum_{j,l} (A_j / A_i) E1_jl  integral_{s: j sees i} f_g(w_l, s) cos_s ds   [W/m^2]

With (tside t, light l) drawn with probability p_tl ~ A_t lum(E1_jl), a uniform
point x on t, one sample of light l at x (irradiance ``e`` with visibility, travel
direction ``w``: :meth:`~raybundle.lights.direct.DirectLighting.light_samples_at`) and s from
the lobe for ``w``, one sample adds ``A_t e weight(s) / (p_tl A_i)`` to the side it
hits, ``weight = f cos / pdf`` (bounded: at most the lobe's albedo).  The light
sample, not the side's mean travel direction, spreads a lamp's reflection as its
extent does (with one mean direction a sharp lobe under a lamp threw a
too-concentrated spot on the ceiling).  ``E_c`` is the running mean over all
samples: a refinement's worth at the solver's set-up (so the warm-up's transfers carry its
light on), a few more every iteration, as the first shot's.  The iteration
then leaves the first shot's glossy reflection out of what glossy sides send
(:meth:`~raybundle.methods.patch_solution.PatchSolution.sent_radiance`) and adds
``E_c`` to the receivers' incoming radiance instead, in both the iterate and
the image's diffuse part; for a glossy receiver its own lobe uses the mean
travel direction of its caustic light (the first shot's approximation).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..tracing.sampling import points_on_triangles


@dataclass
class CausticHits:
    """Where lobe-sampled caustic rays met the lit side of a receiving surface: ``points``
    (K, 3), ``triangles`` (K,), receiving ``sides`` (K,), unit ``travel`` directions (K, 3)
    and the ``power`` (K, 3) [W] each sample carries (an estimate of the whole caustic's
    power when divided by the number of samples drawn); ``rays`` traced."""

    points: np.ndarray
    triangles: np.ndarray
    sides: np.ndarray
    travel: np.ndarray
    power: np.ndarray
    rays: int = 0

    @classmethod
    def empty(cls):
        return cls(np.zeros((0, 3)), np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros((0, 3)),
                   np.zeros((0, 3)))


def luminance(rgb):
    """Rec. 709 luminance of (..., 3) linear RGB."""
    return np.asarray(rgb) @ np.array([0.2126, 0.7152, 0.0722])


class CausticShot:
    """Incoming caustic radiance ``E`` (S, 3) [W/m^2] and its mean travel ``direction``
    (S, 3) for every side, from the first shot reflected by glossy sides."""

    def __init__(self, scene, tracer, first_shot, receiving_area, rng, glossy_sides):
        self.scene, self.tracer, self.first_shot = scene, tracer, first_shot
        self.area = receiving_area
        self.rng = rng
        sc = scene
        # tsides of glossy sides that the first shot samples (some light is in front)
        ts = first_shot.receiving_tsides
        self.tsides = ts[np.isin(sc.tside_side[ts], glossy_sides)]
        self.tside_area = sc.triangle_area[sc.tside_triangle[self.tsides]]
        n = sc.n_sides
        self._sum = np.zeros((n, 3))
        self._dsum = np.zeros((n, 3))
        self.samples = 0
        self.E = np.zeros((n, 3))
        self.direction = np.zeros((n, 3))
        self.rays = 0

    @property
    def active(self):
        return len(self.tsides) > 0 and self.first_shot.n_lights > 0

    def sample(self, n_samples, rng):
        """``n_samples`` lobe-sampled rays drawn as :meth:`refine` draws them, with the
        uniforms of ``rng``: a :class:`CausticHits` of the rays that carry light to a
        receiving side (every drawn sample counts in an estimator's normalisation, these
        and the ones that carry nothing)."""
        sc, fs = self.scene, self.first_shot
        side = sc.tside_side[self.tsides]
        power = luminance(fs.E)[side]                       # (T, L): no (T, L, 3) copy of E,
        power *= self.tside_area[:, None]                   # nor a second (T, L) array
        total = power.sum()
        if n_samples <= 0 or not total > 0:                 # nothing lit yet: these samples carry zero
            return CausticHits.empty()
        cdf = np.cumsum(power.ravel())
        pick = np.minimum(np.searchsorted(cdf, rng.random(n_samples) * cdf[-1], side="right"),
                          power.size - 1)
        t_idx, light = np.divmod(pick, power.shape[1])
        p = power.ravel()[pick] / total
        ts = self.tsides[t_idx]
        u = rng.random((n_samples, 4))
        pts = points_on_triangles(sc.triangle_corners[sc.tside_triangle[ts]], u[:, 0], u[:, 1])
        nrm = sc.tside_normal[ts]
        # the light arriving at this point: one light sample (irradiance with visibility, travel
        # direction), so an extended lamp's reflection spreads as the lamp's extent makes it
        e = np.zeros((n_samples, 3))
        travel = np.zeros((n_samples, 3))
        for li in np.unique(light):
            sel = np.nonzero(light == li)[0]
            e[sel], travel[sel], _ = fs.direct.light_samples_at(pts[sel], nrm[sel], fs.lights[li],
                                                              rng.random((len(sel), 3)),
                                                              receivers=sc.link_groups(sc.tside_triangle[ts[sel]]))
        s, weight = sc.materials.sample_glossy(sc.side_material[side[t_idx]], nrm, -travel, u[:, 2:])
        carried = (self.tside_area[t_idx] / p)[:, None] * e * weight   # [W]
        live = np.nonzero(np.any(carried > 0, axis=1))[0]
        if not len(live):
            return CausticHits.empty()
        tri, dist, _, _ = self.tracer.first_hit(pts[live] + nrm[live] * self.tracer.eps, s[live])
        hit = tri >= 0
        live, tri, dist = live[hit], tri[hit], dist[hit]
        rec = sc.side_facing(tri, -s[live])
        ok = rec >= 0
        live, tri, dist, rec = live[ok], tri[ok], dist[ok], rec[ok]
        return CausticHits(pts[live] + dist[:, None] * s[live], tri, rec, s[live], carried[live], len(hit))

    def refine(self, n_samples):
        """``n_samples`` more lobe-sampled rays; updates ``E`` and ``direction``."""
        if not self.active or n_samples <= 0:
            return
        self.samples += n_samples
        h = self.sample(n_samples, self.rng)
        self.rays += h.rays
        a = self.area[h.sides]
        keep = a > 0
        rec, c, d = h.sides[keep], h.power[keep] / a[keep, None], h.travel[keep]
        n = self.scene.n_sides
        for k in range(3):
            self._sum[:, k] += np.bincount(rec, c[:, k], minlength=n)
            self._dsum[:, k] += np.bincount(rec, luminance(c) * d[:, k], minlength=n)
        self._update()

    def sums(self):
        """Copies of the running sums and the sample count ``(sum, dsum, samples)``
        (what chains pool, :mod:`raybundle.app.chains`)."""
        return self._sum.copy(), self._dsum.copy(), self.samples

    def set_sums(self, total, dtotal, samples):
        """Replace the running sums and sample count (chains pooled, :mod:`raybundle.app.chains`)."""
        self._sum, self._dsum, self.samples = total.copy(), dtotal.copy(), samples
        self._update()

    def _update(self):
        self.E = self._sum / max(self.samples, 1)
        norm = np.linalg.norm(self._dsum, axis=1, keepdims=True)
        self.direction = np.where(norm > 0, self._dsum / np.maximum(norm, 1e-300), 0.0)
