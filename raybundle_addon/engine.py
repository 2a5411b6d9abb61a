"""The ``RAYBUNDLE`` render engine ("Ray Bundle GI") and the progressive render job behind it.

:class:`RenderJob` is independent of :class:`bpy.types.RenderEngine`: it exports
the evaluated depsgraph (:mod:`.translation.export`), subdivides it into patches, runs the
core's stochastic iteration and hands images to a ``display`` callback — a
quick preview as soon as the first image pass is done (direct light only), then
every few hundred milliseconds (at most ~1/5 of the time goes to previews), and
the fully resolved image at the end; in the background (``blender -b``, the bpy module),
where nobody sees a preview, only the final image.  It stops at the time limit, the iteration
count, or when its ``stop`` event is set; the engine sets that event when
Blender's ``test_break()`` says so (Esc), tests and the command line set it
directly.  The image so far is kept either way; a stop during set-up (export,
patch layout, tracer, first shot) ends the job at the next set-up step with
:class:`raybundle.app.pipeline.Cancelled` and no image.

The engine pushes images with ``RenderPass.rect.foreach_set`` (rows bottom-up,
RGBA float32, alpha 1) into one result per view layer; the pixels are linear
radiance [W m^-2 sr^-1], so a 32-bit OpenEXR save holds the core's numbers.
Resolution percentage and the render border (cropped or not) are honoured; each
view layer is rendered in turn (each for the whole time limit).  A view layer's Light
Components (``view_layer.raybundle.use_pass_components``) adds the image's parts as passes
(:data:`COMPONENT_PASSES`), written with the final image.  Errors
(:class:`raybundle.scene.model.SceneError`, ValueError) become one-line ``ERROR``
reports; export warnings become ``WARNING`` reports.
"""
from __future__ import annotations

import threading
import time
import traceback
from dataclasses import dataclass, field

import bpy
import numpy as np

from .translation.export import export_scene
from .properties import LAST_RUN, run_options, wants_components

#: callables ``fn(job, event)`` told about every job: events "export" (after export),
#: "progress" (as the run loop reports it), "image" (after each displayed image) and "done".
#: The command line uses it for its progress bar and Ctrl-C; tests use it to time the first
#: image and to cancel.
observers: list = []
#: jobs running now (``cancel_all`` sets their stop flags)
active_jobs: set = set()
#: the component passes: the core's part (:mod:`raybundle.imaging.components`), Blender's pass
#: name (prefixed "RB ": Blender's own passes of these names mean other things), its
#: channels and their ids
COMPONENT_PASSES = [("emission", "RB Emission", 3, "RGB"), ("lamps", "RB Lamps", 3, "RGB"),
                    ("world", "RB World", 3, "RGB"), ("glossy", "RB Glossy", 3, "RGB"),
                    ("diffuse indirect", "RB Diffuse Indirect", 3, "RGB"), ("caustics", "RB Caustics", 3, "RGB"),
                    ("glass", "RB Glass", 1, "X")]


def cancel_all():
    """Ask every running job to stop after its current iteration (keeps the image so far)."""
    for job in list(active_jobs):
        job.stop.set()


@dataclass
class RenderOutcome:
    image: np.ndarray            # (H, W, 3) float32 linear radiance, row 0 at the top
    stats: dict
    warnings: list
    cancelled: bool
    export: object = None        # the ExportResult
    timings: dict = field(default_factory=dict)
    #: the image's parts by name (:class:`raybundle.imaging.progressive.RenderResult`), or None
    components: dict | None = None


