"""Camera images from a solver: the measurement M L_n averaged over iterations.

The pixel value is the box-filtered (one pixel wide) radiance seen through the
pixel.  It is split into four parts, each estimated where it is cheapest and
sharpest:

* **emission seen** by the eye (and the world where nothing is hit): its
  own per-pixel average with its own sample count, from every pass's primary
  ray plus, where a pixel's earlier samples disagree (the edge of a visible
  light, a silhouette against a bright world), ``emission_edge_samples`` more
  rays per pass, continuing one low-discrepancy sequence per pixel, so light edges
  antialias long before the rest has converged (a sample-count-weighted average
  whose weights depend on earlier samples: consistent, its bias falls as 1/passes);
* **direct**: light reflected from the first-shot lights, evaluated per
  pixel at the visible point with shadow rays
  (:meth:`~raybundle.lights.direct.DirectLighting.reflected_radiance`).  Every
  *image pass* jitters the sub-pixel position anew, so edges antialias as the
  average converges (as Cycles' box filter does);
* **glossy indirect**: the glossy lobe applied per pixel to the current
  iterate, ``E_i^n f_i(t_i^n, w_eye)``, averaged over iterations (this is what
  makes the method view-dependent);
* **diffuse indirect**: ``kd / pi * E_bar``, linear in the running average
  ``E_bar`` of the incoming radiance, so it is resolved once from the final
  average at ``resolve_samples`` stratified sub-pixel positions, with ``E_bar``
  interpolated linearly over each smooth surface from vertex values that are
  the L2 projection of the patch values onto hat functions
  (:meth:`~raybundle.patches.reconstruction.LinearReconstruction.projected`), or flat per patch.

:class:`Renderer` drives solver iterations and image passes, reports progress,
honours a stop flag, and returns a :class:`RenderResult`.
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from ..lights.direct import ALL_LIGHTS
from ..lights.sources import ShapeLight
from ..lights.world_light import WorldLight
from ..scene.shading import seen_normals
from ..scene.transmission import scatter
from ..tracing.sampling import ShiftedKronecker, kronecker_alpha, stratified_2d
from ..util.arrays import ranges
from .caustic_splats import CausticSplats
from .gather import EdgeGather, FinalGather
from .glossy_paths import GlossyEyePaths
from .run import RunLoop
from .settings import RenderSettings


@dataclass
class GBuffer:
    """Visible surface per pixel: triangle (-1 = nothing), the triangle side seen
    ``tside`` (:meth:`~raybundle.scene.model.PatchScene.seen_tside`), point, the normal it
    is shaded with (that side's, on smooth-shaded faces the shading normal:
    :func:`~raybundle.scene.shading.seen_normals`), material, direction to the eye ``w_eye``, barycentrics (N, 3)."""

    triangle: np.ndarray
    tside: np.ndarray
    point: np.ndarray
    normal: np.ndarray
    material: np.ndarray
    w_eye: np.ndarray
    bary: np.ndarray
    #: (N,) the pixel (row-major index) of each primary ray, None for other rays
    pixel: np.ndarray | None = None
    #: (N, 3) what the eye path's reflections and refractions on the way let through
    #: (:meth:`Renderer.trace_gbuffer`), None: 1 (a scene without transmissive surfaces)
    weight: np.ndarray | None = None
    #: (N,) bool: the eye path was reflected or refracted on its way (None: none was)
    bounced: np.ndarray | None = None
    #: (N, 3) the area lamps the eye path met after it was turned, times :attr:`weight` there
    #: (None: none)
    lamps: np.ndarray | None = None

    @property
    def hit(self):
        return self.triangle >= 0

    def weighted(self, values, idx=None):
        """``values`` (N, 3) (of the rays ``idx``, default all) times what the eye path's way
        through transmissive surfaces let through (:attr:`weight`)."""
        if self.weight is None:
            return values
        return values * (self.weight if idx is None else self.weight[idx])


@dataclass
class RenderResult:
    image: np.ndarray              # (H, W, 3) float32 linear radiance, row 0 at the top
    stats: dict = field(default_factory=dict)
    cancelled: bool = False


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

    def run(self, iterations=None, seconds=None, progress=None, stop=None, snapshots=(), on_snapshot=None,
            started=None, stage=None, between=None):
        """Iterate (:class:`~raybundle.imaging.run.RunLoop`: ``iterations``, or ``seconds`` of the whole
        run from ``started``, set-up included; ``progress``; ``stop``; ``between``) and form the final
        image; returns :class:`RenderResult`, whose stats add the set-up's seconds
        (``setup_seconds``), the run's (``total_seconds``) and, when the budget was too short
        for the minimum of iterations, ``budget_note``.  ``stage(text)`` is told when the
        final image is formed.  ``on_snapshot(seconds, iterations, image)`` is called when the
        run's clock passes each of ``snapshots`` (seconds): ``seconds`` includes forming that
        image (what stopping there would have cost); the run's clock then leaves it out."""
        loop = RunLoop(self, iterations, seconds, started, final_share=self.final_share(), progress=progress,
                       stop=stop, between=between)
        pending = sorted(snapshots) if on_snapshot is not None else []
        try:
            if self.passes == 0:
                self.image_pass()
        except KeyboardInterrupt:
            loop.cancelled = loop.finished = True
        while loop.advance(until=pending[0] if pending else None):
            pending.pop(0)
            t_snap = time.perf_counter()
            try:
                img = self.resolve(loop.final_seconds())
                on_snapshot(loop.elapsed() + time.perf_counter() - t_snap, loop.iterations, img)
            except KeyboardInterrupt:         # Ctrl-C while a snapshot forms: a stop, as in the loop
                loop.cancelled = loop.finished = True
                break
            loop.pause(time.perf_counter() - t_snap)
        reserve = loop.final_seconds()
        if reserve and not self.automatic_gather_pays(reserve):
            loop.extend(reserve)                  # the time kept for a gather that would not pay: iterate on
            while loop.advance():
                pass
            reserve = None
        if stage is not None:
            stage("forming the final image")
        t_res = time.perf_counter()
        img = self.resolve(reserve)
        if not np.isfinite(img).all():
            raise FloatingPointError("the image has non-finite values; this is a bug, please report it")
        t_end = time.perf_counter()
        stats = self.stats(t_end - loop.t0, t_end - t_res, loop.cancelled)
        stats.update(setup_seconds=round(loop.setup_seconds, 4), total_seconds=round(t_end - loop.started, 4))
        note = loop.budget_note(t_end - loop.started)
        if note:
            stats["budget_note"] = note
        return RenderResult(img, stats, loop.cancelled)

    def final_share(self):
        """The final image's share of a time-limited run's iteration seconds (none here)."""
        return 0.0

    def resolve(self, final_seconds=None):
        """The image at the end of a run or at a snapshot; ``final_seconds``: what forming it
        may take in a run limited by time (:meth:`~raybundle.imaging.run.RunLoop.final_seconds`), None
        in a run of given iterations."""
        return self.image()


