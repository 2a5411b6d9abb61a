"""Transmission: light through glass, refraction and transparent surfaces.

A material's ``transmission`` share ``w_t`` (:class:`~raybundle.scene.materials.MaterialTable`)
is a smooth dielectric interface of relative IOR ``eta`` (outside -> inside through the
triangle's front, as Cycles' Glass BSDF reads ``backfacing``); the material's reflectances
are the opaque rest's, already weighted.  The interface reflects the Fresnel share
``F(cos, eta)`` (:func:`~raybundle.scene.microfacet.fresnel_dielectric_cos`, 1 under total
internal reflection) tinted ``transmission_reflection`` and refracts the rest tinted
``transmission_color``; a Refraction BSDF (``transmission_fresnel`` 0) refracts it all but
what is totally reflected, which it absorbs; ``eta`` = 1 is a Transparent BSDF: no bend, no
reflection.  Cycles scales no radiance by ``eta^2`` across an interface; neither does this.

It is used in two ways:

* **straight on** (:func:`pass_probability`), for the light the bundles, shadow rays and
  gathers carry (:class:`~raybundle.tracing.visibility.RayTracer`): a ray meeting the
  surface at ``cos`` passes on unbent with probability
  ``P = w_t T(cos) mean(transmission_color)``, ``T = 1 - F(cos, max(eta, 1 / eta))`` (1 for
  a Refraction BSDF), and otherwise stops there.  Through a pane (two parallel
  interfaces whose bends cancel) this is exact in expectation up to the light reflected
  between its faces (``R^2 / (1 - R^2)``, under 0.2% at ``eta`` 1.5 below 60 degrees) and
  the shift of the line by the pane's thickness; a tint is carried as its mean; a curved
  glass object casts its transmittance as a soft shadow where Cycles focuses a caustic.
  What a ray does not pass it meets (:meth:`~raybundle.tracing.visibility.RayTracer.first_hit`):
  the patches of a transmissive surface hold the light it reflects, as a cut-out's
  (:func:`solver_share`): spread over the hemisphere, where the eye sees it mirrored.  What it
  reflects of the first-shot lights' direct light is a caustic (a lamp's image in the pane,
  thrown on the room): left out.  The glossy lobes' eye paths that stop there go on mirrored
  with probability ``w_t F / (1 - P)`` (:func:`mirror_probability`,
  :meth:`~raybundle.imaging.glossy_paths.GlossyEyePaths.trace`), so a floor sees the room in a
  balustrade, not the light the pane's patches spread.
* **by Fresnel** (:func:`scatter`), for the eye's paths (the image): at each interface the
  eye path is reflected with probability ``F`` (weight the reflection tint) or refracted
  (weight the refraction tint), until Cycles' transmission or glossy bounces are spent
  (``transmission_depth``, ``glossy_depth``), as Cycles
  samples a smooth Glass BSDF.  A rough interface (``transmission_roughness`` r, GGX of
  ``alpha = r^2``, single scattering as Cycles' GGX Glass BSDF) first draws a microfacet normal
  ``h`` from those visible along the path and then reflects or refracts about ``h`` by
  ``F(h)``, weighted ``G2 / G1`` (Heitz 2018; 0 where the new direction falls on the wrong side
  of the surface): the eye sees through frosted glass blurred.  The light the bundles and
  shadow rays carry still passes a rough interface straight on (its shadows are not blurred).
"""
from __future__ import annotations

import numpy as np

from .microfacet import fresnel_dielectric_cos, fresnel_dielectric_fss, sample_ggx_visible_normal, smith_g2_over_g1


def _fresnel(materials, mat, cos):
    """(N,) the interface's Fresnel reflectance ``F(|cos|, max(eta, 1 / eta))`` for materials
    ``mat`` (N,), 0 for a Refraction BSDF (no Fresnel reflection)."""
    eta = np.asarray(materials.transmission_ior, float)[mat]
    f = fresnel_dielectric_cos(np.abs(cos), np.maximum(eta, 1.0 / eta))
    return np.where(np.asarray(materials.transmission_fresnel)[mat] == 1, f, 0.0)


def pass_probability(materials, mat, cos):
    """(N,) probability that a ray meeting materials ``mat`` (N,) at ``|cos|`` (N,) (of its
    angle to the surface normal) passes straight through (module docstring)."""
    t = 1.0 - _fresnel(materials, mat, cos)
    return np.asarray(materials.transmission, float)[mat] * t * materials.transmission_color[mat].mean(axis=1)


def mirror_probability(materials, mat, cos):
    """(N,) probability ``w_t F`` that a ray meeting materials ``mat`` (N,) at ``|cos|`` (N,) is
    reflected by the interface (0 for a Refraction BSDF): the share of the hits
    :func:`pass_probability` keeps that an eye path follows as a mirror's (:func:`scatter`)."""
    return np.asarray(materials.transmission, float)[mat] * _fresnel(materials, mat, cos)