class RenderJob:
    """One progressive render of an evaluated depsgraph (see the module docstring).

    ``options``: :class:`raybundle.app.plan.RunOptions` (default: the scene's settings).
    Callbacks (all optional): ``display(image (H, W, 3) f32 top-down, final)``,
    ``progress(fraction)``, ``stats(text)``; ``user_break()`` is polled between
    iterations and sets ``stop`` when true.
    """

    def __init__(self, depsgraph, options=None, stop=None, display=None, progress=None, stats=None,
                 user_break=None, camera_object=None, preview_interval=0.3):
        self.depsgraph = depsgraph
        #: :class:`raybundle.app.plan.RunOptions`: given, or (None) the scene's, read when the job runs
        self.options = options
        self.stop = stop if stop is not None else threading.Event()
        self.display, self.progress, self.stats_cb = display, progress, stats
        self.choice = None           # auto's Choice, when the method is auto
        self.user_break = user_break
        self.camera_object = camera_object
        #: seconds between preview images (None: none, only the final image)
        self.preview_interval = None if preview_interval is None else float(preview_interval)
        self.t_start = None
        self.first_image_seconds = None
        self.images = 0
        self.export = None
        self.world_wait = 0.0        # seconds the set-up waited for Blender's render of the world
        self.last_image = None
        self.renderer = None
        self._interval = self.preview_interval
        self._last_push = 0.0
        self._last_stats = 0.0
        self.fraction = 0.0

    # ---------------------------------------------------------------- events
    def _notify(self, event):
        for fn in list(observers):
            fn(self, event)

    def _show(self, image, final=False):
        self.last_image = image
        if self.display is not None:
            self.display(image, final)
        self.images += 1
        if self.first_image_seconds is None:
            self.first_image_seconds = time.perf_counter() - self.t_start
        self._notify("image")

    def _stopped(self):
        """Esc (``user_break``) or ``stop``: True once either asked to stop."""
        if self.user_break is not None and self.user_break():
            self.stop.set()
        return self.stop.is_set()

    def _preview(self):
        """Between iterations: a preview image when the last is old enough."""
        if self.preview_interval is None:
            return
        now = time.perf_counter()
        if self.images == 0 or now - self._last_push >= self._interval:
            img = self.renderer.image(preview=True)
            self._show(img)
            done = time.perf_counter()
            self._interval = max(self.preview_interval, 4.0 * (done - now))   # previews <= ~20% of the time
            self._last_push = done

    def _on_progress(self, fraction, info):
        self.fraction = fraction
        self._notify("progress")
        if self.progress is not None:
            self.progress(fraction)
        now = time.perf_counter()
        if self.stats_cb is not None and now - self._last_stats > 0.2:
            self._last_stats = now
            st = self.renderer.solver.stats
            rays = (st.rays + self.renderer.image_rays) / 1e6
            self.stats_cb(f"Ray Bundle GI | Iteration {info['iterations']} | {rays:.1f} M rays | "
                          f"{info['seconds']:.1f} s")

    # ------------------------------------------------------------------ run
    def run(self):
        """Export, prepare and iterate; returns :class:`RenderOutcome`.  Raises
        SceneError/ValueError for scenes and settings that cannot be rendered, and
        :class:`raybundle.app.pipeline.Cancelled` when stopped during set-up (no image yet)."""
        from raybundle.app import pipeline
        from raybundle.app.phases import PhaseClock
        from raybundle.app.plan import check, plan

        self.t_start = time.perf_counter()
        if self.options is None:
            self.options = run_options(self.depsgraph.scene, self.depsgraph.view_layer)
        check(self.options)
        active_jobs.add(self)
        try:
            stage = PhaseClock(None if self.stats_cb is None else
                               (lambda text: self.stats_cb(f"Ray Bundle GI | {text}")))
            t_kernels = time.perf_counter()
            pipeline.compile_kernels(stage, self._stopped)      # a cold compile its own phase, not the export's
            t_kernels = time.perf_counter() - t_kernels          # the set-up's seconds, as in the pipeline
            stage("exporting the scene")
            # the world's render (where Blender must render it) runs on while the patches are laid out
            self.export = export_scene(self.depsgraph, camera_object=self.camera_object, defer_world=True)
            t_export = time.perf_counter() - self.t_start
            self._notify("export")
            def attach(scene):
                """Between the layout and the renderer: the world Blender rendered meanwhile."""
                if self.export.world_render is not None:
                    stage("waiting for Blender's render of the world")
                self.world_wait = self.export.attach_world(scene)
                if scene is not self.export.scene:
                    self.export.scene.release_caches()          # the prepared copy renders

            try:
                p = plan(self.export.scene, self.options)
                self.choice = p.choice
                _, self.renderer = pipeline.build(self.export.scene, p, stage=stage, stop=self._stopped, attach=attach)
            finally:
                self.export.cancel_world()
            t_prepared = time.perf_counter() - self.t_start
            try:
                result = self.renderer.run(iterations=p.iterations, time_limit=p.time_limit, progress=self._on_progress,
                                           stop=self._stopped, between=self._preview, started=self.t_start,
                                           stage=stage)
            finally:
                self.renderer.tracer.close()
            self._show(result.image, final=True)
        finally:
            active_jobs.discard(self)
        stats = dict(result.stats)
        stats.update(export_seconds=round(t_export - t_kernels, 4),
                     prepare_seconds=round(t_prepared - t_export + t_kernels, 4),
                     world_wait_seconds=round(self.world_wait, 4),
                     first_image_seconds=round(self.first_image_seconds, 4),
                     total_seconds=round(time.perf_counter() - self.t_start, 4),
                     warnings=len(self.export.warnings), phases=stage.finish(),
                     **{f"scene_{k}": v for k, v in self.export.counts.items()})
        if "budget_note" in stats:
            self.export.warnings.append(stats["budget_note"] + ": raise the time limit")
        if self.choice is not None:
            stats["auto"] = self.choice.as_dict()
        if self.options.components and result.components is None:
            self.export.warnings.append(f"{stats['solver']} does not keep the image's parts apart: "
                                        "the Light Components passes are black")
        outcome = RenderOutcome(result.image, stats, list(self.export.warnings), result.cancelled, self.export,
                                components=result.components)
        self._notify("done")
        return outcome


