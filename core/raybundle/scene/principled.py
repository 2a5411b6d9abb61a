"""Blender's Principled BSDF as a layered GGX material.

Principled (layered) materials
------------------------------
Blender's Principled BSDF (Cycles 5.0, ``svm/closure.h``) is not a Mix of
Diffuse and Glossy: a Fresnel-weighted dielectric GGX layer sits over the
Lambertian base, and the base only gets the light the layer did not reflect
towards the viewer; the metallic part is a GGX lobe with Schlick/F82-tint
conductor Fresnel (F0 = base color), and the default "Multiscatter GGX"
distribution scales every GGX lobe to restore the energy lost by single
scattering.  Four optional per-material parameters switch this on; with all
of them off (their defaults) a material is exactly the Mix above, bit for bit:

* ``specular_ior`` (eta; 0 = off): a dielectric GGX layer of the same roughness
  over the diffuse lobe, with Cycles' remapped dielectric Fresnel
  ``F_s(c) = mix(f0, 1, clamp((F_eta(c) - F0(eta)) / (1 - F0(eta)), 0, 1))``,
  ``f0 = F0(eta) * specular_tint``, ``F0(eta) = ((eta - 1) / (eta + 1))^2``,
  ``c = h.w_out``; the layer has the weight ``(1 - g)``;
* ``specular_tint`` (RGB, default 1): the layer's f0 multiplier, and the F82 tint
  of a conductor glossy lobe;
* ``glossy_fresnel`` (0 = none, 1 = F82-tint conductor): the glossy lobe's color
  ``ks`` is replaced by ``F_g(c) = clamp(mix(ks, 1, (1-c)^5) - B c (1-c)^6, 0, 1)``
  with ``B`` from the tint (``B = 0`` for a white tint: plain Schlick);
* ``multiscatter`` (0/1): Cycles' energy compensation
  ``C(w_out) = 1 + Fms (1 - E(mu_o)) / E(mu_o)``,
  ``Fms = Fss E_avg / (1 - Fss (1 - E_avg))`` on each GGX lobe, where ``E`` is the
  single-scattering GGX albedo (:func:`ggx_albedo`), ``E_avg = 2 int E mu dmu``
  and ``Fss`` the lobe's cosine-averaged Fresnel (the tint for a plain glossy
  lobe).  Like Cycles it depends on the outgoing direction only, so the BRDF is
  not reciprocal; the reflection operator still has norm max_w albedo(w) <= 1.

The layered BRDF, with ``D G2 / (4 cos_i cos_o)`` the untinted GGX lobe::

    f = (1 - g) kd / pi * W_d(w_out)
      + (1 - g) F_s(h.w_out) C_s(w_out) D G2 / (4 cos_i cos_o)
      + g       F_g(h.w_out) C_g(w_out) D G2 / (4 cos_i cos_o)          [1/sr]

    W_d(w_out) = clamp(1 - max_rgb A_s(w_out), 0, 1)   (capped so that albedo <= 1)

where ``A_s`` is Cycles' estimate of the layer's albedo (``closure_layering_weight``
with ``bsdf_microfacet_estimate_albedo``): ``A_s = [E C_s if multiscatter else 1]
mix(f0, 1, S(mu_o))``, ``S`` the mean of the Fresnel interpolation factor over
visible normals (``ggx_gen_schlick_ior_s``), computed here by quadrature instead
of Cycles' 16^3 table.  :func:`principled_material` maps a Principled BSDF's
inputs onto these parameters.
"""
from __future__ import annotations

import numpy as np

from .microfacet import (f0_from_ior, fresnel_dielectric_fss, fresnel_f82_fss, fresnel_f82_tint_b,
                         ggx_fresnel_moments, ior_from_f0)

MU_TABLE = 65               # samples of cos(theta_out) in the directional-albedo tables


