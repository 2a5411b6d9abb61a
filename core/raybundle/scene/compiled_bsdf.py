"""The BSDF of :class:`~raybundle.scene.materials.MaterialTable` evaluated per point, compiled.

:meth:`~raybundle.scene.materials.MaterialTable.brdf` and
:meth:`~raybundle.scene.materials.MaterialTable.glossy_pdf` run here where the kernels are on
(:mod:`raybundle.util.compiled`): one loop over the points, each evaluating its own material's
lobes in registers, where the NumPy path makes a dozen whole-array temporaries per lobe and a
pass per layered material.  The arithmetic is the NumPy path's, operation for operation and
in the same order (the GGX lobe and Smith terms of :mod:`~raybundle.scene.microfacet`, the
layer tables of :mod:`~raybundle.scene.principled` read by ``np.interp``'s formula), so both
give the same values (``tests/test_compiled_bsdf.py``).

:class:`Packed` holds what the kernels read of a material table, one row per material: the
parameters and each layered material's tables on the :data:`~raybundle.scene.principled.MU_TABLE`
grid (zeros for the others), made once per set of parameters (:func:`packed`).
"""
from __future__ import annotations

import hashlib
from dataclasses import dataclass

import numpy as np

from ..util.compiled import helper, kernel
from .compiled_microfacet import dot3, fresnel_at, lambda_at, visible_normal_at
from .principled import MU_TABLE


@dataclass
class Packed:
    """A material table's parameters as kernel arguments (M materials, K = MU_TABLE)."""
    kdr: np.ndarray              # (M, 3) the diffuse lobe's albedo (1 - g) kd
    g: np.ndarray                # (M,) glossy weight
    ks: np.ndarray               # (M, 3) glossy tint
    alpha: np.ndarray            # (M,) GGX alpha
    layered: np.ndarray          # (M,) bool: any Principled feature
    has_layer: np.ndarray        # (M,) bool: a dielectric layer
    fresnel: np.ndarray          # (M,) bool: F82-tint conductor Fresnel
    eta: np.ndarray              # (M,) the layer's IOR
    f82_f0: np.ndarray           # (M, 3)
    f82_b: np.ndarray            # (M, 3)
    layer_f0: np.ndarray         # (M, 3)
    glossy_scale: np.ndarray     # (M, K, 3)
    layer_scale: np.ndarray      # (M, K, 3)
    diffuse_weight: np.ndarray   # (M, K)

    def arrays(self):
        return (self.kdr, self.g, self.ks, self.alpha, self.layered, self.has_layer, self.fresnel, self.eta,
                self.f82_f0, self.f82_b, self.layer_f0, self.glossy_scale, self.layer_scale, self.diffuse_weight)


_FIELDS = ("diffuse", "glossy", "roughness", "glossy_weight", "specular_ior", "specular_tint", "glossy_fresnel",
           "multiscatter")


def packed(mt) -> Packed:
    """The :class:`Packed` arrays of material table ``mt``, kept on it while the parameters
    they are made of stay the same (a digest of them is compared on every call)."""
    h = hashlib.sha1()
    for k in _FIELDS:
        h.update(np.ascontiguousarray(getattr(mt, k)).tobytes())
    key = ("packed", h.hexdigest())
    got = mt._albedo_tables.get(key)
    if got is None:
        got = mt._albedo_tables[key] = _pack(mt)
    return got


def _pack(mt) -> Packed:
    m = len(mt)
    layered, has_layer = np.asarray(mt.is_layered, bool), np.asarray(mt.has_layer, bool)
    zeros3 = np.zeros((m, 3))
    f82_f0, f82_b, layer_f0 = zeros3.copy(), zeros3.copy(), zeros3.copy()
    glossy_scale, layer_scale = np.zeros((m, MU_TABLE, 3)), np.zeros((m, MU_TABLE, 3))
    diffuse_weight = np.ones((m, MU_TABLE))
    for i in np.nonzero(layered)[0]:
        t = mt._layer_table(i)
        f82_f0[i], f82_b[i], layer_f0[i] = t["f82_f0"], t["f82_b"], t["layer_f0"]
        glossy_scale[i], layer_scale[i] = t["glossy_scale"], t["layer_scale"]
        if has_layer[i]:
            diffuse_weight[i] = t["diffuse_weight"]
    f = np.ascontiguousarray
    return Packed(f(mt.diffuse_reflectance, float), f(mt.glossy_weight, float), f(mt.glossy, float),
                  f(mt.alpha, float), layered, has_layer, f(np.asarray(mt.glossy_fresnel) != 0),
                  f(mt.specular_ior, float), f82_f0, f82_b, layer_f0, glossy_scale, layer_scale, diffuse_weight)