def scatter(materials, mat, travel, geometric, shading, u):
    """One event of eye paths that meet transmissive materials ``mat`` (N,) travelling along
    ``travel`` (N, 3) at triangles of normal ``geometric`` (N, 3), shaded with ``shading``
    (N, 3) (either orientation), for uniforms ``u`` (N, 4) (the last two draw a rough
    interface's microfacet normal; (N, 2) where no interface is rough).

    With probability ``w_t`` the path meets the interface and goes on, reflected with
    probability ``F`` (weight the reflection tint) or refracted (weight the refraction tint;
    a Refraction BSDF always refracts, weight 0 under total internal reflection); otherwise it stops on the opaque rest, weighted ``1 / (1 - w_t)``.
    As in Cycles, a direction on the wrong side of the face (``geometric``) or of the shading
    normal ends the path (weight 0): a reflection that does not stay, a refraction that does not
    cross.
    Returns ``(on, direction, weight)``: (N,) bool, the new directions (N, 3) where ``on``
    and the weights (N, 3) the path's throughput is multiplied by."""
    m = np.asarray(mat)
    w_t = np.asarray(materials.transmission, float)[m]
    on = u[:, 0] * (1.0 - 1e-12) < w_t
    weight = np.ones((len(m), 3))
    stop = ~on
    weight[stop] /= np.maximum(1.0 - w_t[stop], 1e-12)[:, None]
    d = np.asarray(travel, float)
    n = np.asarray(shading, float)
    n = np.where((np.einsum("ij,ij->i", n, d) < 0)[:, None], n, -n)          # facing the path
    g = np.asarray(geometric, float)
    entering = np.einsum("ij,ij->i", g, d) < 0
    eta = np.asarray(materials.transmission_ior, float)[m]
    eta = np.where(entering, eta, 1.0 / eta)
    alpha = np.asarray(materials.transmission_roughness, float)[m] ** 2
    rough = np.nonzero(on & (alpha > 0))[0]
    surface = n
    if len(rough):                  # reflect or refract about a visible microfacet normal
        n = n.copy()
        n[rough] = sample_ggx_visible_normal(alpha[rough], surface[rough], -d[rough], u[rough, 2:4])
    cos_i = np.clip(-np.einsum("ij,ij->i", n, d), 0.0, 1.0)
    f = fresnel_dielectric_cos(cos_i, eta)
    fresnel = np.asarray(materials.transmission_fresnel)[m] == 1
    reflect = np.where(fresnel, u[:, 1] < f, f >= 1.0)
    out = d + 2.0 * cos_i[:, None] * n
    sin2_t = (1.0 - cos_i * cos_i) / (eta * eta)
    cos_t = np.sqrt(np.maximum(1.0 - sin2_t, 0.0))
    refr = d / eta[:, None] + (cos_i / eta - cos_t)[:, None] * n
    out = np.where(reflect[:, None], out, refr)
    out /= np.linalg.norm(out, axis=1, keepdims=True)
    tint = np.where(reflect[:, None], materials.transmission_reflection[m], materials.transmission_color[m])
    # a Refraction BSDF's TIR; and, as Cycles samples, a direction on the wrong side of the face or
    # of the shading normal (a refraction about a normal turned far from the face's that stays on
    # its side, a reflection that goes into it): reflected stays, refracted crosses, or the path ends
    cos_g, cos_n = np.einsum("ij,ij->i", g, out) * np.where(entering, 1.0, -1.0), np.einsum("ij,ij->i", surface, out)
    absorbed = (~fresnel & reflect) | np.where(reflect, (cos_g <= 0) | (cos_n <= 0), (cos_g >= 0) | (cos_n >= 0))
    tint = np.where(absorbed[:, None], 0.0, tint)
    if len(rough):
        cos_o = np.einsum("ij,ij->i", surface[rough], -d[rough])
        tint[rough] *= smith_g2_over_g1(alpha[rough], cos_o, cos_n[rough])[:, None]
    weight[on] *= tint[on]
    return on, out, weight


def solver_share(materials):
    """Per material, what the solver's patches of a transmissive surface take: ``(kept (M,),
    reflectance (M, 3), mirror (M, 3))``, ``mirror`` the part of the reflectance that is the
    interface's (``w_t F_avg`` times the reflection tint, over ``kept``).

    ``kept`` = the cosine-weighted mean over the hemisphere of the probability that a ray
    stops there, ``1 - w_t (1 - F_avg) mean(tint)`` (``F_avg`` = 2 int F mu dmu,
    :func:`~raybundle.scene.microfacet.fresnel_dielectric_fss`; 0 for a Refraction BSDF): the
    patch's receiving area is scaled by it, as by a cut-out's coverage, so its irradiance is
    the light arriving on the surface.  The patch sends only along the lines that stop there
    (a share ``kept`` of them), so the diffuse reflectance that gives the power the surface
    reflects (its opaque rest's ``kd`` plus the interface's ``w_t F_avg`` times the
    reflection tint) is that sum over ``kept``, at most 1.  In a uniform light field
    (the furnace) a white glass then leaves every radiance as it was."""
    eta = np.asarray(materials.transmission_ior, float)
    w = np.asarray(materials.transmission, float)
    f_avg = np.where(np.asarray(materials.transmission_fresnel) == 1,
                     fresnel_dielectric_fss(np.maximum(eta, 1.0 / eta)), 0.0)
    kept = 1.0 - w * (1.0 - f_avg) * materials.transmission_color.mean(axis=1)
    kept = np.maximum(kept, 1e-6)
    mirror = (w * f_avg)[:, None] * materials.transmission_reflection / kept[:, None]
    reflected = materials.diffuse_reflectance / kept[:, None] + mirror
    return kept, np.clip(reflected, 0.0, 1.0), np.minimum(mirror, 1.0)
