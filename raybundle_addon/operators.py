"""The ``raybundle.bake`` operator: :class:`.bake.BakeJob` from the UI, scripts and ``blender -b``.

With a window (``invoke``), the bake runs as a modal operator: a timer calls
:meth:`.bake.BakeJob.step` for ~0.1 s per tick on the main thread (NumPy and
Embree do the work; Blender stays responsive between ticks), the status bar and
the cursor show the progress of the iteration and then of the final gather, and Esc
stops either and writes what has converged so far (the points not gathered yet
interpolated from the patches).  Headless (``bpy.app.background``) and from scripts
(``execute``) it runs to the time limit in one call.  Lightmaps are baked for the
selected objects (every mesh with a UV map when nothing is selected).
"""
from __future__ import annotations

import traceback

import bpy

from .bake import BakeJob
from .properties import LAST_BAKE


def _report_outcome(op, outcome):
    for w in outcome.warnings[:8]:
        op.report({"WARNING"}, f"Ray Bundle GI bake: {w}")
    for w in outcome.warnings[8:]:
        print(f"Ray Bundle GI bake: warning: {w}")
    st = outcome.stats
    parts = []
    if outcome.attributes:
        parts.append(f"{len(outcome.attributes)} color attributes")
    if outcome.lightmaps:
        parts.append(f"{len(outcome.lightmaps)} lightmaps")
    if outcome.camera:
        parts.append("the camera view")
    op.report({"INFO"}, f"Ray Bundle GI: baked {', '.join(parts) or 'nothing'} "
                        f"({'stopped early, ' if outcome.cancelled else ''}{st['iterations']} iterations, "
                        f"{st['total_seconds']:.1f} s)")


def _make_job(context):
    sel = [o.name for o in (context.selected_objects or [])] if hasattr(context, "selected_objects") else []
    return BakeJob(context.evaluated_depsgraph_get(), lightmap_objects=sel or None)


class RAYBUNDLE_OT_bake(bpy.types.Operator):
    """Solve the global illumination of the scene and write it into the file: a color attribute on every
    mesh, lightmaps of the selected meshes, the camera view (view-independent light: glossy reflections
    are left out of attributes and lightmaps)"""

    bl_idname = "raybundle.bake"
    bl_label = "Bake Ray Bundle GI"
    bl_options = {"REGISTER"}

    _running = False          # one bake at a time

    @classmethod
    def poll(cls, context):
        if cls._running:
            cls.poll_message_set("a bake is running (Esc stops it)")
            return False
        return context.scene is not None

    def _fail(self, context, message, job=None):
        LAST_BAKE[context.scene.name] = {"status": f"error: {message}", "warnings": [], "stats": {}}
        self.report({"ERROR"}, f"Ray Bundle GI bake: {message}")
        if job is not None and job.solver is not None:
            job.solver.tracer.close()
        return {"CANCELLED"}

    def execute(self, context):
        from raybundle.app.pipeline import Cancelled
        from raybundle.scene.model import SceneError

        job = _make_job(context)
        try:
            outcome = job.run()
        except (SceneError, ValueError) as e:
            return self._fail(context, str(e), job)
        except Cancelled as e:
            LAST_BAKE[context.scene.name] = {"status": str(e), "warnings": [], "stats": {}}
            self.report({"INFO"}, f"Ray Bundle GI bake: {e}; nothing written")
            return {"CANCELLED"}
        except Exception as e:      # a bug: keep Blender alive, keep the trace in the console
            traceback.print_exc()
            return self._fail(context, f"internal error ({type(e).__name__}: {e}); please report it", job)
        _report_outcome(self, outcome)
        return {"FINISHED"}

    def invoke(self, context, event):
        from raybundle.scene.model import SceneError

        if bpy.app.background:
            return self.execute(context)
        self.job = _make_job(context)
        try:
            self.job.start()
        except (SceneError, ValueError) as e:
            return self._fail(context, str(e), self.job)
        wm = context.window_manager
        self._timer = wm.event_timer_add(0.05, window=context.window)
        wm.modal_handler_add(self)
        wm.progress_begin(0, 100)
        type(self)._running = True
        self._status(context)
        return {"RUNNING_MODAL"}

    def _status(self, context):
        job = self.job
        text = f"Ray Bundle GI bake: {100 * job.fraction:.0f}% | {job.phase} | Esc stops and keeps the result so far"
        if context.workspace is not None:
            context.workspace.status_text_set(text)
        context.window_manager.progress_update(100 * job.fraction)

    def _end(self, context):
        wm = context.window_manager
        wm.event_timer_remove(self._timer)
        wm.progress_end()
        if context.workspace is not None:
            context.workspace.status_text_set(None)
        type(self)._running = False

    def modal(self, context, event):
        if event.type == "ESC" and event.value == "PRESS":
            self.job.stop.set()
        elif event.type != "TIMER":
            return {"PASS_THROUGH"}
        try:
            more = self.job.step(0.1)
            self._status(context)
            if more:
                return {"RUNNING_MODAL"}
            outcome = self.job.finish()
        except Exception as e:
            self._end(context)
            traceback.print_exc()
            return self._fail(context, f"internal error ({type(e).__name__}: {e}); please report it", self.job)
        self._end(context)
        _report_outcome(self, outcome)
        for area in context.screen.areas if context.screen else ():
            for space in area.spaces:
                if space.type == "VIEW_3D" and space.shading.type == "SOLID" and outcome.attributes:
                    space.shading.color_type = "VERTEX"       # show the baked attribute
            area.tag_redraw()
        return {"FINISHED"}


def _menu(self, context):
    self.layout.separator()
    self.layout.operator(RAYBUNDLE_OT_bake.bl_idname, icon="RENDER_STILL")


classes = (RAYBUNDLE_OT_bake,)


def register():
    for c in classes:
        bpy.utils.register_class(c)
    bpy.types.TOPBAR_MT_render.append(_menu)


def unregister():
    bpy.types.TOPBAR_MT_render.remove(_menu)
    for c in reversed(classes):
        bpy.utils.unregister_class(c)
