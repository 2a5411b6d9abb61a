"""The world light's samples, compiled: :meth:`~raybundle.lights.world_light.WorldLight.sample`
as one loop over the samples, where the kernels are on (:mod:`raybundle.util.compiled`).

Each sample takes its pixel by inverting the cumulative brightness, or, drawn by its side's
guide, a cell of the sky by the guide's cumulative probabilities and then a pixel inside the
cell by the brightness cumulated cell by cell: the NumPy path's binary searches (the same
``searchsorted(..., side="right")``) and arithmetic, so both give the same directions,
densities and radiance (``tests/test_compiled_lights.py``).  The NumPy path searches the whole
image's cumulative brightness for every sample, also those its guide then draws; here each
sample searches only the table it uses, and only where its answer lies: the guide's row of its
side, the cell's pixels, and for the brightness the range a cut-point table gives (the first
index above ``b T / M`` for each of M buckets, T the total: a key in bucket b has its answer
between the cut points of buckets b - 1 and b + 2, a bucket of margin on either side for the
rounding of ``x M``), where a search of the whole table over a large sky image missed the cache
at nearly every step.

:func:`world_guides` makes :meth:`~raybundle.lights.world_light.WorldLight.guide_at`'s guides
side by side in one loop, where the NumPy path makes a dozen (sides, cells) arrays; its sums
run in order, so its guides may differ from the NumPy path's (pairwise sums) in the last bits.
"""
from __future__ import annotations

import numpy as np

from ..util.compiled import helper, kernel


def world_sample(wl, u, guide=None, sides=None):
    """``(directions (N, 3), pdf (N,) [1/sr], radiance (N, 3))`` of
    :meth:`~raybundle.lights.world_light.WorldLight.sample` for world light ``wl``."""
    n = len(u)
    d, pdf, radiance = np.empty((n, 3)), np.empty(n), np.empty((n, 3))
    if guide is None:
        share, cdf_g, prob, at = np.zeros(0), np.zeros(0), np.zeros(0), np.zeros(n, np.int64)
    else:
        (share, cdf_g, prob), at = guide, np.asarray(sides, np.int64)
    f = np.ascontiguousarray
    tables = [f(t, np.int64) for t in wl.tables()[:5]] + [f(t, float) for t in wl.tables()[5:]]
    _world_sample(f(u, float), guide is not None, f(share, float), f(cdf_g, float), f(prob, float), f(at),
                  *tables, f(wl.world.image, float), float(wl.total), d, pdf, radiance)
    return d, pdf, radiance


#: cut-point buckets per entry of the cumulative brightness (module docstring)
CUTS_PER_PIXEL = 1 / 16


def cut_points(cdf):
    """(M + 2,) the first index of the cumulative brightness ``cdf`` above ``b T / M`` for
    b = 0 .. M + 1 (module docstring)."""
    m = max(1, int(len(cdf) * CUTS_PER_PIXEL))
    return np.searchsorted(cdf, np.arange(m + 2) / m * cdf[-1], side="right").astype(np.int64)


def world_guides(wl, bundle_sums, seen, share, equal, most, rows, cols):
    """``(share (U,), cdf (U cells,), prob (U cells,))``: :meth:`~raybundle.lights.world_light.WorldLight.guide_at`'s
    guide of sides ``seen`` (U,) from the bundles' sums
    (:class:`~raybundle.lights.world_light.SideSums`) or None and ``wl's learned
    sums (weighted ``min(hits, most) / equal``), blurred over the ``rows`` x ``cols`` cells;
    ``share`` for the sides with sums."""
    u, cells = len(seen), rows * cols
    out = np.empty(u), np.empty(u * cells), np.empty(u * cells)
    bundle = (np.zeros(0, np.int64), np.zeros((0, cells), np.float32)) if bundle_sums is None else \
        (bundle_sums.row, bundle_sums.sums)
    _guides(bundle, np.ascontiguousarray(seen, np.int64), wl.learned_rows(), float(share), float(equal), float(most),
            rows, cols, *out)
    return out


def _sample_guides():
    return ((np.array([0, -1], np.int64), np.ones((1, 8), np.float32)), np.array([0, 1], np.int64),
            (np.array([0, -1], np.int64), np.array([3], np.int64), np.ones((1, 8), np.float32)),
            0.8, 4.0, 64.0, 2, 4, np.empty(2), np.empty(16), np.empty(16))


