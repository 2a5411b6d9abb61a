"""The incoming first shot per patch side (thesis 3.4), used inside the iteration: for every
light l the side-average irradiance ``E_{i,l}`` [W/m^2] and its mean travel direction
``w_{i,l}``, so the first-shot radiance is ``L1_i(w) = sum_l E_{i,l} f_i(w_{i,l}, w)`` (only
incoming values are stored, the BRDF is applied on the fly).  Its glossy reflections, the
caustic first shot, are :mod:`raybundle.lights.caustics`."""
from __future__ import annotations

import numpy as np

from ..tracing.sampling import points_on_triangles
from ..util.arrays import stable_order
from .direct import DirectLighting, may_light


class PatchFirstShot:
    """Incoming first shot per patch, refined progressively while the solver iterates.

    For every side i (:mod:`raybundle.scene.model`) and light l it keeps running sums
    over uniformly random points of the side and light samples of the
    irradiance ``e cos_x V`` (:meth:`DirectLighting.light_samples_at`) and of the
    irradiance-weighted travel direction, divided by the side's receiving area
    (``receiving_area`` (S,); buried parts receive nothing).  ``E`` (S, L, 3)
    [W/m^2] is the side-average irradiance, ``direction`` (S, L, 3) the mean
    travel direction.  Samples are kept per triangle side (tside) that some light is in front of
    (:attr:`receiving_tsides`: their rows of the sums), the others receiving nothing.

    A fixed first shot would freeze its Monte Carlo noise into the solution (a
    bias that no number of iterations removes); refining it with a few shadow
    rays per iteration (:meth:`refine`) keeps E a running average of unbiased
    samples.  Half of those go round robin over the tsides, half where the
    noise is: to the sides in proportion to ``A_s sigma_s`` (Neyman's allocation,
    which minimises the variance ``sum_s A_s^2 sigma_s^2 / n_s`` of the light's power
    over the sides), ``sigma_s`` the spread of the side's samples of ``sum_l e``
    (their mean over RGB; pilot samples, below) and ``n_s`` the number of its samples.  A side cut by a lamp's edge
    or plane, lit on a small part of its area, has samples of 0 and of nearly
    pi Le: round robin alone leaves its power a few samples' guess.

    The spread is measured on ``pilot_samples`` per side drawn at the start and kept out
    of E (two-phase sampling).  Were E's own samples to decide where more samples go, a
    side whose samples happened to be high would be refined down to its mean while one
    whose samples happened to be low (a side lit on a sliver, all of whose samples missed
    the light) would not be, and E would be low on average: where the samples drawn do
    not depend on the values averaged, each tside's mean is unbiased.

    For glossy patches the reflected first shot uses one mean
    direction per light, ``E f(w_mean, w)``: an approximation (exact for point
    lights, close for lights small as seen from the patch), used only inside
    the iteration; the image's direct light is per pixel and exact.  ``directed`` (S,) bool
    (default all): the sides whose ``direction`` is kept (the glossy ones); the others' rows of
    it stay zero and their tsides keep no direction sums.
    """

    def __init__(self, direct: DirectLighting, rng, initial_samples=16, receiving_area=None, pilot_samples=4,
                 directed=None):
        self.direct = direct
        # average over the area that can receive light (see RayTracer.open_fraction)
        sc = direct.scene
        self.receiving_area = sc.patch_area[sc.side_patch] if receiving_area is None else receiving_area
        self.rng = rng
        self.scene = sc
        self.lights = direct.sampled_lights()
        n_l = len(self.lights)
        self._next = 0
        # per side: pilot samples, and the sums of their sum_l e (mean over RGB) and its square
        self._side_n = np.zeros(sc.n_sides)
        self._side_y = np.zeros(sc.n_sides)
        self._side_y2 = np.zeros(sc.n_sides)
        self.E = np.zeros((sc.n_sides, n_l, 3))
        self._d_patch = np.zeros((sc.n_sides, n_l, 3))
        self.direction = np.zeros((sc.n_sides, n_l, 3))
        # tsides that no light is in front of receive nothing: they cost no samples
        origin, normal = sc.triangle_corners[sc.tside_triangle, 0], np.asarray(sc.tside_normal)
        self.receiving_tsides = np.nonzero(np.any([light.in_front(origin, normal) for light in self.lights],
                                            axis=0))[0].astype(np.int32) if n_l else np.zeros(0, np.int32)
        del origin, normal
        n_r = len(self.receiving_tsides)
        # the sums and counts per receiving tside (row), light, RGB, in 32 bits: one to a few
        # (TS, 3) arrays held through the render, where the sides' E and direction take 64
        self._e_sum = np.zeros((n_r, n_l, 3), np.float32)
        # the direction sums of the receiving tsides of directed sides, by their row there (-1: none)
        side_of = sc.tside_side[self.receiving_tsides]
        kept = np.ones(n_r, bool) if directed is None else np.asarray(directed, bool)[side_of]
        self._d_row = np.where(kept, np.cumsum(kept) - 1, -1).astype(np.int32)
        self._d_sum = np.zeros((int(kept.sum()), n_l, 3), np.float32)
        self._count = np.zeros(n_r, np.float32)
        # each receiving tside's share of its side's receiving tsides' area (Neyman's draws, _targeted)
        ts_area = sc.triangle_area[sc.tside_triangle[self.receiving_tsides]]
        ts_side = sc.tside_side[self.receiving_tsides]
        self._share_in_side = (ts_area / np.maximum(np.bincount(ts_side, ts_area, minlength=sc.n_sides)[ts_side],
                                                    1e-300)).astype(np.float32)
        # initial_samples per side into E, shared out over a cluster's triangles by area (each
        # receiving tside's mean needs one at least); pilot_samples per side into the spread,
        # shared out the same way where a side has at most as many receiving tsides, else each
        # at a point uniform over the side's receiving area (on a tside drawn by area)
        counts = sc.tside_samples(initial_samples)[self.receiving_tsides]
        for r in range(initial_samples if n_r else 0):
            self._add_in_steps(np.nonzero(counts > r)[0], form=False)
        self._form()                             # E and direction from the sums, once
        for rows in self._pilot_rows(pilot_samples, ts_side):
            self._add_in_steps(rows, pilot=True)

    def _pilot_rows(self, k, ts_side):
        """Each round's rows (of :attr:`receiving_tsides`, whose sides are ``ts_side``) for ``k``
        pilot samples a side: a side with at most ``k`` receiving tsides shares them out by area
        (:meth:`~raybundle.scene.model.PatchScene.tside_samples`), each other side takes one a
        round on a tside drawn by area, so that its points are uniform over its receiving area."""
        counts = self.scene.tside_samples(k)[self.receiving_tsides]
        few = np.bincount(ts_side)[ts_side] <= k
        order, side = stable_order(ts_side[~few])
        order = np.flatnonzero(~few)[order]
        first = np.flatnonzero(np.r_[True, side[1:] != side[:-1]]) if len(side) else np.zeros(0, np.int64)
        last = np.r_[first[1:], len(side)] - 1          # each such side's rows in ``order``
        cdf = np.cumsum(self._share_in_side[order], dtype=float)
        before = cdf[first] - self._share_in_side[order[first]]
        for r in range(k if len(ts_side) else 0):
            at = np.searchsorted(cdf, before + self.rng.random(len(first)) * (cdf[last] - before), side="right") \
                if len(first) else np.zeros(0, np.int64)
            yield np.r_[np.nonzero(few & (counts > r))[0], order[np.clip(at, first, last)]]

    def _add_in_steps(self, rows, pilot=False, form=True):
        """:meth:`_add` of ``rows`` in steps: bounded temporaries on big scenes (a row's are a few
        hundred bytes)."""
        step = 1 << 16
        for lo in range(0, len(rows), step):
            self._add(rows[lo:lo + step], pilot, form)

    @property
    def n_lights(self):
        return len(self.lights)

    def _add(self, rows, pilot=False, form=True):
        """One new sample on each receiving tside of ``rows`` (distinct rows of
        :attr:`receiving_tsides`): into E and direction (with ``form`` False into their sums
        only, :meth:`_form` to make them after), or with ``pilot`` into the sides' spread only
        (class docstring)."""
        sc = self.scene
        tri = self.receiving_tsides[rows]
        u = self.rng.random((len(tri), 2))
        pts = points_on_triangles(sc.triangle_corners[sc.tside_triangle[tri]], u[:, 0], u[:, 1])
        nrm = sc.tside_normal[tri]
        d_row = self._d_row[rows]
        d = np.nonzero(d_row >= 0)[0]                  # the rows whose direction sums are kept
        if not pilot and form:
            # the means in 64 bits: E's updates then add up to what _form makes of the sums
            old = self._e_sum[rows] / np.maximum(self._count[rows], 1).astype(float)[:, None, None]
            old_d = self._d_sum[d_row[d]] / np.maximum(self._count[rows[d]], 1).astype(float)[:, None, None]
        y = np.zeros(len(tri))
        for li, light in enumerate(self.lights):
            u_l = self.rng.random((len(tri), 3))
            at = np.nonzero(may_light(light, pts, nrm))[0]       # elsewhere the light gives nothing
            if len(at) == 0:
                continue
            e, travel, _ = self.direct.light_samples_at(pts[at], nrm[at], light, u_l[at],
                                                        receivers=sc.link_groups(sc.tside_triangle[tri[at]]))
            y[at] += e.mean(axis=1)
            if not pilot:
                self._e_sum[rows[at], li] += e
                kept = d_row[at] >= 0
                self._d_sum[d_row[at][kept], li] += e[kept].sum(axis=1, keepdims=True) * travel[kept]
        side = sc.tside_side[tri]
        if pilot:
            self._side_n += np.bincount(side, minlength=sc.n_sides)
            self._side_y += np.bincount(side, y, minlength=sc.n_sides)
            self._side_y2 += np.bincount(side, y * y, minlength=sc.n_sides)
            return
        self._count[rows] += 1
        if not form:
            return
        # side average = sum over its tsides of area * (tside mean) / side area
        w = (sc.triangle_area[sc.tside_triangle[tri]] / self.receiving_area[side])[:, None, None]
        new = self._e_sum[rows] / self._count[rows].astype(float)[:, None, None]
        p, at = np.unique(side, return_inverse=True)
        self.E[p] += _summed(at, len(p), w * (new - old))
        if len(d):
            new_d = self._d_sum[d_row[d]] / self._count[rows[d]].astype(float)[:, None, None]
            p, at = np.unique(side[d], return_inverse=True)
            self._d_patch[p] += _summed(at, len(p), w[d] * (new_d - old_d))
            norm = np.linalg.norm(self._d_patch[p], axis=2, keepdims=True)
            self.direction[p] = np.where(norm > 0, self._d_patch[p] / np.maximum(norm, 1e-300), 0.0)

    def sums(self):
        """Copies of the sums and counts ``(e_sum, d_sum, count)`` per receiving tside (``d_sum``
        those of directed sides) that ``E`` and ``direction`` are formed from (what chains pool,
        :mod:`raybundle.app.chains`)."""
        return self._e_sum.copy(), self._d_sum.copy(), self._count.copy()

    def set_sums(self, e_sum, d_sum, count):
        """Replace the sums and counts per receiving tside (e.g. those of several chains pooled,
        :mod:`raybundle.app.chains`) and recompute ``E`` and ``direction`` from them."""
        self._e_sum, self._d_sum, self._count = e_sum.copy(), d_sum.copy(), count.copy()
        self._form()

    def _form(self):
        """``E`` and ``direction`` made from the sums and counts per receiving tside: the
        side's area-weighted mean of its tsides' means."""
        sc = self.scene
        ts = self.receiving_tsides
        side = sc.tside_side[ts]
        n = sc.n_sides
        # each tside's weight over its count: area / side's receiving area / samples
        w = (sc.triangle_area[sc.tside_triangle[ts]] / np.maximum(self.receiving_area[side], 1e-300)
             / np.maximum(self._count, 1))[:, None]
        d = self._d_row >= 0
        side_d, w_d = side[d], w[d]               # the directed rows, in the order of the direction sums
        for li in range(self.E.shape[1]):        # a light at a time: temporaries of (TS, 3)
            self.E[:, li] = _summed(side, n, w * self._e_sum[:, li])
            self._d_patch[:, li] = _summed(side_d, n, w_d * self._d_sum[:, li])
        norm = np.linalg.norm(self._d_patch, axis=2, keepdims=True)
        self.direction = np.where(norm > 0, self._d_patch / np.maximum(norm, 1e-300), 0.0)

    def refine(self, n_samples):
        """``n_samples`` more samples: one on each of the next ``n_samples / 2`` receiving tsides
        (round robin), the rest on the sides in proportion to ``A_s sigma_s`` (class docstring),
        each on a tside of the side drawn by area."""
        n_t = len(self.receiving_tsides)
        if n_t == 0 or n_samples <= 0:
            return
        targeted = self._targeted(n_samples - n_samples // 2 if n_samples > 1 else 0)
        k = (self._next + np.arange(min(n_samples - len(targeted), n_t))) % n_t
        self._next = int((self._next + len(k)) % n_t)
        self._add(k)
        while len(targeted):                       # _add takes distinct rows: in rounds
            first, at = np.unique(targeted, return_index=True)
            self._add(first)
            targeted = np.delete(targeted, at)

    def _targeted(self, n):
        """(n,) rows of receiving tsides drawn for Neyman's allocation (with repeats): a side with
        probability ``A_s sigma_s / sum`` (``sigma_s`` from the pilot samples), then a tside of it
        by area; none where no side's pilot samples spread."""
        n_s = np.maximum(self._side_n, 1)
        var = np.maximum(self._side_y2 / n_s - (self._side_y / n_s) ** 2, 0.0) * self._side_n / np.maximum(n_s - 1, 1)
        weight = self.receiving_area * np.sqrt(var)
        total = weight.sum()
        if n <= 0 or not total > 0:
            return np.zeros(0, np.int64)
        ts = self.receiving_tsides
        # one draw: a tside with probability weight(side) * its share of the side's area
        cdf = np.cumsum(weight[self.scene.tside_side[ts]] * self._share_in_side)
        return np.minimum(np.searchsorted(cdf, self.rng.random(n) * cdf[-1], side="right"), len(ts) - 1)


def _summed(group, n, values):
    """(n, ...) the sums of ``values`` (N, ...) by ``group`` (N,) in [0, n) (``np.add.at``'s
    result, by one bincount per column: many times faster)."""
    flat = values.reshape(len(values), int(np.prod(values.shape[1:])))
    out = np.empty((n, flat.shape[1]))
    for c in range(flat.shape[1]):
        out[:, c] = np.bincount(group, flat[:, c], minlength=n)
    return out.reshape((n,) + values.shape[1:])
