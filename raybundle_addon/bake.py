"""Bake the solution into the file: color attributes, lightmaps and the camera's view.

:class:`BakeJob` is the whole bake, in three calls that the operator
(:mod:`.operators`), the command line and the tests share:

* :meth:`BakeJob.start` exports the evaluated depsgraph (:mod:`.translation.export`), picks
  the targets and reads what they need (corners, UVs), subdivides into patches
  and sets up the core's solver;
* :meth:`BakeJob.step` works for about ``budget`` seconds and returns False once done:
  it iterates until the time limit or the iteration count is reached or ``stop`` is set,
  then gathers the color attributes' indirect light, then bakes the lightmaps one at a time
  (:mod:`.bake_lightmaps`; the modal operator calls it on every timer tick, headless code in a loop);
* :meth:`BakeJob.finish` evaluates the radiance at the targets' points
  (:func:`raybundle.imaging.baking.baked_parts`: per-point direct light with
  ``light_samples`` shadow rays; the indirect light of vertices and corners gathered from
  the solution, :class:`raybundle.imaging.bake_gather.BakeGather`) and writes it and the
  lightmaps into the file, on the main thread.

The gather of a bake limited by time is part of its budget: the run loop leaves
:data:`~.properties.GATHER_SHARE` of the iteration time for it, and Gather Rays set to automatic
(``gather_rays`` -1) gathers as many rays per point as the time left buys (at least
:attr:`~raybundle.imaging.bake_gather.BakeGather.MIN_RAYS`, else the patches are interpolated); a
bake of given iterations gathers :data:`~.properties.FIXED_GATHER_RAYS` rays a point, the same values on
every run.  A stop during the gather keeps what is gathered and interpolates the rest (warned).

What is written (Blender's units: linear radiance [W m^-2 sr^-1], view-independent:
the diffuse light and the emission; glossy reflections depend on the viewer and
are left out):

* a ``FLOAT_COLOR`` attribute ``RayBundle`` (point or face-corner domain) on every
  baked mesh, active for display and render.  The mesh's geometry is not changed.
  A face is baked on the side its normal points to, as Cycles' bake does.  A
  corner's value is the radiance at the corner on its own face; a vertex's, the
  mean over its corners (a vertex on a crease averages its faces).  Objects that
  share a mesh (linked duplicates, instances) share the first object's values
  (warned) unless ``single_user`` gives each its own copy of the mesh.  An object
  whose modifiers change the topology (or a curve, text...) is baked into a new
  mesh object ``<name>.RayBundle`` made from its evaluated mesh, hidden from
  renders (so it does not add its geometry twice), and the original is left alone;
* a lightmap per selected mesh with a UV map: an RGB float EXR
  ``<object>.lightmap.exr`` of ``lightmap_size``² texels, each texel the radiance at
  its centre's point (the active UV map), its direct light averaged over its footprint (as
  Cycles' bake does), its indirect light interpolated from the patches or, next to concave
  edges and contacts, gathered (:class:`raybundle.imaging.lightmap.TexelGather`), dilated by
  ``lightmap_margin`` texels around the islands, loaded as an Image of the same name;
* with ``camera``, the active camera's view as ``<scene>.camera.exr`` and an Image.

Files go to ``directory`` (``//`` = next to the .blend); an unsaved file's
relative folder falls back to a temporary one and the Images are packed into the
file (warned), so nothing is lost.  EXRs are written atomically.
"""
from __future__ import annotations

import os
import tempfile
import threading
import time
from dataclasses import dataclass, field

import bpy
import numpy as np

from raybundle.imaging.run import RunLoop

from .translation.export import export_scene
from .translation.mesh_data import corner_vertices
from .bake_lightmaps import LightmapBake
from .properties import FIXED_GATHER_RAYS, GATHER_SHARE, LAST_BAKE, BakeSettings, run_options

ATTRIBUTE = "RayBundle"
COPY_SUFFIX = ".RayBundle"


