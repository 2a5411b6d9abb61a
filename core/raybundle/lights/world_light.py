"""Direct light of the world at surface points, importance-sampled by the world's brightness.

The irradiance the world gives a point ``x`` with normal ``n`` directly (along unblocked
directions) is

    E_w(x) = integral L_w(w) max(0, n.w) V(x, w) dw                      [W/m^2]

estimated with directions drawn from the world's image (:mod:`raybundle.scene.world`): a
pixel with probability proportional to its brightest channel times its solid angle, then
a direction uniform in solid angle inside the pixel, so that ``pdf(w) = P_pixel / Omega_pixel``
[1/sr] and ``E_w ~ (1/K) sum_k L_w(w_k) max(0, n.w_k) V(x, w_k) / pdf(w_k)`` with one
shadow ray per sample.  Every pixel that sends light can be drawn, so the estimate is
unbiased.  Bright skies and suns seen through windows are found at once, where cosine
sampling or the patch solution meet them by chance or smear them over a patch.

Through a room's windows most of the sky is hidden: drawn by brightness alone, few samples
reach the sky (docs/benchmarks.md).  Each side then draws
``GUIDE_SHARE`` of its samples by a *guide*, a distribution over cells of the sky: what the
solver's bundles brought the side from each cell, and what the image passes' own samples on
that side found open (:meth:`WorldLight.learn`: ``L cos / pdf`` of each unblocked sample by its
cell, an unbiased estimate of the cell's share of the side's irradiance, whichever density drew
it).  A bundle direction crosses a window rarely (16 directions per iteration against the
passes' thousands of samples per side), so once a side has ``LEARNED_EQUAL`` unblocked samples
its learned guide weighs as much as the bundles', and more as they grow.  The guide is spread
over each cell's neighbours and mixed with the brightness (1 - ``GUIDE_SHARE``): every pixel
that sends light keeps a density, so the estimate stays unbiased whatever the guide.
"""
from __future__ import annotations

import numpy as np

from ..scene.world import World, pixel_of
from ..util import compiled
from . import compiled_world
from .direct import DirectLighting

#: the guide cells of the sky: bands of polar angle x sectors of azimuth, each a block of the
#: world image's pixels (module docstring)
GUIDE_ROWS, GUIDE_COLS = 16, 32
GUIDE_CELLS = GUIDE_ROWS * GUIDE_COLS
#: the share of a side's samples drawn by its guide (the rest by the world's brightness alone)
GUIDE_SHARE = 0.8
#: unblocked samples of a side's own after which its learned guide weighs as much as the
#: bundles' (in proportion to them, up to LEARNED_MAX of them: 16 times as much)
LEARNED_EQUAL = 4
LEARNED_MAX = 64


def guide_cell(directions, h, w):
    """(N,) the guide cell (module docstring) of the unit ``directions`` (N, 3), towards the sky,
    for a world image ``h`` x ``w``."""
    row, col = pixel_of(directions, h, w)
    return _pixel_cell(row, col, h, w)


def _blurred(g):
    """Guide sums (U, cells) spread over each cell and its eight neighbours (azimuth wraps
    round, the poles do not): a cell next to where the bundles found the sky open is likely
    open too, and a guide that leaves it out would weight its samples up to 1 / (1 - share)."""
    g = g.reshape(len(g), GUIDE_ROWS, GUIDE_COLS)
    a = g + np.roll(g, 1, axis=2) + np.roll(g, -1, axis=2)
    out = a.copy()
    out[:, 1:] += a[:, :-1]
    out[:, :-1] += a[:, 1:]
    return out.reshape(len(g), GUIDE_CELLS)