def brdf(mt, mat, normal, w_i, w_o, diffuse, glossy, diffuse_scale):
    """(N, 3) :meth:`~raybundle.scene.materials.MaterialTable.brdf` with ``w_i`` (N, 3) towards
    the light and ``w_o`` (N, 3) towards the viewer, by the kernel."""
    n = len(mat)
    scale = np.zeros((0, 3)) if diffuse_scale is None else np.ascontiguousarray(diffuse_scale, float)
    out = np.empty((n, 3))
    _brdf(np.ascontiguousarray(mat, np.int64), _rows(normal, n), _rows(w_i, n), _rows(w_o, n), bool(diffuse),
          bool(glossy), scale, *packed(mt).arrays(), out)
    return out


def sample_glossy(mt, mat, normal, w_out, u):
    """``(w_i (N, 3), weight (N, 3))`` of :meth:`~raybundle.scene.materials.MaterialTable.sample_glossy`
    (the visible-normal sampler of :func:`~raybundle.scene.microfacet.sample_ggx_reflection`,
    its weight times the tint or the layered material's factor), by the kernel."""
    n = len(mat)
    w_i, weight = np.empty((n, 3)), np.empty((n, 3))
    _sample_glossy(np.ascontiguousarray(mat, np.int64), _rows(normal, n), _rows(w_out, n),
                   np.ascontiguousarray(u, float), *packed(mt).arrays(), w_i, weight)
    return w_i, weight


def glossy_pdf(mt, mat, normal, w_in, w_out):
    """(N,) :meth:`~raybundle.scene.materials.MaterialTable.glossy_pdf`, by the kernel."""
    n = len(mat)
    out = np.empty(n)
    _glossy_pdf(np.ascontiguousarray(mat, np.int64), _rows(normal, n), _rows(w_in, n), _rows(w_out, n),
                packed(mt).alpha, out)
    return out


def _rows(a, n):
    """``a`` as (n, 3) contiguous writeable floats, the kernels' compiled signature (a read-only
    view, as ``broadcast_to`` gives, would compile them again during the run)."""
    a = np.asarray(a, float)
    return np.ascontiguousarray(a) if a.shape == (n, 3) and a.flags.writeable else \
        np.array(np.broadcast_to(a, (n, 3)), order="C")


# ------------------------------------------------------------------------------------- kernels
def _sample_brdf():
    m = np.zeros(2, np.int64)
    v = np.tile([[0.0, 0.0, 1.0]], (2, 1))
    p = _pack_sample()
    return (m, v, v, v, True, True, np.zeros((0, 3)), *p, np.empty((2, 3)))


def _pack_sample():
    z3, z = np.zeros((1, 3)), np.zeros(1)
    b = np.zeros(1, bool)
    return (z3, z, z3, z + 0.25, b, b, b, z, z3, z3, z3, np.zeros((1, MU_TABLE, 3)), np.zeros((1, MU_TABLE, 3)),
            np.ones((1, MU_TABLE)))


@helper
def _interp_at(mu, k):
    """Where ``np.interp(mu, linspace(0, 1, k), table)`` reads a table, for ``mu`` in [0, 1]:
    ``(j, dx, dmu)``, its value ``table[j]`` where ``dx < 0``, else ``_lerp(table[j],
    table[j + 1], dx, dmu)`` (np.interp's formula).  Scalars only: a helper taking an array
    costs a reference count of it on every call."""
    step = 1.0 / (k - 1)
    j = int(mu * (k - 1))
    if j >= k - 1:
        return k - 1, -1.0, 0.0
    x0 = j * step
    if mu == x0:
        return j, -1.0, 0.0
    return j, (j + 1) * step - x0, mu - x0


@helper
def _lerp(t0, t1, dx, dmu):
    return t0 if dx < 0 else (t1 - t0) / dx * dmu + t0


@helper
def _ggx_distribution(a, n0, n1, n2, i0, i1, i2, o0, o1, o2):
    """The unit half vector of ``w_i`` and ``w_o`` and the GGX ``D(h)`` about normal ``n``
    (:func:`~raybundle.scene.microfacet.ggx_distribution`, per point)."""
    h0, h1, h2 = i0 + o0, i1 + o1, i2 + o2
    norm = np.sqrt(h0 * h0 + h1 * h1 + h2 * h2) + 1e-300
    h0, h1, h2 = h0 / norm, h1 / norm, h2 / norm
    cos_h = dot3(n0, n1, n2, h0, h1, h2)
    a2 = a * a
    denom = cos_h * cos_h * (a2 - 1.0) + 1.0
    return h0, h1, h2, a2 / (np.pi * denom * denom)


