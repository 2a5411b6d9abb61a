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

from dataclasses import dataclass, field

import numpy as np

#: Smallest GGX alpha evaluated; below it the lobe is a near-mirror that stochastic
#: iteration cannot resolve (documented failure mode: fireflies / black highlights).
MIN_ALPHA = 1e-3
#: glossy lobes below this GGX roughness count as near-mirrors (:mod:`raybundle.app.auto`,
#: :mod:`raybundle.methods.ray_bundle_walk`)
NEAR_MIRROR_ROUGHNESS = 0.1
_MU_TABLE = 65               # samples of cos(theta_out) in the directional-albedo tables
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
        """BRDF value f(w_in, w_out) [1/sr], RGB.

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
        out[~front] = 0.0
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
                out[sel] += gm * _interp_mu(tab["glossy_albedo"], mu[sel]) \
                    + (1.0 - gm) * _interp_mu(tab["layer_albedo"], mu[sel])
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
            out[sel] = _interp_mu(self._layer_table(m)["diffuse_weight"], mu[sel])[:, None]
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

    def glossy_pdf(self, mat, normal, w_in, w_out):
        """Density [1/sr] with which :meth:`sample_glossy` draws ``w_in`` (N, 3), towards
        the light, for the viewer direction ``w_out`` (N, 3): ``G1(w_out) D(h) / (4 cos_out)``
        (visible normals, density ``G1 (h.w_out) D(h) / cos_out``, mirrored: Jacobian
        1 / (4 h.w_out)); 0 where either direction is below the surface."""
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
                out[sel] += gm * f * _interp_mu(tab["glossy_scale"], mu[sel])
            if self.has_layer[m] and gm < 1:
                f = _dielectric_layer_fresnel(c[sel], float(self.specular_ior[m]), tab["layer_f0"])
                out[sel] += (1.0 - gm) * f * _interp_mu(tab["layer_scale"], mu[sel])
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
            mu = np.linspace(0.0, 1.0, _MU_TABLE)
            a = ggx_albedo(alpha, np.maximum(mu, 1e-4))
            self._albedo_tables[alpha] = lambda x, mu=mu, a=a: np.interp(x, mu, a)
        return self._albedo_tables[alpha]

    def _layer_table(self, m):
        """Tables in mu_o = cos_out (the :data:`_MU_TABLE` grid) for layered material m:
        ``glossy_albedo`` (K, 3) = C_g int F_g lobe cos_i (without g), ``glossy_scale``
        (K, 3) = C_g, ``layer_albedo`` (K, 3) = C_s int F_s lobe cos_i (without 1 - g),
        ``layer_scale`` (K, 3) = C_s, ``diffuse_weight`` (K,) = W_d; one quadrature
        (:func:`ggx_fresnel_moments`, a quadrature worth caching) per distinct parameter set."""
        alpha = float(self.alpha[m])
        eta = float(self.specular_ior[m]) if self.has_layer[m] else 0.0
        fres, ms = int(self.glossy_fresnel[m]), int(self.multiscatter[m])
        ks = np.clip(np.asarray(self.glossy[m], float), 0.0, 1.0)
        tint = np.clip(np.asarray(self.specular_tint[m], float), 0.0, 1.0)
        g, kd = float(self.glossy_weight[m]), np.asarray(self.diffuse[m], float)
        key = ("layer", alpha, eta, tuple(ks), tuple(tint), fres, ms, g, tuple(kd))
        if key in self._albedo_tables:
            return self._albedo_tables[key]
        mu = np.linspace(0.0, 1.0, _MU_TABLE)
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
        self._albedo_tables[key] = t
        return t

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


# ------------------------------------------------------- Principled BSDF model
def _interp_mu(table, mu):
    """Linear interpolation of a table on the :data:`_MU_TABLE` grid of mu in [0, 1];
    ``table`` (K,) or (K, C) gives (N,) or (N, C)."""
    grid = np.linspace(0.0, 1.0, len(table))
    if table.ndim == 1:
        return np.interp(mu, grid, table)
    return np.stack([np.interp(mu, grid, table[:, k]) for k in range(table.shape[1])], axis=1)


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


def _dielectric_layer_fresnel(c, eta, f0):
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
    * ``F82`` (K, 3) = E[w F82(c)] if ``f82 = (f0, b)`` is given.

    The lobe is smooth in the azimuth: 256 x 32 points give the albedo of 256 x 128 to 1e-7
    (within 2e-5 of a 16x finer rule, :func:`ggx_albedo`) in a quarter of the time, and each
    distinct layered material's table takes one such quadrature per row of the mu table at
    set-up.
    """
    cos_out = np.atleast_1d(np.asarray(cos_out, float))
    t = (np.arange(n_theta) + 0.5) / n_theta
    u = np.stack(np.meshgrid(1.0 - (1.0 - t) ** 3, (np.arange(n_phi) + 0.5) / n_phi, indexing="ij"),
                 axis=-1).reshape(-1, 2)
    jac = np.repeat(3.0 * (1.0 - t) ** 2, n_phi)         # du/dt: the quadrature weight
    normal = np.tile([0.0, 0.0, 1.0], (len(u), 1))
    a = np.full(len(u), float(alpha))
    k = len(cos_out)
    out = {"E": np.empty(k), "Ed": np.zeros(k), "Sd": np.zeros(k)}
    if f82 is not None:
        out["F82"] = np.empty((k, 3))
        f82_f0, f82_b = (np.asarray(x, float) for x in f82)
    f0_real = f0_from_ior(eta) if eta > 1 else 0.0
    for j, mu in enumerate(cos_out):
        mu = float(np.clip(mu, 1e-6, 1.0))
        wo = np.broadcast_to([np.sqrt(1 - mu * mu), 0.0, mu], normal.shape)
        w_i, w = sample_ggx_reflection(a, normal, wo, u)
        h = w_i + wo
        c = np.clip(np.einsum("ij,ij->i", h, wo) / np.linalg.norm(h, axis=1).clip(1e-300), 0.0, 1.0)
        valid = jac * (w > 0)
        w = w * jac
        out["E"][j] = w.mean()
        if eta > 1:
            s = np.clip((fresnel_dielectric_cos(c, eta) - f0_real) / (1.0 - f0_real), 0.0, 1.0)
            out["Ed"][j] = (w * s).mean()
            out["Sd"][j] = (valid * s).mean()
        if f82 is not None:
            out["F82"][j] = (w[:, None] * fresnel_f82(c, f82_f0, f82_b)).mean(axis=0)
    return out


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