def interp_mu(table, mu):
    """Linear interpolation of a table on the :data:`MU_TABLE` grid of mu in [0, 1];
    ``table`` (K,) or (K, C) gives (N,) or (N, C)."""
    grid = np.linspace(0.0, 1.0, len(table))
    if table.ndim == 1:
        return np.interp(mu, grid, table)
    return np.stack([np.interp(mu, grid, table[:, k]) for k in range(table.shape[1])], axis=1)


def layer_tables(alpha, eta, glossy_fresnel, multiscatter, ks, tint, g, kd) -> dict:
    """Tables in mu_o = cos_out (the :data:`MU_TABLE` grid) of one layered material (GGX
    ``alpha``, layer IOR ``eta`` (0: no layer), F82 conductor Fresnel on or off, multiscatter
    on or off, glossy color ``ks``, specular tint, glossy weight ``g``, diffuse color ``kd``):
    ``glossy_albedo`` (K, 3) = C_g int F_g lobe cos_i (without g), ``glossy_scale``
    (K, 3) = C_g, ``layer_albedo`` (K, 3) = C_s int F_s lobe cos_i (without 1 - g),
    ``layer_scale`` (K, 3) = C_s, ``diffuse_weight`` (K,) = W_d; one quadrature
    (:func:`~raybundle.scene.microfacet.ggx_fresnel_moments`) each."""
    fres, ms = glossy_fresnel, multiscatter
    mu = np.linspace(0.0, 1.0, MU_TABLE)
    f82_b = fresnel_f82_tint_b(ks, tint) if fres else np.zeros(3)
    q = ggx_fresnel_moments(alpha, np.maximum(mu, 1e-4), eta=eta, f82=(ks, f82_b) if fres else None)
    e = q["E"]
    y = 2.0 * mu * e                                  # E_avg = int_0^1 2 mu E(mu) dmu, trapezoid rule
    e_avg = float(np.sum(0.5 * (y[1:] + y[:-1]) * np.diff(mu)))

    def scale(fss):                                   # Cycles' microfacet_ggx_preserve_energy
        if not ms:
            return np.ones((len(mu), 3))
        fms = fss * e_avg / (1.0 - fss * (1.0 - e_avg))
        return 1.0 + fms[None, :] * ((1.0 - e) / e)[:, None]

    t = {"f82_f0": ks, "f82_b": f82_b}
    if fres:
        t["glossy_scale"] = scale(fresnel_f82_fss(ks, f82_b))
        t["glossy_albedo"] = t["glossy_scale"] * q["F82"]
    else:
        t["glossy_scale"] = scale(ks)
        t["glossy_albedo"] = t["glossy_scale"] * e[:, None] * ks[None, :]
    if eta > 1.0:
        f0_real = f0_from_ior(eta)
        f0 = np.clip(f0_real * tint, 0.0, 1.0)
        s_ss = np.clip((fresnel_dielectric_fss(eta) - f0_real) / (1.0 - f0_real), 0.0, 1.0)
        t["layer_f0"] = f0
        t["layer_scale"] = scale(f0 + (1.0 - f0) * s_ss)
        t["layer_albedo"] = t["layer_scale"] * (f0[None, :] * e[:, None] + (1.0 - f0[None, :]) * q["Ed"][:, None])
        estimate = f0[None, :] + (1.0 - f0[None, :]) * q["Sd"][:, None]      # bsdf_microfacet_estimate_albedo
        if ms:
            estimate = estimate * (e[:, None] * t["layer_scale"])          # sc->weight carries E C_s
        w_d = np.clip(1.0 - estimate.max(axis=1), 0.0, 1.0)
        # Cycles' estimate can let the total albedo exceed 1 by up to 0.5% at grazing
        # angles for a white base; cap W_d so that albedo <= 1 (the iteration's contraction).
        kdd = (1.0 - g) * kd
        if np.any(kdd > 0):
            rest = (1.0 - g) * t["layer_albedo"] + g * t["glossy_albedo"]
            cap = ((1.0 - rest)[:, kdd > 0] / kdd[kdd > 0]).min(axis=1)
            w_d = np.clip(np.minimum(w_d, cap), 0.0, 1.0)
        t["diffuse_weight"] = w_d
    else:
        t["layer_f0"] = np.zeros(3)
        t["layer_scale"] = np.zeros((len(mu), 3))
        t["layer_albedo"] = np.zeros((len(mu), 3))
        t["diffuse_weight"] = np.ones(len(mu))
    return t


