"""What a :class:`~raybundle.app.plan.Plan` says, built: the patch layout, the ray tracer, the first
shot, the solver and the image accumulator.

:func:`build` is what the CLI, the Blender add-on, the bench and the chains call after
:func:`~raybundle.app.plan.plan`; :func:`run_plan` builds and runs in one call; :func:`render`
renders a scene already laid out with settings as given.
"""
from __future__ import annotations

import os
import time
import warnings
from dataclasses import replace

import numpy as np

from ..imaging.renderer import Renderer
from ..imaging.settings import RenderSettings
from ..lights.direct import DirectLighting
from ..lights.sources import small_emitters
from ..methods.registry import SOLVERS, image_only
from ..methods.stochastic_iteration import StochasticIterationSolver
from ..patches.clusters import DEFAULT_PATCHES, make_patches, triangle_patches
from ..patches.layout import subdivide
from ..patches.lit_splits import split_where_lit_unevenly
from ..tracing.sampling import NOT_CUD, PointUniforms
from ..tracing.visibility import RayTracer
from ..util import compiled


class Cancelled(Exception):
    """Set-up was stopped (the caller's ``stop``) before the first iteration: there is no image yet."""


def _step(stage, stop, text):
    """Start a set-up step: raise :class:`Cancelled` if ``stop`` (a callable or an
    object with ``is_set()``, as for :meth:`~raybundle.imaging.progressive.ProgressiveImage.run`) says so,
    else tell ``stage(text)``."""
    if stop is not None and (stop.is_set() if hasattr(stop, "is_set") else stop()):
        raise Cancelled(f"stopped during set-up, before {text}")
    if stage is not None:
        stage(text)


#: memory a pixel's buffers take in an image method (sums, counts, G-buffers, resolve) [bytes]
BYTES_PER_PIXEL = 600
#: memory a patch takes (its triangles, both sides' solver arrays) [bytes]
BYTES_PER_PATCH = 2048


def machine_memory():
    """This machine's physical memory [bytes], or None where the system does not say."""
    try:
        return os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
    except (ValueError, OSError, AttributeError):
        return None


def check_resources(scene, patches=0):
    """Refuse, before anything is allocated, settings that need more memory than the machine
    has: the camera's pixels (``BYTES_PER_PIXEL`` each) and ``patches`` (``BYTES_PER_PATCH``
    each).  Raises ValueError naming the setting to lower."""
    have = machine_memory()
    if not have:
        return
    cam = scene.camera
    if cam is not None and cam.width * cam.height * BYTES_PER_PIXEL > have:
        raise ValueError(f"a {cam.width} x {cam.height} image needs about "
                         f"{cam.width * cam.height * BYTES_PER_PIXEL / 2 ** 30:.0f} GB; this machine has "
                         f"{have / 2 ** 30:.0f} GB: lower the resolution")
    if patches and patches * BYTES_PER_PATCH > have:
        raise ValueError(f"{patches:,} patches need about {patches * BYTES_PER_PATCH / 2 ** 30:.0f} GB; this "
                         f"machine has {have / 2 ** 30:.0f} GB: lower the patch count")


def prepare(scene, patches=DEFAULT_PATCHES, max_edge=None, stage=None, stop=None):
    """The patch layout of ``scene``: about ``patches`` patches, large faces cut and
    triangles much smaller than a patch grouped (:func:`~raybundle.patches.clusters.make_patches`),
    or every face cut to edges <= ``max_edge`` m; ``patches`` = 0: one patch per triangle.
    ``stage(text)`` is told what set-up step starts (progress for large scenes); a
    ``stop`` that is set when a step starts raises :class:`Cancelled`."""
    check_resources(scene, patches)
    _step(stage, stop, f"laying out the patches of {len(scene.triangles):,} triangles")
    if max_edge is not None:
        return subdivide(scene, max_edge=max_edge)
    if patches:
        laid_out = make_patches(scene, patches=patches, stage=stage)
        _step(stage, stop, "splitting patches where the lamps' light changes within them")
        return split_lit_unevenly(scene, laid_out)
    return triangle_patches(scene)