@helper
def _layer_fl(hc, eta, on):
    """The dielectric layer's Fresnel remapped from [F0(eta), 1] to [0, 1] at ``c = h.w_out``
    (``microfacet.dielectric_layer_fresnel``'s ``s``); 0 where ``on`` is False."""
    if not on:
        return 0.0
    f_real = ((eta - 1.0) / (eta + 1.0)) ** 2
    return min(max((fresnel_at(hc, eta) - f_real) / (1.0 - f_real), 0.0), 1.0)


@helper
def _layer_factor(gm, f82, f82_f0, f82_b, ks, has_layer, layer_f0, fl, s, s5, gs0, gs1, ls0, ls1, dx, dmu):
    """One channel of ``MaterialTable._glossy_factor``: ``g F_g(c) C_g(mu) + (1 - g) F_s(c)
    C_s(mu)``, with ``s = clip(1 - c, 0, 1)``, ``s5 = s^5``, ``fl`` of :func:`_layer_fl` and
    the tables' neighbours ``gs0, gs1`` and ``ls0, ls1`` at :func:`_interp_at`'s ``dx, dmu``."""
    factor = 0.0
    if gm > 0:
        if f82:
            f = f82_f0 + (1.0 - f82_f0) * s5 - f82_b * (1.0 - s) * s5 * s
            f = min(max(f, 0.0), 1.0)
        else:
            f = ks
        factor = factor + gm * f * _lerp(gs0, gs1, dx, dmu)
    if has_layer and gm < 1:
        f = layer_f0 + (1.0 - layer_f0) * fl
        factor = factor + (1.0 - gm) * f * _lerp(ls0, ls1, dx, dmu)
    return factor


@kernel(_sample_brdf)
def _brdf(mat, normal, w_i, w_o, diffuse, glossy, scale, kdr, g, ks, alpha, layered, has_layer, fresnel, eta,
          f82_f0, f82_b, layer_f0, glossy_scale, layer_scale, diffuse_weight, out):
    """``out`` (N, 3) = f(w_i, w_o) of ``MaterialTable.brdf`` (``scale`` (N, 3), or (0, 3) for none)."""
    scaled = scale.shape[0] > 0
    r = np.empty(3)
    last = diffuse_weight.shape[1] - 1
    for p in range(len(mat)):
        m = mat[p]
        n0, n1, n2 = normal[p, 0], normal[p, 1], normal[p, 2]
        i0, i1, i2 = w_i[p, 0], w_i[p, 1], w_i[p, 2]
        o0, o1, o2 = w_o[p, 0], w_o[p, 1], w_o[p, 2]
        cos_i = dot3(n0, n1, n2, i0, i1, i2)
        cos_o = dot3(n0, n1, n2, o0, o1, o2)
        if not cos_i > 0:
            out[p, 0] = out[p, 1] = out[p, 2] = 0.0
            continue
        mu = min(max(cos_o, 0.0), 1.0)
        r[0] = r[1] = r[2] = 0.0
        if diffuse:         # whatever side the viewer is on, the glossy lobes above it only
            wd = 1.0
            if layered[m] and has_layer[m]:
                j, dx, dmu = _interp_at(mu, diffuse_weight.shape[1])
                wd = _lerp(diffuse_weight[m, j], diffuse_weight[m, min(j + 1, last)], dx, dmu)
            for c in range(3):
                v = kdr[m, c] / np.pi
                if scaled:
                    v = v * scale[p, c]
                if layered[m]:
                    v = v * wd
                r[c] = v
        if glossy and (layered[m] or g[m] > 0) and cos_i > 0 and cos_o > 0:
            a = alpha[m]
            h0, h1, h2, d = _ggx_distribution(a, n0, n1, n2, i0, i1, i2, o0, o1, o2)
            g2 = 1.0 / (1.0 + lambda_at(a, cos_i) + lambda_at(a, cos_o))
            lobe = d * g2 / (4.0 * cos_i * cos_o)
            if not layered[m]:
                gl = g[m] * lobe
                for c in range(3):
                    r[c] = r[c] + gl * ks[m, c]
            else:
                hc = dot3(h0, h1, h2, o0, o1, o2)
                gm = g[m]
                fl = _layer_fl(hc, eta[m], has_layer[m] and gm < 1)
                s = min(max(1.0 - hc, 0.0), 1.0)
                s5 = s ** 5.0
                j, dx, dmu = _interp_at(mu, glossy_scale.shape[1])
                j1 = min(j + 1, last)
                for c in range(3):
                    r[c] = r[c] + lobe * _layer_factor(
                        gm, fresnel[m], f82_f0[m, c], f82_b[m, c], ks[m, c], has_layer[m], layer_f0[m, c], fl, s, s5,
                        glossy_scale[m, j, c], glossy_scale[m, j1, c], layer_scale[m, j, c], layer_scale[m, j1, c],
                        dx, dmu)
        out[p, 0], out[p, 1], out[p, 2] = r[0], r[1], r[2]


