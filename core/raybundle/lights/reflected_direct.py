"""Direct light reflected towards the eye, per pixel: the image passes' first shot.

:func:`reflected_radiance` estimates, at the points an image pass sees, the direct radiance
the first-shot lights (:class:`~raybundle.lights.direct.DirectLighting`) reflect towards the
eye, with fresh shadow rays every pass, so shadows and glossy highlights are sharp.  Its
parts: the lights that can reach each point (and their exact unoccluded irradiance, a
control variate for the diffuse lobe), lamps chosen by their contribution, the sample
points of each light (more where a penumbra crosses a point, on a Kronecker sequence per
pixel and light), and one shadow-ray sample, its glossy part weighted against the lobe's
own ray by multiple importance sampling.

Penumbra samples (``penumbra``): the lights in a point's ``mask`` take ``count`` times as many
samples there, on the randomly shifted Kronecker (R_3) sequence ``(shift + l beta + j alpha)
mod 1`` of light ``l`` (``beta`` a fixed irrational offset, so each light has a shift of its
own), in place of those of ``u``: the penumbra samples cost rays only for the lights whose
shadow edge crosses the point. Without ``first``, ``j = c n + s`` for the s-th of the light's n
= ``samples_per_light`` samples in its c-th set; with ``first`` every light takes every sample
from its sequence, from index ``first + c n + s``: a caller that keeps ``shift`` per pixel and
advances ``first`` by ``count n`` every pass continues one sequence per pixel and light over
the passes, so a penumbra's shadow rays stay stratified over the light across passes, not only
within one.

The control variate (``analytic``): the diffuse lobe of polygonal lights
(:func:`~raybundle.lights.polygon.light_polygon_irradiance`) with the exact unoccluded
irradiance as a control variate, ``f_d (Le I(x) - mean_s (e_s - e_s V_s))``, ``e_s`` the
sample's unshadowed estimate: still unbiased, and exact wherever the light is wholly seen or
wholly hidden from the point's upper side (only which samples are blocked is random, not where
on the light they land: the Cornell back wall's per-pass noise). In an umbra the plain estimate
is exact (0) and the control variate is not, so a caller that knows where earlier samples were
all blocked passes a mask.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..tracing.sampling import kronecker_alpha
from ..util import compiled
from ..util.arrays import ranges
from . import compiled_lights
from .direct import ALL_LIGHTS, light_bits, may_light, seen_blocked
from .polygon import light_polygon_irradiance
from .sources import MeshLight, ShapeLight

#: the golden ratio's fraction: lamp l's selection uniform is (u + l phi) mod 1
_GOLDEN = 0.6180339887498949
#: each light's offset of a point's Kronecker shift (``penumbra``): light l adds l times this,
#: mod 1 (the R_3 generators of the next dimensions)
_LIGHT_OFFSET = kronecker_alpha(6)[3:]
#: the R_3 generators of a penumbra's sample sequence
_ALPHA = kronecker_alpha(3)
#: the stand-in light index for the light tree's samples
TREE = -1
#: :func:`_selection`: a lamp giving at least this share of all lamps' unoccluded light at a
#: point is always taken there; one giving less, with probability share / SELECT_SHARE ...
SELECT_SHARE = 0.05
#: ... but at least this (a rough estimate of the share must not make rare, heavy samples)
SELECT_MIN = 1.0 / 16.0
#: lamps chosen only up to this many (the estimates cost N x lamps; a light tree is the way beyond)
SELECT_MAX_LIGHTS = 64


@dataclass
class _Points:
    """The shading points of one call and what they ask for (:func:`reflected_radiance`), and
    the lights (:meth:`~raybundle.lights.direct.DirectLighting.light_list`) with their bits."""
    lights: list
    bits: np.ndarray
    points: np.ndarray
    normals: np.ndarray
    mats: np.ndarray
    w_out: np.ndarray
    diffuse_scale: np.ndarray | None
    mis: np.ndarray | None
    shadow_flags: np.ndarray | None
    receivers: np.ndarray | None
    #: (N, 3) or None: where the glossy lobe's part of the light is added (``glossy_part``)
    glossy: np.ndarray | None = None
    #: the points' :class:`~raybundle.scene.shading.ShadowTerminator`, or None (``terminator``)
    terminator: object = None


@dataclass
class _Samples:
    """One light's samples in a call: light ``li`` (:data:`TREE` for the tree's), its bit, the
    sample points ``pt`` (ids of :class:`_Points`, repeated for penumbra samples) with their
    weights, and where they take a Kronecker sequence (``kron``, its ``start`` and ``shift``)."""
    li: int
    light: object
    bit: np.uint64
    pt: np.ndarray
    weight: np.ndarray
    kron: np.ndarray | None = None
    start: np.ndarray | None = None
    shift: np.ndarray | None = None

    def at(self, at: _Points):
        """The sample points' position, normal, material, outgoing direction and texture scale."""
        scale = None if at.diffuse_scale is None else at.diffuse_scale[self.pt]
        return at.points[self.pt], at.normals[self.pt], at.mats[self.pt], at.w_out[self.pt], scale