def _record(scene_name, outcome=None, error=None):
    if outcome is not None:
        st = outcome.stats
        LAST_RUN[scene_name] = {
            "status": ("stopped early" if outcome.cancelled else "done") +
                      (f", {len(outcome.warnings)} warnings" if outcome.warnings else ""),
            "iterations": st["iterations"], "seconds": st["seconds"], "mrays": st["rays_traced"] / 1e6,
            "patches": st["patches"], "triangles": st["triangles"],
            "first_image_seconds": st["first_image_seconds"], "n_warnings": len(outcome.warnings),
            "warnings": list(outcome.warnings), "stats": st}
    else:
        LAST_RUN[scene_name] = {"status": f"error: {error}", "warnings": []}


def render_with_engine(engine, depsgraph):
    """The body of ``RAYBUNDLE.render``: a :class:`RenderJob` whose images go to the
    engine's render result.  Never raises: errors become reports."""
    from raybundle.app.pipeline import Cancelled
    from raybundle.scene.model import SceneError

    scene = depsgraph.scene
    layer = depsgraph.view_layer.name
    width, height = engine.resolution_x, engine.resolution_y
    state = {"result": None}
    components = wants_components(depsgraph.view_layer)
    if components:                     # before the result is begun
        for _, name, channels, chan_id in COMPONENT_PASSES:
            engine.add_pass(name, channels, chan_id, layer=layer)

    def display(image, final):
        res = state["result"]
        if res is None:
            res = state["result"] = engine.begin_result(0, 0, width, height, layer=layer)
            if res is None:
                raise RuntimeError("Blender gave no render result to write into")
        h, w = image.shape[:2]
        rgba = np.ones((h, w, 4), np.float32)
        rgba[..., :3] = image[::-1]                        # RenderPass rows are bottom-up
        rect = res.layers[0].passes["Combined"].rect
        if len(rect) != h * w:
            raise RuntimeError(f"the render result has {len(rect)} pixels, the image {w} x {h}: "
                               "an unsupported render border or resolution setting")
        rect.foreach_set(rgba.ravel())
        engine.update_result(res)

    # in the background (``blender -b``, the bpy module) nobody sees a preview: its time goes to the image
    job = RenderJob(depsgraph, display=display, progress=engine.update_progress,
                    stats=lambda text: engine.update_stats("", text), user_break=engine.test_break,
                    camera_object=engine.camera_override, preview_interval=None if bpy.app.background else 0.3)
    try:
        outcome = job.run()
        for w in outcome.warnings[:8]:
            engine.report({"WARNING"}, f"Ray Bundle GI: {w}")
        if len(outcome.warnings) > 8:
            engine.report({"WARNING"}, f"Ray Bundle GI: {len(outcome.warnings) - 8} more warnings "
                                       "(see the panel / the console)")
            for w in outcome.warnings[8:]:
                print(f"Ray Bundle GI: warning: {w}")
        if components and outcome.components is not None and state["result"] is not None:
            write_components(state["result"], outcome.components)
            engine.update_result(state["result"])
        _record(scene.name, outcome)
        st = outcome.stats
        engine.update_stats("", f"Ray Bundle GI | {'Stopped' if outcome.cancelled else 'Done'} | "
                                f"{st['iterations']} iterations | {st['rays_traced'] / 1e6:.1f} M rays | "
                                f"{st['seconds']:.1f} s")
    except (SceneError, ValueError) as e:
        _record(scene.name, error=str(e))
        engine.report({"ERROR"}, f"Ray Bundle GI: {e}")
    except Cancelled as e:          # Esc during set-up: nothing rendered, nothing to report as an error
        LAST_RUN[scene.name] = {"status": str(e), "warnings": []}
        engine.update_stats("", "Ray Bundle GI | Stopped during set-up")
    except Exception as e:   # a bug: keep Blender alive, say what happened, keep the trace in the console
        traceback.print_exc()
        _record(scene.name, error=f"{type(e).__name__}: {e}")
        engine.report({"ERROR"}, f"Ray Bundle GI: internal error ({type(e).__name__}: {e}); please report it")
    finally:
        if state["result"] is not None:
            engine.end_result(state["result"])


