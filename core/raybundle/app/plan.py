"""The one set-up decision: from what the user asks and the scene to what runs.

Every front-end (the CLI, the Blender render engine, the bake, the bench, the chains on
Dask) turns its user's input into :class:`RunOptions` and calls :func:`plan`, which makes
every decision they share and returns a :class:`Plan`:

* the method: a :data:`~raybundle.methods.registry.SOLVERS` name, or ``auto``'s choice
  (:func:`~raybundle.app.auto.choose`, made on the loaded scene); a bake needs a patch
  solution, so where ``auto`` would pick an image-only method a bake takes the bundle
  iteration, and naming an image-only method for a bake or for chains is an error;
* what ``auto`` decides is what the user left open (``None``): the random sequence; a value
  the user gave is kept;
* the budget: ``iterations`` or ``time_limit`` (the whole run's seconds, from its start),
  :data:`DEFAULT_TIME_LIMIT` when neither is given;
* the :class:`~raybundle.imaging.settings.RenderSettings` the run is built with, validated.

:func:`raybundle.app.pipeline.build` then lays out the patches and builds the renderer or the
solver the plan says.
"""
from __future__ import annotations

from dataclasses import dataclass, field

from ..imaging.run import check_budget
from ..imaging.settings import RenderSettings
from ..methods.registry import SOLVERS, image_only
from ..methods.stochastic_iteration import StochasticIterationSolver
from ..patches.clusters import DEFAULT_PATCHES
from ..tracing.sampling import DEFAULT_SEQUENCE
from .auto import Choice, choose

#: the time limit of a run given neither iterations nor a time limit [s]
DEFAULT_TIME_LIMIT = 30.0


@dataclass
class RunOptions:
    """What the user asks for, as plain values (CLI options, the add-on's properties).

    ``method``: a :data:`~raybundle.methods.registry.SOLVERS` name or ``"auto"``; ``iterations`` or
    ``time_limit`` (the whole run's seconds from its start, set-up included; neither:
    :data:`DEFAULT_TIME_LIMIT`);
    ``patches`` (0: one patch per triangle) and ``sequence``: None leaves them to ``auto``
    or the defaults; ``first_shot``: shoot the lights and small emitters first;
    ``gather_rays``: final-gather rays per pixel next to concave edges (-1: as many as
    ``RenderSettings.gather_share``, a quarter, of a timed run buys); ``threads``: the ray tracer's (None: all cores);
    ``transmission_depth`` and ``glossy_depth``: the refractions and the reflections on glass after
    which an eye path ends (None: the defaults of
    :class:`~raybundle.imaging.settings.RenderSettings`; the add-on passes the file's own Light
    Paths limits); ``components``: keep the image's parts apart
    (:mod:`~raybundle.imaging.components`; not over chains)."""

    method: str = StochasticIterationSolver.name
    iterations: int | None = None
    time_limit: float | None = None
    seed: int = 0
    patches: int | None = None
    sequence: str | None = None
    bundle_resolution: int = 0
    first_shot: bool = True
    gather_rays: int = -1
    threads: int | None = None
    transmission_depth: int | None = None
    glossy_depth: int | None = None
    components: bool = False


@dataclass
class Plan:
    """What runs: the method, the patch count, the budget and the settings; ``choice`` is
    ``auto``'s (None when the user named the method)."""

    method: str
    patches: int
    iterations: int | None
    time_limit: float | None
    settings: RenderSettings
    choice: Choice | None = None
    notes: list = field(default_factory=list)

    @property
    def image_only(self):
        """The method renders images only: no patch layout, no bake, no chains."""
        return image_only(self.method)

    def describe(self):
        """One line: auto's choice and why (None when the user named the method)."""
        if self.choice is None:
            return None
        if self.choice.method != self.method:        # a bake or chains overrode an image-only choice
            return (f"auto chose {self.choice.method} ({self.choice.reason}); " + "; ".join(self.notes) +
                    f", {self.patches:,} patches")
        return f"auto: {self.method}, {self.patches:,} patches: {self.choice.reason}"


def check(options: RunOptions, bake=False, chains=False):
    """Raise ValueError (one line) for options that cannot run whatever the scene: what
    :func:`plan` checks first, for front-ends to call before loading or exporting."""
    o = options
    if o.method != "auto" and o.method not in SOLVERS:
        raise ValueError(f"unknown method {o.method!r}; choose one of {sorted(SOLVERS)} or auto")
    check_budget(o.iterations, _time_limit(o))
    if o.patches is not None and int(o.patches) < 0:
        raise ValueError("the patch count must be non-negative (0: one patch per triangle)")
    if o.method != "auto":
        _check_method(o.method, bake, chains)
    if chains and o.components:
        raise ValueError("the image's components are not pooled over chains; render them in one process")
    _settings(o, o.sequence).validate()


def _time_limit(o):
    """The budget's time limit: the options', or :data:`DEFAULT_TIME_LIMIT` when neither a time
    limit nor iterations are given."""
    return DEFAULT_TIME_LIMIT if o.iterations is None and o.time_limit is None else o.time_limit


def _check_method(method, bake, chains):
    if bake and image_only(method):
        raise ValueError(f"{method} renders images only, it has no patch solution to bake; choose another method")
    if chains and not SOLVERS[method].merges_chains:
        why = "renders images only, it has no patch solution to merge" if image_only(method) else \
            "cannot run as merged chains"
        raise ValueError(f"{method} {why}; chains take "
                         f"{', '.join(n for n, c in SOLVERS.items() if c.merges_chains)}")


def _settings(o, sequence):
    depth = {k: int(getattr(o, k)) for k in ("transmission_depth", "glossy_depth") if getattr(o, k) is not None}
    return RenderSettings(seed=int(o.seed), sequence=sequence or DEFAULT_SEQUENCE,
                          bundle_resolution=int(o.bundle_resolution), threads=o.threads,
                          first_shot="auto" if o.first_shot else "none", gather_rays=int(o.gather_rays),
                          components=bool(o.components), **depth)


def plan(scene, options: RunOptions, bake=False, chains=False) -> Plan:
    """The :class:`Plan` for ``scene`` (loaded or exported, not yet laid out) and ``options``
    (module docstring).  ``bake``: the run bakes a patch solution; ``chains``: it runs as
    independent chains that are merged (:mod:`raybundle.app.chains`).  Raises ValueError with
    a one-line reason for options that cannot run (:func:`check`)."""
    o = options
    check(o, bake, chains)
    time_limit = _time_limit(o)
    method, choice, notes, sequence, patches = o.method, None, [], o.sequence, o.patches
    if method == "auto":
        choice = choose(scene)
        method = choice.method
        if sequence is None:
            sequence = choice.sequence
        if (bake or chains) and image_only(method):
            method, sequence = StochasticIterationSolver.name, o.sequence
            notes.append(f"{'a bake needs' if bake else 'chains need'} a patch solution: {method}")
        _check_method(method, bake, chains)
    settings = _settings(o, sequence)
    return Plan(method, DEFAULT_PATCHES if patches is None else int(patches), o.iterations, time_limit, settings,
                choice, notes)