def _unique_points(input_scene, face, bary):
    """Representatives of the bake points (input face ids ``face`` (N,), barycentrics
    (N, 3)) that share a position and a face normal: ``(rep (M,), back (N,))`` with point
    i baked as point ``rep[back[i]]``."""
    from raybundle.imaging.baking import input_rows

    r = input_rows(input_scene, face)
    ok = r >= 0
    p = np.zeros((len(face), 3))
    nrm = np.zeros((len(face), 3))
    p[ok] = np.einsum("nk,nkc->nc", bary[ok], input_scene.triangle_corners[r[ok]])
    nrm[ok] = input_scene.triangle_normal[r[ok]]
    _, radius = input_scene.bounding_sphere
    key = np.concatenate([np.round(p / max(radius * 1e-7, 1e-12)), np.round(nrm * 1e4), (~ok)[:, None] *
                          np.arange(len(face))[:, None]], axis=1).astype(np.int64)
    _, rep, back = np.unique(key, axis=0, return_index=True, return_inverse=True)
    return rep, back.reshape(-1)


@dataclass
class _Target:
    """One mesh to write: the export's object entry and, per corner of its evaluated
    mesh, the export triangle (-1: none) and barycentrics there."""

    info: object
    corner_face: np.ndarray
    corner_bary: np.ndarray
    copy: bool = False                  # bake into a new object made from the evaluated mesh
    refine: bool = False                # ... cut where the lighting needs it (corners set in finish)
    refined: object = None              # raybundle.imaging.baking.RefinedTriangles
    own_mesh: bool = False              # give the object its own copy of a shared mesh first
    sharing: list = field(default_factory=list)      # other objects that share the mesh


@dataclass
class BakeOutcome:
    stats: dict
    warnings: list
    cancelled: bool
    attributes: list            # (object name, mesh name) written
    lightmaps: dict             # object name -> EXR path
    camera: str | None          # camera EXR path


