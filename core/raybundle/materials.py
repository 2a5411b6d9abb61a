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
(``emission_albedo_complement = c``); see :mod:`raybundle.scenes`.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

#: Smallest GGX alpha evaluated; below it the lobe is a near-mirror that stochastic
#: iteration cannot resolve (documented failure mode: fireflies / black highlights).
MIN_ALPHA = 1e-3
_MU_TABLE = 65  # samples of cos(theta_out) in the directional-albedo tables


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
    """

    names: list
    diffuse: np.ndarray
    glossy: np.ndarray
    roughness: np.ndarray
    glossy_weight: np.ndarray
    emission: np.ndarray
    emission_albedo_complement: np.ndarray
    _albedo_tables: dict = field(default_factory=dict, repr=False, compare=False)

    @classmethod
    def from_list(cls, specs):
        """Build from a list of dicts with keys ``name``, ``diffuse``, ``glossy``,
        ``roughness``, ``glossy_weight``, ``emission`` (all optional but name)."""
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
        return t

    def __len__(self):
        return len(self.names)

    # ------------------------------------------------------------------ queries
    @property
    def alpha(self) -> np.ndarray:
        """GGX alpha = roughness^2 (Blender), clamped to :data:`MIN_ALPHA`."""
        return np.maximum(np.asarray(self.roughness, float) ** 2, MIN_ALPHA)

    @property
    def is_glossy(self) -> np.ndarray:
        """(M,) bool: the material has a glossy lobe that reflects light."""
        return (self.glossy_weight > 0) & np.any(self.glossy > 0, axis=1)

    @property
    def is_emitter(self) -> np.ndarray:
        return np.any(self.emission > 0, axis=1) | np.any(self.emission_albedo_complement > 0, axis=1)

    @property
    def diffuse_reflectance(self) -> np.ndarray:
        """(M, 3) ``(1 - g) * kd``: the albedo of the diffuse lobe."""
        return (1.0 - self.glossy_weight)[:, None] * self.diffuse

    def validate(self):
        """Raise ValueError on parameters that break energy conservation or are not finite."""
        arrays = {k: np.asarray(getattr(self, k), float) for k in (
            "diffuse", "glossy", "roughness", "glossy_weight", "emission", "emission_albedo_complement")}
        for k, a in arrays.items():
            bad = ~np.isfinite(a)
            if bad.any():
                m = int(np.nonzero(bad.reshape(len(a), -1).any(axis=1))[0][0])
                raise ValueError(f"material {self.names[m]!r}: {k} is not finite")
            if (a < 0).any():
                m = int(np.nonzero((a < 0).reshape(len(a), -1).any(axis=1))[0][0])
                raise ValueError(f"material {self.names[m]!r}: {k} is negative")
        for k in ("diffuse", "glossy"):
            over = arrays[k] > 1.0
            if over.any():
                m = int(np.nonzero(over.any(axis=1))[0][0])
                raise ValueError(
                    f"material {self.names[m]!r}: {k} color {tuple(arrays[k][m])} has a component > 1 "
                    "(albedo > 1 creates energy; the iteration would diverge)")
        if (arrays["glossy_weight"] > 1).any() or (arrays["roughness"] > 1).any():
            m = int(np.nonzero((arrays["glossy_weight"] > 1) | (arrays["roughness"] > 1))[0][0])
            raise ValueError(f"material {self.names[m]!r}: glossy_weight and roughness must lie in [0, 1]")

    # --------------------------------------------------------------- evaluation
    def brdf(self, mat, normal, w_in, w_out, diffuse=True, glossy=True) -> np.ndarray:
        """BRDF value f(w_in, w_out) [1/sr], RGB.

        Parameters
        ----------
        mat : (N,) int  material ids
        normal : (N, 3) float  unit front normals
        w_in : (N, 3) or (3,) float  travel direction of the incoming light
        w_out : (N, 3) or (3,) float  outgoing direction
        diffuse, glossy : bool  which lobes to include

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
        if diffuse:
            out += self.diffuse_reflectance[mat] / np.pi
        if glossy:
            g = self.glossy_weight[mat]
            sel = front & (g > 0)
            if sel.any():
                lobe = ggx_lobe(self.alpha[mat[sel]], normal[sel], w_i[sel], w_o[sel],
                                cos_i[sel], cos_o[sel])
                out[sel] += (g[sel] * lobe)[:, None] * self.glossy[mat[sel]]
        out[~front] = 0.0
        return out

    def albedo(self, mat, cos_out, diffuse=True, glossy=True) -> np.ndarray:
        """Directional albedo a(w_out) = integral of f(w_in, w_out) cos_i dw_in, RGB.

        By reciprocity this is also the hemispherical reflectance for light
        arriving from w_out.  The GGX part comes from a table in cos_out,
        integrated once per distinct alpha (:func:`ggx_albedo`, about 0.5 s),
        linearly interpolated.
        """
        mat = np.asarray(mat)
        mu = np.clip(np.asarray(cos_out, float), 0.0, 1.0)
        out = np.zeros((len(mat), 3))
        if diffuse:
            out += self.diffuse_reflectance[mat]
        if glossy:
            g = self.glossy_weight[mat]
            for m in np.unique(mat[g > 0]):
                sel = mat == m
                out[sel] += (g[sel] * self._ggx_albedo_table(m)(mu[sel]))[:, None] * self.glossy[m]
        out[mu <= 0] = 0.0
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

    # ------------------------------------------------------------------- io
    def to_arrays(self, prefix="material_") -> dict:
        return {prefix + "names": np.array(self.names, dtype=str),
                prefix + "diffuse": self.diffuse, prefix + "glossy": self.glossy,
                prefix + "roughness": self.roughness, prefix + "glossy_weight": self.glossy_weight,
                prefix + "emission": self.emission,
                prefix + "emission_albedo_complement": self.emission_albedo_complement}

    @classmethod
    def from_arrays(cls, d, prefix="material_"):
        n = len(d[prefix + "names"])
        comp = d.get(prefix + "emission_albedo_complement")
        return cls(names=[str(s) for s in d[prefix + "names"]],
                   diffuse=np.asarray(d[prefix + "diffuse"], float).reshape(n, 3),
                   glossy=np.asarray(d[prefix + "glossy"], float).reshape(n, 3),
                   roughness=np.asarray(d[prefix + "roughness"], float).reshape(n),
                   glossy_weight=np.asarray(d[prefix + "glossy_weight"], float).reshape(n),
                   emission=np.asarray(d[prefix + "emission"], float).reshape(n, 3),
                   emission_albedo_complement=(np.zeros((n, 3)) if comp is None
                                               else np.asarray(comp, float).reshape(n, 3)))


