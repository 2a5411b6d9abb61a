"""The final gather's rays shared among an image's pixels by what one ray's noise costs each.

A pixel's gathered light averages ``n_i`` rays, each an estimate of variance ``v_i`` (one ray's
``pi L`` times what the pixel makes of it: ``W_d kd / pi``, the albedo's texture, the eye path's
weight through glass) that takes ``c_i`` seconds (more where its rays land near and sample the
lamps there), so the image's summed variance is ``sum_i v_i / n_i`` for ``sum_i c_i n_i``
seconds.  For given seconds it is least at ``n_i`` proportional to ``sqrt(v_i / c_i)`` (Neyman
allocation).

The first sub-pixel sample gathers the same rays in every pixel and measures ``v`` and ``c``
there.  The samples after it take rays in proportion to ``sqrt(v / c)`` of the pixel's neighbours
in a (2 :data:`RADIUS` + 1)² window, the pixel itself left out: a pixel's rays then depend on
its own samples only through the one scale that makes them spend the seconds equal rays would
(a sum over all pixels), and each of its samples' means stays unbiased.  No pixel takes fewer than :data:`FLOOR` of the average: a neighbourhood may not show
a pixel's own thin detail.  Where the light varies little (a box's walls) the shares are near
equal; beside small bright patches (a window's sunlit reveal) the pixels that see them take more.
"""
from __future__ import annotations

import numpy as np


class GatherAllocation:
    """Rays per sub-pixel sample for the pixels of a ``height`` x ``width`` image whose
    gather averages ``per_sample`` rays a sample (stochastically rounded, from ``rng``);
    ``used`` counts each pixel's rays so far (the next index of its R_2 sequence)."""

    #: the neighbourhood's half width, in pixels
    RADIUS = 2
    #: the fewest rays a pixel takes, as a share of the average
    FLOOR = 0.25

    def __init__(self, height, width, per_sample, rng):
        self.shape, self.per_sample, self.rng = (int(height), int(width)), int(per_sample), rng
        self.used = np.zeros(self.shape[0] * self.shape[1], np.int64)
        self.rate = None            # (H W,) rays per sample a pixel takes once measured
        #: whether the next gather should measure its rays' variance (it takes at least two)
        self.measuring = self.per_sample >= 2

    def rays(self, pixels):
        """(N,) int: the rays each of ``pixels`` (N,) gathers at this sample (at least 1)."""
        if self.rate is None:
            return np.full(len(pixels), max(self.per_sample, 1), np.int64)
        r = self.rate[pixels]
        whole = np.floor(r)
        return np.maximum(1, whole + (self.rng.random(len(pixels)) < r - whole)).astype(np.int64)

    def measure(self, pixels, variance, cost=None):
        """Share the later samples' rays by one ray's ``variance`` (N,) and ``cost`` (N,) (in any
        unit; default equal) in ``pixels`` (N,), each pixel once (module docstring)."""
        self.measuring = False
        if len(pixels) == 0:
            return
        cost = np.ones(len(pixels)) if cost is None else np.asarray(cost, float)
        v, c = self._around(pixels, variance), self._around(pixels, cost)
        weight = np.sqrt(v / np.maximum(c, 1e-300))
        self.rate = self.per_sample * shares(weight, weight[pixels], cost, self.FLOOR)

    def _around(self, pixels, values):
        """(H W,) the mean of ``values`` (N,) at ``pixels`` over each pixel's window, the pixel
        left out (the mean of all where none of the others is measured)."""
        h, w = self.shape
        total, count = np.zeros(h * w), np.zeros(h * w)
        total[pixels], count[pixels] = values, 1.0
        # (the window sums are differences of running sums: clipped at 0 against their rounding)
        around_total = np.maximum(window_sums(total.reshape(h, w), self.RADIUS).ravel() - total, 0)
        around_count = window_sums(count.reshape(h, w), self.RADIUS).ravel() - count
        return np.where(around_count > 0.5, around_total / np.maximum(around_count, 1), float(np.mean(values)))


def window_sums(a, radius):
    """(H, W) sums of ``a`` (H, W) over each element's (2 ``radius`` + 1)² window (clipped at
    the borders)."""
    n = 2 * radius + 1
    c = np.pad(np.cumsum(np.cumsum(np.pad(a, radius), 0), 1), ((1, 0), (1, 0)))
    return c[n:, n:] - c[:-n, n:] - c[n:, :-n] + c[:-n, :-n]


def shares(weight, measured, cost, floor):
    """``max(floor, k weight)`` (same shape as ``weight``), each point's share of an average of 1,
    in proportion to its weight and never below ``floor``: ``k`` such that the ``measured`` points
    (their weights, and ``cost`` (M,) of a ray each) spend what shares of 1 would,
    ``sum cost max(floor, k measured) = sum cost``."""
    budget = float(np.sum(cost))
    if not np.sum(cost * measured) > 0:
        return np.ones_like(weight)
    lo, hi = 0.0, budget / float(np.sum(cost * measured))       # at hi the spending is at least the budget
    for _ in range(50):                       # the spending grows with k
        k = 0.5 * (lo + hi)
        lo, hi = (k, hi) if np.sum(cost * np.maximum(floor, k * measured)) < budget else (lo, k)
    return np.maximum(floor, 0.5 * (lo + hi) * weight)
