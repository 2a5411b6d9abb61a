"""Lightmaps: the texels a UV map covers, their radiance, and the margin around the islands.

A texel bakes the radiance at its centre's point (:func:`texel_points`), as a vertex does
(:mod:`raybundle.imaging.baking`), but for its direct light, averaged over the texel's footprint
(:func:`texel_footprints`) as Cycles' bake averages a texel; its indirect light is interpolated from
the patches, except next to concave edges and contacts, where the patch
values are not to be trusted (the sides that :meth:`~raybundle.imaging.gather.EdgeGather.near_edge`
flags).  There :class:`TexelGather` gathers it from the solution as a vertex's is gathered
(:class:`~raybundle.imaging.bake_gather.BakeGather`), with fewer rays a texel, and averages the
gather's correction (gathered minus interpolated) over a window of ``2 r + 1`` texels a side,
on the same surface only (its texels' points within twice their texel distance of each other, their
normals alike).  The window spans about a quarter of a patch (:data:`WINDOW_PER_PATCH`), so the
correction, which changes over a patch, keeps its shape, and the texels of a window share the
rays a vertex would take: ``R / (2 r + 1)^2`` a texel, at least :data:`MIN_TEXEL_RAYS`.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..tracing.footprint import Footprint
from .bake_gather import BakeGather
from .baking import baked_parts, input_rows

#: the correction's averaging window spans this share of a patch's size (its square root of area)
WINDOW_PER_PATCH = 0.25
#: the widest window's radius in texels
MAX_RADIUS = 4
#: the fewest gather rays a texel
MIN_TEXEL_RAYS = 8


@dataclass
class Texels:
    """Lightmap texels covered by UV triangles: flat texel index ``y * width + x`` (N,)
    (row y = 0 at v = 0, the bottom: Blender's image order), the triangle (N,) (an
    index into the ``uv`` array given) and barycentrics on it (N, 3); ``overlap``: how
    many texels more than one triangle claimed (overlapping UV islands: the last one
    in triangle order wins)."""

    texel: np.ndarray
    triangle: np.ndarray
    bary: np.ndarray
    overlap: int = 0


def texel_points(uv, width, height, chunk=1 << 22):
    """The texels whose centres ``((x + 0.5) / W, (y + 0.5) / H)`` lie in UV triangles
    ``uv`` (T, 3, 2) (u right, v up, the unit square is the image), with each centre's
    barycentrics on its triangle: the points a lightmap bakes.  Texels on an edge shared
    by two triangles of one island go to one of them (the same point either way).
    Degenerate UV triangles (zero area) cover nothing.  Returns :class:`Texels`."""
    uv = np.asarray(uv, float)
    w, h = int(width), int(height)
    if w < 1 or h < 1:
        raise ValueError("the lightmap size must be at least 1 x 1")
    p = uv * np.array([w, h]) - 0.5                          # texel-centre coordinates
    lo = np.ceil(p.min(axis=1) - 1e-9).astype(np.int64)
    hi = np.floor(p.max(axis=1) + 1e-9).astype(np.int64)
    lo = np.maximum(lo, 0)
    hi = np.minimum(hi, [w - 1, h - 1])
    a = p[:, 1] - p[:, 0]
    b = p[:, 2] - p[:, 0]
    det = a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0]
    nx, ny = np.maximum(hi[:, 0] - lo[:, 0] + 1, 0), np.maximum(hi[:, 1] - lo[:, 1] + 1, 0)
    count = np.where(np.abs(det) > 1e-12, nx * ny, 0)
    bounds = np.concatenate([[0], np.cumsum(count)])
    texels, tris, barys = [], [], []
    t0 = 0
    n_tri = len(uv)
    while t0 < n_tri:
        t1 = max(t0 + 1, int(np.searchsorted(bounds, bounds[t0] + chunk, "right")) - 1)
        t1 = min(t1, n_tri)
        c = count[t0:t1]
        tri = np.repeat(np.arange(t0, t1), c)
        k = np.arange(int(c.sum())) - np.repeat(bounds[t0:t1] - bounds[t0], c)     # index inside the box
        x = lo[tri, 0] + k % np.maximum(nx[tri], 1)
        y = lo[tri, 1] + k // np.maximum(nx[tri], 1)
        d = np.stack([x, y], axis=1) - p[tri, 0]
        b1 = (d[:, 0] * b[tri, 1] - d[:, 1] * b[tri, 0]) / det[tri]
        b2 = (a[tri, 0] * d[:, 1] - a[tri, 1] * d[:, 0]) / det[tri]
        b0 = 1.0 - b1 - b2
        inside = (b0 >= -1e-9) & (b1 >= -1e-9) & (b2 >= -1e-9)
        texels.append((y * w + x)[inside])
        tris.append(tri[inside])
        barys.append(np.clip(np.stack([b0, b1, b2], axis=1)[inside], 0.0, 1.0))
        t0 = t1
    texel = np.concatenate(texels) if texels else np.zeros(0, np.int64)
    tri = np.concatenate(tris) if tris else np.zeros(0, np.int64)
    bary = np.concatenate(barys) if barys else np.zeros((0, 3))
    bary /= np.maximum(bary.sum(axis=1, keepdims=True), 1e-300)
    # one triangle per texel: the last; a texel two triangles claim along a shared edge
    # is not an overlap, one claimed by triangles that do not touch it on an edge is
    last = len(texel) - 1 - np.unique(texel[::-1], return_index=True)[1]
    on_edge = np.zeros(len(texel), bool) if len(texel) == 0 else bary.min(axis=1) < 1e-6
    claims = np.bincount(texel[~on_edge], minlength=w * h) if len(texel) else np.zeros(w * h, np.int64)
    overlap = int((claims > 1).sum())
    return Texels(texel[last], tri[last], bary[last], overlap)


def dilate(image, filled, margin):
    """Fill ``margin`` texels around the filled ones (``image`` (H, W, C), ``filled``
    (H, W) bool): each step, every empty texel next to filled ones (8-neighbourhood)
    takes their mean, so bilinear lookups and mip-maps at UV seams read baked values,
    as Cycles' bake margin does.  Returns the new image and mask."""
    img = np.array(image, float)
    ok = np.array(filled, bool)
    hgt, wid = ok.shape
    for _ in range(int(margin)):
        if ok.all() or not ok.any():
            break
        pad_v = np.pad(img * ok[..., None], ((1, 1), (1, 1), (0, 0)))
        pad_n = np.pad(ok.astype(float), 1)
        total = np.zeros_like(img)
        num = np.zeros(ok.shape)
        for dy in (-1, 0, 1):
            for dx in (-1, 0, 1):
                if dx or dy:
                    total += pad_v[1 + dy:1 + dy + hgt, 1 + dx:1 + dx + wid]
                    num += pad_n[1 + dy:1 + dy + hgt, 1 + dx:1 + dx + wid]
        grow = ~ok & (num > 0)
        img[grow] = total[grow] / num[grow][:, None]
        ok = ok | grow
    return img, ok