def smith_lambda(alpha, cos_theta):
    """GGX Smith Lambda(w) = (sqrt(1 + alpha^2 tan^2 theta) - 1) / 2."""
    c2 = np.clip(cos_theta, 1e-12, 1.0) ** 2
    tan2 = (1.0 - c2) / c2
    return 0.5 * (np.sqrt(1.0 + alpha * alpha * tan2) - 1.0)


def ggx_lobe(alpha, n, w_i, w_o, cos_i, cos_o):
    """Untinted GGX lobe D(h) G2 / (4 cos_i cos_o) [1/sr] for front-facing pairs.

    ``w_i`` points towards the light, ``w_o`` towards the viewer; all arrays (N, ...).
    """
    h = w_i + w_o
    h /= np.linalg.norm(h, axis=1, keepdims=True) + 1e-300
    cos_h = np.einsum("ij,ij->i", n, h)
    a2 = alpha * alpha
    denom = cos_h * cos_h * (a2 - 1.0) + 1.0
    d = a2 / (np.pi * denom * denom)
    g2 = 1.0 / (1.0 + smith_lambda(alpha, cos_i) + smith_lambda(alpha, cos_o))
    return d * g2 / (4.0 * cos_i * cos_o)


def sample_ggx_reflection(alpha, normal, w_out, u):
    """Importance-sample the GGX lobe seen from ``w_out``: half vectors h with
    density D(h) (n.h), mirrored to the light-side direction ``w_i``.

    Returns ``(w_i (N, 3), weight (N,))`` with ``weight = lobe * cos_i / pdf(w_i)
    = G2 (h.w_out) / (cos_out cos_h)`` (0 where ``w_i`` is below the surface), so
    ``E[weight * L(w_i)]`` is the lobe's reflected radiance (untinted).
    """
    from .sampling import frames_from_normals

    t, b = frames_from_normals(normal)
    tan2 = alpha * alpha * u[:, 0] / np.maximum(1.0 - u[:, 0], 1e-12)
    cos_h = 1.0 / np.sqrt(1.0 + tan2)
    sin_h = np.sqrt(np.maximum(0.0, 1.0 - cos_h * cos_h))
    phi = 2 * np.pi * u[:, 1]
    h = (sin_h * np.cos(phi))[:, None] * t + (sin_h * np.sin(phi))[:, None] * b + cos_h[:, None] * normal
    h_o = np.einsum("ij,ij->i", h, w_out)
    w_i = 2 * h_o[:, None] * h - w_out
    cos_i = np.einsum("ij,ij->i", normal, w_i)
    cos_o = np.einsum("ij,ij->i", normal, w_out)
    ok = (cos_i > 0) & (h_o > 0) & (cos_o > 0)
    g2 = 1.0 / (1.0 + smith_lambda(alpha, np.where(ok, cos_i, 1.0)) + smith_lambda(alpha, np.where(ok, cos_o, 1.0)))
    weight = np.where(ok, g2 * h_o / (np.maximum(cos_o, 1e-12) * cos_h), 0.0)
    return w_i, weight