def principled_material(base_color, metallic=0.0, roughness=0.5, ior=1.5, specular_ior_level=0.5,
                        emission=(0.0, 0.0, 0.0), specular_tint=(1.0, 1.0, 1.0),
                        distribution="MULTI_GGX", name="principled") -> dict:
    """A :meth:`MaterialTable.from_list` spec for Blender's Principled BSDF (Cycles 5.0).

    Parameters are the node's inputs: ``base_color`` (RGB), ``metallic``,
    ``roughness``, ``ior``, ``specular_ior_level``, ``specular_tint`` (RGB),
    ``emission`` = Emission Color x Emission Strength [W m^-2 sr^-1] and the node's
    ``distribution`` ("MULTI_GGX", Blender's default, or "GGX").  Mapping (as in
    Cycles' ``svm_node_closure_bsdf``):

    * diffuse = base color, glossy = base color (the conductor's F0),
      glossy_weight = metallic, glossy_fresnel = 1 (F82 tint), roughness = roughness;
    * specular_ior = eta with ``F0(eta) = F0(ior) * 2 * specular_ior_level``
      (eta = ior at level 0.5; no layer when eta = 1, i.e. level 0); an ``ior < 1``
      is mapped to 1/eta (the reflection of a dielectric seen from outside);
    * specular_tint = tint (layer f0 multiplier and F82 tint), multiscatter =
      distribution is "MULTI_GGX".

    Ignored (the exporter warns): coat, sheen, transmission, subsurface, diffuse
    roughness, anisotropy, thin film, alpha, normal maps.  Base color and tint are
    clamped to [0, 1] (Cycles clamps the conductor's F0 there too).

    Measured against Cycles (a plane under a white world, radiance = directional albedo),
    the mapping matches it up to Cycles' own lookup-table interpolation, where a plain
    Mix(Diffuse, Glossy GGX) with fac = metallic + (1 - metallic) F0, or even the best
    constant Mix per material, is far off, most for dark bases (the figures: docs/benchmarks.md,
    'Measured choices behind the defaults').  ``tests/test_principled.py``
    re-measures a dozen of these points.
    """
    base = np.clip(np.asarray(base_color, float)[:3], 0.0, 1.0)
    metallic = float(np.clip(metallic, 0.0, 1.0))
    ior = max(float(ior), 1e-5)
    f0 = f0_from_ior(ior)
    eta = ior
    if specular_ior_level != 0.5:
        f0 *= 2.0 * max(float(specular_ior_level), 0.0)
        eta = float(ior_from_f0(f0))
        if ior < 1.0:
            eta = 1.0 / eta
    if eta < 1.0:
        eta = 1.0 / eta
    if abs(eta - 1.0) < 1e-7:
        eta = 0.0                                         # Cycles skips the specular layer
    glossy = metallic > 0 or eta > 0                      # else plain Lambert (level 0, not metallic)
    return dict(name=name, diffuse=tuple(base), glossy=tuple(base), glossy_weight=metallic,
                roughness=float(np.clip(roughness, 0.0, 1.0)), glossy_fresnel=int(glossy),
                specular_ior=eta, specular_tint=tuple(np.clip(np.asarray(specular_tint, float)[:3], 0.0, 1.0)),
                multiscatter=int(glossy and distribution == "MULTI_GGX"),
                emission=tuple(np.maximum(np.asarray(emission, float)[:3], 0.0)))
