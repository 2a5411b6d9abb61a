"""GGX microfacet lobes and Fresnel terms, as Cycles evaluates them.

The untinted GGX lobe is ``D(h) G2(w_i, w_out) / (4 cos_i cos_o)`` with
``D(h) = a^2 / (pi ((n.h)^2 (a^2 - 1) + 1)^2)``, ``a = roughness^2`` (Blender's mapping),
and the height-correlated Smith term ``G2 = 1 / (1 + Lambda(w_i) + Lambda(w_out))``,
``Lambda(w) = (sqrt(1 + a^2 tan^2 theta) - 1) / 2``.  Sampling draws visible normals;
the directional moments (albedo, Fresnel-weighted albedo) are quadratures over the
sampler's unit square.  Directions follow :mod:`raybundle.scene.materials`' conventions.
"""
from __future__ import annotations

import functools

import numpy as np

from ..util import compiled


def smith_lambda(alpha, cos_theta):
    """GGX Smith Lambda(w) = (sqrt(1 + alpha^2 tan^2 theta) - 1) / 2."""
    c2 = np.clip(cos_theta, 1e-12, 1.0) ** 2
    tan2 = (1.0 - c2) / c2
    return 0.5 * (np.sqrt(1.0 + alpha * alpha * tan2) - 1.0)


def ggx_distribution(alpha, n, w_i, w_o):
    """Half vectors h (N, 3) of ``w_i`` and ``w_o``, ``cos_h = n.h`` and the GGX normal
    distribution ``D(h) = alpha^2 / (pi (cos_h^2 (alpha^2 - 1) + 1)^2)`` [1/sr]."""
    h = w_i + w_o
    h = h / (np.linalg.norm(h, axis=1, keepdims=True) + 1e-300)
    cos_h = np.einsum("ij,ij->i", n, h)
    a2 = alpha * alpha
    denom = cos_h * cos_h * (a2 - 1.0) + 1.0
    return h, cos_h, a2 / (np.pi * denom * denom)


def ggx_lobe(alpha, n, w_i, w_o, cos_i, cos_o):
    """Untinted GGX lobe D(h) G2 / (4 cos_i cos_o) [1/sr] for front-facing pairs.

    ``w_i`` points towards the light, ``w_o`` towards the viewer; all arrays (N, ...).
    """
    _, _, d = ggx_distribution(alpha, n, w_i, w_o)
    g2 = 1.0 / (1.0 + smith_lambda(alpha, cos_i) + smith_lambda(alpha, cos_o))
    return d * g2 / (4.0 * cos_i * cos_o)


def sample_ggx_reflection(alpha, normal, w_out, u):
    """Importance-sample the GGX lobe seen from ``w_out``: half vectors h drawn from
    the distribution of normals visible from ``w_out``, ``G1(w_out) (h.w_out)^+ D(h) /
    cos_out`` (Heitz 2018, "Sampling the GGX distribution of visible normals"),
    mirrored to the light-side direction ``w_i``: pdf(w_i) = G1(w_out) D(h) / (4 cos_out).

    Returns ``(w_i (N, 3), weight (N,))`` with ``weight = lobe * cos_i / pdf(w_i)
    = G2 / G1(w_out)`` (at most 1; 0 where ``w_i`` is below the surface), so
    ``E[weight * L(w_i)]`` is the lobe's reflected radiance (untinted).  Drawing h from
    D(h) (n.h) instead gave ``G2 (h.w_out) / (cos_out cos_h)``, up to about 2 / alpha
    where the lobe is seen at grazing angles: eye paths off the side of a glossy block
    carried many times the lamp's light into single pixels (docs/benchmarks.md, 'Where the method is weak').
    """
    alpha = np.broadcast_to(np.asarray(alpha, float), (len(normal),))
    h = sample_ggx_visible_normal(alpha, normal, w_out, u)
    cos_o = np.einsum("ij,ij->i", normal, w_out)
    h_o = np.einsum("ij,ij->i", h, w_out)
    w_i = 2 * h_o[:, None] * h - w_out
    cos_i = np.einsum("ij,ij->i", normal, w_i)
    ok = (cos_i > 0) & (h_o > 0) & (cos_o > 0)
    return w_i, np.where(ok, smith_g2_over_g1(alpha, cos_o, cos_i), 0.0)