def split_lit_unevenly(scene, laid_out):
    """``laid_out`` (``scene``'s patch layout) with the patches over which the first shot's
    lamps' light changes strongly split (:func:`~raybundle.patches.lit_splits.split_where_lit_unevenly`),
    their light probed with shadow rays over ``scene`` (the same surfaces) by numbers tied to the
    probed points (:class:`~raybundle.tracing.sampling.PointUniforms`), so a layout is the same on
    every run and however the scene's triangles and patches are numbered."""
    if not (len(scene.point_lights) or len(scene.sun_lights) or len(scene.area_lights) or len(small_emitters(scene))):
        return laid_out                 # no lamp of the first shot: no tracer built
    tracer = RayTracer(scene)
    try:
        direct = DirectLighting(scene, tracer)
        if not direct.n_lights:
            return laid_out
        def light(points, normals):         # each point's numbers its own: the same layout however numbered
            return direct.irradiance(points, normals, PointUniforms(points), samples_per_light=2,
                                     penumbra_samples=8).mean(axis=1)

        return split_where_lit_unevenly(laid_out, light)[0]
    finally:
        tracer.close()


def _check_world(scene):
    """ValueError where the scene's world is still a stand-in (its render not attached)."""
    if scene.world.stand_in:
        raise ValueError("the scene's world is a stand-in: attach its rendered image first "
                         "(raybundle.scene.build.attach_world)")


def make_solver(scene, settings: RenderSettings | None = None, solver=StochasticIterationSolver.name, stage=None,
                stop=None):
    """Tracer + first shot + solver for a prepared scene (no camera needed: bakes);
    the solver holds them as ``solver.tracer`` and ``solver.direct``.  ``stage(text)``
    and ``stop`` as in :func:`prepare`."""
    settings = settings or RenderSettings()
    settings.validate()
    _check_world(scene)
    if solver not in SOLVERS:
        raise ValueError(f"unknown method {solver!r}; choose one of {sorted(SOLVERS)}")
    if image_only(solver):
        raise ValueError(f"{solver} renders images only, it has no patch solution to bake; "
                         f"bakes take {StochasticIterationSolver.name}")
    if settings.sequence in NOT_CUD and SOLVERS[solver].iterates:
        warnings.warn(f"the {settings.sequence.capitalize()} sequence is not completely uniformly distributed: "
                      f"{solver} driven by it converges to a wrong image (thesis 1.2); use 'prng', "
                      "'stratified' or 'pi-powers'", stacklevel=3)
    small = small_emitters(scene) if settings.first_shot == "none" else []
    if small:
        names = ", ".join(repr(scene.materials.names[m]) for m in small)
        warnings.warn(f"first shot is off: the small emitters {names} light the scene only through the bundle "
                      "lines that happen to hit them, so the image is far noisier (thesis 3.4); keep "
                      "first_shot='auto'", stacklevel=3)
    compile_kernels(stage, stop)
    _step(stage, stop, f"building the ray tracer over {len(scene.triangles):,} triangles")
    tracer = RayTracer(scene, threads=settings.threads)
    try:
        _step(stage, stop, f"first shot and solver set-up for {scene.n_patches:,} patches")
        direct = DirectLighting(scene, tracer, first_shot=settings.first_shot, light_tree=settings.light_tree)
        method = SOLVERS[solver](scene, tracer, direct, settings)
        if hasattr(method, "warm_up"):
            _step(stage, stop, f"warming up the iteration ({method.warm_up_steps} transfers)")
            stopped = None if stop is None else getattr(stop, "is_set", stop)
            method.warm_up(stopped)
            if stopped is not None and stopped():
                raise Cancelled("stopped during set-up, while warming up the iteration")
        return method
    except BaseException:           # Cancelled, bad input, Ctrl-C: the tracer's threads end now
        tracer.close()
        raise


def make_renderer(scene, settings: RenderSettings | None = None, camera=None,
                  solver=StochasticIterationSolver.name, stage=None, stop=None):
    """Tracer + first shot + solver + image accumulator for a prepared scene."""
    settings = settings or RenderSettings()
    if image_only(solver):
        _check_world(scene)
        return _make_image_method(scene, settings, camera, solver, stage, stop)
    solver_obj = make_solver(scene, settings, solver, stage=stage, stop=stop)
    try:
        return Renderer(scene, camera if camera is not None else scene.camera, solver_obj, solver_obj.direct,
                        settings)
    except BaseException:
        solver_obj.tracer.close()
        raise