class BakeJob:
    """One bake of an evaluated depsgraph (module docstring).  ``lightmap_objects``:
    names of the objects to bake lightmaps for (None: every mesh object with a UV map)."""

    def __init__(self, depsgraph, options=None, bake=None, lightmap_objects=None, stop=None):
        self.depsgraph = depsgraph
        self.scene = depsgraph.scene
        #: :class:`raybundle.app.plan.RunOptions` (None: the scene's settings, read at the start); the plan
        self.options = options
        self.plan = None
        self.bake = bake or BakeSettings.from_scene(self.scene)
        self.lightmap_objects = None if lightmap_objects is None else set(lightmap_objects)
        self.stop = stop if stop is not None else threading.Event()
        self.warnings = []
        self.fraction = 0.0
        self.export = self.solver = self.renderer = None
        self.targets = []
        self.lightmaps = LightmapBake(self)
        self._final = None
        self.t_start = self.loop = None
        self.timings = {}
        #: the color attributes' points once the iteration ends: ``(rep, back, points, parts, gather)``
        self._points = None

    def warn(self, message):
        if message not in self.warnings:
            self.warnings.append(message)

    # ----------------------------------------------------------------- start
    def start(self):
        """Export, choose the targets, prepare the solver.  Raises SceneError/ValueError
        (one-line reasons) for what cannot be baked, :class:`raybundle.app.pipeline.Cancelled`
        when ``stop`` is set during set-up (nothing is written)."""
        from raybundle.app import pipeline
        from raybundle.app.plan import check, plan

        self.t_start = time.perf_counter()
        b = self.bake
        if self.options is None:
            self.options = run_options(self.scene)
        check(self.options, bake=True)
        b.validate()
        pipeline.compile_kernels(None, self.stop)             # before the export's first use of one
        # the world's render (where Blender must render it) runs on while the patches are laid out
        self.export = export_scene(self.depsgraph, require_camera=b.camera, defer_world=True)
        try:
            for w in self.export.warnings:
                self.warn(w)
            if b.color_attribute:
                self._pick_attribute_targets()
            if b.lightmaps:
                self.lightmaps.pick(self.lightmap_objects)
                if not self.lightmaps.targets and not b.color_attribute and not b.camera:
                    raise ValueError("nothing to bake: no selected mesh has a UV map for a lightmap")
            self.timings["export_seconds"] = time.perf_counter() - self.t_start
            self.plan = plan(self.export.scene, self.options, bake=True)
            if self.plan.notes:
                self.warn(self.plan.describe())
            _, runner = pipeline.build(self.export.scene, self.plan, image=b.camera, stop=self.stop,
                                       attach=self._attach_world)
        finally:
            self.export.cancel_world()
        self.renderer = runner if b.camera else None
        self.solver = runner.solver if b.camera else runner
        self.timings["prepare_seconds"] = time.perf_counter() - self.t_start - self.timings["export_seconds"]
        share = GATHER_SHARE if self.targets and b.gather_rays < 0 else 0.0
        self.loop = RunLoop(runner, self.plan.iterations, self.plan.time_limit, started=self.t_start, stop=self.stop,
                            final_share=share)
        return self

    def _attach_world(self, scene):
        """Wait for the world's render and give it to ``scene`` (the laid-out one), warning
        what it warned."""
        known = len(self.export.warnings)
        self.timings["world_wait_seconds"] = self.export.attach_world(scene)
        for w in self.export.warnings[known:]:
            self.warn(w)

    def _corners(self, info):
        """Per corner of ``info``'s evaluated mesh: export triangle and barycentrics."""
        tri = np.arange(info.first_triangle, info.first_triangle + info.n_triangles)
        loops = self.export.triangle_loops[tri].ravel()
        face = np.full(info.n_loops, -1, np.int64)
        bary = np.zeros((info.n_loops, 3))
        face[loops] = np.repeat(tri, 3)
        bary[loops] = np.tile(np.eye(3), (len(tri), 1))
        return face, bary

    def _pick_attribute_targets(self):
        by_mesh = {}
        infos = sorted(self.export.objects, key=lambda i: i.is_instance)      # real objects before instances
        for info in infos:
            ob = bpy.data.objects.get(info.original)
            if ob is None:
                continue
            same = (ob.type == "MESH" and len(ob.data.loops) == info.n_loops
                    and len(ob.data.polygons) == info.n_polygons)
            if ob.type == "MESH" and not same:
                self.warn(f"object {ob.name!r}: its modifiers change the topology; baked into a new object "
                          f"{ob.name + COPY_SUFFIX!r} made from the evaluated mesh (hidden from renders)")
            elif ob.type != "MESH":
                self.warn(f"object {ob.name!r} ({ob.type.lower()}) has no mesh to hold a color attribute; baked "
                          f"into a new mesh object {ob.name + COPY_SUFFIX!r} (hidden from renders)")
            if same and ob.data.library is not None:
                self.warn(f"object {ob.name!r}: its mesh is linked from a library and cannot be written; not baked")
                continue
            key = ob.data.name_full if same else ("copy", info.original)
            first = by_mesh.get(key)
            own = False
            if first is not None:
                if same and self.bake.single_user and not info.is_instance and info.original != first.info.original:
                    key, own = ("single", info.original), True      # gets its own copy of the mesh
                    if key in by_mesh:
                        continue
                else:
                    if info.original != first.info.original or info.is_instance:
                        first.sharing.append(info.instancer if info.is_instance and info.instancer else info.name)
                    continue
            face, bary = self._corners(info)
            refine = self.bake.subdivide and info.n_triangles > 0
            by_mesh[key] = t = _Target(info, face, bary, copy=not same or refine, own_mesh=own and not refine,
                                       refine=refine)
            self.targets.append(t)
        for t in self.targets:
            if t.sharing:
                names = ", ".join(repr(n) for n in sorted(set(t.sharing))[:5])
                more = f" and {len(set(t.sharing)) - 5} more" if len(set(t.sharing)) > 5 else ""
                self.warn(f"mesh of {t.info.original!r} is shared with {names}{more}: it holds "
                          f"{t.info.original!r}'s light (turn on Make Single User to bake each)")

    # ------------------------------------------------------------------ step
    def step(self, budget=0.1):
        """Work for about ``budget`` seconds (the run loop, :class:`raybundle.imaging.run.RunLoop`,
        owns the whole job's budget from its start, export and set-up included): iterate, then
        gather the color attributes' indirect light, then the lightmaps' (after the budget, one at a
        time); False once done (or stopped)."""
        lm = self.lightmaps
        timed = 0.5 if lm.targets else 1.0          # the bar's share of the budgeted part
        if not self.loop.finished:
            more = self.loop.advance(max_seconds=budget)
            self.fraction = timed * self.loop.fraction / (1.0 + self.loop.final_share)
            if more:
                return True
            if self.targets and not self.loop.cancelled:
                self._start_gather()
        if self.stop.is_set() or self.loop.cancelled:
            self.fraction = 1.0
            return False
        gather = self._points[4] if self._points is not None else None
        if gather is not None and not gather.done:
            more = gather.advance(budget)
            share = self.loop.final_share / (1.0 + self.loop.final_share)
            self.fraction = timed * (1.0 - share + share * gather.fraction)
            if more:
                return True
        if not lm.targets:
            self.fraction = 1.0
            return False
        t0 = time.perf_counter()
        more = lm.step(budget)
        self.timings["lightmap_seconds"] = self.timings.get("lightmap_seconds", 0.0) + time.perf_counter() - t0
        self.fraction = 1.0 if not more else timed + (1.0 - timed) * lm.done / len(lm.targets)
        return more

    @property
    def phase(self):
        """What :meth:`step` does now, for the progress display: the iteration, the gather or a lightmap."""
        if self.lightmaps.phase:
            return self.lightmaps.phase
        if self._points is None:
            return f"iteration {self.solver.stats.iterations}"
        g = self._points[4]
        return f"gathering {g.gathered:,} of {len(g.todo):,} points, {g.rays:,} rays each"

    @property
    def final_gather(self):
        """The solution's :class:`raybundle.imaging.gather.FinalGather` (with the second bounce), made once
        the iteration ends and shared by the color attributes' gather and the lightmaps'."""
        if self._final is None:
            from raybundle.imaging.gather import FinalGather

            self._final = FinalGather(self.solver, bounce=True)
        return self._final

    def _start_gather(self):
        """Locate the color attributes' points (cut where the lighting needs it first, with
        Subdivide), light them directly and start their gather with the rays the bake affords
        (module docstring)."""
        from raybundle.imaging.bake_gather import BakeGather
        from raybundle.imaging.baking import baked_parts, locate_points

        solver, ex = self.solver, self.export
        rng = np.random.default_rng([self.plan.settings.seed, 21])
        for t in self.targets:
            if t.refine:
                self._refine(t, rng)
        face = np.concatenate([t.corner_face for t in self.targets])
        bary = np.concatenate([t.corner_bary for t in self.targets])
        # corners at one point of one plane (a vertex inside a face) are one bake point
        rep, back = _unique_points(ex.scene, face, bary)
        pts = locate_points(ex.scene, solver.scene, solver.tracer, face[rep], bary[rep])
        parts = baked_parts(solver, pts, self.bake.light_samples, rng)
        gather = BakeGather(solver, pts, seed=self.plan.settings.seed, final=self.final_gather)
        rays, deadline = self.bake.gather_rays, None
        if self.loop.cancelled or self.stop.is_set():
            rays = 0
        elif rays < 0 and self.plan.time_limit is None:
            rays = FIXED_GATHER_RAYS
        elif rays < 0:
            deadline = self.t_start + 0.99 * self.plan.time_limit      # a hundredth left for the writing
            left = deadline - time.perf_counter()
            rays = gather.automatic_rays(left)
            if not rays:
                self.warn(f"no time left for the final gather ({max(left, 0.0):.1f} s): the indirect light is "
                          "interpolated from the patches; raise the time limit")
        gather.start(rays, deadline=deadline)
        self._points = (rep, back, pts, parts, gather)

    def run(self):
        """start, step to the end, finish: the headless bake.  Returns :class:`BakeOutcome`."""
        self.start()
        while self.step(1.0):
            pass
        return self.finish()

    # ---------------------------------------------------------------- finish
    def _directory(self):
        raw = self.bake.directory or "//"
        if raw.startswith("//") and not bpy.data.filepath:
            self.warn("the file is not saved: the EXRs went to a temporary folder and the Images are packed "
                      "into the file (save it to keep them)")
            return tempfile.mkdtemp(prefix="raybundle-bake-"), True
        path = bpy.path.abspath(raw)
        os.makedirs(path, exist_ok=True)
        return path, False

    def finish(self):
        """Evaluate and write everything (main thread).  Returns :class:`BakeOutcome`."""
        t0 = time.perf_counter()
        stepped = self.timings.get("lightmap_seconds", 0.0)        # the lightmaps' time in step
        cancelled = self.stop.is_set() or self.loop.cancelled
        solver = self.solver
        attributes, lightmaps, camera_path = [], {}, None
        try:
            if self.targets:
                if self._points is None:            # stopped while iterating: no gather
                    self._start_gather()
                    if self.bake.gather_rays:
                        self.warn("stopped: the color attributes' indirect light is interpolated from the patches "
                                  "(no final gather)")
                _, back, pts, parts, gather = self._points
                if gather.interpolated and gather.gathered:
                    why = "stopped during the final gather" if self.stop.is_set() else "the time limit came"
                    self.warn(f"{why}: {gather.gathered:,} of {len(gather.todo):,} points gathered, the rest "
                              "interpolated from the patches")
                values = parts.radiance(gather.indirect)[back]
                self.timings.update(gather_rays=gather.fewest, gather_seconds=gather.seconds)
                found = pts.found[back]
                k = 0
                for t in self.targets:
                    m = len(t.corner_face)
                    got = self._write_attribute(t, values[k:k + m], found[k:k + m])
                    if got:
                        attributes.append(got)
                    k += m
            directory = packed = None
            if self.lightmaps.targets or self.bake.camera:
                directory, packed = self._directory()
            t1 = time.perf_counter()
            for (info, _, uv_name), img in self.lightmaps.images():
                lightmaps[info.original] = self._save_image(
                    f"{info.original}.lightmap", img, directory, packed,
                    {"raybundle_object": info.original, "raybundle_uv_map": uv_name,
                     "raybundle_iterations": self.solver.stats.iterations})
            if self.lightmaps.targets:
                self.timings["lightmap_seconds"] = stepped + time.perf_counter() - t1
            if self.bake.camera:
                camera_path = self._camera_image(directory, packed)
        finally:
            solver.tracer.close()
        t_done = time.perf_counter()
        st = solver.stats
        # the budget covers the iterations and the gather, not the lightmaps
        note = self.loop.budget_note(t0 - self.t_start - stepped)
        if note:
            self.warn(note)
        stats = {"iterations": st.iterations, "directions": st.directions, "patches": int(solver.scene.n_patches),
                 "triangles": int(len(solver.scene.triangles)), "rays_traced": int(st.rays),
                 "solve_seconds": round(t0 - self.loop.t0 - stepped, 4),
                 "bake_seconds": round(t_done - t0, 4), "total_seconds": round(t_done - self.t_start, 4),
                 "attributes": len(attributes), "lightmaps": len(lightmaps), "cancelled": cancelled,
                 **{k: round(v, 4) for k, v in self.timings.items()}}
        LAST_BAKE[self.scene.name] = {"status": ("stopped early" if cancelled else "done") +
                                      (f", {len(self.warnings)} warnings" if self.warnings else ""),
                                      "stats": stats, "warnings": list(self.warnings)}
        return BakeOutcome(stats, list(self.warnings), cancelled, attributes, lightmaps, camera_path)

    def _target_mesh(self, t):
        """The mesh to write for target ``t`` (making the copy object when needed)."""
        ob = bpy.data.objects.get(t.info.original)
        if ob is None:
            self.warn(f"object {t.info.original!r} was deleted during the bake; not written")
            return None, None
        if not t.copy:
            me = ob.data
            if len(me.loops) != t.info.n_loops:
                self.warn(f"object {ob.name!r} changed during the bake; not written")
                return None, None
            if t.own_mesh and me.users > 1:
                ob.data = me = me.copy()
            return ob, me
        ev = ob.evaluated_get(self.depsgraph)
        me = self._refined_mesh(t, ev) if t.refine else bpy.data.meshes.new_from_object(ev)
        if me is None or len(me.loops) != len(t.corner_face):
            if me is not None:
                bpy.data.meshes.remove(me)
            self.warn(f"object {ob.name!r}: its evaluated mesh changed during the bake; not written")
            return None, None
        name = ob.name + COPY_SUFFIX
        old = bpy.data.objects.get(name)
        if old is not None and old.type == "MESH":
            old_mesh = old.data
            old.data = me
            if old_mesh.users == 0:
                bpy.data.meshes.remove(old_mesh)
            copy = old
        else:
            copy = bpy.data.objects.new(name, me)
            for coll in ob.users_collection or [self.scene.collection]:
                coll.objects.link(copy)
        copy.matrix_world = ob.matrix_world.copy()
        copy.hide_render = True
        return copy, me

    def _refine(self, t, rng):
        """Cut target ``t``'s triangles where the lighting needs it
        (:func:`raybundle.imaging.baking.refine_by_lighting`); its corners become the copy's."""
        from raybundle.imaging.baking import refine_by_lighting

        faces = np.arange(t.info.first_triangle, t.info.first_triangle + t.info.n_triangles)
        t.refined = r = refine_by_lighting(self.solver, self.export.scene, faces, max_level=self.bake.subdivide_levels,
                                           rng=rng)
        if r.capped:
            self.warn(f"object {t.info.original!r}: the subdivided copy stops at {len(r.face)} triangles "
                      "(cutting further would pass 2 million); lower Max Subdivisions or bake parts separately")
        t.corner_face = np.repeat(r.face, 3)
        t.corner_bary = r.bary.reshape(-1, 3)

    def _refined_mesh(self, t, ev):
        """A new mesh of target ``t``'s refined triangles (object space of ``ev``, its evaluated
        object): vertices welded by position, material indices and UV maps carried over
        by interpolation.  None when ``ev``'s mesh no longer matches the export."""
        src = ev.to_mesh()
        try:
            if len(src.loops) != t.info.n_loops:
                return None
            n_v, n_l, n_p = len(src.vertices), len(src.loops), len(src.polygons)
            co = np.empty(3 * n_v)
            src.vertices.foreach_get("co", co)
            loop_vertex = corner_vertices(src)
            total = np.empty(n_p, np.int64)
            src.polygons.foreach_get("loop_total", total)
            loop_poly = np.repeat(np.arange(n_p), total)
            mat_index = np.zeros(n_p, np.int64)
            if n_p:
                src.polygons.foreach_get("material_index", mat_index)
            loops = self.export.triangle_loops[t.refined.face]                    # (K, 3) source loops
            bary = t.refined.bary                                                  # (K, 3 corners, 3)
            corner_xyz = np.einsum("kcj,kjx->kcx", bary, co.reshape(-1, 3)[loop_vertex[loops]]).reshape(-1, 3)
            scale = max(float(np.abs(co).max()) if n_v else 1.0, 1e-9) * 1e-7
            _, first, vert = np.unique(np.round(corner_xyz / scale).astype(np.int64), axis=0, return_index=True,
                                       return_inverse=True)
            vert = vert.reshape(-1)
            me = bpy.data.meshes.new(ev.name + COPY_SUFFIX)
            k = len(loops)
            me.vertices.add(len(first))
            me.vertices.foreach_set("co", corner_xyz[first].astype(np.float32).ravel())
            me.loops.add(3 * k)
            me.loops.foreach_set("vertex_index", vert.astype(np.int32))
            me.polygons.add(k)
            me.polygons.foreach_set("loop_start", (3 * np.arange(k)).astype(np.int32))
            me.polygons.foreach_set("loop_total", np.full(k, 3, np.int32))
            me.polygons.foreach_set("material_index", mat_index[loop_poly[loops[:, 0]]].astype(np.int32))
            for uv in src.uv_layers:
                data = np.empty(2 * n_l, np.float32)
                uv.data.foreach_get("uv", data)
                layer = me.uv_layers.new(name=uv.name)
                layer.data.foreach_set("uv", np.einsum("kcj,kjx->kcx", bary, data.reshape(-1, 2)[loops])
                                       .astype(np.float32).ravel())
            for m in src.materials:
                me.materials.append(m)
            me.update(calc_edges=True)
            return me
        finally:
            ev.to_mesh_clear()

    def _write_attribute(self, t, values, found):
        """Write corner ``values`` (n_loops, 3) of target ``t`` as the ``RayBundle`` attribute."""
        ob, me = self._target_mesh(t)
        if me is None:
            return None
        if self.bake.domain == "POINT":
            cv = corner_vertices(me)
            w = found.astype(float)
            num = np.stack([np.bincount(cv, w * values[:, c], minlength=len(me.vertices)) for c in range(3)], axis=1)
            den = np.bincount(cv, w, minlength=len(me.vertices))
            values = num / np.maximum(den, 1e-300)[:, None]
            if np.any(den == 0):
                self.warn(f"mesh {me.name!r}: {int((den == 0).sum())} loose or degenerate vertices baked black")
        elif not found.all():
            self.warn(f"mesh {me.name!r}: {int((~found).sum())} corners of degenerate faces baked black")
        attr = me.color_attributes.get(ATTRIBUTE)
        if attr is not None and (attr.domain != self.bake.domain or attr.data_type != "FLOAT_COLOR"):
            me.color_attributes.remove(attr)
            attr = None
        if attr is None:
            attr = me.color_attributes.new(ATTRIBUTE, "FLOAT_COLOR", self.bake.domain)
        rgba = np.ones((len(values), 4), np.float32)
        rgba[:, :3] = values
        attr.data.foreach_set("color", rgba.ravel())
        me.color_attributes.active_color = attr
        me.color_attributes.render_color_index = me.color_attributes.find(attr.name)
        me.update()
        return ob.name, me.name

    def _save_image(self, name, rgb_bottom_up, directory, packed, header):
        """Write (H, W, 3) rows bottom-up as ``directory/name.exr`` and load it as Image ``name``."""
        from raybundle.util.io import write_exr

        safe = "".join("_" if ch in '/\\:*?"<>|' else ch for ch in name)
        path = os.path.join(directory, safe + ".exr")
        write_exr(path, rgb_bottom_up[::-1].astype(np.float32), header)
        img = bpy.data.images.get(name)
        if img is not None and bpy.path.abspath(img.filepath) == path:
            img.reload()
        else:
            img = bpy.data.images.load(path, check_existing=False)
            img.name = name
        img.use_fake_user = True          # kept when the file is saved, though no material uses it yet
        if packed:
            img.pack()
        return path

    def _camera_image(self, directory, packed):
        r = self.renderer
        img = r.image()
        return self._save_image(f"{self.scene.name}.camera", img[::-1], directory, packed,
                                {"raybundle_iterations": self.solver.stats.iterations})