def smith_g2_over_g1(alpha, cos_out, cos_in):
    """The visible-normal sampler's weight ``G2(w_out, w_in) / G1(w_out)`` (height-correlated
    Smith), ``(1 + L(w_out)) / (1 + L(w_out) + L(w_in))`` with ``L`` :func:`smith_lambda` of
    ``|cos|``; at most 1."""
    lam_o = smith_lambda(alpha, np.abs(cos_out))
    return (1.0 + lam_o) / (1.0 + lam_o + smith_lambda(alpha, np.abs(cos_in)))


def sample_ggx_visible_normal(alpha, normal, w_out, u):
    """Microfacet normals h (N, 3) of the GGX distribution ``alpha`` (N,) about unit ``normal``
    (N, 3) drawn from the normals visible from ``w_out`` (N, 3), density
    ``G1(w_out) (h.w_out)^+ D(h) / cos_out`` (Heitz 2018), for uniforms ``u`` (N, 2)."""
    from ..tracing.sampling import frames_from_normals

    t, b = frames_from_normals(normal)
    vx, vy = np.einsum("ij,ij->i", w_out, t), np.einsum("ij,ij->i", w_out, b)
    cos_o = np.einsum("ij,ij->i", normal, w_out)
    # the view in the stretched (alpha = 1) configuration, where visible normals are a
    # projected disc: a uniform point on the disc, foreshortened by the view's slant
    v = np.stack([alpha * vx, alpha * vy, np.maximum(cos_o, 1e-12)], axis=1)
    v /= np.linalg.norm(v, axis=1, keepdims=True)
    lens = np.hypot(v[:, 0], v[:, 1])
    flat = lens < 1e-12
    t1 = np.where(flat[:, None], [1.0, 0.0, 0.0],
                  np.stack([-v[:, 1], v[:, 0], np.zeros(len(v))], axis=1) / np.where(flat, 1.0, lens)[:, None])
    t2 = np.cross(v, t1)
    r, phi = np.sqrt(u[:, 0]), 2 * np.pi * u[:, 1]
    p1, p2 = r * np.cos(phi), r * np.sin(phi)
    s = 0.5 * (1.0 + v[:, 2])
    p2 = (1.0 - s) * np.sqrt(np.maximum(0.0, 1.0 - p1 * p1)) + s * p2
    nh = p1[:, None] * t1 + p2[:, None] * t2 + np.sqrt(np.maximum(0.0, 1.0 - p1 * p1 - p2 * p2))[:, None] * v
    m = np.stack([alpha * nh[:, 0], alpha * nh[:, 1], np.maximum(nh[:, 2], 1e-12)], axis=1)
    m /= np.linalg.norm(m, axis=1, keepdims=True)
    return m[:, :1] * t + m[:, 1:2] * b + m[:, 2:] * normal


def ggx_albedo(alpha, cos_out, n_theta=256, n_phi=32):
    """Directional albedo of the untinted GGX lobe, integral of lobe * cos_i dw_i:
    ``E`` of :func:`ggx_fresnel_moments`, a midpoint rule over the unit square of
    :func:`sample_ggx_reflection` (visible normals), ``a = E_u[G2 / G1(w_o)]``, with the
    weight 0 where the mirrored ``w_i`` is below the surface.  The integrand is bounded by
    1: against a 16x finer rule the error is below 2e-5 for every cos_out and alpha (the
    rule over h ~ D(h) (n.h) used before, whose weight grows as 1 / cos_out, was 6e-3 off
    at cos_out 0.02, alpha 0.04).
    """
    return ggx_fresnel_moments(alpha, cos_out, n_theta=n_theta, n_phi=n_phi)["E"]


def f0_from_ior(eta):
    """Normal-incidence reflectance of a dielectric, ((eta - 1) / (eta + 1))^2."""
    return ((eta - 1.0) / (eta + 1.0)) ** 2


