"""The GGX lobe's arithmetic at one point, for kernels, and the layer tables' quadrature compiled.

The scalar helpers of :mod:`~raybundle.scene.compiled_bsdf` and
:mod:`~raybundle.lights.compiled_lights` (Smith's Lambda, the dielectric Fresnel, the
visible-normal sampler, a dot product summed in NumPy's order), computed operation for operation
as :mod:`~raybundle.scene.microfacet` computes them on arrays, and :func:`lobe_moments`, the GGX
lobe's albedo and Fresnel moments that :mod:`~raybundle.scene.principled`'s layer tables are made of.
"""
from __future__ import annotations

import numpy as np

from ..util.compiled import helper, kernel


@helper
def dot3(a0, a1, a2, b0, b1, b2):
    """a.b summed as ``np.einsum("ij,ij->i", a, b)`` sums three terms (two SIMD lanes: the
    first and third, then the second), so that both paths give the same bits."""
    return (a0 * b0 + a2 * b2) + a1 * b1


@helper
def lambda_at(alpha, c):
    """``microfacet.smith_lambda`` at one cosine ``c``."""
    c = min(max(c, 1e-12), 1.0)
    c2 = c * c
    tan2 = (1.0 - c2) / c2
    return 0.5 * (np.sqrt(1.0 + alpha * alpha * tan2) - 1.0)


@helper
def fresnel_at(c, eta):
    """``microfacet.fresnel_dielectric_cos`` at one cosine ``c``."""
    c = abs(c)
    g2 = eta * eta - 1.0 + c * c
    if not g2 > 0:
        return 1.0
    g = np.sqrt(g2)
    a = (g - c) / (g + c)
    b = (c * (g + c) - 1.0) / (c * (g - c) + 1.0)
    return 0.5 * a * a * (1.0 + b * b)


@helper
def visible_normal_at(a, n0, n1, n2, o0, o1, o2, u0, u1):
    """A GGX normal about n drawn from those visible from w_out (Heitz 2018), as
    ``microfacet.sample_ggx_visible_normal`` computes it."""
    sign = 1.0 if n2 >= 0 else -1.0                          # sampling.frames_from_normals
    fa = -1.0 / (sign + n2)
    fb = n0 * n1 * fa
    t0, t1, t2 = 1 + sign * (n0 * n0) * fa, sign * fb, -sign * n0
    b0, b1, b2 = fb, sign + (n1 * n1) * fa, -n1
    v0, v1, v2 = a * dot3(o0, o1, o2, t0, t1, t2), a * dot3(o0, o1, o2, b0, b1, b2), max(dot3(n0, n1, n2, o0, o1, o2), 1e-12)
    nv = np.sqrt((v0 * v0 + v1 * v1) + v2 * v2)
    v0, v1, v2 = v0 / nv, v1 / nv, v2 / nv
    lens = np.hypot(v0, v1)
    if lens < 1e-12:
        e0, e1, e2 = 1.0, 0.0, 0.0
    else:
        e0, e1, e2 = -v1 / lens, v0 / lens, 0.0 / lens
    f0, f1, f2 = v1 * e2 - v2 * e1, v2 * e0 - v0 * e2, v0 * e1 - v1 * e0
    r, phi = np.sqrt(u0), 2 * np.pi * u1
    p1, p2 = r * np.cos(phi), r * np.sin(phi)
    s = 0.5 * (1.0 + v2)
    p2 = (1.0 - s) * np.sqrt(max(0.0, 1.0 - p1 * p1)) + s * p2
    q = np.sqrt(max(0.0, 1.0 - p1 * p1 - p2 * p2))
    h0, h1, h2 = p1 * e0 + p2 * f0 + q * v0, p1 * e1 + p2 * f1 + q * v1, p1 * e2 + p2 * f2 + q * v2
    m0, m1, m2 = a * h0, a * h1, max(h2, 1e-12)
    nm = np.sqrt((m0 * m0 + m1 * m1) + m2 * m2)
    m0, m1, m2 = m0 / nm, m1 / nm, m2 / nm
    return m0 * t0 + m1 * b0 + m2 * n0, m0 * t1 + m1 * b1 + m2 * n1, m0 * t2 + m1 * b2 + m2 * n2


def _sample_moments():
    return 0.5, 1.5, 0.04, np.array([0.25, 1.0]), 2, 2, np.empty((2, 4))


@kernel(_sample_moments)
def lobe_moments(alpha, eta, f0_real, cos_out, n_theta, n_phi, out):
    """``out`` (K, 4): ``microfacet._moments``' ``E``, ``F5``, ``Ed`` and ``Sd`` (those two 0
    unless ``eta`` > 1; ``f0_real`` its F0) of the GGX lobe ``alpha`` seen from each of
    ``cos_out`` (K,), by its midpoint rule over the visible-normal sampler's unit square
    (``u_1 = 1 - (1 - t)^3``, Jacobian ``3 (1 - t)^2``), point by point; the sums in another
    order than NumPy's means."""
    n = n_theta * n_phi
    for j in range(len(cos_out)):
        mu = min(max(cos_out[j], 1e-6), 1.0)
        o0, o2 = np.sqrt(1 - mu * mu), mu
        lam_o = lambda_at(alpha, mu)
        e = f5 = ed = sd = 0.0
        for it in range(n_theta):
            t = (it + 0.5) / n_theta
            u0, jac = 1.0 - (1.0 - t) ** 3, 3.0 * (1.0 - t) ** 2
            for ip in range(n_phi):
                h0, h1, h2 = visible_normal_at(alpha, 0.0, 0.0, 1.0, o0, 0.0, o2, u0, (ip + 0.5) / n_phi)
                h_o = dot3(h0, h1, h2, o0, 0.0, o2)
                i0, i1, i2 = 2 * h_o * h0 - o0, 2 * h_o * h1, 2 * h_o * h2 - o2
                w = 0.0
                if i2 > 0 and h_o > 0:
                    w = (1.0 + lam_o) / (1.0 + lam_o + lambda_at(alpha, i2))
                x0, x1, x2 = i0 + o0, i1, i2 + o2
                nx = max(np.sqrt((x0 * x0 + x1 * x1) + x2 * x2), 1e-300)
                c = min(max(dot3(x0, x1, x2, o0, 0.0, o2) / nx, 0.0), 1.0)
                ww = w * jac
                e += ww
                f5 += ww * (1.0 - c) ** 5
                if eta > 1:
                    s = min(max((fresnel_at(c, eta) - f0_real) / (1.0 - f0_real), 0.0), 1.0)
                    ed += ww * s
                    if w > 0:
                        sd += jac * s
        out[j, 0], out[j, 1], out[j, 2], out[j, 3] = e / n, f5 / n, ed / n, sd / n
