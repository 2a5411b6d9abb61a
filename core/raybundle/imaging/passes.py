"""When image passes run, and which pixels take more samples in them.

The renderer alternates solver iterations and image passes.  An image pass is due once the
iterations since the last one have done ``(1 - s) / s`` times the work of the rays an image
pass traces on average, ``s`` the image passes' share of the traced rays (``image_ray_share``;
by default :data:`PassSchedule.DIFFUSE_IMAGE_SHARE` for diffuse scenes and
:data:`PassSchedule.GLOSSY_IMAGE_SHARE` with glossy lobes, whose eye paths the passes trace and
whose caustic they splat).  The first pass's rays, with every pixel a penumbra, are set-up, not
the passes' average; passes grow when penumbrae are found, so the ratio is re-read every time.
Within a pass, the pixels whose estimates vary most take extra samples (:meth:`PassSchedule.noisy_pixels`).
"""
from __future__ import annotations

import numpy as np


class PassSchedule:
    """The pass schedule of a renderer over ``solver`` with ``settings``: ``since`` iterations
    since the last pass, the seconds spent in iterations and in passes, and the first pass's
    rays (``setup_rays``)."""

    #: the image passes' share of the traced rays when ``image_ray_share`` is 0
    DIFFUSE_IMAGE_SHARE = 0.2
    GLOSSY_IMAGE_SHARE = 0.55

    def __init__(self, solver, settings):
        self.solver, self.settings = solver, settings
        self.since = 0                       # iterations since the last image pass
        self.iteration_seconds = 0.0         # seconds spent in solver iterations
        self.pass_seconds = 0.0              # seconds spent in image passes
        self.setup_rays = 0                  # the first pass's rays

    def due(self, since, passes, image_rays):
        """Whether an image pass is due after ``since`` iterations since the last, ``passes``
        passes and ``image_rays`` image rays so far (module docstring)."""
        solver = self.solver
        share = self.settings.image_ray_share or (
            self.DIFFUSE_IMAGE_SHARE if solver.diffuse_only else self.GLOSSY_IMAGE_SHARE)
        per_pass = (image_rays - self.setup_rays) / (passes - 1) if passes > 1 else self.setup_rays
        per_iter = solver.work_rays() / max(solver.stats.iterations, 1)
        return since * share * max(per_iter, 1) >= per_pass * (1 - share)

    def next_step_seconds(self, passes, image_rays):
        """What the next step will take [s], from this run's means: an iteration, and an image
        pass where one will be due (the run loop's clock, :class:`~raybundle.imaging.run.RunLoop`)."""
        iterations = self.solver.stats.iterations
        if iterations == 0 or passes == 0:
            return 0.0
        t = self.iteration_seconds / iterations
        return t + (self.pass_seconds / passes if self.due(self.since + 1, passes, image_rays) else 0.0)

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