def write_components(result, components):
    """Write the image's parts ``components`` (by the core's names, rows top-down) into the
    render ``result``'s passes (:data:`COMPONENT_PASSES`)."""
    passes = result.layers[0].passes
    for part, name, channels, _ in COMPONENT_PASSES:
        image = np.asarray(components[part], np.float32)[::-1]           # RenderPass rows are bottom-up
        passes[name].rect.foreach_set(np.ascontiguousarray(image.reshape(-1, channels)).ravel())


class RAYBUNDLE_RenderEngine(bpy.types.RenderEngine):
    bl_idname = "RAYBUNDLE"
    bl_label = "Ray Bundle GI"
    bl_use_preview = False
    bl_use_shading_nodes_custom = False     # Blender's own shader nodes (the Cycles ones)
    bl_use_eevee_viewport = True            # material preview / viewport shading through EEVEE

    def __init__(self, *args, **kwargs):    # Blender 4.4+/5.x: pass the arguments on (blender.md §2)
        super().__init__(*args, **kwargs)

    def render(self, depsgraph):
        render_with_engine(self, depsgraph)

    def update_render_passes(self, scene=None, renderlayer=None):
        """The passes the compositor offers: Combined, and the Light Components where asked."""
        self.register_pass(scene, renderlayer, "Combined", 4, "RGBA", "COLOR")
        if wants_components(renderlayer):
            for _, name, channels, chan_id in COMPONENT_PASSES:
                self.register_pass(scene, renderlayer, name, channels, chan_id, "COLOR" if channels == 3 else "VALUE")


classes = (RAYBUNDLE_RenderEngine,)


def register():
    for c in classes:
        bpy.utils.register_class(c)


def unregister():
    for c in reversed(classes):
        bpy.utils.unregister_class(c)
