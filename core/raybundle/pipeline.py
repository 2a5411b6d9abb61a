"""One call from a scene to an image: subdivide, build the tracer, first shot, solve, image.

This is the entry point the CLI, the Blender add-on and the bench share.
"""
from __future__ import annotations

import warnings

from .clusters import make_patches
from .imaging import Renderer, RenderSettings
from .lights import DirectLighting
from .sampling import make_sequence
from .scene import subdivide
from .solvers import SOLVERS, StochasticIterationSolver
from .visibility import RayTracer

#: default patch count for scenes rendered without an explicit one
DEFAULT_PATCHES = 4000


def prepare(scene, patches=DEFAULT_PATCHES, max_edge=None, stage=None):
    """The patch layout of ``scene``: about ``patches`` patches, large faces cut and
    triangles much smaller than a patch grouped (:func:`~raybundle.clusters.make_patches`),
    or every face cut to edges <= ``max_edge`` m; ``patches`` = 0: one patch per triangle.
    ``stage(text)`` is told what set-up step starts (progress for large scenes)."""
    if stage is not None and (patches or max_edge is not None):
        stage(f"laying out the patches of {len(scene.triangles):,} triangles")
    if max_edge is not None:
        return subdivide(scene, max_edge=max_edge)
    if patches:
        return make_patches(scene, patches=patches)
    return scene


def make_solver(scene, settings: RenderSettings | None = None, solver=StochasticIterationSolver.name, stage=None):
    """Tracer + first shot + solver for a prepared scene (no camera needed: bakes);
    the solver holds them as ``solver.tracer`` and ``solver.direct``.  ``stage(text)``
    as in :func:`prepare`."""
    settings = settings or RenderSettings()
    settings.validate()
    if settings.sequence == "halton":
        warnings.warn("the Halton sequence is not completely uniformly distributed: stochastic iteration "
                      "driven by it converges to a wrong image (thesis 1.2); use 'prng' or 'pi-powers'",
                      stacklevel=3)
    if stage is not None:
        stage(f"building the ray tracer over {len(scene.triangles):,} triangles")
    tracer = RayTracer(scene, threads=settings.threads)
    if stage is not None:
        stage(f"first shot and solver set-up for {scene.n_patches:,} patches")
    direct = DirectLighting(scene, tracer, first_shot=settings.first_shot)
    sequence = make_sequence(settings.sequence, settings.seed)
    return SOLVERS[solver](scene, tracer, direct, sequence, bundle_resolution=settings.bundle_resolution,
                           seed=settings.seed, directions_per_step=settings.directions_per_step,
                           caustics=settings.caustics, glossy_send_rays=settings.glossy_send_rays)


def make_renderer(scene, settings: RenderSettings | None = None, camera=None,
                  solver=StochasticIterationSolver.name, stage=None):
    """Tracer + first shot + solver + image accumulator for a prepared scene."""
    settings = settings or RenderSettings()
    solver_obj = make_solver(scene, settings, solver, stage=stage)
    return Renderer(scene, camera if camera is not None else scene.camera, solver_obj, solver_obj.direct, settings)


def render(scene, settings=None, iterations=None, seconds=None, progress=None, stop=None, camera=None, stage=None):
    """Render a prepared scene; returns :class:`~raybundle.imaging.RenderResult`."""
    renderer = make_renderer(scene, settings, camera, stage=stage)
    try:
        return renderer.run(iterations=iterations, seconds=seconds, progress=progress, stop=stop)
    finally:
        renderer.tracer.close()
