"""The one run loop: iterate a renderer or a solver until the budget is spent or the user stops.

Renders (:meth:`~raybundle.imaging.progressive.ProgressiveImage.run`), bakes (the add-on's ``BakeJob``)
and the chains on Dask (:mod:`raybundle.app.distributed`) all iterate through :class:`RunLoop`,
which owns the budget of the whole run:

* ``iterations``: that many steps of the runner, reproducible with a fixed seed; or
* ``time_limit`` [s], counted from ``started`` (the start of the command or the job, so
  loading, export and set-up count).  It falls into three parts: the set-up, the
  *iteration time* and the *final time*, ``final_share`` of the iteration time, what forming
  the final image may take (the automatic final gather,
  :meth:`~raybundle.imaging.resolve.DiffuseIndirect.image`).  The iterations stop when what is
  left is the final time, or less than half the next
  step more (:meth:`RunLoop._next_step_seconds`), so that the image is written when
  the budget ends, but not before :data:`RunLoop.MIN_ITERATIONS` steps; the run then says
  its budget was too short (:meth:`RunLoop.budget_note`).

The loop checks ``stop`` (a callable or an object with ``is_set()``, e.g. a
``threading.Event`` that Esc or Ctrl-C sets) between steps, and treats KeyboardInterrupt
as a stop; what has been computed is kept either way.  It can run in one go
(:meth:`RunLoop.advance` with no limit) or in slices (a modal operator's timer ticks,
a chain's reports).
"""
from __future__ import annotations

import math
import time


def check_budget(iterations=None, time_limit=None):
    """Raise ValueError (one line) for a budget that cannot run: both or neither given,
    negative iterations, a time limit that is negative or not finite."""
    if (iterations is None) == (time_limit is None):
        raise ValueError("give iterations or a time limit" + (", not both" if iterations is not None else ""))
    if iterations is not None and int(iterations) < 0:
        raise ValueError("iterations must be non-negative")
    if time_limit is not None and not (math.isfinite(time_limit) and time_limit >= 0):
        raise ValueError("the time limit must be a finite, non-negative number of seconds")


def iteration_time(time_limit, started, final_share=0.0):
    """Of a ``time_limit`` [s] from ``started`` (a ``time.perf_counter()`` reading), the
    iteration time left now: what set-up left, less the final time (``final_share`` of the
    iteration time)."""
    return max(time_limit - (time.perf_counter() - started), 0.0) / (1.0 + final_share)


def iterations_of(runner):
    """Iterations a renderer (``runner.solver.stats``) or a solver (``runner.stats``) has done."""
    return getattr(runner, "solver", runner).stats.iterations


class RunLoop:
    """Steps ``runner`` (``step()``; a renderer or a solver) within a budget (module docstring).

    ``progress(fraction, {"iterations", "seconds"})`` is told after every step;
    ``between()`` is called between steps before ``stop`` is checked (the render engine's
    previews)."""

    #: the fewest iterations of a run limited by time, however short its budget
    MIN_ITERATIONS = 8

    def __init__(self, runner, iterations=None, time_limit=None, started=None, final_share=0.0, progress=None,
                 stop=None, between=None):
        check_budget(iterations, time_limit)
        self.runner, self.target, self.time_limit = runner, iterations, time_limit
        self.final_share = float(final_share)
        self.progress, self.between = progress, between
        self._stop = (stop.is_set if hasattr(stop, "is_set") else stop) or (lambda: False)
        self.t0 = time.perf_counter()
        self.started = self.t0 if started is None else started
        #: seconds from ``started`` to the first step (loading, export, set-up)
        self.setup_seconds = self.t0 - self.started
        #: the iteration time a timed run has: what set-up left, less the final time
        self.iteration_time = None if time_limit is None else iteration_time(time_limit, self.started,
                                                                               self.final_share)
        self.cancelled = self.short = self.finished = False
        self._first_iteration = self.iterations
        schedule = getattr(runner, "schedule", None)     # a renderer's passes share time or rays
        if schedule is not None:
            schedule.by_time = time_limit is not None

    @property
    def iterations(self):
        return iterations_of(self.runner)

    def elapsed(self):
        """Seconds of iteration so far (pauses left out)."""
        return time.perf_counter() - self.t0

    def pause(self, seconds):
        """Leave ``seconds`` (spent outside the run: a bench's snapshot) off the run's clock."""
        self.t0 += seconds

    @property
    def fraction(self):
        """How much of the budget is spent, in [0, 1]."""
        if self.target is not None:
            return min(1.0, self.iterations / self.target) if self.target else 1.0
        return min(1.0, self.elapsed() / max(self.iteration_time, 1e-9))

    def advance(self, max_seconds=None, until=None):
        """Step until the budget is spent or ``stop`` is set (then False, and :attr:`finished`),
        or for about ``max_seconds`` (at least one step) or until ``until`` seconds of iteration
        (then True: call again to go on)."""
        if self.finished:
            return False
        t_end = None if max_seconds is None else time.perf_counter() + max_seconds
        try:
            while True:
                elapsed = self.elapsed()
                if until is not None and elapsed >= until:
                    return True
                it = self.iterations
                if self.target is not None and it >= self.target:
                    break
                if self.iteration_time is not None and elapsed + 0.5 * self._next_step_seconds() >= self.iteration_time:
                    if it >= self.MIN_ITERATIONS:
                        break
                    self.short = self.short or elapsed >= self.iteration_time
                if self.between is not None:
                    self.between()
                if self._stop():
                    self.cancelled = True
                    break
                self.runner.step()
                if self.progress is not None:
                    self.progress(self.fraction, {"iterations": self.iterations, "seconds": self.elapsed()})
                if t_end is not None and time.perf_counter() >= t_end:
                    return True
        except KeyboardInterrupt:
            self.cancelled = True
        self.finished = True
        return False

    def _next_step_seconds(self):
        """What the runner's next step will take [s]: its own ``next_step_seconds()`` (a renderer
        knows when an image pass is due), else this loop's mean step.  The loop stops when less
        than half of it is left, so a run ends within half a step of its budget, however long
        its steps (an image pass can take seconds)."""
        own = getattr(self.runner, "next_step_seconds", None)
        if own is not None:
            return own()
        steps = self.iterations - self._first_iteration
        return self.elapsed() / steps if steps > 0 else 0.0

    def extend(self, seconds):
        """Give the run ``seconds`` more of iteration time, taken from the final time (which is
        then none): :meth:`advance` goes on."""
        self.iteration_time = (self.iteration_time or 0.0) + seconds
        self.final_share = 0.0
        self.finished = False

    def final_time(self):
        """The final time [s], what forming the final image may take: ``final_share`` of the
        iteration time in a run limited by time that ran to its end; None in a run of given
        iterations (which stays reproducible) or one that was stopped (a stop ends it now)."""
        if self.time_limit is None or self.cancelled:
            return None
        return self.final_share * self.elapsed()

    def budget_note(self, total_seconds):
        """Why a timed run overran its budget (None when it did not): set-up and the minimum
        of iterations took longer."""
        if not self.short:
            return None
        return (f"budget {self.time_limit:g} s too short: set-up {self.setup_seconds:.1f} s, total "
                f"{total_seconds:.1f} s ({self.iterations} iterations)")