def texel_footprints(input_scene, face, uv, texels, width, height):
    """:class:`~raybundle.tracing.footprint.Footprint` of each texel of ``texels`` (:class:`Texels` of UV
    triangles ``uv`` (T, 3, 2)) on its input face ``face`` (T,) (the values of ``input_scene``'s
    ``triangle_source``): a texel's steps on the face, ``dP/du / W`` and ``dP/dv / H``, from the
    face's corners and its UV triangle."""
    r = input_rows(input_scene, np.asarray(face)[texels.triangle])
    corners = input_scene.triangle_corners[np.maximum(r, 0)]
    t = np.asarray(uv, float)[texels.triangle]
    e = np.stack([corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]], axis=2)     # (N, 3, 2)
    m = np.stack([t[:, 1] - t[:, 0], t[:, 2] - t[:, 0]], axis=2)                            # (N, 2, 2)
    det = m[:, 0, 0] * m[:, 1, 1] - m[:, 0, 1] * m[:, 1, 0]
    det = np.where(np.abs(det) > 1e-300, det, 1e-300)
    inv = np.stack([np.stack([m[:, 1, 1], -m[:, 0, 1]], 1),
                    np.stack([-m[:, 1, 0], m[:, 0, 0]], 1)], 1) / det[:, None, None]
    j = np.einsum("nck,nkl->ncl", e, inv)                                                   # dP/d(u, v)
    return Footprint(j[:, :, 0] / width, j[:, :, 1] / height, corners)


# ------------------------------------------------------------- the gather
#: normals this alike (cosine) lie on one surface, for the texel distances and the window
_SAME_SURFACE = 0.99


def _neighbours(look, y, x, size):
    """(N,) the located texel at ``(y, x)`` (look-up ``look``: texel -> point, -1 none), -1 off the image."""
    ok = (y >= 0) & (y < size) & (x >= 0) & (x < size)
    j = np.full(len(y), -1, np.int64)
    j[ok] = look[y[ok] * size + x[ok]]
    return j


def _same_surface(points, i, j):
    """(M,) bool: points ``i`` and ``j`` (M,) face alike (:data:`_SAME_SURFACE`)."""
    return np.einsum("ij,ij->i", points.normal[i], points.normal[j]) > _SAME_SURFACE