def sample_gather_rays(per_sample, seconds_left, seconds_per_sample):
    """The automatic gather's rays for the next sub-pixel sample: all ``per_sample`` while the
    budget left holds a sample at the pace so far, else none (:meth:`Renderer.diffuse_indirect`).
    Never a few: a gather thinned below what the probe found it needs adds more noise than
    the bias it removes."""
    return int(per_sample) if seconds_left >= seconds_per_sample else 0


class Renderer(ProgressiveImage):
    """Runs a solver and forms the image.  See the module docstring."""

    def __init__(self, scene, camera, solver, direct, settings: RenderSettings):
        if camera is None:
            raise ValueError("the scene has no camera; give one (Camera.from_blender / Camera.look_at)")
        settings.validate()
        self.scene, self.camera, self.solver, self.direct = scene, camera, solver, direct
        #: (pixels, 3) the mean of the world's view over each pixel, or None (no view through this
        #: camera: the world by direction); where an earlier sample of a pixel hit geometry
        #: (``_hit_seen``), camera rays that miss read the view's sub-pixel they pass (seen_radiance)
        self._view_means = scene.world.view_pixel_means(camera) if scene.world.view_for(camera) else None
        self._hit_seen = np.zeros(camera.width * camera.height, bool)
        self.tracer = solver.tracer
        self.settings = settings
        self.rng = np.random.default_rng([settings.seed, 1])
        self._resolve_rng = np.random.default_rng([settings.seed, 2])
        # per pass and pixel: the glossy lobe's uniforms.  The sub-pixel position continues the
        # pixel's own R_2 sequence (image_pass), the light samples one R_3 sequence per pixel and
        # light (_shade), from this shift per pixel
        self.pass_sampler = ShiftedKronecker(camera.width * camera.height, 2, self.rng)
        self._light_shift = np.random.default_rng([settings.seed, 9]).random((camera.width * camera.height, 3))
        n = camera.width * camera.height
        self.pass_sum = np.zeros((n, 3))                 # per-pass estimates times their samples
        self.pass_samples = np.zeros(n)                   # ... and those samples, per pixel
        self.pass_sq_sum = np.zeros(n)                    # per-pass luminance squared (for the variance)
        self.glossy_sum = np.zeros((n, 3))
        self.passes = 0
        # the passes' glossy eye paths read the solver's running average: their own sum and
        # count, restarted with the solver's average (:meth:`_restart_solver_parts`)
        self.gather_sum = np.zeros((n, 3))
        self.gather_passes = 0
        self._restarted = False
        self._setup_rays = 0                              # one-time rays of the first pass
        self.glossy_iterations = 0
        self.image_rays = 0
        self._since_pass = 0                              # iterations since the last image pass (step)
        self._iteration_seconds = 0.0                     # seconds spent in solver iterations (step)
        self.pass_seconds = 0.0                           # seconds spent in image passes
        self.gbuffer = None
        self._planned = None                # automatic_gather_pays' plan for the next diffuse_indirect
        self._glossy_pixels = np.zeros(0, np.int64)   # pixels for accumulate_glossy
        self.emission_sum = np.zeros((n, 3))             # emission seen: sum and count per pixel
        self.emission_count = np.zeros(n)
        self._emission_range = np.stack([np.full(n, np.inf), np.full(n, -np.inf)])   # min, max seen
        # the extra samples' sequences (_subpixel_sequence): a random shift and the next index per pixel
        self._edge_shift = np.random.default_rng([settings.seed, 8]).random((n, 2))
        self._edge_index = np.zeros(n, np.int64)
        # ... and of the first interface's choice, reflected or refracted (a 1-D Kronecker sequence)
        self._choice_shift = np.random.default_rng([settings.seed, 9]).random(n)
        mats = scene.materials
        self.glossy_material = mats.is_glossy
        py, px = np.divmod(np.arange(n), camera.width)
        self._pixel = np.stack([px, py], axis=1).astype(float)
        # the world as a light to sample, where it changes with direction (the glossy eye paths'
        # MIS, and the world samples at visible points below)
        world = scene.world
        sky = WorldLight(world, self.tracer) if world.emits and not world.is_constant else None
        # the glossy lobe the eye sees, by lobe-sampled eye paths (glossy_gather)
        self.glossy_paths = GlossyEyePaths(scene, solver, direct, self.tracer, settings, self.rng, self.surface_values,
                                           world_light=sky)
        # the final gather next to concave edges and contacts
        self.edge_gather = EdgeGather(scene, self.tracer, settings.seed)
        #: the world's direct light on the diffuse lobe, sampled at the visible points of every
        #: pass (the patches then give the rest: the solver's ``image_incoming``)
        self.world_samples = self.automatic_world_samples(settings.world_samples, direct)
        self.world_light = ((sky if sky is not None else WorldLight(world, self.tracer))
                            if self.world_samples > 0 and hasattr(solver, "separate_world")
                            and solver.separate_world() else None)
        self.gather_rays_used = 0                         # rays per pixel of the last resolve's gather
        # per pixel: some earlier shadow ray reached a light / was blocked (both: a penumbra)
        self.shadow_flags = np.zeros((n, 2), np.uint64)     # per-light masks (light_bits)
        # the caustic first shot on the surfaces seen, light-traced into the pixels (None: read
        # from the patches as the rest of the diffuse indirect light)
        self.caustic_splats = None
        if solver.caustic is not None and settings.caustic_splats > 0:
            self.caustic_splats = CausticSplats(scene, camera, self.tracer, direct, solver.caustic, settings.seed,
                                                self._pixel, lambda: self.trace_gbuffer(np.full((n, 2), 0.5)))

    #: world samples per visible point and pass where the world alone lights the scene
    #: (``world_samples`` = -1, :meth:`automatic_world_samples`)
    WORLD_ONLY_SAMPLES = 4

    def automatic_world_samples(self, setting, direct):
        """The world samples per visible point and pass: ``setting``, or for -1
        :data:`WORLD_ONLY_SAMPLES` where a world that changes with direction is the only light
        (no first-shot lights in ``direct``), else 0.  A sky through windows is then all the
        direct light, which patches a window wide carry with their finite-element error;
        beside a sun (a lamp, or one split out of the world) the world is a small part whose
        samples mostly meet the blinds and walls (docs/benchmarks.md, 'Real interiors')."""
        if setting >= 0:
            return int(setting)
        world = self.scene.world
        return self.WORLD_ONLY_SAMPLES if world.emits and not world.is_constant and not direct.n_lights else 0

    # --------------------------------------------------------------- passes
    def trace_gbuffer(self, jitter, pixels=None):
        """Primary rays through the pixels' sample positions for uniforms ``jitter`` (N, 2) in
        [0,1)^2 (:meth:`~raybundle.scene.camera.Camera.subpixel`: the pixel filter's), for all
        pixels or for the pixel indices ``pixels`` (N,), followed through the interfaces of
        glass and other transmissive surfaces (:meth:`_through_interfaces`; a third column of
        ``jitter`` chooses at the first interface, reflected or refracted)."""
        cam = self.camera
        jitter = np.asarray(jitter, float)
        pos = (self._pixel if pixels is None else self._pixel[pixels]) + cam.subpixel(jitter[:, :2])
        org, dirs = cam.rays(pos[:, 0], pos[:, 1])
        tri, t, u, v = self.tracer.first_hit(org, dirs, glass=False)
        self.image_rays += len(dirs)
        weight = bounced = lamps = None
        if self.tracer.glass is not None:
            org, dirs, tri, t, u, v, weight, bounced, lamps = self._through_interfaces(
                org, dirs, tri, t, u, v, jitter[:, 2] if jitter.shape[1] > 2 else None)
        hit = tri >= 0
        sc = self.scene
        ts = sc.seen_tside(np.where(hit, tri, 0), dirs)
        point = org + np.where(hit, t, 0.0)[:, None] * dirs
        normal = sc.tside_normal[ts]
        if sc.shading is not None:               # smooth-shaded faces: Blender's shading normal
            h = np.nonzero(hit)[0]
            normal[h] = seen_normals(sc.shading, sc.triangle_source[tri[h]], point[h], normal[h], -dirs[h])
        if sc.texture is not None and sc.texture.has_normal_maps:     # normal and bump maps
            h = np.nonzero(hit)[0]
            normal[h] = sc.texture.shading_normals(sc.triangle_source[tri[h]], point[h], normal[h], -dirs[h])
        return GBuffer(tri, ts, point, normal,
                       sc.triangle_material[sc.tside_triangle[ts]], -dirs, np.stack([1 - u - v, u, v], axis=1),
                       np.arange(len(self._pixel)) if pixels is None else np.asarray(pixels), weight, bounced, lamps)

    def _through_interfaces(self, org, dirs, tri, t, u, v, choice=None):
        """Eye rays ``org``, ``dirs`` (N, 3) with first hits ``(tri, t, u, v)`` followed through
        the transmissive surfaces they meet (:func:`~raybundle.scene.transmission.scatter`: by
        Fresnel, reflected or refracted, at the first by the uniforms ``choice`` (N,) where
        given): as Cycles' transmission and glossy bounces, a path that has been refracted
        ``transmission_depth`` times or reflected ``glossy_depth`` times ends at the next
        interface it meets, black.  Returns the last segments' ``(org, dirs, tri, t, u, v)``, each ray's weight
        (N, 3), (N,) bool, whether it was turned, and the area lamps (N, 3) its turned segments
        met before the surface they end on, weighted (or None where the scene has no area lamps).

        Blender's area lamps are not visible to the camera's own rays by default, but are to the
        glossy and transmission rays a turned path continues as: a lamp reflected in a pane or
        seen through it adds its radiance, and the path goes on (a lamp is not geometry and
        hides nothing behind it), as in Cycles."""
        sc, tracer = self.scene, self.tracer
        org, dirs = org.copy(), dirs.copy()
        weight = np.ones((len(tri), 3))
        bounced = np.zeros(len(tri), bool)
        reflections = np.zeros(len(tri), np.int64)
        refractions = np.zeros(len(tri), np.int64)
        shapes = [light for light in self.direct.area_lights if isinstance(light, ShapeLight)]
        lamps = np.zeros((len(tri), 3)) if shapes else None
        live = np.nonzero(tri >= 0)[0]
        most_t, most_g = int(self.settings.transmission_depth), int(self.settings.glossy_depth)
        columns = 4 if np.any(sc.materials.transmission_roughness > 0) else 2     # rough ones draw microfacets
        for depth in range(most_t + most_g + 1):
            live = live[tracer.glass[tri[live]]]
            if len(live) == 0:
                break
            # as Cycles, a path that has spent its transmission or glossy bounces ends at the next
            # surface it meets (black where that is glass)
            spent = (refractions[live] >= most_t) | (reflections[live] >= most_g)
            weight[live[spent]], tri[live[spent]] = 0.0, -1
            live = live[~spent]
            if len(live) == 0:
                break
            d = dirs[live]
            p = org[live] + t[live, None] * d
            geo = sc.triangle_normal[tri[live]]
            shade = geo
            if sc.shading is not None:
                shade = seen_normals(sc.shading, sc.triangle_source[tri[live]], p,
                                     np.where((np.einsum("ij,ij->i", geo, d) < 0)[:, None], geo, -geo), -d)
            uniforms = self.rng.random((len(live), columns))
            if depth == 0 and choice is not None:
                uniforms[:, 1] = choice[live]
            on, new, w = scatter(sc.materials, sc.triangle_material[tri[live]], d, geo, shade, uniforms)
            weight[live] *= w
            turned = np.einsum("ij,ij->i", d, geo) * np.einsum("ij,ij->i", new, geo) < 0
            reflections[live] += on & turned
            refractions[live] += on & ~turned
            live = live[on]
            bounced[live] = True
            org[live] = p[on] + tracer.eps * new[on]
            dirs[live] = new[on]
            tri[live], t[live], u[live], v[live] = tracer.first_hit(org[live], dirs[live], glass=False)
            self.image_rays += len(live)
            if shapes and len(live):
                reach = np.where(tri[live] >= 0, t[live], np.inf)
                for light in shapes:
                    met, _ = light.hit(org[live], dirs[live], reach)
                    lamps[live[met]] += weight[live[met]] * light.radiance
            live = live[tri[live] >= 0]
        return org, dirs, tri, t, u, v, weight, bounced, lamps

    def seen_radiance(self, g):
        """Radiance (N, 3) that reaches the eye directly: emission of the surfaces
        seen, the world's radiance where nothing is hit; and (N,) bool, the
        pixels whose sample saw an emitting surface.

        The world comes from its view through this camera where there is one
        (:attr:`~raybundle.scene.world.World.view`): the pixel's mean, or in a pixel an earlier
        sample found partly covered (a window bar), the view's sub-pixel the ray passes
        (:meth:`~raybundle.scene.world.World.view_radiance`): the sky beside the bar, not the
        mean of the sky behind it too.  Which one depends on earlier samples only: consistent,
        the pixel's first samples aside; exact in pixels that see only the world."""
        out = np.zeros((len(g.triangle), 3))
        miss = np.nonzero(~g.hit)[0]
        world = self.scene.world
        if g.bounced is not None and len(miss):     # turned by glass: the world as light, no longer the camera's view
            turned = miss[g.bounced[miss]]
            out[turned] = world.radiance(-g.w_eye[turned])
            miss = miss[~g.bounced[miss]]
        if len(miss) and self._view_means is None:
            out[miss] = world.radiance(-g.w_eye[miss], camera=True)
        elif len(miss):
            fine = self._hit_seen[g.pixel[miss]]
            out[miss[~fine]] = self._view_means[g.pixel[miss[~fine]]]
            out[miss[fine]] = world.view_radiance(-g.w_eye[miss[fine]])
        self._hit_seen[g.pixel[g.hit]] = True
        h = np.nonzero(g.hit)[0]
        cos_eye = np.einsum("ij,ij->i", g.normal[h], g.w_eye[h])
        out[h] = self.scene.materials.emitted_radiance(g.material[h], cos_eye)
        emitter = np.zeros(len(out), bool)
        emitter[h] = np.any(out[h] > 0, axis=1)
        out = g.weighted(out)
        if g.lamps is not None:
            out += g.lamps
        return out, emitter

    def surface_values(self, side_values, vert, tside, bary):
        """Side values (S, C) at hit points on triangle sides ``tside`` (N,):
        interpolated from welded-vertex values ``vert`` (V, C) with barycentrics
        (N, 3), or flat per side when ``vert`` is None."""
        if vert is None:
            return side_values[self.scene.tside_side[tside]]
        return self.solver.reconstruction.at(vert, tside, bary)

    def albedo_scale(self, triangles, points):
        """Texture modulation (N, 3) of the diffuse reflectance at ``points`` on patch
        ``triangles`` (:mod:`raybundle.scene.textures`), None for an untextured scene."""
        tex = self.scene.texture
        return None if tex is None else tex.at(self.scene.triangle_source[triangles], points)

    def image_pass(self):
        """One jittered sample per pixel of the per-pass part: emission seen, direct
        light of the first-shot lights and (with ``glossy_gather``) the glossy lobe;
        more samples at the edges of visible lights and where the pixel's passes
        disagree most (:meth:`_noisy_pixels`).  The sample's sub-pixel position is the
        next of the pixel's R_2 sequence (:meth:`_subpixel_sequence`, shared with the extra
        samples), so a pixel's passes cover it evenly from the first ones on: an edge's
        coverage converges faster than with independent positions (the R_d sequence of the
        lobe and light samples, d up to 16, moved its first two coordinates only a few
        percent of a pixel from pass to pass: docs/benchmarks.md, the table of methods).
        Keeps the G-buffer for :meth:`accumulate_glossy`."""
        t0 = time.perf_counter()
        u = self.pass_sampler.next()
        g = self.trace_gbuffer(self._subpixel_sequence(np.arange(len(self._pixel)), 1)[1])
        self.gbuffer = g
        n = len(g.triangle)
        emitted, _ = self.seen_radiance(g)
        before_pass = self.image_rays - len(g.triangle)
        if self.passes == 0:                          # find most edges at once, a sample per pixel at a time
            for _ in range(max(4, min(self.FIRST_EDGE_SAMPLES, self.FIRST_EDGE_RAYS // max(n, 1)))):
                self._emission_samples(np.arange(n), 1)
        # pixels whose earlier samples disagree (the edge of a visible light, which is
        # also where a lamp lights a narrow rim) get extra samples (one R_2 sequence per pixel)
        # for both the emission average and this pass's estimate, the mean of 1 + k
        # samples: chosen from earlier passes only, so every pass stays unbiased; the pixel's
        # image is the mean of all its samples (``pass_samples``), not of its passes
        lo, hi = self._emission_range
        noisy, factor = self._noisy_pixels()
        extra_pix = np.union1d(np.nonzero(lo < hi)[0], noisy)
        self._add_emission(np.arange(n), emitted)
        self._restart_solver_parts()
        value, gathered, gl = self._shade(g, u, None, np.arange(n))
        k = np.full(len(extra_pix), int(self.settings.emission_edge_samples))
        k[np.searchsorted(extra_pix, noisy)] *= factor
        count = np.ones(n)                 # the samples this pass takes in each pixel
        if len(extra_pix) and k[0] > 0:
            count[extra_pix] += k
            pix, jitter = self._subpixel_sequence(extra_pix, k)
            gx = self.trace_gbuffer(jitter, pixels=pix)
            le, _ = self.seen_radiance(gx)
            self._add_emission(pix, le)
            extra, extra_g, _ = self._shade(gx, self.rng.random((len(pix), 2)), self.rng, pix)
            row = np.repeat(np.arange(len(extra_pix)), k)
            for total, more in ((value, extra), (gathered, extra_g)):
                summed = np.stack([np.bincount(row, more[:, c], minlength=len(extra_pix)) for c in range(3)], axis=1)
                total[extra_pix] = (total[extra_pix] + summed) / (k + 1)[:, None]
        self.pass_sum += value * count[:, None]
        self.pass_samples += count
        self.gather_sum += gathered
        self.gather_passes += 1
        y = (value + gathered).sum(axis=1)
        self.pass_sq_sum += count * y * y
        if self.caustic_splats is not None:
            cs = self.caustic_splats
            before = cs.rays
            cs.splat(int(np.ceil(self.settings.caustic_splats * n)))
            self.image_rays += cs.rays - before
        if self.passes == 0:
            self._setup_rays = self.image_rays - before_pass
        self.passes += 1
        self._glossy_pixels = gl
        self.pass_seconds += time.perf_counter() - t0

    def _restart_solver_parts(self):
        """Drop what the passes and iterations read from the solver before its running
        average restarted (after ``burn_in`` iterations, when the iterates have forgotten
        their zero start): the glossy eye paths' sum and the glossy iterates.  Read from an
        average still rising from zero, they kept a start-up bias that fell only as 1/n.
        Done at the first pass after the restart, so a run always keeps at least one pass."""
        solver = self.solver
        if self._restarted or solver.stats.iterations <= getattr(solver, "burn_in", 0):
            return
        self._restarted = True
        self.gather_sum[:] = 0.0
        self.gather_passes = 0
        if self.glossy_iterations > 1:
            self.glossy_sum[:] = 0.0
            self.glossy_iterations = 0

    def _shade(self, g, u_lobe, u_light, pixels):
        """Per-pass radiance (N, 3) of the samples in G-buffer ``g`` taken in ``pixels``
        (N,): direct light of the first-shot lights and, with ``glossy_gather``, the
        glossy lobe; and the pixels left for :meth:`accumulate_glossy`.  ``u_lobe`` (N, 2)
        uniforms; ``u_light`` a Generator for the light samples, or None for a pass's own samples
        (one per pixel): each pixel's light samples then continue, light by light, one randomly
        shifted R_3 sequence over the passes, the penumbra samples of pass p taking indices
        p c .. p c + c - 1 (c = ``penumbra_samples``), the others the first of those.  A penumbra's
        shadow rays thus stay stratified over the light across passes.

        The diffuse lobe of polygonal lights takes their exact unoccluded irradiance
        as a control variate (:meth:`~raybundle.lights.direct.DirectLighting.reflected_radiance`
        with ``analytic``), so only the shadow rays' outcome is random, in pixels where an
        earlier shadow ray reached that light (elsewhere, in an umbra or on the first pass,
        the plain estimate is exact or at least never negative).  Pixels whose earlier
        shadow rays both reached and missed a light (a penumbra, where then most of the
        noise is: the floor behind the Cornell blocks) get ``penumbra_samples`` shadow rays
        for that light, a randomly shifted Kronecker set, and one for the others: the flags
        are kept per pixel and light (:func:`~raybundle.lights.direct.light_bits`), so a hall
        of 13 lamps spends its penumbra rays on the lamps whose shadow edges cross the pixel.
        Those lamps share the pixel's ``penumbra_samples`` (rounded up, at least one each), so a
        pixel's penumbra costs the same however many lamps cross it.  Both choices use earlier
        passes only, so every pass stays unbiased.  The first pass, with no earlier samples,
        treats every pixel as a penumbra (with the control variate), so single lit pixels are
        not left to a plain one-ray estimate."""
        out = np.zeros((len(g.triangle), 3))
        h = np.nonzero(g.hit)[0]
        front = np.einsum("ij,ij->i", g.normal[h], g.w_eye[h]) > 0
        hf = h[front]
        if self.direct.n_lights and len(hf):
            before = self.direct.rays
            mis = self.glossy_material[g.material[hf]] if self.glossy_paths.light_mis else None
            flags = self.shadow_flags[pixels[hf]]
            start = self.passes == 0          # no earlier samples: every point is treated as a penumbra
            # per point, the lights whose earlier samples were both seen and blocked
            pen_lights = np.full(len(hf), ALL_LIGHTS) if start else self._penumbrae()[pixels[hf]]
            if mis is not None:       # the lobe's MIS weight assumes light_samples light samples
                pen_lights[mis] = 0
            # penumbra_samples / light_samples sets of samples for the lights in a point's
            # penumbra, on one randomly shifted Kronecker sequence per point and light
            n_s = int(self.settings.light_samples)
            f = flags.copy()
            more = -(-int(self.settings.penumbra_samples) // n_s)
            # the pixel's penumbra samples shared by the lights whose shadow edges cross it
            crossing = np.zeros(len(hf), np.int64)
            for bits in self.direct.sampled_apart():
                crossing += (pen_lights & bits) != 0
            share = -(-more // np.maximum(crossing, 1))
            if u_light is None:       # the pass's own: each pixel's sequences continue over the passes
                u, sequence = None, (self._light_shift[pixels[hf]], np.full(len(hf), self.passes * more * n_s))
            else:
                u, sequence = u_light, (self.rng.random((len(hf), 3)), None)
            value = self.direct.reflected_radiance(
                g.point[hf], g.normal[hf], g.material[hf], g.w_eye[hf], u, n_s,
                mis=mis, diffuse_scale=self.albedo_scale(g.triangle[hf], g.point[hf]), shadow_flags=f,
                analytic=np.full(len(hf), ALL_LIGHTS) if start else flags[:, 0],
                penumbra=(pen_lights, share) + sequence, select=self.rng.random(len(hf)),
                receivers=self.scene.link_groups(g.triangle[hf]))
            out[hf] += value
            np.bitwise_or.at(self.shadow_flags, pixels[hf], f)
            self.image_rays += self.direct.rays - before
        kt = self.scene.materials.translucent[g.material[hf]]
        far = np.nonzero(np.any(kt > 0, axis=1))[0] if self.direct.n_lights else []
        if len(far):          # the first-shot lights on a translucent surface's far side, let through
            t = hf[far]
            out[t] += kt[far] / np.pi * self.direct.far_side_irradiance(g.point[t], g.normal[t], self.rng,
                                                                       self.scene.link_groups(g.triangle[t]))
        gl = hf[self.glossy_material[g.material[hf]]]
        lobe_world = 0          # world samples the glossy lobes share with the diffuse one
        lobe_guide = None       # ... and the guide they were drawn by, for the lobes' MIS
        if self.world_light is not None and len(hf):
            before = self.world_light.rays
            lobe = None
            sides = self.scene.tside_side[g.tside[hf]]
            guide = self.world_light.guide_at(self.solver.world_guide, sides)
            if self.settings.glossy_gather and self.glossy_paths.world_light is self.world_light and len(gl):
                at = np.searchsorted(hf, gl)
                lobe = (self.scene.materials, at, g.material[gl], g.w_eye[gl])
                lobe_world, lobe_guide = self.world_samples, (guide[0], guide[1][at])
            # the unblocked samples teach the sides' guide (for the next passes)
            e = self.world_light.irradiance(g.point[hf], g.normal[hf],
                                            self.rng.random((len(hf), self.world_samples, 3)),
                                            guide, lobe=lobe, learn=sides)
            if lobe is not None:
                e, sky = e
                out[gl] += sky
            m = g.material[hf]
            w_d = self.scene.materials.diffuse_weight(m, np.einsum("ij,ij->i", g.normal[hf], g.w_eye[hf]))
            scale = self.albedo_scale(g.triangle[hf], g.point[hf])
            out[hf] += w_d * self.scene.materials.diffuse_reflectance[m] / np.pi * e * (1.0 if scale is None else scale)
            self.image_rays += self.world_light.rays - before
        gathered = np.zeros_like(out)
        if self.settings.glossy_gather:
            before = self.glossy_paths.rays
            # the lamps and the world the paths meet count with the pass (kept over the solver's
            # restart); what they read from the solver with the gather (dropped at its restart)
            light, gathered[gl] = self.glossy_paths.gather(g, gl, u_lobe[gl], world_samples=lobe_world,
                                                           guide=lobe_guide)
            out[gl] += light
            self.image_rays += self.glossy_paths.rays - before
            gl = gl[:0]
        return g.weighted(out), g.weighted(gathered), gl

    def _penumbrae(self):
        """(pixels,) uint64: per pixel, the lights whose earlier shadow rays there or in one of
        its four neighbours both reached and missed the light.  A light that a small blocker
        hides from 1% of a pixel's view is found blocked by one pass in a hundred, whose
        estimate then drops to nothing: the neighbours' flags find such pixels sooner."""
        f = self.shadow_flags
        pen = (f[:, 0] & f[:, 1]).reshape(self.camera.height, self.camera.width)
        out = pen.copy()
        out[1:] |= pen[:-1]
        out[:-1] |= pen[1:]
        out[:, 1:] |= pen[:, :-1]
        out[:, :-1] |= pen[:, 1:]
        return out.ravel()

    #: the image passes' share of the traced rays when ``image_ray_share`` is 0 (:meth:`step`)
    DIFFUSE_IMAGE_SHARE = 0.2
    GLOSSY_IMAGE_SHARE = 0.55

    #: the first pass's extra emission samples per pixel (at least 4; at most FIRST_EDGE_RAYS in
    #: all): the edges of lights and window bars they find get samples of their own from then on
    #: (:meth:`seen_radiance` reads the sky beside a bar only once a pixel is known to hold one;
    #: docs/benchmarks.md, 'Real interiors')
    FIRST_EDGE_SAMPLES = 16
    FIRST_EDGE_RAYS = 4_000_000

    #: :meth:`_noisy_pixels`: at most this share of the pixels, those whose squared standard
    #: error is above NOISY_CUT times the image's mean one
    NOISY_SHARE = 0.02
    NOISY_CUT = 16.0
    #: ... each taking up to this many times the extra samples of an edge, all of them together at
    #: most NOISY_BUDGET samples per pixel of the image
    NOISY_MAX_FACTOR = 16
    NOISY_BUDGET = 0.5

    def _noisy_pixels(self):
        """Pixels whose per-pass estimates vary most: the standard error of their
        mean (from the passes so far) above 4 times the image's RMS standard error,
        at most 2% of the pixels (e.g. the rim a lamp lights through a narrow gap,
        where a pixel's direct light changes by orders of magnitude across it), and per pixel
        how many times an edge's extra samples it takes: ``sqrt(se^2 / cut)`` rounded, 1 to
        :data:`NOISY_MAX_FACTOR` (samples in proportion to the standard deviation, which
        minimises the summed squared error for their number: the edge of a small lamp's
        reflection in a near-mirror)."""
        if self.passes < 4:
            return np.zeros(0, np.int64), np.zeros(0, np.int64)
        # passes of k samples: sum_p k_p (y_p - m)^2 estimates passes x the per-sample variance
        k = np.maximum(self.pass_samples, 1)
        m = self.pass_sum.sum(axis=1) / k
        se2 = np.maximum(self.pass_sq_sum - k * m * m, 0.0) / self.passes / k
        cut = self.NOISY_CUT * se2.mean()
        idx = np.nonzero(se2 > cut)[0]
        cap = max(1, int(len(se2) * self.NOISY_SHARE))
        if len(idx) > cap:
            idx = np.sort(idx[np.argsort(se2[idx])[-cap:]])
        factor = np.clip(np.rint(np.sqrt(se2[idx] / max(cut, 1e-300))), 1, self.NOISY_MAX_FACTOR)
        # at most NOISY_BUDGET extra samples per pixel of the image, on average
        budget = self.NOISY_BUDGET * len(se2) / max(self.settings.emission_edge_samples, 1)
        if factor.sum() > budget:
            factor = np.maximum(np.floor(factor * budget / factor.sum()), 1.0)
        return idx, factor.astype(np.int64)

    def _add_emission(self, pixels, le):
        """Add emission samples ``le`` (N, 3) seen in ``pixels`` (N,) (repeats allowed)."""
        for k in range(3):
            self.emission_sum[:, k] += np.bincount(pixels, le[:, k], minlength=len(self.emission_sum))
        self.emission_count += np.bincount(pixels, minlength=len(self.emission_count))
        y = le.sum(axis=1)
        np.minimum.at(self._emission_range[0], pixels, y)
        np.maximum.at(self._emission_range[1], pixels, y)

    def _emission_samples(self, pixels, k):
        """``k`` more primary rays in each of ``pixels`` (:meth:`_subpixel_sequence`), added
        to the emission average.  The average stays unbiased: which
        pixels get them depends only on earlier samples."""
        pix, jitter = self._subpixel_sequence(pixels, k)
        le, _ = self.seen_radiance(self.trace_gbuffer(jitter, pixels=pix))
        self._add_emission(pix, le)

    def _subpixel_sequence(self, pixels, k):
        """``k`` (or (N,) counts) sub-pixel positions in each of ``pixels``, continuing one
        randomly shifted R_2 sequence per pixel (:func:`~raybundle.tracing.sampling.kronecker_alpha`) from
        pass to pass: returns (pixel ids (N k,), positions (N k, 3)), the third column the
        choice at the first interface of glass the eye path meets (:meth:`trace_gbuffer`), on a
        1-D Kronecker sequence per pixel: over a pixel's samples, the share reflected by a pane
        is F to within one sample, where independent choices left the reflection in a grazing
        balustrade a binomial speckle.  Every position is
        uniform in its pixel (the averages stay unbiased) and all of a pixel's samples (the
        passes' own and the extra ones) together fill it with discrepancy O(log n / n), where
        fresh jittered grids every pass left the coverage of an edge noisy as n^-3/4: a
        window bar against a sky 20 times brighter than the room is mostly that coverage."""
        pixels = np.asarray(pixels, np.int64)
        k = np.broadcast_to(k, len(pixels))
        pix = np.repeat(pixels, k)
        i = self._edge_index[pix] + ranges(0, k)
        self._edge_index[pixels] += k
        choice = (self._choice_shift[pix] + i * kronecker_alpha(1)[0]) % 1.0
        return pix, np.column_stack([(self._edge_shift[pix] + i[:, None] * kronecker_alpha(2)) % 1.0, choice])

    def accumulate_glossy(self):
        """Add this iterate's glossy lobe per pixel: E_i f_glossy(t_i, w_eye) (+ Ec_i f_glossy(w_c, w_eye))."""
        self.glossy_iterations += 1
        gl = self._glossy_pixels
        if len(gl) == 0:
            return
        g = self.gbuffer
        patch = self.scene.tside_side[g.tside[gl]]
        mats, solver = self.scene.materials, self.solver
        f = mats.brdf(g.material[gl], g.normal[gl], solver.receive_direction[patch], g.w_eye[gl], diffuse=False)
        self.glossy_sum[gl] += g.weighted(solver.glossy_incoming[patch] * f, gl)
        if solver.caustic is not None:     # the first shot's glossy reflections arrive as Ec
            f = mats.brdf(g.material[gl], g.normal[gl], solver.caustic.direction[patch], g.w_eye[gl], diffuse=False)
            self.glossy_sum[gl] += g.weighted(solver.caustic.E[patch] * f, gl)

    # -------------------------------------------------------------- resolve
    def diffuse_indirect(self, e_bar=None, samples=None, gather=True, gather_seconds=None):
        """(N, 3) W_d kd/pi * E_bar at the pixels (W_d: the diffuse weight under a
        Principled layer, 1 without), box-filtered with ``samples`` (default
        ``resolve_samples``) stratified sub-pixel samples.

        ``e_bar`` (S, 3) defaults to the solver's
        :meth:`~raybundle.methods.stochastic_iteration.StochasticIterationSolver.indirect_incoming`.
        With ``smooth``, the bundles' running average and the caustic first shot are
        interpolated by :meth:`~raybundle.patches.reconstruction.LinearReconstruction.smooth_and_sharp`.
        With ``gather`` (and ``e_bar`` the solver's own), points on the sides
        :meth:`~raybundle.imaging.gather.EdgeGather.near_edge` flags gather their indirect light
        instead (:class:`~raybundle.imaging.gather.FinalGather`): ``gather_rays`` rays per pixel,
        spread over its sub-pixel samples as one stratified set.  With ``gather_rays`` = -1
        the count is what ``gather_seconds`` buy (the run loop gives ``gather_share`` of a timed
        run's iteration seconds, :meth:`resolve`; none: no automatic gather), from the gather's
        cost per ray measured on a few of the last image pass's points and the number of its
        points on flagged sides (:class:`~raybundle.imaging.gather.EdgeGather`), and none where
        the gather's own noise would outweigh the bias it removes
        (:meth:`~raybundle.imaging.gather.EdgeGather.automatic_rays`).  Once its budget is spent
        (a machine slower than at the probe, sides first seen by a sub-pixel sample probed for
        edges then), the automatic gather leaves the remaining sub-pixel samples to the patch
        values (:func:`sample_gather_rays`; docs/benchmarks.md, 'Real interiors').
        """
        t_start = time.perf_counter()
        sc = self.scene
        n = len(self._pixel)
        out = np.zeros((n, 3))
        k = max(1, int(samples or self.settings.resolve_samples))
        final, per_sample, rays = None, 0, self.settings.gather_rays
        if e_bar is None:
            planned, self._planned = self._planned, None
            if planned is not None and planned[0] == (gather_seconds, k):
                e_bar, vert, final, per_sample = planned[1]
                t_start -= planned[2]                 # the probe's time counts against the gather's budget
            else:
                e_bar, vert, final, per_sample = self._indirect_plan(gather, gather_seconds, k)
            self.gather_rays_used = 0
        else:
            vert = self.solver.reconstruction.smooth_and_sharp(e_bar, None) \
                if self.settings.smooth and np.any(e_bar) else None
        if not np.any(e_bar) and final is None and not len(getattr(self.solver, "translucent_sides", ())):
            return out
        kd = sc.materials.diffuse_reflectance
        # translucent sides: what their patch's other side receives, sent on (smoothed like E_bar)
        through = through_vert = None
        if len(getattr(self.solver, "translucent_sides", ())):      # the first shot's part: _shade's
            through = self.solver.translucent_radiance(self.solver.indirect_incoming())
            through_vert = self.solver.reconstruction.averaged(through) if self.settings.smooth else None
        offsets = stratified_2d(k, self._resolve_rng)     # new positions at every resolve
        if final is not None:
            shift = self._resolve_rng.random((n, 2))
        t_loop = time.perf_counter()
        for j in range(k):
            g = self.trace_gbuffer(np.broadcast_to(offsets[j], (n, 2)))
            h = np.nonzero(g.hit & (np.einsum("ij,ij->i", g.normal, g.w_eye) > 0))[0]
            e = self.surface_values(e_bar, vert, g.tside[h], g.bary[h])
            if final is not None:
                rays_j = per_sample
                if rays < 0 and j > 0:     # the automatic gather keeps to its budget: none once it is spent
                    now = time.perf_counter()
                    rays_j = sample_gather_rays(per_sample, gather_seconds - (now - t_start), (now - t_loop) / j)
                f = np.nonzero(self.edge_gather.near_edge(g.tside[h]))[0] if rays_j else []
                if len(f):
                    e[f] = final.irradiance(g.point[h[f]], sc.tside_normal[g.tside[h[f]]], rays_j,
                                            self._resolve_rng, shift=shift[h[f]], first=j * per_sample,
                                            at=(g.tside[h[f]], g.bary[h[f]]))
                    self.edge_gather.points += len(f)
                self.gather_rays_used += rays_j
            m = g.material[h]
            w_d = sc.materials.diffuse_weight(m, np.einsum("ij,ij->i", g.normal[h], g.w_eye[h]))
            scale = self.albedo_scale(g.triangle[h], g.point[h])
            value = w_d * kd[m] / np.pi * e * (1.0 if scale is None else scale)
            if through is not None:
                value += self.surface_values(through, through_vert, g.tside[h], g.bary[h])
            out[h] += g.weighted(value, h)
        return out / k

    def _indirect_plan(self, gather, gather_seconds, k):
        """What :meth:`diffuse_indirect` reads from the solver: ``(e_bar, vert, final,
        per_sample)``, the solver's E_bar (S, 3) for the image, its vertex values (with
        ``smooth``, else None), the :class:`~raybundle.imaging.gather.FinalGather` or None
        and its rays per sub-pixel sample for ``k`` sub-pixel samples (the automatic count
        is probed: :meth:`~raybundle.imaging.gather.EdgeGather.automatic_rays`)."""
        solver = self.solver
        caustic = solver.caustic is not None and self.caustic_splats is None
        # a caustic light-traced into the pixels (caustic_splats) is left out here
        e_bar = solver.image_incoming(caustic=caustic, world=self.world_light is None)
        sharp = solver.caustic.E if caustic else None
        rays, final, per_sample = self.settings.gather_rays, None, 0
        if gather and self.scene.n_patches and (rays > 0 or (rays < 0 and gather_seconds and
                                                             self.edge_gather.affordable(self._probe_gbuffer(),
                                                                                         gather_seconds))):
            final = FinalGather(solver, near=self.GATHER_NEAR, caustic=caustic, world=self.world_light is None,
                                image_values=(e_bar, sharp) if self.settings.smooth else None)
        vert = final.image_vert if final is not None else None
        if vert is None and self.settings.smooth and np.any(e_bar):
            vert = solver.reconstruction.smooth_and_sharp(e_bar, sharp)
        if final is not None:
            per_sample = (-(-int(rays) // k) if rays > 0 else
                          self.edge_gather.automatic_rays(final, self._probe_gbuffer(), k, gather_seconds,
                                                          lambda ts, bary: self.surface_values(e_bar, vert, ts, bary)))
            if per_sample == 0:
                final = None
        return e_bar, vert, final, per_sample

    #: the image's final gather reads the patch values at every hit, however near
    #: (:class:`~raybundle.imaging.gather.FinalGather`'s ``near`` 0): the direct light estimated
    #: at hits within a patch size of the gathering point (bakes do, where a vertex's value is
    #: final) costs many times as much per ray where lamps are many and takes no noise away
    GATHER_NEAR = 0.0

    def automatic_gather_pays(self, gather_seconds):
        """Whether the automatic final gather (``gather_rays`` -1) would spend ``gather_seconds``
        on the image: a timed run whose gather would not pay gives the seconds it kept for it
        to more iterations (:meth:`run`).  When it pays, the probe's plan is kept for the
        :meth:`diffuse_indirect` that follows."""
        t0 = time.perf_counter()                  # probing the sides for edges counts too
        if self.settings.gather_rays != -1 or not gather_seconds or not self.scene.n_patches or \
                not self.edge_gather.affordable(self._probe_gbuffer(), gather_seconds):
            return False
        k = max(1, int(self.settings.resolve_samples))
        plan = self._indirect_plan(True, gather_seconds, k)
        self._planned = ((gather_seconds, k), plan, time.perf_counter() - t0) if plan[2] is not None else None
        return plan[2] is not None

    def _probe_gbuffer(self):
        """The G-buffer the automatic gather measures on: the last image pass's, or for a
        renderer without a pass of its own (chains merged into it) the pixel centres'."""
        if self.gbuffer is None:
            self.gbuffer = self.trace_gbuffer(np.full((len(self._pixel), 2), 0.5))
        return self.gbuffer

    def final_share(self):
        """The automatic final gather's share of a time-limited run (``gather_share``)."""
        return self.settings.gather_share if self.settings.gather_rays < 0 else 0.0

    def resolve(self, final_seconds=None):
        """The image at the end of a run or at a snapshot; in a run limited by time the
        automatic final gather may take ``final_seconds``."""
        return self.image(gather_seconds=final_seconds)

    def image(self, diffuse=None, preview=False, gather_seconds=None):
        """The current estimate (H, W, 3) float32; ``diffuse`` = precomputed diffuse
        indirect; ``preview``: resolve it with one sub-pixel sample (fast, aliased);
        ``gather_seconds``: the automatic final gather's budget (:meth:`diffuse_indirect`)."""
        img = (self.pass_sum / np.maximum(self.pass_samples, 1)[:, None]
               + self.emission_sum / np.maximum(self.emission_count, 1)[:, None])
        if self.gather_passes:
            img = img + self.gather_sum / self.gather_passes
        if self.caustic_splats is not None and self.caustic_splats.samples:
            img = img + self.caustic_splats.image()
        if self.glossy_iterations:
            img = img + self.glossy_sum / self.glossy_iterations
        if diffuse is None:
            diffuse = self.diffuse_indirect(samples=1 if preview else None, gather=not preview,
                                            gather_seconds=gather_seconds)
        img = img + diffuse
        return img.reshape(self.camera.height, self.camera.width, 3).astype(np.float32)

    def step(self):
        """One solver iteration, this iterate's glossy lobe per pixel, and an image pass
        once the iterations since the last one have done (1 - s) / s times the work of the
        rays an image pass traces on average, s = ``image_ray_share`` (the solver's work in
        rays: :meth:`~raybundle.methods.stochastic_iteration.StochasticIterationSolver.work_rays`; the first call also
        makes the first pass, whose rays, with every pixel a penumbra, are set-up, not the
        passes' average; passes grow when penumbrae are found, so the ratio is re-read every
        time).  By default s = 0.2 for diffuse scenes and 0.55 with glossy lobes, whose eye paths
        the passes trace and whose caustic they splat (docs/benchmarks.md, 'Measured choices
        behind the defaults')."""
        self._planned = None
        solver = self.solver
        if self.passes == 0:
            self.image_pass()
        t0 = time.perf_counter()
        solver.step()
        if not solver.diffuse_only:
            self.accumulate_glossy()
        self._iteration_seconds += time.perf_counter() - t0
        self._since_pass += 1
        if self._pass_due(self._since_pass):
            self.image_pass()
            self._since_pass = 0

    def _pass_due(self, since):
        """Whether an image pass is due after ``since`` iterations since the last (:meth:`step`)."""
        solver = self.solver
        share = self.settings.image_ray_share or (
            self.DIFFUSE_IMAGE_SHARE if solver.diffuse_only else self.GLOSSY_IMAGE_SHARE)
        per_pass = (self.image_rays - self._setup_rays) / (self.passes - 1) if self.passes > 1 else self._setup_rays
        per_iter = solver.work_rays() / max(solver.stats.iterations, 1)
        return since * share * max(per_iter, 1) >= per_pass * (1 - share)

    def next_step_seconds(self):
        """What the next :meth:`step` will take [s], from this run's means: an iteration, and an
        image pass where one will be due (the run loop's clock, :class:`~raybundle.imaging.run.RunLoop`)."""
        iterations = self.solver.stats.iterations
        if iterations == 0 or self.passes == 0:
            return 0.0
        t = self._iteration_seconds / iterations
        return t + (self.pass_seconds / self.passes if self._pass_due(self._since_pass + 1) else 0.0)

    #: the arrays that are sums over image passes and iterations (:meth:`sums`)
    SUMS = ("pass_sum", "pass_samples", "pass_sq_sum", "glossy_sum", "gather_sum", "emission_sum", "emission_count")
    COUNTS = ("passes", "glossy_iterations", "gather_passes", "image_rays")

    def sums(self):
        """Copies of the running sums and counts the image is formed from, by name (what
        independent chains pool by adding, :mod:`raybundle.app.chains`; ``shadow_flags`` by or)."""
        out = {k: getattr(self, k).copy() for k in self.SUMS}
        out.update({k: getattr(self, k) for k in self.COUNTS}, shadow_flags=self.shadow_flags.copy())
        if self.caustic_splats is not None:
            cs = self.caustic_splats
            out.update(caustic_splat_sum=cs.sum.copy(), caustic_splat_samples=cs.samples)
        return out

    def set_sums(self, sums):
        """Hold ``sums`` (:meth:`sums` of a renderer on the same prepared scene, or of several pooled)."""
        for k in self.SUMS:
            setattr(self, k, sums[k].copy())
        for k in self.COUNTS:
            setattr(self, k, sums[k])
        self.shadow_flags = sums["shadow_flags"].copy()
        if self.caustic_splats is not None:
            self.caustic_splats.sum = sums["caustic_splat_sum"].copy()
            self.caustic_splats.samples = sums["caustic_splat_samples"]

    def stats(self, total_seconds, resolve_seconds=0.0, cancelled=False):
        """The run's figures as a plain dict (what the CLI, the add-on and the bench report)."""
        solver = self.solver
        st = solver.stats
        return {"scene": self.scene.name, "solver": solver.name, "iterations": st.iterations,
                 "directions": st.directions, "seconds": round(total_seconds, 4), "solver_seconds": round(st.seconds, 4),
                 "resolve_seconds": round(resolve_seconds, 4),
                 "rays_traced": int(st.rays + self.image_rays), "bundle_rays": int(st.bundle_rays),
                 "bundle_queries": int(st.rays), "image_rays": int(self.image_rays),
                 "image_passes": self.passes, "image_pass_seconds": round(self.pass_seconds, 4),
                 "gather_rays_per_pixel": self.gather_rays_used, "world_samples": self.world_samples,
                 "patches": int(self.scene.n_patches),
                 "triangles": int(len(self.scene.triangles)), "resolution": [self.camera.width, self.camera.height],
                 "bundle_resolution": solver.bundle_resolution, "sequence": self.settings.sequence,
                 "seed": self.settings.seed, "diffuse_only": bool(solver.diffuse_only),
                 "first_shot_lights": self.direct.n_lights, "light_tree": self.direct.tree is not None,
                 "cancelled": cancelled, **solver.report()}
