"""A run's phases as its progress display tells them (export, layout steps, tracer, first shot,
warm-up, iterations, final image): each one's seconds and the process's peak resident memory at
its end, for the Last Render figures and the benches.

A :class:`PhaseClock` wraps the ``stage(text)`` callback that :mod:`raybundle.app.pipeline` and
the run loop already tell: each call ends the phase running and starts one named ``text``.
"""
from __future__ import annotations

import sys
import time
from dataclasses import asdict, dataclass

try:
    import resource
except ImportError:                   # Windows: no peak figure
    resource = None


def peak_rss_mb() -> float | None:
    """The process's peak resident memory so far [MB]; None where the platform does not say."""
    if resource is None:
        return None
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    return peak / 2 ** 20 if sys.platform == "darwin" else peak / 1024      # bytes on macOS, KiB elsewhere


@dataclass
class Phase:
    """One phase: the text the progress display showed, its seconds, the peak resident memory
    of the process at its end [MB] (None where unknown)."""
    name: str
    seconds: float
    peak_rss_mb: float | None


class PhaseClock:
    """A ``stage(text)`` callback that times its phases and passes each ``text`` on to ``stage``
    (None: to nobody); :meth:`finish` ends the last one and gives them all."""

    def __init__(self, stage=None):
        self.stage = stage
        self.phases: list[Phase] = []
        self._name, self._t = None, None

    def __call__(self, text):
        self._end()
        self._name, self._t = text, time.perf_counter()
        if self.stage is not None:
            self.stage(text)

    def _end(self):
        if self._name is not None:
            self.phases.append(Phase(self._name, time.perf_counter() - self._t, peak_rss_mb()))
            self._name = None

    def finish(self) -> list[dict]:
        """End the phase running; every phase so far as dicts (``name``, ``seconds``, ``peak_rss_mb``)."""
        self._end()
        return [asdict(p) for p in self.phases]