def reflected_radiance(direct, points, normals, mats, w_out, u, samples_per_light=1, mis=None, diffuse_scale=None,
                       shadow_flags=None, analytic=False, penumbra=None, select=None, receivers=None,
                       glossy_part=None, terminator=None):
    """Direct radiance reflected towards ``w_out`` (N, 3) at surface points, RGB.

    Unbiased estimate with ``samples_per_light`` shadow rays per area light (one per point light
    or sun): ``sum_l mean_s e_l cos_x f(w_travel, w_out) V``. ``u``: uniforms (N, K, 3) with K =
    :meth:`~raybundle.lights.direct.DirectLighting.samples_per_pass`, a Generator, or None where
    ``penumbra`` gives every sample's sequence (its ``first``). ``mis`` (N,) bool: points whose
    glossy lobe also gets one lobe-sampled ray that counts the mesh lights it meets
    (:meth:`~raybundle.lights.direct.DirectLighting.mis_weight`); the glossy part of their
    mesh-light samples is weighted by ``w_l = (n p_l)^2 / ((n p_l)^2 + p_g^2)`` (power
    heuristic; n = ``samples_per_light``, p_l and p_g the light's and the lobe's densities of
    the sampled direction), so a sharp lobe reflecting a lamp is found by the lobe's ray, not by
    rare light samples with a huge BRDF value. ``diffuse_scale`` (N, 3): texture modulation of
    the diffuse reflectance.

    Per-light masks are uint64 bit sets, light ``l``'s bit ``min(l, 63)``
    (:func:`~raybundle.lights.direct.light_bits`). ``shadow_flags`` (N, 2) uint64, updated in
    place: in column 0 the lights a sample reached, in column 1 those a sample facing them found
    blocked.

    ``penumbra`` ``(mask (N,) uint64, count (int or (N,) ints), shift (N, 3), first (N,) int or
    None)`` or None: more samples where a penumbra crosses a point (module docstring).

    With a light tree (``direct.tree``) its ``samples_per_light`` samples per point
    (:meth:`~raybundle.lights.direct.DirectLighting.tree_sample`, penumbra samples as for one
    light, each sample flagging its own lamp's bit) stand for every lamp, the suns one each; the
    control variate and ``select`` are then not used.

    ``select`` (N,) uniforms or None: lamps chosen by their contribution (:func:`_selection`): a
    lamp whose unoccluded contribution at a point is a small share of all lamps' there is taken
    with probability ``P < 1`` (its samples weighted 1 / P), the decision ``(select + l phi) mod
    1 < P`` for lamp ``l`` (phi the golden ratio's fraction). A lamp taken by chance at a point
    (``P < 1``: a small share of the light there) takes no penumbra samples there.

    ``receivers`` (N,) or None: the points' link groups; a linked light lights only those it
    reaches (:mod:`raybundle.scene.linking`).  ``analytic`` (bool, (N,) bool, or (N,) uint64
    mask of lights): where the control variate applies (module docstring).  ``glossy_part``
    (N, 3) or None: the glossy lobe's share of the result is added to it (the rest is the
    diffuse lobe's, the control variate's whole part included).  ``terminator``: the points'
    :class:`~raybundle.scene.shading.ShadowTerminator` or None.

    The points are split into pieces run in parallel
    (:meth:`~raybundle.tracing.visibility.RayTracer.map_pieces`); a point's value does not
    depend on the split but for the cut-out and glass choices of its shadow rays.
    """
    n = len(points)
    if isinstance(u, np.random.Generator):
        u = u.random((n, direct.samples_per_pass(samples_per_light), 3))
    an = np.asarray(analytic)
    an = np.where(np.broadcast_to(an, n), ALL_LIGHTS, np.uint64(0)) if an.dtype == bool else an.astype(np.uint64)

    def piece(a, b):
        def cut(x):
            return x[a:b] if isinstance(x, np.ndarray) and x.ndim else x

        pen = None if penumbra is None else tuple(cut(x) for x in penumbra)
        return _reflected(direct, *(cut(x) for x in (points, normals, mats, w_out, u)), samples_per_light,
                          *(cut(x) for x in (mis, diffuse_scale, shadow_flags, an)), pen,
                          *(cut(x) for x in (select, receivers, glossy_part)),
                          None if terminator is None else terminator.take(slice(a, b)))

    return np.concatenate(direct.tracer.map_pieces(piece, n))


