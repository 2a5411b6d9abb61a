"""Materials: Lambertian, Blender's Glossy BSDF (GGX), their mix, and emission.

Conventions (shared with the whole package):

* ``w_in`` is the *travel* direction of the incoming light (it points **towards**
  the surface), ``w_out`` the direction the reflected light leaves in (it points
  **away** from the surface).  Both are unit vectors in world space.
* Surfaces are one-sided: light is reflected only when it arrives at the front
  (``n . w_in < 0``) and leaves through the front (``n . w_out > 0``); otherwise
  ``f = 0``.  The back side of every patch is a black absorber.

The BRDF of material ``m`` is the Blender node set-up
``Mix Shader(Fac = glossy_weight, Diffuse BSDF(diffuse), Glossy BSDF(GGX, glossy, roughness))``::

    f(w_in, w_out) = (1 - g) * kd / pi
                   + g * ks * D(h) * G2(w_i, w_out) / (4 cos_i cos_o)     [1/sr]

with ``w_i = -w_in``, ``h = normalize(w_i + w_out)``, the GGX normal distribution
``D(h) = a^2 / (pi ((n.h)^2 (a^2 - 1) + 1)^2)``, ``a = roughness^2`` (Blender's
mapping) and the height-correlated Smith term
``G2 = 1 / (1 + Lambda(w_i) + Lambda(w_out))``,
``Lambda(w) = (sqrt(1 + a^2 tan^2 theta) - 1) / 2``.  No Fresnel term: Blender's
Glossy BSDF has none; the tint ``ks`` multiplies the lobe.

Emission is one-sided radiance [W m^-2 sr^-1] per RGB channel.  For the analytic
glossy furnace a material may also emit ``c * (1 - albedo(w_out))``
(``emission_albedo_complement = c``); see :mod:`raybundle.scene.builtin`.

Blender's Principled BSDF is a layered form of this model (four optional parameters,
:mod:`raybundle.scene.principled`); with those off a material is exactly the Mix above.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..util import compiled
from . import compiled_bsdf
from .microfacet import (dielectric_layer_fresnel, fresnel_f82, ggx_albedo, ggx_distribution, ggx_lobe,
                         sample_ggx_reflection, smith_lambda)
from .principled import MU_TABLE, interp_mu, layer_tables

#: Smallest GGX alpha evaluated; below it the lobe is a near-mirror that stochastic
#: iteration cannot resolve (documented failure mode: fireflies / black highlights).
MIN_ALPHA = 1e-3
#: glossy lobes below this GGX roughness count as near-mirrors (:mod:`raybundle.app.auto`,
#: :mod:`raybundle.methods.ray_bundle_walk`)
NEAR_MIRROR_ROUGHNESS = 0.1
#: the transmission parameters and their defaults (an opaque surface)
_TRANSMISSION_DEFAULTS = {"transmission": 0.0, "transmission_ior": 1.0, "transmission_color": (1.0, 1.0, 1.0),
                          "transmission_reflection": (1.0, 1.0, 1.0), "transmission_fresnel": 1,
                          "translucent": (0.0, 0.0, 0.0), "transmission_roughness": 0.0}


@dataclass
class MaterialTable:
    """Per-material parameters as arrays indexed by material id.

    Attributes
    ----------
    names : list[str]
    diffuse : (M, 3) float  Diffuse BSDF color (reflectance, unitless, <= 1).
    glossy : (M, 3) float   Glossy BSDF color (tint, <= 1).
    roughness : (M,) float  Glossy BSDF roughness in [0, 1]; alpha = roughness^2.
    glossy_weight : (M,) float  Mix Shader factor: 0 = diffuse only, 1 = glossy only.
    emission : (M, 3) float  one-sided emitted radiance [W m^-2 sr^-1].
    emission_albedo_complement : (M, 3) float  c: adds c * (1 - albedo(w_out)) to
        the emission (the generalized furnace emitter); normally 0.
    specular_ior : (M,) float  eta of a dielectric GGX layer over the diffuse lobe
        (Principled BSDF); 0 (default) or 1 = no layer.
    specular_tint : (M, 3) float  f0 multiplier of that layer and F82 tint of a
        conductor glossy lobe, in [0, 1]; default 1.
    glossy_fresnel : (M,) int  0 (default) = Glossy BSDF (no Fresnel, tint ks);
        1 = F82-tint conductor Fresnel with F0 = ks (Principled metallic).
    multiscatter : (M,) int  1 = Cycles' Multiscatter GGX energy compensation on
        the GGX lobes; 0 (default) = single scattering.
    transmission : (M,) float  the share of the surface that is a smooth dielectric
        interface (Glass / Refraction / Transparent BSDF, Principled Transmission), in [0, 1];
        0 (default) = opaque.  The reflectances above are the rest's, already weighted
        (:mod:`raybundle.scene.transmission`).
    transmission_ior : (M,) float  its IOR (outside -> inside through the front); 1 = no
        bending and no Fresnel (Transparent BSDF).
    transmission_color : (M, 3) float  the tint of the light it refracts, in [0, 1].
    transmission_reflection : (M, 3) float  the tint of the light it reflects (Fresnel).
    transmission_fresnel : (M,) int  1 (default): refraction takes 1 - F (Glass BSDF,
        Principled); 0: all that is not totally reflected (Refraction BSDF).
    translucent : (M, 3) float  kt, Blender's Translucent BSDF: light arriving on one side
        leaves the other, ``f_t = kt / pi`` for ``w_in`` and ``w_out`` on opposite sides of
        the surface (light through a curtain or a lampshade); ``(1 - g) kd + kt <= 1``.
    transmission_roughness : (M,) float  the interface's GGX roughness (alpha its square) in
        [0, 1] for the eye's paths (frosted glass); 0 (default) = smooth.
    See the module docstring for the equations.
    """

    names: list
    diffuse: np.ndarray
    glossy: np.ndarray
    roughness: np.ndarray
    glossy_weight: np.ndarray
    emission: np.ndarray
    emission_albedo_complement: np.ndarray
    specular_ior: np.ndarray = None
    specular_tint: np.ndarray = None
    glossy_fresnel: np.ndarray = None
    multiscatter: np.ndarray = None
    transmission: np.ndarray = None
    transmission_ior: np.ndarray = None
    transmission_color: np.ndarray = None
    transmission_reflection: np.ndarray = None
    transmission_fresnel: np.ndarray = None
    translucent: np.ndarray = None
    transmission_roughness: np.ndarray = None
    _albedo_tables: dict = field(default_factory=dict, repr=False, compare=False)

    def __post_init__(self):
        n = len(self.names)
        if self.specular_ior is None:
            self.specular_ior = np.zeros(n)
        if self.specular_tint is None:
            self.specular_tint = np.ones((n, 3))
        if self.glossy_fresnel is None:
            self.glossy_fresnel = np.zeros(n, dtype=np.int64)
        if self.multiscatter is None:
            self.multiscatter = np.zeros(n, dtype=np.int64)
        for k, default in _TRANSMISSION_DEFAULTS.items():
            if getattr(self, k) is None:
                setattr(self, k, np.array([default] * n, float if k != "transmission_fresnel" else np.int64)
                        .reshape((n,) + np.shape(default)))

    @classmethod
    def from_list(cls, specs):
        """Build from a list of dicts with keys ``name``, ``diffuse``, ``glossy``,
        ``roughness``, ``glossy_weight``, ``emission``, ``emission_albedo_complement``,
        ``specular_ior``, ``specular_tint``, ``glossy_fresnel``, ``multiscatter``, and the
        ``transmission*`` keys (all optional; :func:`principled_material` makes such a dict from a Principled BSDF)."""
        n = len(specs)
        t = cls(
            names=[s.get("name", f"material_{k}") for k, s in enumerate(specs)],
            diffuse=np.zeros((n, 3)),
            glossy=np.zeros((n, 3)),
            roughness=np.full(n, 0.5),
            glossy_weight=np.zeros(n),
            emission=np.zeros((n, 3)),
            emission_albedo_complement=np.zeros((n, 3)),
        )
        for k, s in enumerate(specs):
            t.diffuse[k] = s.get("diffuse", (0.0, 0.0, 0.0))
            t.glossy[k] = s.get("glossy", (0.0, 0.0, 0.0))
            t.roughness[k] = s.get("roughness", 0.5)
            t.glossy_weight[k] = s.get("glossy_weight", 0.0)
            t.emission[k] = s.get("emission", (0.0, 0.0, 0.0))
            t.emission_albedo_complement[k] = s.get("emission_albedo_complement", (0.0, 0.0, 0.0))
            t.specular_ior[k] = s.get("specular_ior", 0.0)
            t.specular_tint[k] = s.get("specular_tint", (1.0, 1.0, 1.0))
            t.glossy_fresnel[k] = int(s.get("glossy_fresnel", 0))
            t.multiscatter[k] = int(bool(s.get("multiscatter", 0)))
            for key, default in _TRANSMISSION_DEFAULTS.items():
                getattr(t, key)[k] = s.get(key, default)
        return t

    def __len__(self):
        return len(self.names)

    # ------------------------------------------------------------------ queries
    @property
    def alpha(self) -> np.ndarray:
        """GGX alpha = roughness^2 (Blender), clamped to :data:`MIN_ALPHA`."""
        return np.maximum(np.asarray(self.roughness, float) ** 2, MIN_ALPHA)

    @property
    def has_layer(self) -> np.ndarray:
        """(M,) bool: a dielectric specular layer over the diffuse lobe (``specular_ior > 1``)."""
        return np.asarray(self.specular_ior, float) > 1.0

    @property
    def is_layered(self) -> np.ndarray:
        """(M,) bool: the material uses any Principled feature (layer, conductor
        Fresnel or multiscatter); the others are exactly the plain Mix."""
        return self.has_layer | (np.asarray(self.glossy_fresnel) != 0) | (np.asarray(self.multiscatter) != 0)

    @property
    def is_glossy(self) -> np.ndarray:
        """(M,) bool: the material has a glossy lobe that reflects light (the Glossy
        lobe, or the dielectric specular layer of a Principled material)."""
        conductor = np.asarray(self.glossy_fresnel) != 0
        lobe = (self.glossy_weight > 0) & (np.any(self.glossy > 0, axis=1) | conductor)
        return lobe | (self.has_layer & (self.glossy_weight < 1))

    @property
    def is_mirror(self) -> np.ndarray:
        """(M,) bool: the surface is a sharp mirror and nothing else: a glossy lobe of weight 1
        (a Glossy BSDF, or a Principled BSDF's metal) at the smallest roughness (alpha at
        :data:`MIN_ALPHA`), nothing diffuse, translucent, transmissive or emitting.  The eye's
        paths are reflected there as at glass
        (:meth:`~raybundle.imaging.eye_rays.EyeRays.through_interfaces`)."""
        plain = (self.glossy_weight >= 1.0) & (self.alpha <= MIN_ALPHA)
        rest = np.any(self.diffuse_reflectance > 0, axis=1) | np.any(self.translucent > 0, axis=1)
        return plain & self.is_glossy & ~rest & ~self.transmits & ~self.is_emitter

    @property
    def transmits(self) -> np.ndarray:
        """(M,) bool: part of the surface is a dielectric interface light passes
        (:mod:`raybundle.scene.transmission`)."""
        return np.asarray(self.transmission, float) > 0

    @property
    def is_emitter(self) -> np.ndarray:
        return np.any(self.emission > 0, axis=1) | np.any(self.emission_albedo_complement > 0, axis=1)

    @property
    def reflects(self) -> np.ndarray:
        """(M,) bool: the material reflects some light (a diffuse or a glossy lobe) or lets it
        through diffusely (translucent)."""
        return np.any(self.diffuse_reflectance > 0, axis=1) | self.is_glossy | np.any(self.translucent > 0, axis=1)

    @property
    def diffuse_reflectance(self) -> np.ndarray:
        """(M, 3) ``(1 - g) * kd``: the albedo of the diffuse lobe."""
        return (1.0 - self.glossy_weight)[:, None] * self.diffuse

    def validate(self):
        """Raise ValueError on parameters that break energy conservation or are not finite."""
        arrays = {k: np.asarray(getattr(self, k), float) for k in (
            "diffuse", "glossy", "roughness", "glossy_weight", "emission", "emission_albedo_complement",
            "specular_ior", "specular_tint", "glossy_fresnel", "multiscatter", *_TRANSMISSION_DEFAULTS)}
        for k, a in arrays.items():
            bad = ~np.isfinite(a)
            if bad.any():
                m = int(np.nonzero(bad.reshape(len(a), -1).any(axis=1))[0][0])
                raise ValueError(f"material {self.names[m]!r}: {k} is not finite")
            if (a < 0).any():
                m = int(np.nonzero((a < 0).reshape(len(a), -1).any(axis=1))[0][0])
                raise ValueError(f"material {self.names[m]!r}: {k} is negative")
        arrays["diffuse and translucent"] = arrays["diffuse"] * (1 - arrays["glossy_weight"])[:, None] + arrays[
            "translucent"]
        for k in ("diffuse", "glossy", "specular_tint", "transmission_color", "transmission_reflection",
                  "translucent", "diffuse and translucent"):
            over = arrays[k] > 1.0
            if over.any():
                m = int(np.nonzero(over.any(axis=1))[0][0])
                raise ValueError(
                    f"material {self.names[m]!r}: {k} color {color_text(arrays[k][m])} has a component > 1 "
                    "(albedo > 1 creates energy; the iteration would diverge)")
        if (arrays["glossy_weight"] > 1).any() or (arrays["roughness"] > 1).any():
            m = int(np.nonzero((arrays["glossy_weight"] > 1) | (arrays["roughness"] > 1))[0][0])
            raise ValueError(f"material {self.names[m]!r}: glossy_weight and roughness must lie in [0, 1]")
        eta = arrays["specular_ior"]
        if ((eta > 0) & (eta < 1)).any():
            m = int(np.nonzero((eta > 0) & (eta < 1))[0][0])
            raise ValueError(f"material {self.names[m]!r}: specular_ior {eta[m]} must be 0 (no layer) or >= 1")
        rough = arrays["transmission_roughness"]
        if ((rough < 0) | (rough > 1)).any():
            m = int(np.nonzero((rough < 0) | (rough > 1))[0][0])
            raise ValueError(f"material {self.names[m]!r}: transmission_roughness must lie in [0, 1]")
        if (arrays["transmission"] > 1).any() or (arrays["transmission_ior"] <= 0).any():
            m = int(np.nonzero((arrays["transmission"] > 1) | (arrays["transmission_ior"] <= 0))[0][0])
            raise ValueError(f"material {self.names[m]!r}: transmission must lie in [0, 1] and its IOR be positive")
        for k in ("glossy_fresnel", "multiscatter", "transmission_fresnel"):
            bad = (arrays[k] != 0) & (arrays[k] != 1)
            if bad.any():
                m = int(np.nonzero(bad)[0][0])
                raise ValueError(f"material {self.names[m]!r}: {k} must be 0 or 1")

    # --------------------------------------------------------------- evaluation
    def brdf(self, mat, normal, w_in, w_out, diffuse=True, glossy=True, diffuse_scale=None) -> np.ndarray:
        """BRDF value f(w_in, w_out) [1/sr], RGB: 0 where the light comes from below ``normal``,
        the glossy lobes also where ``w_out`` lies below it (Cycles' Diffuse BSDF takes a smooth
        normal that faces away from the eye as it is: :mod:`raybundle.scene.shading`).

        Parameters
        ----------
        mat : (N,) int  material ids
        normal : (N, 3) float  unit front normals
        w_in : (N, 3) or (3,) float  travel direction of the incoming light
        w_out : (N, 3) or (3,) float  outgoing direction
        diffuse, glossy : bool  which lobes to include
        diffuse_scale : (N, 3) float or None  texture modulation of the diffuse
            reflectance at each point (:mod:`raybundle.scene.textures`)

        Returns
        -------
        (N, 3) float
        """
        mat = np.asarray(mat)
        normal = np.asarray(normal, float)
        w_i = -np.broadcast_to(np.asarray(w_in, float), normal.shape)
        w_o = np.broadcast_to(np.asarray(w_out, float), normal.shape)
        if compiled.use():
            return compiled_bsdf.brdf(self, mat, normal, w_i, w_o, diffuse, glossy, diffuse_scale)
        cos_i = np.einsum("ij,ij->i", normal, w_i)
        cos_o = np.einsum("ij,ij->i", normal, w_o)
        front = (cos_i > 0) & (cos_o > 0)
        out = np.zeros((len(mat), 3))
        lay = self.is_layered[mat]
        if diffuse:
            out += self.diffuse_reflectance[mat] / np.pi
            if diffuse_scale is not None:
                out *= diffuse_scale
            if lay.any():
                out[lay] *= self.diffuse_weight(mat[lay], cos_o[lay])
        if glossy:
            g = self.glossy_weight[mat]
            sel = front & (g > 0) & ~lay
            if sel.any():
                lobe = ggx_lobe(self.alpha[mat[sel]], normal[sel], w_i[sel], w_o[sel],
                                cos_i[sel], cos_o[sel])
                out[sel] += (g[sel] * lobe)[:, None] * self.glossy[mat[sel]]
            sel = front & lay
            if sel.any():
                lobe = ggx_lobe(self.alpha[mat[sel]], normal[sel], w_i[sel], w_o[sel],
                                cos_i[sel], cos_o[sel])
                h = w_i[sel] + w_o[sel]
                h /= np.linalg.norm(h, axis=1, keepdims=True) + 1e-300
                c = np.einsum("ij,ij->i", h, w_o[sel])
                out[sel] += lobe[:, None] * self._glossy_factor(mat[sel], c, cos_o[sel])
        out[cos_i <= 0] = 0.0        # a diffuse lobe whatever side the viewer is on (Cycles')
        return out

    def albedo(self, mat, cos_out, diffuse=True, glossy=True) -> np.ndarray:
        """Directional albedo a(w_out) = integral of f(w_in, w_out) cos_i dw_in, RGB.

        By reciprocity this is also the hemispherical reflectance for light
        arriving from w_out.  The GGX part comes from a table in cos_out,
        integrated once per distinct alpha (:func:`ggx_albedo`, a quadrature worth caching:
        docs/benchmarks.md, 'Measured choices behind the defaults'), linearly interpolated.
        """
        mat = np.asarray(mat)
        mu = np.clip(np.asarray(cos_out, float), 0.0, 1.0)
        out = np.zeros((len(mat), 3))
        lay = self.is_layered[mat]
        if diffuse:
            out += self.diffuse_reflectance[mat]
            if lay.any():
                out[lay] *= self.diffuse_weight(mat[lay], mu[lay])
        if glossy:
            g = self.glossy_weight[mat]
            for m in np.unique(mat[(g > 0) & ~lay]):
                sel = mat == m
                out[sel] += (g[sel] * self._ggx_albedo_table(m)(mu[sel]))[:, None] * self.glossy[m]
            for m in np.unique(mat[lay]):
                sel = mat == m
                tab, gm = self._layer_table(m), float(self.glossy_weight[m])
                out[sel] += gm * interp_mu(tab["glossy_albedo"], mu[sel]) \
                    + (1.0 - gm) * interp_mu(tab["layer_albedo"], mu[sel])
        out[mu <= 0] = 0.0
        return out

    def diffuse_weight(self, mat, cos_out) -> np.ndarray:
        """(N, 3) factor W_d(w_out) on the diffuse lobe: the diffuse radiance leaving
        towards ``w_out`` is ``diffuse_weight * diffuse_reflectance / pi * E_irr``
        [W m^-2 sr^-1] for irradiance ``E_irr`` [W m^-2].

        1 for materials without a dielectric layer (every pre-Principled material);
        ``clamp(1 - max_rgb A_s(mu_o), 0, 1)`` for a layered one, ``A_s`` Cycles'
        estimate of the specular layer's directional albedo at ``mu_o = cos_out``
        (unitless; the diffuse lobe only sees the light the layer lets through
        towards the viewer, ``closure_layering_weight`` in Cycles), lowered where
        needed so that the total albedo stays <= 1 (Cycles' estimate lets a white
        base reach 1.004 at grazing angles).  Depends on
        the outgoing direction only, so a renderer can gather the diffuse
        irradiance view-independently and apply this factor at the end.
        """
        mat = np.asarray(mat)
        mu = np.clip(np.asarray(cos_out, float), 0.0, 1.0)
        out = np.ones((len(mat), 3))
        lay = self.has_layer[mat]
        for m in np.unique(mat[lay]):
            sel = mat == m
            out[sel] = interp_mu(self._layer_table(m)["diffuse_weight"], mu[sel])[:, None]
        return out

    def sample_glossy(self, mat, normal, w_out, u):
        """Importance-sample the glossy lobes (Glossy/metallic lobe and dielectric layer).

        Parameters: ``mat`` (N,) ids, ``normal`` (N, 3) unit front normals, ``w_out``
        (N, 3) or (3,) direction towards the viewer, ``u`` (N, 2) uniform numbers.

        Returns ``(w_i (N, 3), weight (N, 3))``: ``w_i`` points **towards** the light
        (the direction to trace), ``weight = f_glossy(w_i, w_out) cos_i / pdf(w_i)``
        RGB, unitless, with the tint, Fresnel, multiscatter factor and lobe weights
        included, so ``E[weight * L(w_i)]`` is the radiance [W m^-2 sr^-1] the glossy
        part reflects towards ``w_out``.  Half vectors are drawn from the normals
        visible from ``w_out`` (:func:`sample_ggx_reflection`); both lobes share the roughness,
        so one sample serves both.  For a plain material this is exactly
        ``glossy_weight * glossy * sample_ggx_reflection(alpha, ...)[1]``; weight 0
        where ``w_i`` falls below the surface.
        """
        mat = np.asarray(mat)
        normal = np.asarray(normal, float)
        w_out = np.broadcast_to(np.asarray(w_out, float), normal.shape)
        if compiled.use():
            return compiled_bsdf.sample_glossy(self, mat, normal, w_out, u)
        w_i, w = sample_ggx_reflection(self.alpha[mat], normal, w_out, u)
        weight = self.glossy_weight[mat][:, None] * self.glossy[mat] * w[:, None]
        lay = self.is_layered[mat] & (w > 0)
        if lay.any():
            h = w_i[lay] + w_out[lay]
            h /= np.linalg.norm(h, axis=1, keepdims=True) + 1e-300
            c = np.einsum("ij,ij->i", h, w_out[lay])
            cos_o = np.einsum("ij,ij->i", normal[lay], w_out[lay])
            weight[lay] = w[lay][:, None] * self._glossy_factor(mat[lay], c, cos_o)
        return w_i, weight

    def mirror_reflection(self, mat, normal, w_out):
        """The exact reflection of sharp mirrors ``mat`` (N,) (:attr:`is_mirror`) about unit
        ``normal`` (N, 3) towards ``w_out`` (N, 3): ``(w_i (N, 3), weight (N, 3))`` as
        :meth:`sample_glossy` returns them for the lobe's limit of zero roughness (the mirror
        direction, weighted by the tint and Fresnel there; 0 where ``w_out`` is below the
        surface), as Cycles treats a roughness of 0: its lobe at :data:`MIN_ALPHA` would spread
        a lamp seen in a bathroom mirror over its neighbouring pixels by its long tails."""
        mat = np.asarray(mat)
        normal = np.asarray(normal, float)
        w_out = np.asarray(w_out, float)
        cos_o = np.einsum("ij,ij->i", normal, w_out)
        w_i = 2.0 * cos_o[:, None] * normal - w_out
        weight = self.glossy_weight[mat][:, None] * self.glossy[mat]
        lay = np.nonzero(self.is_layered[mat])[0]
        if len(lay):
            weight[lay] = self._glossy_factor(mat[lay], cos_o[lay], cos_o[lay])
        return w_i, np.where((cos_o > 0)[:, None], weight, 0.0)

    def glossy_pdf(self, mat, normal, w_in, w_out):
        """Density [1/sr] with which :meth:`sample_glossy` draws ``w_in`` (N, 3), towards
        the light, for the viewer direction ``w_out`` (N, 3): ``G1(w_out) D(h) / (4 cos_out)``
        (visible normals, density ``G1 (h.w_out) D(h) / cos_out``, mirrored: Jacobian
        1 / (4 h.w_out)); 0 where either direction is below the surface."""
        if compiled.use():
            return compiled_bsdf.glossy_pdf(self, np.asarray(mat), normal, w_in, w_out)
        alpha = self.alpha[np.asarray(mat)]
        h, _, d = ggx_distribution(alpha, normal, w_in, w_out)
        h_o = np.einsum("ij,ij->i", h, w_out)
        cos_o = np.einsum("ij,ij->i", normal, w_out)
        ok = (np.einsum("ij,ij->i", normal, w_in) > 0) & (cos_o > 0) & (h_o > 0)
        g1 = 1.0 / (1.0 + smith_lambda(alpha, np.where(ok, cos_o, 1.0)))
        return np.where(ok, g1 * d / (4.0 * np.where(ok, cos_o, 1.0)), 0.0)

    def _glossy_factor(self, mat, c, cos_out):
        """(N, 3) ``g F_g(c) C_g(mu_o) + (1 - g) F_s(c) C_s(mu_o)`` of layered materials:
        what multiplies the untinted GGX lobe; ``c = h.w_out``."""
        mu = np.clip(cos_out, 0.0, 1.0)
        out = np.zeros((len(mat), 3))
        for m in np.unique(mat):
            sel = mat == m
            tab, gm = self._layer_table(m), float(self.glossy_weight[m])
            if gm > 0:
                if self.glossy_fresnel[m]:
                    f = fresnel_f82(c[sel], tab["f82_f0"], tab["f82_b"])
                else:
                    f = self.glossy[m][None, :]
                out[sel] += gm * f * interp_mu(tab["glossy_scale"], mu[sel])
            if self.has_layer[m] and gm < 1:
                f = dielectric_layer_fresnel(c[sel], float(self.specular_ior[m]), tab["layer_f0"])
                out[sel] += (1.0 - gm) * f * interp_mu(tab["layer_scale"], mu[sel])
        return out

    def emitted_radiance(self, mat, cos_out) -> np.ndarray:
        """One-sided emitted radiance Le(w_out) [W m^-2 sr^-1], RGB; 0 behind the surface."""
        mat = np.asarray(mat)
        cos_out = np.asarray(cos_out, float)
        le = self.emission[mat]           # fancy indexing: already a copy
        if np.any(self.emission_albedo_complement > 0):
            le += self.emission_albedo_complement[mat] * (1.0 - self.albedo(mat, cos_out))
        le[cos_out <= 0] = 0.0
        return le

    def _ggx_albedo_table(self, m):
        alpha = float(self.alpha[m])
        if alpha not in self._albedo_tables:
            mu = np.linspace(0.0, 1.0, MU_TABLE)
            a = ggx_albedo(alpha, np.maximum(mu, 1e-4))
            self._albedo_tables[alpha] = lambda x, mu=mu, a=a: np.interp(x, mu, a)
        return self._albedo_tables[alpha]

    def _layer_table(self, m):
        """:func:`~raybundle.scene.principled.layer_tables` of layered material m, one
        quadrature (worth caching) per distinct parameter set."""
        alpha = float(self.alpha[m])
        eta = float(self.specular_ior[m]) if self.has_layer[m] else 0.0
        fres, ms = int(self.glossy_fresnel[m]), int(self.multiscatter[m])
        ks = np.clip(np.asarray(self.glossy[m], float), 0.0, 1.0)
        tint = np.clip(np.asarray(self.specular_tint[m], float), 0.0, 1.0)
        g, kd = float(self.glossy_weight[m]), np.asarray(self.diffuse[m], float)
        key = ("layer", alpha, eta, tuple(ks), tuple(tint), fres, ms, g, tuple(kd))
        if key not in self._albedo_tables:
            self._albedo_tables[key] = layer_tables(alpha, eta, fres, ms, ks, tint, g, kd)
        return self._albedo_tables[key]


    # ------------------------------------------------------------------- io
    def to_arrays(self, prefix="material_") -> dict:
        return {prefix + "names": np.array(self.names, dtype=str),
                prefix + "diffuse": self.diffuse, prefix + "glossy": self.glossy,
                prefix + "roughness": self.roughness, prefix + "glossy_weight": self.glossy_weight,
                prefix + "emission": self.emission,
                prefix + "emission_albedo_complement": self.emission_albedo_complement,
                prefix + "specular_ior": np.asarray(self.specular_ior, float),
                prefix + "specular_tint": np.asarray(self.specular_tint, float),
                prefix + "glossy_fresnel": np.asarray(self.glossy_fresnel, np.int64),
                prefix + "multiscatter": np.asarray(self.multiscatter, np.int64),
                **{prefix + k: np.asarray(getattr(self, k)) for k in _TRANSMISSION_DEFAULTS}}

    @classmethod
    def from_arrays(cls, d, prefix="material_"):
        n = len(d[prefix + "names"])
        comp = d.get(prefix + "emission_albedo_complement")

        def opt(k, shape, dtype=float):                   # arrays added with the Principled model
            a = d.get(prefix + k)
            return None if a is None else np.asarray(a, dtype).reshape(shape)
        return cls(names=[str(s) for s in d[prefix + "names"]],
                   diffuse=np.asarray(d[prefix + "diffuse"], float).reshape(n, 3),
                   glossy=np.asarray(d[prefix + "glossy"], float).reshape(n, 3),
                   roughness=np.asarray(d[prefix + "roughness"], float).reshape(n),
                   glossy_weight=np.asarray(d[prefix + "glossy_weight"], float).reshape(n),
                   emission=np.asarray(d[prefix + "emission"], float).reshape(n, 3),
                   emission_albedo_complement=(np.zeros((n, 3)) if comp is None
                                               else np.asarray(comp, float).reshape(n, 3)),
                   specular_ior=opt("specular_ior", n), specular_tint=opt("specular_tint", (n, 3)),
                   glossy_fresnel=opt("glossy_fresnel", n, np.int64),
                   multiscatter=opt("multiscatter", n, np.int64),
                   **{k: opt(k, (n,) + np.shape(v), np.int64 if k == "transmission_fresnel" else float)
                      for k, v in _TRANSMISSION_DEFAULTS.items()})


def color_text(c, digits=3) -> str:
    """``(r, g, b)`` rounded to ``digits`` decimals, as plain numbers (NumPy 2 prints its scalars as
    ``np.float64(0.5)``): the color in a message."""
    return "(" + ", ".join(repr(round(float(x), digits)) for x in np.ravel(c)) + ")"
