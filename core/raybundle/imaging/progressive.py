"""What a progressive image method is to the run loop, and what a run returns.

:class:`ProgressiveImage` is the protocol of the camera-image methods (the bundle iteration's
:class:`~raybundle.imaging.renderer.Renderer`, :class:`~raybundle.methods.path_tracing.PathTracer`,
:class:`~raybundle.methods.single_ray_iteration.SingleRayIteration`): the one run loop
(:class:`~raybundle.imaging.run.RunLoop`) drives it, and it forms the final image into a
:class:`RenderResult`.
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from .run import RunLoop

#: the share of a time-limited run's iteration time the first pass's extra emission samples may
#: take (:attr:`ProgressiveImage.first_edge_seconds`)
FIRST_EDGE_SHARE = 0.1


@dataclass
class RenderResult:
    image: np.ndarray              # (H, W, 3) float32 linear radiance, row 0 at the top
    stats: dict = field(default_factory=dict)
    cancelled: bool = False
    #: the image's parts by name, (H, W, 3) each, and ``glass`` (H, W)
    #: (:mod:`~raybundle.imaging.components`), or None (``RenderSettings.components`` off)
    components: dict | None = None


@dataclass
class ImagePasses:
    """The solver of an image-only method (:class:`~raybundle.methods.path_tracing.PathTracer`,
    :class:`~raybundle.methods.single_ray_iteration.SingleRayIteration`), as progress reporting and the run
    loop read it: ``stats.iterations`` (its passes) and ``stats.rays`` (0: every ray is an
    image ray)."""

    tracer: object
    stats: object
    name: str
    diffuse_only: bool = False


class ProgressiveImage:
    """A progressive image method (:class:`Renderer`, :class:`~raybundle.methods.path_tracing.PathTracer`,
    :class:`~raybundle.methods.single_ray_iteration.SingleRayIteration`) run by the one run loop
    (:class:`~raybundle.imaging.run.RunLoop`): they provide ``solver.stats.iterations``, ``passes``,
    ``image_pass()``, ``step()``, ``image()`` and ``stats(...)``."""

    #: in a run limited by time, the seconds the first pass's extra emission samples may take
    #: (:attr:`FIRST_EDGE_SHARE` of the iteration time; None: no bound; read by
    #: :meth:`~raybundle.imaging.renderer.Renderer.image_pass`)
    first_edge_seconds = None

    def run(self, iterations=None, time_limit=None, progress=None, stop=None, snapshots=(), on_snapshot=None,
            started=None, stage=None, between=None):
        """Iterate (:class:`~raybundle.imaging.run.RunLoop`: ``iterations``, or the whole run's
        ``time_limit`` [s] from ``started``, set-up included; ``progress``; ``stop``; ``between``) and form the final
        image; returns :class:`RenderResult`, whose stats add the set-up's seconds
        (``setup_seconds``), the run's (``total_seconds``) and, when the budget was too short
        for the minimum of iterations, ``budget_note``.  ``stage(text)`` is told when the
        iterations start and when the final image is formed.  ``on_snapshot(seconds, iterations,
        image)`` is called when the run's clock passes each of ``snapshots`` (seconds): ``seconds``
        includes forming that image (what stopping there would have cost); the run's clock then
        leaves it out."""
        loop = RunLoop(self, iterations, time_limit, started, final_share=self.final_share(), progress=progress,
                       stop=stop, between=between)
        pending = sorted(snapshots) if on_snapshot is not None else []
        if stage is not None:
            stage("iterating")
        if loop.iteration_time is not None:
            self.first_edge_seconds = FIRST_EDGE_SHARE * loop.iteration_time
        try:
            if self.passes == 0:
                self.image_pass()
        except KeyboardInterrupt:
            loop.cancelled = loop.finished = True
        while loop.advance(until=pending[0] if pending else None):
            pending.pop(0)
            t_snap = time.perf_counter()
            try:
                img = self.resolve(loop.final_time())
                on_snapshot(loop.elapsed() + time.perf_counter() - t_snap, loop.iterations, img)
            except KeyboardInterrupt:         # Ctrl-C while a snapshot forms: a stop, as in the loop
                loop.cancelled = loop.finished = True
                break
            loop.pause(time.perf_counter() - t_snap)
        final_time = loop.final_time()
        if final_time and not self.automatic_gather_pays(final_time):
            loop.extend(final_time)               # the time kept for a gather that would not pay: iterate on
            while loop.advance():
                pass
            final_time = None
        if stage is not None:
            stage("forming the final image")
        t_res = time.perf_counter()
        img = self.resolve(final_time)
        if not np.isfinite(img).all():
            raise FloatingPointError("the image has non-finite values; this is a bug, please report it")
        t_end = time.perf_counter()
        stats = self.stats(t_end - loop.t0, t_end - t_res, loop.cancelled)
        stats.update(setup_seconds=round(loop.setup_seconds, 4), total_seconds=round(t_end - loop.started, 4))
        note = loop.budget_note(t_end - loop.started)
        if note:
            stats["budget_note"] = note
        return RenderResult(img, stats, loop.cancelled, self.components())

    def components(self):
        """The final image's parts (:mod:`~raybundle.imaging.components`), or None: this
        method does not keep them apart."""
        return None

    def final_share(self):
        """The final image's share of a time-limited run's iteration seconds (none here)."""
        return 0.0

    def resolve(self, final_time=None):
        """The image at the end of a run or at a snapshot; ``final_time``: what forming it may
        take in a run limited by time (:meth:`~raybundle.imaging.run.RunLoop.final_time`), None in
        a run of given iterations."""
        return self.image()