def _reflected(direct, points, normals, mats, w_out, u, samples_per_light, mis, diffuse_scale, shadow_flags, an,
               penumbra, select, receivers, glossy_part, terminator):
    """:func:`reflected_radiance` at one piece of its points, ``u`` an array or None and ``an``
    (N,) uint64 masks."""
    n = len(points)
    out = np.zeros((n, 3))
    lights = direct.light_list()
    at = _Points(lights, light_bits(len(lights)), points, normals, mats, w_out, diffuse_scale, mis, shadow_flags,
                 receivers, glossy_part, terminator)
    f_d_all = _diffuse_part(direct, at, an)
    # with a light tree, the tree's samples (TREE) and the suns on their own
    own = range(len(lights)) if direct.tree is None else direct.suns
    reach, exact = _lights_reaching(direct, at, None if f_d_all is None else an, own)
    chance = _selection(at, reach, exact) if select is not None and direct.tree is None else None
    k = 0
    for li in ([TREE] if direct.tree is not None else []) + list(own):
        light = lights[li] if li != TREE else None
        polygonal = li == TREE or isinstance(light, (MeshLight, ShapeLight))
        n_s = samples_per_light if polygonal else 1
        base, picked = (reach[li], 1.0) if li != TREE else (np.arange(n), 1.0)
        if chance is not None:                 # the lamps chosen by their contribution
            base, picked = _chosen(li, base, chance[li], select, mis if polygonal else None)
        s = _light_samples(direct, at, li, base, picked, n_s, penumbra, chance is not None)
        acc = np.zeros((len(s.pt), 3 if glossy_part is None else 6))      # the glossy part beside
        f_d = _control_variate(exact[li], light, f_d_all, s.pt, out) if li != TREE else None
        shading = s.at(at)
        lift = None if at.terminator is None else at.terminator.take(s.pt)      # the samples' terminator
        for j in range(n_s):
            uk = u[s.pt, k] if u is not None else np.empty((len(s.pt), 3))
            if s.kron is not None and len(s.kron):
                uk[s.kron] = (s.shift + (s.start + j)[:, None] * _ALPHA) % 1.0
            _one_sample(direct, at, s, shading, lift, uk, f_d, n_s, polygonal, acc)
            k += 1
        for c in range(acc.shape[1]):
            (out if c < 3 else glossy_part)[:, c % 3] += np.bincount(s.pt, acc[:, c], minlength=n)
    return out


def _diffuse_part(direct, at, an):
    """(N, 3) the diffuse BRDF at the points where the control variate applies (``an`` (N,)
    uint64 masks not 0), or None where none does (no polygonal light, or no mask set); f_d does
    not depend on the incoming direction."""
    cv = np.nonzero(an)[0] if any(isinstance(light, (MeshLight, ShapeLight)) for light in at.lights) else []
    if not len(cv):
        return None
    f_d = np.zeros((len(at.points), 3))
    f_d[cv] = direct.scene.materials.brdf(at.mats[cv], at.normals[cv], -at.normals[cv], at.w_out[cv], glossy=False,
                                          diffuse_scale=None if at.diffuse_scale is None else at.diffuse_scale[cv])
    return f_d


def _control_variate(exact, light, f_d_all, pt, out):
    """Add the control variate's exact part of ``light`` (``exact``: ``(here, irradiance, ok)``
    or None) to ``out``; returns the diffuse BRDF (len(pt), 3) its samples at points ``pt``
    subtract (zero where it does not apply), or None where it applies nowhere."""
    if exact is None:
        return None
    here, irr, ok = exact
    out[here] += f_d_all[here] * (ok * irr)[:, None] * np.asarray(light.radiance, float)
    taken = np.zeros(len(out), bool)
    taken[here[ok]] = True
    return f_d_all[pt] * taken[pt, None]


