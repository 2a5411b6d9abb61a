"""Patches split where the lamps' light changes within them.

A patch holds one value per side.  Where the lamps' direct light changes strongly across it
(a wall a few centimetres behind an area lamp, a plate over a strip light, a floor patch
under a lamp's edge), that value is its average, and every surface near it reads the average
as the light it reflects: near a lamp the average is far from the local value, and the error
reaches the image through the patch's neighbours (the diffuse indirect light of the final
gather and of the interpolation), as a bias that no number of iterations removes.

:func:`split_where_lit_unevenly` finds such patches from the lamps' light at their triangles
(the first shot's lights, given as a function: this layer knows no lights) and splits them
in two along each of their wide in-plane axes, level after level.  A patch *misplaces*
about ``spread x area`` of power within itself (``spread`` the largest difference of the light
at its triangles, on either side); it is split while that exceeds :data:`SPLIT_SHARE` times
the power an average patch of the layout receives, ``mean irradiance x mean area``: a measure
without units, so it means the same in any room at any scale.  The splits only regroup a
patch's triangles (a single triangle stays whole), so the pieces keep what made the patch:
one plane, material, contact side and gap.
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np

from ..scene.model import PatchScene
from ..tracing.sampling import frames_from_normals
from ..util.arrays import stable_order, unique_ints

#: a patch is split while it misplaces more than this share of the power an average patch receives
SPLIT_SHARE = 1.0
#: splits in a row: a patch h wide ends at most h / 2^LEVELS wide
LEVELS = 4
#: at most this share of the layout's patch count is added (the strongest misplacements first)
MAX_ADDED = 1.0
#: triangles of a patch whose light is probed before the patch is known to be uneven
PROBES_PER_PATCH = 6


def split_where_lit_unevenly(scene: PatchScene, light, levels=LEVELS, share=SPLIT_SHARE, max_added=MAX_ADDED):
    """``scene`` (laid out) with the patches over which the lamps' light changes strongly split
    (module docstring), and the number of patches added.

    ``light(points (N, 3), normals (N, 3)) -> (N,)``: the lamps' direct irradiance [W/m^2] at
    points facing ``normals``.  It is asked at the centroids of up to :data:`PROBES_PER_PATCH`
    triangles of each patch, and of each half of a patch split, so its cost grows with the
    patches, not the triangles."""
    n0 = scene.n_patches
    if not n0:
        return scene, 0
    probe = _Probe(scene, light)
    area = scene.triangle_area
    patch = scene.triangle_patch
    unit = None
    for _ in range(levels):
        probe.first(patch, PROBES_PER_PATCH)
        if unit is None:
            unit = _unit(scene, probe.e, share, n0)
            if not unit > 0:
                return scene, 0
        n = int(patch.max()) + 1
        score = _spread(patch, probe.e, n) * np.bincount(patch, area, minlength=n)
        many = np.bincount(patch, minlength=n) > 1
        room = (int(max_added * n0) - (n - n0)) // 3          # a split adds up to three patches
        chosen = np.nonzero((score > unit) & many)[0]
        chosen = chosen[np.argsort(-score[chosen], kind="stable")][:max(room, 0)]
        if not len(chosen):
            break
        patch = _halved(scene, patch, np.isin(patch, chosen), n)
    added = int(patch.max()) + 1 - n0
    return (replace(scene, triangle_patch=patch), added) if added else (scene, 0)


def _unit(scene, e, share, n0):
    """``share`` times the power an average patch receives: the mean irradiance over the
    sides that receive light (from the probed triangles ``e`` (T, 2)) times the mean patch area."""
    area = scene.triangle_area
    sides = scene.materials.reflects[scene.triangle_material][:, None] & np.stack(
        [np.ones(len(area), bool), scene.triangle_two_sided], axis=1)
    w = np.where(sides & ~np.isnan(e), area[:, None], 0.0)
    level = float((np.nan_to_num(e) * w).sum() / max(w.sum(), 1e-300))
    return share * level * float(area[sides[:, 0]].sum()) / n0


class _Probe:
    """The lamps' light at triangle centroids, front and back (T, 2); NaN where not asked yet,
    0 on the back of a one-sided triangle and on triangles that reflect nothing."""

    def __init__(self, scene, light):
        self.scene, self.light = scene, light
        self.e = np.full((len(scene.triangles), 2), np.nan)
        dark = ~scene.materials.reflects[scene.triangle_material]
        self.e[dark] = 0.0
        self.e[~scene.triangle_two_sided, 1] = 0.0
        self.order = np.random.default_rng(0).permutation(len(scene.triangles))

    def first(self, patch, k):
        """Probe ``k`` triangles of each patch of ``patch`` (T,) (all of a smaller one), the
        same ones on every call for a patch that has not changed: the first in one random
        order of the triangles drawn once, from a fixed seed."""
        order = self.order[stable_order(patch[self.order])[0]]
        p = patch[order]
        start = np.flatnonzero(np.r_[True, p[1:] != p[:-1]])
        rank = np.arange(len(order)) - np.repeat(start, np.diff(np.append(start, len(order))))
        self.all(order[rank < k])

    def all(self, tri):
        """Probe triangles ``tri`` where not yet probed."""
        sc = self.scene
        for col, sign in ((0, 1.0), (1, -1.0)):
            t = tri[np.isnan(self.e[tri, col])]
            if len(t):
                n = sign * sc.triangle_normal[t]
                self.e[t, col] = self.light(sc.triangle_corners[t].mean(axis=1), n)


def _spread(patch, e, n):
    """(n,) per patch, the larger over its two sides of the difference between the most and
    the least light at its probed triangles."""
    out = np.zeros(n)
    for col in range(2):
        v = e[:, col]
        ok = ~np.isnan(v)
        hi = np.full(n, -np.inf)
        lo = np.full(n, np.inf)
        np.maximum.at(hi, patch[ok], v[ok])
        np.minimum.at(lo, patch[ok], v[ok])
        out = np.maximum(out, np.where(hi >= lo, hi - lo, 0.0))
    return out


def _halved(scene, patch, inside, n):
    """``patch`` (T,) with the patches of triangles ``inside`` halved, by their triangles'
    centroids, along each in-plane axis at least half as wide as the widest (a strip in
    two, a square in four)."""
    t = np.nonzero(inside)[0]
    p = patch[t]
    u, v = frames_from_normals(_normals(scene, patch, n)[p])
    c = scene.triangle_corners[t].mean(axis=1)
    xy = np.stack([np.einsum("ij,ij->i", c, u), np.einsum("ij,ij->i", c, v)], axis=1)
    lo = np.full((n, 2), np.inf)
    hi = np.full((n, 2), -np.inf)
    for k in range(2):
        np.minimum.at(lo[:, k], p, xy[:, k])
        np.maximum.at(hi[:, k], p, xy[:, k])
    width = hi[p] - lo[p]
    cut = width >= 0.5 * width.max(axis=1, keepdims=True)
    half = (xy > 0.5 * (lo[p] + hi[p])) & cut
    key = patch.astype(np.int64) * 4
    key[t] += half[:, 0] * 2 + half[:, 1]
    return unique_ints(key)[2].astype(np.int64)


def _normals(scene, patch, n):
    """(n, 3) area-weighted unit normal of each patch of ``patch`` (T,)."""
    w = scene.triangle_normal * scene.triangle_area[:, None]
    s = np.stack([np.bincount(patch, w[:, k], minlength=n) for k in range(3)], axis=1)
    return s / np.maximum(np.linalg.norm(s, axis=1, keepdims=True), 1e-300)