def ior_from_f0(f0):
    """Inverse of :func:`f0_from_ior` (f0 clamped to [0, 0.99] as Cycles does)."""
    r = np.sqrt(np.clip(f0, 0.0, 0.99))
    return (1.0 + r) / (1.0 - r)


def fresnel_dielectric_cos(c, eta):
    """Unpolarized Fresnel reflectance of a dielectric of relative IOR ``eta`` at
    cos(angle of incidence) ``c`` (Cycles' ``fresnel_dielectric_cos``); 1 under TIR."""
    c = np.abs(c)
    g2 = eta * eta - 1.0 + c * c
    g = np.sqrt(np.maximum(g2, 0.0))
    a = (g - c) / (g + c)
    b = (c * (g + c) - 1.0) / (c * (g - c) + 1.0)
    return np.where(g2 > 0, 0.5 * a * a * (1.0 + b * b), 1.0)


def fresnel_dielectric_fss(eta):
    """Cosine-weighted hemispherical mean of the dielectric Fresnel, 2 int F mu dmu,
    the Kulla-Conty fit Cycles uses (``fresnel_dielectric_Fss``), eta >= 1."""
    return (eta - 1.0) / (4.08567 + 1.00071 * eta)


def dielectric_layer_fresnel(c, eta, f0):
    """(N, 3) Cycles' Principled specular Fresnel: the real Fresnel remapped from
    [F0(eta), 1] to [f0, 1] (generalized Schlick with negative exponent)."""
    f0_real = f0_from_ior(eta)
    s = np.clip((fresnel_dielectric_cos(c, eta) - f0_real) / (1.0 - f0_real), 0.0, 1.0)
    return f0[None, :] + (1.0 - f0[None, :]) * s[:, None]


def fresnel_f82_tint_b(f0, tint):
    """F82-tint ``B`` (RGB): Schlick at cos = 1/7 times ``tint`` (Cycles' ``fresnel_f82tint_B``); 0 for white."""
    f0, tint = np.asarray(f0, float), np.asarray(tint, float)
    f = 6.0 / 7.0
    f5 = f ** 5
    return (f0 + (1.0 - f0) * f5) * (7.0 / (f5 * f)) * (1.0 - np.minimum(tint, 1.0))


def fresnel_f82(c, f0, b):
    """(N, 3) F82-tint conductor Fresnel clamp(mix(f0, 1, (1-c)^5) - b c (1-c)^6, 0, 1)."""
    s = np.clip(1.0 - np.asarray(c, float), 0.0, 1.0)[:, None]
    s5 = s ** 5
    return np.clip(f0[None, :] + (1.0 - f0[None, :]) * s5 - b[None, :] * (1.0 - s) * s5 * s, 0.0, 1.0)


def fresnel_f82_fss(f0, b):
    """Cosine-weighted mean of the F82 model, mix(f0, 1, 1/21) - b/126 (Cycles' ``fresnel_f82_Fss``)."""
    return f0 + (1.0 - f0) / 21.0 - b / 126.0