def _lights_reaching(direct, at, an, own):
    """``(reach, exact)``, per light of ``own``: the points it can reach (the rest get nothing,
    and no shadow flag) and, where the control variate applies (``an``, or None: nowhere), its
    exact unoccluded irradiance there, ``(here, irradiance, ok)`` or None."""
    reach, exact = [None] * len(at.lights), [None] * len(at.lights)
    for li in own:
        light = at.lights[li]
        base = np.nonzero(may_light(light, at.points, at.normals))[0]
        if direct.linking is not None and at.receivers is not None:
            base = base[direct.linking.receives[direct.light_link[li], at.receivers[base]]]
        polygonal = isinstance(light, (MeshLight, ShapeLight))
        here = base[(an[base] & at.bits[li]) != 0] if an is not None and polygonal else []
        ex = light_polygon_irradiance(light, at.points[here], at.normals[here]) if len(here) else None
        reach[li] = base
        exact[li] = None if ex is None else (here, ex[0], ex[1])
    return reach, exact


def _selection(at, reach, exact):
    """Per light, the probability (one value per point in ``reach[l]``) that it is taken at
    the points: ``clip(c_l / (SELECT_SHARE C), SELECT_MIN, 1)``, ``c_l`` the lamp's
    unoccluded irradiance at the point (luminance: the exact ``Le I(x)`` where ``exact``
    holds it, else :meth:`~raybundle.lights.sources.ShapeLight.selection_estimate`, an upper
    bound for area lamps, a guess for the others) and
    ``C`` the sum over the lamps; None (every lamp always taken) for a single lamp or
    more than :data:`SELECT_MAX_LIGHTS`.  Unbiased whatever the estimates: each lamp's
    samples are weighted 1 / probability."""
    lights, points, normals = at.lights, at.points, at.normals
    if not 1 < len(lights) <= SELECT_MAX_LIGHTS:
        return None
    c = np.zeros((len(points), len(lights)))
    for li, light in enumerate(lights):
        base = reach[li]
        if exact[li] is not None:
            here, irr, ok = exact[li]
            c[here[ok], li] = irr[ok] * float(np.mean(light.radiance))
            base = np.setdiff1d(base, here[ok], assume_unique=True)
        if len(base) == 0:
            continue
        c[base, li] = light.selection_estimate(points[base], normals[base])
    total = c.sum(axis=1, keepdims=True)
    chance = np.clip(c / np.maximum(SELECT_SHARE * total, 1e-300), SELECT_MIN, 1.0)
    return [chance[reach[li], li] for li in range(len(lights))]


def _chosen(li, base, chance, select, mis):
    """``(points, weights)``: of the points ``base``, those where lamp ``li`` is taken, by its
    ``chance`` there (1 where ``mis`` asks for the lobe's MIS weight, which assumes the lamp is
    always taken), and 1 / that chance."""
    if mis is not None:
        chance = np.where(mis[base], 1.0, chance)
    keep = (select[base] + li * _GOLDEN) % 1.0 < chance
    return base[keep], 1.0 / chance[keep]


def _light_samples(direct, at, li, base, picked, n_s, penumbra, by_chance):
    """The :class:`_Samples` of light ``li`` at points ``base`` taken with weight ``picked``
    (1 / the chance of taking it), ``n_s`` a set: repeated where the light takes penumbra
    samples (not where it was taken by chance: it gives little there)."""
    light = at.lights[li] if li != TREE else None
    bit = at.bits[li] if li != TREE else direct.tree_mask
    if penumbra is None:
        return _Samples(li, light, bit, base, np.broadcast_to(picked / n_s, len(base))[:, None])
    mask, more, shift, first = penumbra
    on = (mask[base] & bit) != 0
    if by_chance:
        on &= picked <= 1.0
    reps = np.where(on, more[base] if np.ndim(more) else int(more), 1)
    pt = np.repeat(base, reps)
    copy = ranges(0, reps)
    kron = np.nonzero(np.repeat(on, reps))[0] if first is None else np.arange(len(pt))
    start = copy[kron] * n_s + (0 if first is None else first[pt[kron]])
    light_shift = shift[pt[kron]] + (li if li != TREE else len(at.lights)) * _LIGHT_OFFSET
    return _Samples(li, light, bit, pt, np.repeat(picked / (n_s * reps), reps)[:, None], kron, start, light_shift)