@kernel(_sample_guides)
def _guides(bundle, seen, learned, share, equal, most, rows, cols, share_out, cdf, prob):
    row_of, hits, sums = learned
    bundle_row, bundle_sums = bundle
    cells = rows * cols
    g, a = np.empty(cells), np.empty(cells)
    for u in range(len(seen)):
        g[:] = 0.0
        b = bundle_row[seen[u]] if bundle_row.shape[0] > 0 else -1
        if b >= 0:
            t = 0.0
            for c in range(cells):
                t += float(bundle_sums[b, c])
            t = t if t > 0 else 1.0
            for c in range(cells):
                g[c] = float(bundle_sums[b, c]) / t
        r = row_of[seen[u]]
        if r >= 0:
            w = min(hits[r], most) / equal
            t = 0.0
            for c in range(cells):
                t += float(sums[r, c])
            t = t if t > 0 else 1.0
            for c in range(cells):
                g[c] = g[c] + float(sums[r, c]) / t * w
        for i in range(rows):                     # azimuth wraps round, the poles do not
            for j in range(cols):
                k = i * cols + j
                a[k] = (g[k] + g[i * cols + (j - 1) % cols]) + g[i * cols + (j + 1) % cols]
        total = 0.0
        base = u * cells
        for i in range(rows):
            for j in range(cols):
                k = i * cols + j
                v = a[k]
                if i > 0:
                    v = v + a[k - cols]
                if i < rows - 1:
                    v = v + a[k + cols]
                prob[base + k] = v
                total += v
        has = total > 0
        share_out[u] = share if has else 0.0
        run = 0.0
        step = (1.0 - 1.0 / cells) / (cells - 1)
        for k in range(cells):
            p = prob[base + k] / total if has else prob[base + k]
            prob[base + k] = p
            run += p
            cdf[base + k] = (run if has else (1.0 if k == cells - 1 else k * step + 1.0 / cells)) + u


def _sample_world():
    z = np.zeros(4)
    i = np.arange(4, dtype=np.int64)
    return (np.full((2, 3), 0.5), True, np.full(1, 0.8), np.linspace(0.25, 1.0, 4), np.full(4, 0.25),
            np.zeros(2, np.int64), np.array([0, 2, 4, 4], np.int64), i, i, i, i, np.linspace(0.25, 1.0, 4), np.linspace(0.25, 1.0, 4), z, z + 0.25,
            z + 0.25, np.ones(2), np.array([1.0, 0.0, -1.0]), np.ones((2, 2, 3)), 1.0, np.empty((2, 3)),
            np.empty(2), np.empty((2, 3)))


@helper
def _search_right(a, v, lo, hi):
    """``np.searchsorted(a, v, side="right")`` on sorted ``a`` whose answer lies in [lo, hi]:
    the first index whose value is above ``v`` (``hi`` if none below it)."""
    while lo < hi:
        mid = lo + ((hi - lo) >> 1)
        if v < a[mid]:
            hi = mid
        else:
            lo = mid + 1
    return lo


@kernel(_sample_world)
def _world_sample(u, guided, share, cdf_g, prob, sides, cut, order, cell_first, cell_last, pixel_cell, cdf, cum,
                  cell_before, cell_weight, p, omega, z_edges, image, total, d, pdf, radiance):
    cells = len(cell_weight)
    w = image.shape[1]
    n_p = len(p)
    m = len(cut) - 2
    for i in range(len(u)):
        x = u[i, 0]
        side = sides[i]
        by_guide = False
        if guided:
            a = share[side]
            by_guide = x < a
            x = (x if by_guide else x - a) / (a if by_guide else 1.0 - a)
        if by_guide:
            j = min(max(_search_right(cdf_g, side + x, side * cells, (side + 1) * cells), side * cells),
                    (side + 1) * cells - 1)
            c = j - side * cells
            p_c = prob[j]
            frac = min(max((side + x - (cdf_g[j] - p_c)) / max(p_c, 1e-300), 0.0), 1.0)
            target = cell_before[c] + frac * cell_weight[c]
            q = _search_right(cum, target, cell_first[c], cell_last[c] + 1)
            k = order[min(max(q, cell_first[c]), cell_last[c])]
        else:
            b = min(int(x * m), m - 1)
            k = min(_search_right(cdf, x * cdf[n_p - 1], cut[max(b - 1, 0)], cut[b + 2]), n_p - 1)
        row, col = k // w, k % w
        z = z_edges[row] + (z_edges[row + 1] - z_edges[row]) * u[i, 1]
        phi = np.pi * (1.0 - 2.0 * (col + u[i, 2]) / w)
        s = np.sqrt(max(0.0, 1.0 - z * z))
        d[i, 0], d[i, 1], d[i, 2] = s * np.cos(phi), s * np.sin(phi), z
        q = p[k] / omega[row]
        if guided:
            cell = pixel_cell[k]
            cw = cell_weight[cell]
            g = prob[side * cells + cell] / (cw if cw > 0 else 1.0) * total
            q = q * (share[side] * g + (1.0 - share[side]))
        pdf[i] = q
        radiance[i, 0], radiance[i, 1], radiance[i, 2] = image[row, col, 0], image[row, col, 1], image[row, col, 2]