class SideSums:
    """Per side a row of sums over the sky's guide cells, made when the side first gets a value
    (``row`` (S,): its row, -1 none yet; ``sums`` (rows, cells) float32, grown by half when
    full): what reaches some sides of a room costs their rows, not a (sides, cells) array."""

    def __init__(self, n_sides):
        self.row = np.full(n_sides, -1, np.int64)
        self.sums = np.zeros((0, GUIDE_CELLS), np.float32)
        self.used = 0

    def rows(self, sides):
        """The rows of ``sides`` (M,), made for those without one."""
        new = np.unique(sides[self.row[sides] < 0])
        if len(new):
            self.row[new] = self.used + np.arange(len(new))
            self.used += len(new)
            if self.used > len(self.sums):
                more = max(self.used, (3 * len(self.sums)) // 2) - len(self.sums)
                self.sums = np.vstack([self.sums, np.zeros((more, GUIDE_CELLS), np.float32)])
        return self.row[sides]

    def add(self, sides, cell, values):
        """Add ``values`` (M,) to distinct ``sides`` (M,) in guide ``cell``."""
        rows = self.rows(sides)                  # first: it may grow the sums
        self.sums[rows, cell] += values.astype(np.float32)

    def of(self, sides):
        """(M, cells) float64 the sums of ``sides`` (zero for sides without a row)."""
        out = np.zeros((len(sides), GUIDE_CELLS))
        r = self.row[sides]
        out[r >= 0] = self.sums[r[r >= 0]]
        return out


def _normalized(g):
    """Rows of ``g`` (U, cells) divided by their sums (rows of zeros stay zero)."""
    total = g.sum(axis=1, keepdims=True)
    return g / np.where(total > 0, total, 1.0)


def _pixel_cell(row, col, h, w):
    return (row * GUIDE_ROWS // h) * GUIDE_COLS + col * GUIDE_COLS // w


class WorldLight:
    """The world as a light to sample (module docstring), over a ray tracer of the scene."""

    def __init__(self, world: World, tracer):
        self.world, self.tracer = world, tracer
        img = world.image
        h, w = img.shape[:2]
        self.h, self.w = h, w
        self.omega = world.pixel_solid_angles()[:, 0]                       # (H,) sr per pixel of a row
        weight = (img.max(axis=2) * self.omega[:, None]).reshape(-1)
        total = self.total = weight.sum()
        self.emits = total > 0
        self.p = weight / total if self.emits else weight
        self.cdf = np.cumsum(self.p)
        self.z_edges = np.cos(np.linspace(0.0, np.pi, h + 1))
        # the pixels by guide cell: each cell's pixels contiguous in ``_order``, their
        # brightness cumulated in ``_cum`` (brightness by cell: ``_cell_weight``)
        rows, cols = np.divmod(np.arange(h * w), w)
        self._pixel_cell = _pixel_cell(rows, cols, h, w)
        self._order = np.argsort(self._pixel_cell, kind="stable")
        self._cum = np.cumsum(weight[self._order])
        counts = np.bincount(self._pixel_cell, minlength=GUIDE_CELLS)
        self._cell_first = np.cumsum(counts) - counts
        self._cell_last = self._cell_first + np.maximum(counts, 1) - 1
        self._cell_weight = np.bincount(self._pixel_cell, weight, minlength=GUIDE_CELLS)
        self._cell_before = np.cumsum(self._cell_weight) - self._cell_weight
        self._cut = compiled_world.cut_points(self.cdf)      # where the compiled search starts
        _, radius = tracer.scene.bounding_sphere
        self.far = 4.0 * radius + 1.0
        self.rays = 0
        # what the samples of :meth:`learn` found open, per side seen: the side's row
        # (-1: none yet), per row the sums by guide cell (rows, cells) and the unblocked samples
        self._learned = SideSums(tracer.scene.n_sides)
        self._hits = np.zeros(0, np.int64)              # per row of the learned sums

    def sample(self, u, guide=None, sides=None):
        """``(directions (N, 3), pdf (N,) [1/sr], radiance (N, 3))`` for uniforms ``u`` (N, 3),
        by brightness alone, or with ``guide`` (:meth:`guide_of`) for points on its ``sides``
        (N,: places in the sides it was made for) by the mixture (module docstring; pdf the
        mixture's)."""
        if compiled.use():
            return compiled_world.world_sample(self, u, guide, sides)
        u = np.asarray(u, float)
        x = u[:, 0]
        if guide is not None:
            share, cdf, prob = guide
            a = share[sides]
            by_guide = x < a
            x = np.where(by_guide, x, x - a) / np.where(by_guide, a, 1.0 - a)     # uniform again
        k = np.minimum(np.searchsorted(self.cdf, x * self.cdf[-1], side="right"), len(self.p) - 1)
        if guide is not None and by_guide.any():
            i = np.nonzero(by_guide)[0]
            side = sides[i]
            # the side's cell: its row of the cdf, shifted by the side's index (rows stay sorted)
            j = np.clip(np.searchsorted(cdf, side + x[i], side="right"), side * GUIDE_CELLS,
                        (side + 1) * GUIDE_CELLS - 1)
            c = j - side * GUIDE_CELLS
            p_c = prob[j]
            frac = np.clip((side + x[i] - (cdf[j] - p_c)) / np.maximum(p_c, 1e-300), 0.0, 1.0)   # uniform again
            target = self._cell_before[c] + frac * self._cell_weight[c]
            q = np.clip(np.searchsorted(self._cum, target, side="right"), self._cell_first[c], self._cell_last[c])
            k[i] = self._order[q]
        row, col = np.divmod(k, self.w)
        z = self.z_edges[row] + (self.z_edges[row + 1] - self.z_edges[row]) * u[:, 1]
        phi = np.pi * (1.0 - 2.0 * (col + u[:, 2]) / self.w)
        s = np.sqrt(np.maximum(0.0, 1.0 - z * z))
        d = np.stack([s * np.cos(phi), s * np.sin(phi), z], axis=1)
        return d, self._density(k, row, guide, sides), self.world.image[row, col]

    def learned_rows(self):
        """What :meth:`learn` has kept: each side's row (-1: none yet), each row's unblocked
        samples and its sums by guide cell (rows, cells) (:mod:`~raybundle.lights.compiled_world`;
        rows no side has yet are zero)."""
        return self._learned.row, self._hits, self._learned.sums

    def tables(self):
        """The sampling tables, integer ones first: the cumulative brightness's cut points
        (:func:`~raybundle.lights.compiled_world.cut_points`), the pixels in cell order, each cell's first
        and last place in that order, each pixel's cell; the cumulative brightness, in cell order,
        before each cell and in it; each pixel's probability, the rows' pixel solid angle and the
        rows' z edges (:mod:`~raybundle.lights.compiled_world`)."""
        return (self._cut, self._order, self._cell_first, self._cell_last, self._pixel_cell, self.cdf, self._cum,
                self._cell_before, self._cell_weight, self.p, self.omega, self.z_edges)

    def _density(self, k, row, guide, sides):
        """(N,) [1/sr] :meth:`sample`'s density in pixels ``k`` (N,) (flat index; ``row`` their
        rows), by brightness alone or by ``guide``'s mixture for points on ``sides``."""
        pdf = self.p[k] / self.omega[row]
        if guide is not None:
            share, _, prob = guide
            cell = self._pixel_cell[k]
            cw = self._cell_weight[cell]
            g = prob[sides * GUIDE_CELLS + cell] / np.where(cw > 0, cw, 1.0) * self.total
            pdf = pdf * (share[sides] * g + (1.0 - share[sides]))
        return pdf

    def density(self, directions, guide=None, sides=None):
        """(N,) [1/sr] the density :meth:`sample` draws the unit ``directions`` (N, 3) with (by
        brightness alone, or with ``guide`` for points on ``sides``): the other strategy's
        weight in a combination by multiple importance sampling."""
        row, col = pixel_of(np.asarray(directions, float), self.h, self.w)
        return self._density(row * self.w + col, row, guide, sides)

    def guide_at(self, bundle_sums, sides):
        """``(guide, at)`` for points on ``sides`` (N,): the :meth:`sample` guide of the sides
        they are on and each point's place among them (module docstring).  ``bundle_sums``
        (:class:`SideSums`) or None: what the solver's bundles brought each side from each cell; the
        sides' learned sums (:meth:`learn`) are mixed in by their unblocked samples."""
        seen, at = np.unique(np.asarray(sides), return_inverse=True)
        if compiled.use():
            return compiled_world.world_guides(self, bundle_sums, seen, GUIDE_SHARE, LEARNED_EQUAL, LEARNED_MAX,
                                               GUIDE_ROWS, GUIDE_COLS), at.reshape(-1)
        g = np.zeros((len(seen), GUIDE_CELLS))
        if bundle_sums is not None:
            g += _normalized(bundle_sums.of(seen))
        rows = self._learned.row[seen]
        has = np.nonzero(rows >= 0)[0]
        if len(has):
            weight = np.minimum(self._hits[rows[has]], LEARNED_MAX) / LEARNED_EQUAL
            g[has] += _normalized(self._learned.sums[rows[has]].astype(float)) * weight[:, None]
        return self.guide_of(g), at.reshape(-1)

    @staticmethod
    def guide_of(sums):
        """The ``guide`` of :meth:`sample` for U sides from ``sums`` (U, cells) over the sky's
        cells: per side its share (U,) and, flattened side by side, each cell's probability
        (U cells,) and cumulative probability plus the side's place (U cells,); a side without
        sums draws by brightness alone (share 0)."""
        g = _blurred(np.asarray(sums, float))
        total = g.sum(axis=1)
        has = total > 0
        prob = g / np.where(has, total, 1.0)[:, None]
        cdf = np.cumsum(prob, axis=1)
        cdf[~has] = np.linspace(1.0 / GUIDE_CELLS, 1.0, GUIDE_CELLS)       # never drawn, kept sorted
        cdf += np.arange(len(g))[:, None]
        return np.where(has, GUIDE_SHARE, 0.0), cdf.ravel(), prob.ravel()

    def learn(self, sides, directions, value):
        """Add unblocked samples to the learned guide: on ``sides`` (M,), along the unit
        ``directions`` (M, 3) towards the sky, each with ``value`` (M,) = max_c L_w cos / pdf."""
        if len(sides) == 0:
            return
        rows = self._learned.rows(sides)
        if len(self._hits) < len(self._learned.sums):          # the sums grew
            self._hits = np.concatenate([self._hits, np.zeros(len(self._learned.sums) - len(self._hits), np.int64)])
        cells = guide_cell(directions, self.h, self.w)
        np.add.at(self._learned.sums, (rows, cells), value.astype(np.float32))
        self._hits += np.bincount(rows, minlength=len(self._hits))

    def irradiance(self, points, normals, u, guide=None, lobe=None, learn=None, terminator=None):
        """(N, 3) [W/m^2] estimate of the direct irradiance from the world at ``points``
        (N, 3) with unit ``normals`` (N, 3), with ``u`` (N, K, 3) uniforms: K samples each;
        ``guide`` = ``(guide, at)`` of :meth:`guide_at` for the points, or None (by brightness
        alone).  ``learn`` (N,): the points' sides, whose learned guide the unblocked samples
        join (:meth:`learn`; the ``guide`` given is the one they were drawn by).  ``terminator``:
        the points' :class:`~raybundle.scene.shading.ShadowTerminator` or None.

        With ``lobe = (materials, idx, mats, w_out)``, also the radiance [W m^-2 sr^-1] the glossy
        lobes of materials ``mats`` at the points ``idx`` reflect towards ``w_out`` from the same
        samples, ``(1/K) sum_k L_w f_g cos / p_w`` each weighted ``(K p_w)^2 / ((K p_w)^2 + p_g^2)``
        against one lobe-sampled ray (power heuristic with the sample counts, ``p_g`` the lobe's
        density, :meth:`~raybundle.scene.materials.MaterialTable.glossy_pdf`), which then takes
        ``p_g^2 / (p_g^2 + (K p_w)^2)`` of the sky it meets: returns ``(E, glossy (len(idx), 3))``.
        The diffuse lobe's shadow rays serve the glossy lobe too, K of them where it had one.

        The points are split into pieces run in parallel
        (:meth:`~raybundle.tracing.visibility.RayTracer.map_pieces`); a point's value does not
        depend on the split but for the cut-out and glass choices of its shadow rays."""
        points, normals = np.asarray(points, float), np.asarray(normals, float)
        n, k = u.shape[:2]
        if not self.emits or n == 0:
            out = np.zeros((n, 3))
            return out if lobe is None else (out, np.zeros((len(lobe[1]), 3)))
        idx = None if lobe is None else np.asarray(lobe[1])

        def piece(a, b):
            at = None if guide is None else (guide[0], guide[1][a:b])
            lb = None
            if lobe is not None:                  # the piece's glossy points, in order
                i, j = np.searchsorted(idx, [a, b])
                lb = (lobe[0], idx[i:j] - a, lobe[2][i:j], lobe[3][i:j])
            lift = None if terminator is None else terminator.take(slice(a, b))
            return self._irradiance(points[a:b], normals[a:b], u[a:b], at, lb, learn is not None, lift)

        parts = self.tracer.map_pieces(piece, n)
        self.rays += sum(p[3] for p in parts)
        if learn is not None:                     # in the points' order, as one piece would
            first = np.cumsum([0] + [len(p[0]) for p in parts[:-1]])
            rows = np.concatenate([p[2][0] + a for p, a in zip(parts, first)])
            self.learn(np.asarray(learn)[rows], *(np.concatenate([p[2][c] for p in parts]) for c in (1, 2)))
        out = np.concatenate([p[0] for p in parts]) / k
        return out if lobe is None else (out, np.concatenate([p[1] for p in parts]) / k)

    def _irradiance(self, points, normals, u, guide, lobe, learn, terminator=None):
        """:meth:`irradiance` at one piece of its points, not divided by the samples per point:
        ``(E, glossy or None, learned, rays)``, ``learned`` the unblocked samples' points,
        directions and values for :meth:`learn` (None without ``learn``)."""
        n, k = u.shape[:2]
        out = np.zeros((n, 3))
        glossy = None if lobe is None else np.zeros((len(lobe[1]), 3))
        learned = (np.zeros(0, np.int64), np.zeros((0, 3)), np.zeros(0)) if learn else None
        rep = np.repeat(np.arange(n), k)
        g, at = (None, None) if guide is None else (guide[0], guide[1][rep])
        d, pdf, L = self.sample(u.reshape(-1, 3), g, at)
        cos = np.einsum("ij,ij->i", normals[rep], d)
        live = np.nonzero((cos > 0) & (pdf > 0))[0]
        if len(live):
            origin = points[rep[live]] + normals[rep[live]] * self.tracer.eps
            if terminator is not None:
                lifted = terminator.take(rep[live]).origins(origin, d[live], cos[live])
                origin = origin if lifted is None else lifted
            blocked = self.tracer.occluded(origin, d[live], np.full(len(live), self.far))
            ok = live[~blocked]
            contrib = L[ok] * (cos[ok] / pdf[ok])[:, None]
            if learn:
                learned = (rep[ok], d[ok], contrib.max(axis=1))
            for c in range(3):
                out[:, c] = np.bincount(rep[ok], contrib[:, c], minlength=n)
            if lobe is not None and len(lobe[1]):
                mt, idx, mats, w_out = lobe
                row = np.full(n, -1)
                row[idx] = np.arange(len(idx))
                j = ok[row[rep[ok]] >= 0]
                r = row[rep[j]]
                f = mt.brdf(mats[r], normals[rep[j]], -d[j], w_out[r], diffuse=False)
                w = DirectLighting.mis_weight(k * pdf[j], mt.glossy_pdf(mats[r], normals[rep[j]], d[j], w_out[r]))
                g = L[j] * f * (cos[j] / pdf[j] * w)[:, None]
                for c in range(3):
                    glossy[:, c] = np.bincount(r, g[:, c], minlength=len(idx))
        return out, glossy, learned, len(live)
