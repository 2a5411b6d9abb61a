"""When image passes run, and which pixels take more samples in them.

The renderer alternates solver iterations and image passes, so that the passes take ``s`` of the
work, the image passes' share (``image_share``; by default :data:`PassSchedule.DIFFUSE_SHARE` for
diffuse scenes and :data:`PassSchedule.GLOSSY_SHARE` with glossy lobes, whose eye paths the passes
trace and whose caustic they splat).  The first pass, with every pixel a penumbra, is set-up and
left out of the passes' work; passes grow when penumbrae are found, so their mean is re-read every
time.

* A run limited by time shares its time, measured as it goes, so that cheaper passes buy more of
  them: after each iteration, passes run while the passes' seconds stay within half a pass of
  ``s / (1 - s)`` times the iterations' (several in a row where a pass costs less than that share of
  an iteration).
* A run of given iterations shares the traced rays, so that it repeats with its seed: a pass is
  due once the iterations since the last one have traced ``(1 - s) / s`` times a pass's mean rays.

:class:`~raybundle.imaging.run.RunLoop` says which (:attr:`PassSchedule.by_time`).  Within a pass,
the pixels whose estimates vary most take extra samples (:meth:`PassSchedule.noisy_pixels`).
"""
from __future__ import annotations

import math

import numpy as np


class PassSchedule:
    """The pass schedule of a renderer over ``solver`` with ``settings``: the iterations since the
    last pass, the seconds spent in iterations and in passes, and the first pass's rays and seconds
    (its set-up)."""

    #: the image passes' share of the work when ``image_share`` is 0, by ray count
    #: (:attr:`by_time` False) and by time (True): diffuse scenes, and with glossy lobes (the
    #: shares of time chosen on the interior bench's rooms: CHANGELOG)
    DIFFUSE_SHARE = {False: 0.2, True: 0.4}
    GLOSSY_SHARE = {False: 0.55, True: 0.7}

    def __init__(self, solver, settings):
        self.solver, self.settings = solver, settings
        #: share time (a run limited by time: :class:`~raybundle.imaging.run.RunLoop` sets it), else rays
        self.by_time = False
        self.since = 0                       # iterations since the last image pass
        self.iteration_seconds = 0.0         # seconds spent in solver iterations
        self.pass_seconds = 0.0              # seconds spent in image passes
        self.setup_rays = 0                  # the first pass's rays
        self.setup_seconds = 0.0             # ... and seconds

    def share(self):
        """The image passes' share of the work (module docstring)."""
        return self.settings.image_share or (
            self.DIFFUSE_SHARE if self.solver.diffuse_only else self.GLOSSY_SHARE)[self.by_time]

    def iterated(self, seconds):
        """Count a solver iteration of ``seconds``."""
        self.iteration_seconds += seconds
        self.since += 1

    def passed(self, seconds, rays, first):
        """Count an image pass of ``seconds`` and ``rays``; the ``first`` is set-up."""
        self.pass_seconds += seconds
        self.since = 0
        if first:
            self.setup_rays, self.setup_seconds = rays, seconds

    @staticmethod
    def _mean_pass(spent, setup, passes):
        """A pass's mean work, the first (set-up) left out once there are others."""
        return (spent - setup) / (passes - 1) if passes > 1 else setup

    def _iteration_seconds(self):
        """An iteration's mean seconds so far."""
        return self.iteration_seconds / max(self.solver.stats.iterations, 1)

    def passes_due(self, passes, image_rays, ahead=0):
        """How many image passes are due now, after ``passes`` passes and ``image_rays`` image
        rays (or after ``ahead`` more iterations), by the module docstring's rules."""
        s = self.share()
        if self.by_time:
            per_pass = max(self._mean_pass(self.pass_seconds, self.setup_seconds, passes), 1e-9)
            budget = s / (1 - s) * (self.iteration_seconds + ahead * self._iteration_seconds())
            return max(0, math.floor((budget - (self.pass_seconds - self.setup_seconds)) / per_pass + 0.5))
        since = self.since + ahead
        per_iter = max(self.solver.work_rays() / max(self.solver.stats.iterations, 1), 1)
        return int(since > 0 and since * s * per_iter >= self._mean_pass(image_rays, self.setup_rays, passes) * (1 - s))

    def next_step_seconds(self, passes, image_rays):
        """What the next step will take [s], from this run's means: an iteration, and the image
        passes that will be due after it (the run loop's clock, :class:`~raybundle.imaging.run.RunLoop`)."""
        if self.solver.stats.iterations == 0 or passes == 0:
            return 0.0
        per_pass = self._mean_pass(self.pass_seconds, self.setup_seconds, passes)
        return self._iteration_seconds() + per_pass * self.passes_due(passes, image_rays, ahead=1)

    #: :meth:`noisy_pixels`: at most this share of the pixels, those whose squared standard
    #: error is above NOISY_CUT times the image's mean one
    NOISY_SHARE = 0.02
    NOISY_CUT = 16.0
    #: ... each taking up to this many times the extra samples of an edge, all of them together at
    #: most NOISY_BUDGET samples per pixel of the image
    NOISY_MAX_FACTOR = 16
    NOISY_BUDGET = 0.5

    def noisy_pixels(self, pass_sum, pass_samples, pass_sq_sum, passes):
        """Pixels whose per-pass estimates vary most: the standard error of their
        mean (from the passes so far) above 4 times the image's RMS standard error,
        at most 2% of the pixels (e.g. the rim a lamp lights through a narrow gap,
        where a pixel's direct light changes by orders of magnitude across it), and per pixel
        how many times an edge's extra samples it takes: ``sqrt(se^2 / cut)`` rounded, 1 to
        :data:`NOISY_MAX_FACTOR` (samples in proportion to the standard deviation, which
        minimises the summed squared error for their number: the edge of a small lamp's
        reflection in a near-mirror).  From the passes' sums: ``pass_sum`` (pixels, 3) of the
        estimates times their samples, ``pass_samples`` (pixels,), ``pass_sq_sum`` (pixels,) of
        the luminance squared times the samples, over ``passes`` passes."""
        if passes < 4:
            return np.zeros(0, np.int64), np.zeros(0, np.int64)
        # passes of k samples: sum_p k_p (y_p - m)^2 estimates passes x the per-sample variance
        k = np.maximum(pass_samples, 1)
        m = pass_sum.sum(axis=1) / k
        se2 = np.maximum(pass_sq_sum - k * m * m, 0.0) / passes / k
        cut = self.NOISY_CUT * se2.mean()
        idx = np.nonzero(se2 > cut)[0]
        cap = max(1, int(len(se2) * self.NOISY_SHARE))
        if len(idx) > cap:
            idx = np.sort(idx[np.argsort(se2[idx])[-cap:]])
        factor = np.clip(np.rint(np.sqrt(se2[idx] / max(cut, 1e-300))), 1, self.NOISY_MAX_FACTOR)
        # at most NOISY_BUDGET extra samples per pixel of the image, on average
        budget = self.NOISY_BUDGET * len(se2) / max(self.settings.emission_edge_samples, 1)
        if factor.sum() > budget:
            factor = np.maximum(np.floor(factor * budget / factor.sum()), 1.0)
        return idx, factor.astype(np.int64)