def ggx_albedo(alpha, cos_out, n_theta=1024, n_phi=256):
    """Directional albedo of the untinted GGX lobe, integral of lobe * cos_i dw_i.

    Computed by a deterministic midpoint rule in half-vector space: with h
    distributed as D(h) (n.h) (inverse CDF tan^2 theta_h = alpha^2 u / (1 - u)),
    ``a = E_h[ G2 (h.w_o) / (cos_o cos_h) ]`` over the pairs where the mirrored
    ``w_i`` is above the surface (phi over [0, pi] by symmetry).  Error against
    a 4x finer rule: below 1e-3 for cos_out >= 0.1, a few 1e-3 at grazing.
    """
    cos_out = np.atleast_1d(np.asarray(cos_out, float))
    u = (np.arange(n_theta) + 0.5) / n_theta
    v = (np.arange(n_phi) + 0.5) / n_phi
    tan2 = alpha * alpha * u / (1.0 - u)
    cos_h = 1.0 / np.sqrt(1.0 + tan2)
    sin_h = np.sqrt(1.0 - cos_h * cos_h)
    phi = np.pi * v
    hx = (sin_h[:, None] * np.cos(phi)[None, :]).ravel()
    hz = np.repeat(cos_h, n_phi)
    out = np.empty(len(cos_out))
    for k, mu in enumerate(cos_out):
        mu = float(np.clip(mu, 1e-6, 1.0))
        wo = np.array([np.sqrt(1 - mu * mu), 0.0, mu])
        h_dot_o = hx * wo[0] + hz * wo[2]
        cos_i = 2 * h_dot_o * hz - mu
        ok = (cos_i > 0) & (h_dot_o > 0)
        g2 = 1.0 / (1.0 + smith_lambda(alpha, np.where(ok, cos_i, 1.0)) + smith_lambda(alpha, mu))
        w = np.where(ok, g2 * h_dot_o / (mu * hz), 0.0)
        out[k] = w.mean()
    return out