def _one_sample(direct, at, s, shading, lift, uk, f_d, n_s, polygonal, acc):
    """One shadow-ray sample of :class:`_Samples` ``s`` at uniforms ``uk``, added to ``acc``
    (its rows; with ``at.glossy``, the glossy lobe's part also in its columns 3-5), the control
    variate's correction with it; the shadow flags updated.  ``lift``: the samples'
    :class:`~raybundle.scene.shading.ShadowTerminator` or None."""
    p, nrm, m, wo, scale = shading
    em = None
    if s.li == TREE:
        y, e, em = direct.tree_sample(p, nrm, uk)
        ids = np.where(em >= 0, direct.tree.light[np.maximum(em, 0)], -1)
    else:
        y, e = s.light.sample(p, uk)
        ids = s.li
    rec = None if at.receivers is None else at.receivers[s.pt]
    free = None
    if at.shadow_flags is None and f_d is None:
        e, travel, cos_x = direct.shadowed(p, nrm, y, e, lights=ids, receivers=rec, terminator=lift)
    else:
        e, travel, cos_x, free = direct.shadowed(p, nrm, y, e, unshadowed=True, lights=ids, receivers=rec,
                                                 terminator=lift)
    if compiled.use():
        mis, le = None, np.zeros(3)          # the MIS weight's light radiance, where it applies
        if at.mis is not None and polygonal:
            mis = at.mis[s.pt]
            le = s.light.radiance if s.li != TREE else direct.tree_radiance[np.maximum(em, 0)]
            if s.li == TREE:          # not the point lights, which no ray meets
                mis = mis & np.any(le > 0, axis=1)
        live, blocked = compiled_lights.lamp_accumulate(direct.scene.materials, m, nrm, wo, travel, e, free, cos_x,
                                                        s.weight, f_d, scale, mis, le, n_s, acc)
    else:
        live, blocked = seen_blocked(e, free) if free is not None else (np.any(e > 0, axis=1), None)
        if f_d is not None:
            acc[:, :3] -= s.weight * f_d * (free - e)
        if live.any():
            _accumulate(direct, at, s, shading, em, live, e, travel, cos_x, f_d, n_s, polygonal, acc)
    if at.shadow_flags is not None and s.li == TREE:     # each sample its own light's bit
        lb = at.bits[direct.tree.light[np.maximum(em, 0)]]
        np.bitwise_or.at(at.shadow_flags, (s.pt[live], 0), lb[live])
        np.bitwise_or.at(at.shadow_flags, (s.pt[blocked], 1), lb[blocked])
    elif at.shadow_flags is not None:
        at.shadow_flags[s.pt[live], 0] |= s.bit      # repeated points all write the same value
        at.shadow_flags[s.pt[blocked], 1] |= s.bit


def _accumulate(direct, at, s, shading, em, live, e, travel, cos_x, f_d, n_s, polygonal, acc):
    """The NumPy path of :func:`~raybundle.lights.compiled_lights.lamp_accumulate`: the BRDF
    at the ``live`` samples, less the control variate's diffuse part, the glossy lobe's MIS
    share taken out, times ``e`` and the samples' weights, added to ``acc``."""
    mt = direct.scene.materials
    _, nrm, m, wo, scale = shading
    f = mt.brdf(m[live], nrm[live], travel[live], wo[live], diffuse_scale=None if scale is None else scale[live])
    if f_d is not None:                # the control variate took the diffuse part
        f -= f_d[live]
    glossy = None if at.glossy is None else mt.brdf(m[live], nrm[live], travel[live], wo[live], diffuse=False)
    if at.mis is not None and polygonal:
        before = None if glossy is None else f.copy()
        _lobe_share(direct, at, s, shading, em, live, e, travel, cos_x, n_s, f)
        if glossy is not None:         # the lobe's ray takes its share of the glossy part only
            glossy -= before - f
    acc[live, :3] += s.weight[live] * e[live] * f
    if glossy is not None:
        acc[live, 3:] += s.weight[live] * e[live] * glossy


def _lobe_share(direct, at, s, shading, em, live, e, travel, cos_x, n_s, f):
    """Take from ``f`` (the BRDF of the ``live`` samples) the glossy part that the lobe's own
    ray counts at the points ``at.mis`` asks it for: the light sample keeps the power
    heuristic's weight ``w_l`` of it."""
    mt = direct.scene.materials
    _, nrm, m, wo, _ = shading
    sel = np.nonzero(at.mis[s.pt[live]])[0]
    if s.li == TREE:                 # not the point lights, which no ray meets
        sel = sel[np.any(direct.tree_radiance[em[live][sel]] > 0, axis=1)]
    if len(sel):
        i = np.nonzero(live)[0][sel]
        le = s.light.radiance if s.li != TREE else direct.tree_radiance[em[i]]
        # e = Le cos_x / p_l for an unblocked sample (MeshLight.sample; the tree's probability included)
        p_l = np.mean(le, axis=-1) * cos_x[i] / np.mean(e[i], axis=1)
        p_g = mt.glossy_pdf(m[i], nrm[i], -travel[i], wo[i])
        w_l = 1.0 - direct.mis_weight(p_g, n_s * p_l)
        f[sel] -= (1.0 - w_l)[:, None] * mt.brdf(m[i], nrm[i], travel[i], wo[i], diffuse=False)