def _make_image_method(scene, settings, camera, name, stage, stop):
    """An image-only method (:class:`~raybundle.methods.path_tracing.PathTracer`): tracer and lights, no patches."""
    settings.validate()
    check_resources(scene if camera is None else replace(scene, camera=camera))
    compile_kernels(stage, stop)
    _step(stage, stop, f"building the ray tracer over {len(scene.triangles):,} triangles")
    tracer = RayTracer(scene, threads=settings.threads)
    try:
        direct = DirectLighting(scene, tracer, first_shot=settings.first_shot, light_tree=settings.light_tree)
        return SOLVERS[name](scene, tracer, direct, settings, camera=camera)
    except BaseException:
        tracer.close()
        raise


def compile_kernels(stage, stop):
    """The set-up phase "compiling the kernels" (:func:`raybundle.util.compiled.compile_all`),
    where any is still to compile or load in this process (the add-on's before its export, whose
    sorts use one)."""
    if compiled.pending():
        _step(stage, stop, "compiling the kernels")
        compiled.compile_all()


def lay_out(scene, plan, stage=None, stop=None):
    """``scene`` (loaded, not laid out) as ``plan`` (:func:`~raybundle.app.plan.plan`) runs it: its
    patch layout (:func:`prepare`) with its welded vertices made
    (:attr:`~raybundle.scene.model.PatchScene.smooth_vertex_ids`) for a patch method, itself for
    an image-only one.  ``stage(text)`` is told auto's choice and each set-up step; ``stop`` as in :func:`prepare`."""
    line = plan.describe()
    if line:
        _step(None, stop, "the method's choice")
        if stage is not None:
            stage(line)
    if plan.image_only:
        return scene
    compile_kernels(stage, stop)               # the layout's and the welding's too
    scene = prepare(scene, patches=plan.patches, stage=stage, stop=stop)
    # every patch method's reconstruction reads them: made here, they are made while Blender
    # may still be rendering the world (the add-on attaches it after the layout)
    _step(stage, stop, "welding the patches' vertices")
    scene.smooth_vertex_ids
    return scene


def build(scene, plan, camera=None, image=True, stage=None, stop=None, attach=None):
    """``(prepared scene, runner)`` for ``scene`` (loaded, not laid out) and ``plan``: the
    layout (:func:`lay_out`), then with ``image`` a renderer (:func:`make_renderer`), else
    the solver alone (:func:`make_solver`, bakes).  ``stage`` and ``stop`` as in :func:`lay_out`;
    ``attach(laid-out scene)`` is called between the two (the add-on gives it the world
    Blender rendered meanwhile, :func:`~raybundle.scene.build.attach_world`)."""
    scene = lay_out(scene, plan, stage, stop)
    if attach is not None:
        attach(scene)
    if image:
        return scene, make_renderer(scene, plan.settings, camera, solver=plan.method, stage=stage, stop=stop)
    return scene, make_solver(scene, plan.settings, solver=plan.method, stage=stage, stop=stop)


def run_plan(scene, plan, progress=None, stop=None, camera=None, stage=None, started=None):
    """Build (:func:`build`) and run ``plan`` (:func:`~raybundle.app.plan.plan`) on ``scene``
    (loaded, not laid out): ``(laid-out scene, :class:`~raybundle.imaging.progressive.RenderResult`)``.
    ``stop`` set during set-up raises :class:`Cancelled`; during the iteration it ends the run
    with the image so far.  The plan's ``time_limit`` is the budget from ``started`` (default:
    now), set-up included (:meth:`~raybundle.imaging.progressive.ProgressiveImage.run`)."""
    started = time.perf_counter() if started is None else started
    scene, renderer = build(scene, plan, camera, stage=stage, stop=stop)
    try:
        return scene, renderer.run(iterations=plan.iterations, time_limit=plan.time_limit, progress=progress, stop=stop,
                                   started=started, stage=stage)
    finally:
        renderer.tracer.close()


def render(scene, settings=None, iterations=None, time_limit=None, progress=None, stop=None, camera=None, stage=None,
           solver=StochasticIterationSolver.name, started=None):
    """Render a scene already laid out (:func:`prepare`) with the method ``solver`` and
    ``settings`` as given (no plan: tests and studies of one setting); returns
    :class:`~raybundle.imaging.progressive.RenderResult`.  ``stop``, ``time_limit`` and ``started`` as in
    :func:`run_plan`."""
    started = time.perf_counter() if started is None else started
    renderer = make_renderer(scene, settings, camera, solver=solver, stage=stage, stop=stop)
    try:
        return renderer.run(iterations=iterations, time_limit=time_limit, progress=progress, stop=stop, started=started)
    finally:
        renderer.tracer.close()