def texel_spacing(texels, points, size):
    """(N,) [m] the distance from each texel's point to the nearest of its four neighbours' on the same
    surface; the median over the texels where it has none (or 0 with none at all)."""
    n = len(texels.texel)
    look = np.full(size * size, -1, np.int64)
    ok = np.nonzero(points.found)[0]
    look[texels.texel[ok]] = ok
    y, x = np.divmod(texels.texel[ok], size)
    out = np.full(n, np.inf)
    for dy, dx in ((0, 1), (1, 0), (0, -1), (-1, 0)):
        j = _neighbours(look, y + dy, x + dx, size)
        m = j >= 0
        i, jj = ok[m], j[m]
        same = _same_surface(points, i, jj)
        i, jj = i[same], jj[same]
        np.minimum.at(out, i, np.linalg.norm(points.point[jj] - points.point[i], axis=1))
    known = np.isfinite(out)
    out[~known] = np.median(out[known]) if known.any() else 0.0
    return out


class TexelGather:
    """One lightmap of ``size``² texels: ``texels`` (:class:`Texels`) located at ``points``
    (:class:`~raybundle.imaging.baking.SurfacePoints`).  Holds their parts but the indirect light
    (:func:`~raybundle.imaging.baking.baked_parts`, ``light_samples`` shadow rays a light, ``rng``)
    and the gather of the texels on sides that ``edges`` (an
    :class:`~raybundle.imaging.gather.EdgeGather`) flags, ``rays`` being a vertex's count (0:
    none, all interpolated): :attr:`gather`, a :class:`~raybundle.imaging.bake_gather.BakeGather`
    whose :meth:`~raybundle.imaging.bake_gather.BakeGather.advance` runs it in blocks (a stop keeps
    what is gathered); :attr:`radius` the window's, :attr:`rays` a texel's (module docstring).
    ``footprint``: the texels' :func:`texel_footprints`, over which their direct light is averaged (None:
    at their centres); ``final``: the bake's shared :class:`~raybundle.imaging.gather.FinalGather`, or
    None.  :meth:`image` is the lightmap."""

    def __init__(self, solver, texels, points, size, edges, rays, seed, light_samples, rng, penumbra_samples=None,
                 footprint=None, final=None):
        self.texels, self.points, self.size = texels, points, int(size)
        self.parts = baked_parts(solver, points, light_samples, rng, penumbra_samples, footprint)
        found = np.nonzero(points.found)[0]
        near = found[edges.near_edge(points.tside[found])] if rays and len(found) else found[:0]
        self.spacing = texel_spacing(texels, points, self.size)
        self.radius = 0
        if len(near):
            sc = solver.scene
            patch = np.sqrt(sc.patch_area[sc.triangle_patch[points.triangle[near]]])
            ratio = float(np.median(patch / np.maximum(self.spacing[near], 1e-300)))
            self.radius = int(np.clip(round((WINDOW_PER_PATCH * ratio - 1.0) / 2.0), 0, MAX_RADIUS))
        self.rays = max(MIN_TEXEL_RAYS, -(-int(rays) // (2 * self.radius + 1) ** 2)) if len(near) else 0
        self.gather = BakeGather(solver, points, seed, which=near, final=final)
        self.base = self.gather.indirect.copy()                 # the interpolated indirect light
        self.gather.start(self.rays)

    def corrections(self):
        """(G, 3) [W/m^2] the gathered texels' corrections to the interpolated indirect light,
        averaged over each one's window (module docstring), and the texels (G,)."""
        g, p, size = self.gather, self.points, self.size
        done = g.todo[:g.gathered]
        delta = g.indirect[done] - self.base[done]
        if self.radius == 0 or len(done) == 0:
            return delta, done
        look = np.full(size * size, -1, np.int64)
        look[self.texels.texel[done]] = np.arange(len(done))
        y, x = np.divmod(self.texels.texel[done], size)
        total, count = delta.copy(), np.ones(len(done))
        r = self.radius
        for dy in range(-r, r + 1):
            for dx in range(-r, r + 1):
                if not (dx or dy):
                    continue
                j = _neighbours(look, y + dy, x + dx, size)
                i = np.nonzero(j >= 0)[0]
                j = j[i]
                reach = 2.0 * np.hypot(dx, dy) * self.spacing[done[i]]
                near = (np.linalg.norm(p.point[done[j]] - p.point[done[i]], axis=1) <= reach) & \
                    _same_surface(p, done[i], done[j])
                total[i[near]] += delta[j[near]]          # each texel once an offset
                count[i[near]] += 1
        return total / count[:, None], done

    def image(self, margin):
        """The lightmap (size, size, 3) [W m^-2 sr^-1], rows bottom-up, dilated by ``margin`` texels
        (:func:`dilate`)."""
        indirect = self.base.copy()
        delta, done = self.corrections()
        indirect[done] += delta
        img = np.zeros((self.size * self.size, 3))
        img[self.texels.texel] = self.parts.radiance(indirect)
        filled = np.zeros(self.size * self.size, bool)
        filled[self.texels.texel] = self.points.found
        return dilate(img.reshape(self.size, self.size, 3), filled.reshape(self.size, self.size), margin)[0]
