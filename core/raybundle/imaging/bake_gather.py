"""A bake's final gather within its budget: the indirect irradiance of located bake points
gathered from the solution (:class:`~raybundle.imaging.gather.FinalGather`) in slices, so that
a modal operator stays responsive and a stop ends it, with as many rays per point as the
time left buys.

Points whose gather has not run keep the indirect light interpolated from the patches
(:func:`~raybundle.imaging.baking.interpolated_indirect`): a bake stopped during its gather
still writes every point.  The points are gathered in blocks of :data:`BLOCK`, each with its own
random stream from the seed and its index, so a bake of given iterations and rays gives the
same values however its slices fall.
"""
from __future__ import annotations

import time

import numpy as np

from .baking import interpolated_indirect
from .gather import EdgeGather, FinalGather

#: points gathered with one random stream (a slice is whole blocks)
BLOCK = 256


class BakeGather:
    """The final gather of located bake ``points`` (:class:`~raybundle.imaging.baking.SurfacePoints`),
    or of those ``which`` indexes, into ``solver``'s solution, with random streams from ``seed`` (an
    int or a sequence of ints); where a ray lands within a patch of its point (a concave edge, a
    contact), one more cosine ray from the hit gathers the hit's indirect light
    (:class:`~raybundle.imaging.gather.FinalGather` ``bounce``), where the patch values cannot follow
    it.  :attr:`indirect` (N, 3) [W/m^2] holds the interpolated values until :meth:`advance` replaces
    them, block by block, with gathered ones; :attr:`gathered` counts the points done."""

    #: the fewest rays per point worth gathering: a bake that buys fewer interpolates
    MIN_RAYS = EdgeGather.MIN_GATHER_RAYS
    #: the most rays per point
    MAX_RAYS = 65536
    #: the probe that measures a ray's cost: this many points, this many rays each
    PROBE_POINTS, PROBE_RAYS = EdgeGather.PROBE_POINTS, EdgeGather.PROBE_RAYS

    def __init__(self, solver, points, seed=0, which=None, final=None):
        self.solver, self.points, self.seed = solver, points, seed
        #: the :class:`~raybundle.imaging.gather.FinalGather` (``bounce``) of the solution, shared by a
        #: bake's gathers (``final``) or made when first needed
        self._final = final
        self.indirect = interpolated_indirect(solver, points, None if final is None else final.vert_indirect)
        #: the points to gather (``which``; default: every point found), in order
        self.todo = np.nonzero(points.found)[0] if which is None else np.asarray(which, np.int64)
        self.gathered = 0
        self.rays = self.fewest = 0
        self._deadline, self._spent, self._cast = None, 0.0, 0
        #: seconds :meth:`advance` took
        self.seconds = 0.0

    def _stream(self, k):
        """The random stream ``k`` of the seed (an int or a sequence of ints)."""
        return np.random.default_rng([*np.atleast_1d(self.seed), k])

    @property
    def final(self):
        if self._final is None:
            self._final = FinalGather(self.solver, bounce=True)
        return self._final

    @property
    def done(self):
        return self.rays == 0 or self.gathered >= len(self.todo)

    @property
    def interpolated(self):
        """Points left to the interpolated values: not gathered (yet, or for want of time)."""
        return len(self.todo) - self.gathered

    @property
    def fraction(self):
        """The share of the points gathered, in [0, 1]."""
        return 1.0 if not len(self.todo) else self.gathered / len(self.todo)

    def _irradiance(self, which, rays, rng):
        p = self.points
        ts = p.tside[which]
        return self.final.irradiance(p.point[which], self.solver.scene.tside_normal[ts], rays, rng,
                                     at=(ts, p.bary[which]))

    def automatic_rays(self, seconds):
        """Rays per point that ``seconds`` buy for every point to gather, within [:data:`MIN_RAYS`,
        :data:`MAX_RAYS`]; 0 (interpolate) when they buy fewer than :data:`MIN_RAYS`.  A point's
        gather costs ``a + b R`` seconds for R rays (its own set-up, then each ray), ``a`` and ``b``
        measured on up to :data:`PROBE_POINTS` of the points gathered with :data:`PROBE_RAYS` / 4
        and :data:`PROBE_RAYS` rays; the probes' time counts against ``seconds``."""
        if not len(self.todo) or seconds <= 0:
            return 0
        probe = self.todo[:: max(1, len(self.todo) // self.PROBE_POINTS)]
        rng = self._stream(1 << 30)
        r1, r2 = self.PROBE_RAYS // 4, self.PROBE_RAYS
        t0 = time.perf_counter()
        self._irradiance(probe, r1, rng)
        t1 = time.perf_counter()
        self._irradiance(probe, r2, rng)
        t2 = time.perf_counter()
        per_ray = (t2 - t1) / (r2 * len(probe))
        if (t2 - t1) > (t1 - t0):                       # else the clock's noise: no set-up cost known
            per_ray = ((t2 - t1) - (t1 - t0)) / ((r2 - r1) * len(probe))
        per_point = max((t1 - t0) / len(probe) - r1 * per_ray, 0.0)
        rays = ((seconds - (t2 - t0)) / len(self.todo) - per_point) / per_ray
        return 0 if rays < self.MIN_RAYS else int(min(rays, self.MAX_RAYS))

    def start(self, rays, deadline=None):
        """Gather ``rays`` rays per point from now on (0: none, the interpolated values stay); with
        a ``deadline`` (a ``time.perf_counter()`` reading), fewer in the blocks left where the
        blocks so far show that they would not end by then, and none below :data:`MIN_RAYS`
        (those points keep the interpolated values)."""
        self.rays = int(rays)
        self.gathered = 0
        self.fewest = self.rays              # the fewest rays a block took
        self._deadline = deadline
        self._spent = 0.0                    # seconds and rays of the blocks so far
        self._cast = 0

    def _block_rays(self):
        """Rays per point for the next block (:meth:`start`)."""
        if self._deadline is None or not self._cast:
            return self.rays
        per_ray = self._spent / self._cast
        left = len(self.todo) - self.gathered
        rays = min(self.rays, int((self._deadline - time.perf_counter()) / (per_ray * left)))
        return rays if rays >= self.MIN_RAYS else 0

    def advance(self, seconds=None):
        """Gather the next blocks for about ``seconds`` (at least one block; None: all of them);
        False once every point is gathered (or the deadline leaves the rest interpolated)."""
        t0 = time.perf_counter()
        t_end = None if seconds is None else t0 + seconds
        while not self.done:
            block = self.gathered // BLOCK
            which = self.todo[block * BLOCK:(block + 1) * BLOCK]
            rays = self._block_rays()
            if not rays:
                self.rays = 0                                    # the rest stay interpolated
                break
            t1 = time.perf_counter()
            self.indirect[which] = self._irradiance(which, rays, self._stream(block))
            self._spent += time.perf_counter() - t1
            self._cast += rays * len(which)
            self.fewest = min(self.fewest, rays)
            self.gathered += len(which)
            if t_end is not None and time.perf_counter() >= t_end:
                break
        self.seconds += time.perf_counter() - t0
        return not self.done