def _sample_pdf():
    m = np.zeros(2, np.int64)
    v = np.tile([[0.0, 0.0, 1.0]], (2, 1))
    return m, v, v, v, np.full(1, 0.25), np.empty(2)


@kernel(_sample_pdf)
def _glossy_pdf(mat, normal, w_in, w_out, alpha, out):
    """``out`` (N,) = ``MaterialTable.glossy_pdf``."""
    for p in range(len(mat)):
        out[p] = glossy_pdf_at(alpha[mat[p]], normal[p, 0], normal[p, 1], normal[p, 2], w_in[p, 0], w_in[p, 1],
                               w_in[p, 2], w_out[p, 0], w_out[p, 1], w_out[p, 2])


@helper
def glossy_pdf_at(a, n0, n1, n2, i0, i1, i2, o0, o1, o2):
    """The glossy lobe's density of ``w_in`` (towards the light) at one point of GGX alpha ``a``:
    G1(w_out) D(h) / (4 cos_out), 0 below either side, for kernels (scalars only: a helper
    taking arrays costs a reference count of each on every call)."""
    h0, h1, h2, d = _ggx_distribution(a, n0, n1, n2, i0, i1, i2, o0, o1, o2)
    h_o = dot3(h0, h1, h2, o0, o1, o2)
    cos_o = dot3(n0, n1, n2, o0, o1, o2)
    cos_i = dot3(n0, n1, n2, i0, i1, i2)
    if cos_i > 0 and cos_o > 0 and h_o > 0:
        g1 = 1.0 / (1.0 + lambda_at(a, cos_o))
        return g1 * d / (4.0 * cos_o)
    return 0.0


def _sample_sampler():
    v = np.tile([[0.0, 0.0, 1.0]], (2, 1))
    return (np.zeros(2, np.int64), v, v, np.full((2, 2), 0.5), *_pack_sample(), np.empty((2, 3)), np.empty((2, 3)))


@kernel(_sample_sampler)
def _sample_glossy(mat, normal, w_out, u, kdr, g, ks, alpha, layered, has_layer, fresnel, eta, f82_f0, f82_b,
                   layer_f0, glossy_scale, layer_scale, diffuse_weight, w_i, weight):
    last = glossy_scale.shape[1] - 1
    for p in range(len(mat)):
        m = mat[p]
        a = alpha[m]
        n0, n1, n2 = normal[p, 0], normal[p, 1], normal[p, 2]
        o0, o1, o2 = w_out[p, 0], w_out[p, 1], w_out[p, 2]
        h0, h1, h2 = visible_normal_at(a, n0, n1, n2, o0, o1, o2, u[p, 0], u[p, 1])
        cos_o = dot3(n0, n1, n2, o0, o1, o2)
        h_o = dot3(h0, h1, h2, o0, o1, o2)
        i0, i1, i2 = 2 * h_o * h0 - o0, 2 * h_o * h1 - o1, 2 * h_o * h2 - o2
        w_i[p, 0], w_i[p, 1], w_i[p, 2] = i0, i1, i2
        cos_i = dot3(n0, n1, n2, i0, i1, i2)
        w = 0.0
        if cos_i > 0 and h_o > 0 and cos_o > 0:
            lam_o = lambda_at(a, abs(cos_o))
            w = (1.0 + lam_o) / (1.0 + lam_o + lambda_at(a, abs(cos_i)))
        if not (layered[m] and w > 0):
            for c in range(3):
                weight[p, c] = g[m] * ks[m, c] * w
            continue
        x0, x1, x2 = i0 + o0, i1 + o1, i2 + o2
        nx = np.sqrt((x0 * x0 + x1 * x1) + x2 * x2) + 1e-300
        hc = dot3(x0 / nx, x1 / nx, x2 / nx, o0, o1, o2)
        gm = g[m]
        fl = _layer_fl(hc, eta[m], has_layer[m] and gm < 1)
        s = min(max(1.0 - hc, 0.0), 1.0)
        s5 = s ** 5.0
        j, dx, dmu = _interp_at(min(max(cos_o, 0.0), 1.0), glossy_scale.shape[1])
        j1 = min(j + 1, last)
        for c in range(3):
            weight[p, c] = w * _layer_factor(
                gm, fresnel[m], f82_f0[m, c], f82_b[m, c], ks[m, c], has_layer[m], layer_f0[m, c], fl, s, s5,
                glossy_scale[m, j, c], glossy_scale[m, j1, c], layer_scale[m, j, c], layer_scale[m, j1, c], dx, dmu)