def ggx_fresnel_moments(alpha, cos_out, eta=0.0, f82=None, n_theta=256, n_phi=32):
    """Fresnel-weighted directional moments of the untinted GGX lobe, by a midpoint rule
    over the visible-normal sampler's unit square, ``u_1 = 1 - (1 - t)^3`` (Jacobian
    ``3 (1 - t)^2``) to resolve the lobe's tail, the rim of the visible-normal disc.  With
    ``c = h.w_out``, ``w = G2 / G1(w_out)`` (the sampler's weight, 0 where the mirrored
    ``w_i`` is below the surface) and ``valid`` (w_i above it):

    * ``E``  = E[w]: the lobe's albedo (= :func:`ggx_albedo`);
    * ``Ed`` = E[w s(c)], ``s = clamp((F_eta(c) - F0) / (1 - F0), 0, 1)`` (if eta > 1);
    * ``Sd`` = E[valid s(c)]: the mean of ``s`` over visible normals, 0 for invalid
      reflections, which is what Cycles tabulates as ``ggx_gen_schlick_ior_s`` for its
      layering estimate;
    * ``F82`` (K, 3) = E[w F82(c)] if ``f82 = (f0, b)`` is given: for an untinted F82 (b = 0),
      ``f0 E + (1 - f0) E[w (1 - c)^5]``, the F82 model being linear in f0 there.

    The lobe is smooth in the azimuth: 256 x 32 points give the albedo of 256 x 128 to 1e-7
    (within 2e-5 of a 16x finer rule, :func:`ggx_albedo`) in a quarter of the time.  The
    moments without F82's colors are kept per (alpha, eta, cos_out), so the materials of a
    scene that share a roughness and an IOR take one quadrature.
    """
    cos_out = np.atleast_1d(np.asarray(cos_out, float))
    base = _moments(float(alpha), float(eta), tuple(cos_out.tolist()), n_theta, n_phi)
    out = {k: base[k].copy() for k in ("E", "Ed", "Sd")}
    if f82 is not None:
        f0, b = (np.asarray(x, float) for x in f82)
        if np.all(b == 0):
            out["F82"] = f0[None, :] * base["E"][:, None] + (1.0 - f0[None, :]) * base["F5"][:, None]
        else:
            out["F82"] = np.stack([(w[:, None] * fresnel_f82(c, f0, b)).mean(axis=0)
                                   for w, _, c in _lobe_points(alpha, cos_out, n_theta, n_phi)])
    return out


@functools.lru_cache(maxsize=256)
def _moments(alpha, eta, cos_out, n_theta, n_phi):
    """:func:`ggx_fresnel_moments`' ``E``, ``Ed``, ``Sd`` and ``F5`` = E[w (1 - c)^5], kept
    (compiled where the kernels are on: :func:`~raybundle.scene.compiled_microfacet.lobe_moments`)."""
    k = len(cos_out)
    f0_real = f0_from_ior(eta) if eta > 1 else 0.0
    if compiled.use():
        from .compiled_microfacet import lobe_moments

        q = np.empty((k, 4))
        lobe_moments(float(alpha), float(eta), float(f0_real), np.asarray(cos_out, float), int(n_theta), int(n_phi), q)
        return {"E": q[:, 0], "F5": q[:, 1], "Ed": q[:, 2], "Sd": q[:, 3]}
    out = {"E": np.empty(k), "Ed": np.zeros(k), "Sd": np.zeros(k), "F5": np.empty(k)}
    for j, (w, valid, c) in enumerate(_lobe_points(alpha, np.asarray(cos_out), n_theta, n_phi)):
        out["E"][j] = w.mean()
        out["F5"][j] = (w * (1.0 - c) ** 5).mean()
        if eta > 1:
            s = np.clip((fresnel_dielectric_cos(c, eta) - f0_real) / (1.0 - f0_real), 0.0, 1.0)
            out["Ed"][j] = (w * s).mean()
            out["Sd"][j] = (valid * s).mean()
    return out


def _lobe_points(alpha, cos_out, n_theta, n_phi):
    """For each of ``cos_out``: the quadrature's weights ``w`` (the sampler's weight times the
    Jacobian), ``valid`` (the Jacobian where w_i is above the surface, else 0) and ``c = h.w_out``."""
    t = (np.arange(n_theta) + 0.5) / n_theta
    u = np.stack(np.meshgrid(1.0 - (1.0 - t) ** 3, (np.arange(n_phi) + 0.5) / n_phi, indexing="ij"),
                 axis=-1).reshape(-1, 2)
    jac = np.repeat(3.0 * (1.0 - t) ** 2, n_phi)         # du/dt: the quadrature weight
    normal = np.tile([0.0, 0.0, 1.0], (len(u), 1))
    a = np.full(len(u), float(alpha))
    for mu in cos_out:
        mu = float(np.clip(mu, 1e-6, 1.0))
        wo = np.broadcast_to([np.sqrt(1 - mu * mu), 0.0, mu], normal.shape)
        w_i, w = sample_ggx_reflection(a, normal, wo, u)
        h = w_i + wo
        c = np.clip(np.einsum("ij,ij->i", h, wo) / np.linalg.norm(h, axis=1).clip(1e-300), 0.0, 1.0)
        yield w * jac, jac * (w > 0), c
