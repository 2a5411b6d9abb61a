"""Camera images from a solver: the measurement M L_n averaged over iterations.

A pixel is the radiance through it under the camera's pixel filter, estimated in four parts,
each where it is cheapest and sharpest, each in a module of its own:

* **emission seen** by the eye, and the world where nothing is hit
  (:mod:`~raybundle.imaging.emission_seen`): its own per-pixel average;
* **direct light** of the first-shot lights and the world at the points the eye sees, per pixel,
  with penumbra samples where shadow edges cross (:mod:`~raybundle.imaging.pixel_light`);
  every *image pass* jitters the sub-pixel position anew, so edges antialias as the average
  converges;
* **glossy indirect**: the glossy lobe the eye sees, by lobe-sampled eye paths reading the
  solution (:mod:`~raybundle.imaging.glossy_paths`), or the thesis' per-iteration
  ``E_i^n f_i(t_i^n, w_eye)`` averaged over iterations (:meth:`Renderer.accumulate_glossy`);
* **diffuse indirect**: ``kd / pi * E_bar``, resolved once from the final average, with a
  final gather next to concave edges and contacts (:mod:`~raybundle.imaging.resolve`).

The eye's rays and their way through glass are :mod:`~raybundle.imaging.eye_rays`'s; when
passes run and which pixels take more samples, :mod:`~raybundle.imaging.passes`'.
:class:`Renderer` coordinates them: it drives solver iterations and image passes (run by the
one run loop, :class:`~raybundle.imaging.progressive.ProgressiveImage`) and forms the image.
"""
from __future__ import annotations

import time

import numpy as np

from ..lights.world_light import WorldLight
from ..tracing.sampling import ShiftedKronecker, Stream, stream
from ..util.memory import release_freed
from .caustic_splats import CausticSplats
from .components import ImageComponents
from .emission_seen import EmissionSeen
from .eye_rays import EyeRays
from .gather import EdgeGather
from .glossy_paths import GlossyEyePaths
from .passes import PassSchedule
from .pixel_light import PixelLight
from .progressive import ProgressiveImage
from .resolve import DiffuseIndirect, surface_values
from .settings import RenderSettings


class Renderer(ProgressiveImage):
    """Runs a solver and forms the image.  See the module docstring."""

    def __init__(self, scene, camera, solver, direct, settings: RenderSettings):
        if camera is None:
            raise ValueError("the scene has no camera; give one (Camera.from_blender / Camera.look_at)")
        settings.validate()
        self.scene, self.camera, self.solver, self.direct = scene, camera, solver, direct
        self.emission = EmissionSeen(scene, camera)
        self.tracer = solver.tracer
        self.settings = settings
        self.rng = stream(settings.seed, Stream.IMAGE_PASSES)
        # per pass and pixel: the glossy lobe's uniforms.  The sub-pixel position continues the
        # pixel's own R_2 sequence (image_pass), the light samples one R_3 sequence per pixel and
        # light (pixel_light), from a shift per pixel
        self.pass_sampler = ShiftedKronecker(camera.width * camera.height, 2, self.rng)
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
        self.glossy_iterations = 0
        self.image_rays = 0
        #: the image's parts apart (``settings.components``; :mod:`~raybundle.imaging.components`)
        self.parts = ImageComponents(n) if settings.components else None
        self._diffuse = None                 # the diffuse indirect part of the last image
        #: seconds per estimator: the eye rays (and the emission seen), the lamps', the world's and
        #: the glossy paths' samples, the iterations, the caustic splats, the diffuse indirect light
        self.part_seconds = dict.fromkeys(("eye rays", "lamps", "world", "glossy paths", "iterations",
                                           "caustic splats", "diffuse indirect"), 0.0)
        self.schedule = PassSchedule(solver, settings)
        self.gbuffer = None
        self._glossy_pixels = np.zeros(0, np.int64)   # pixels for accumulate_glossy
        self.eye = EyeRays(scene, camera, self.tracer, direct, settings, self.rng)
        self.glossy_material = scene.materials.is_glossy
        # the world as a light to sample, where it changes with direction (the glossy eye paths'
        # MIS, and the world samples at visible points)
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
        self.light = PixelLight(scene, camera, solver, direct, settings, self.rng, self.world_light, self.world_samples)
        # the caustic first shot on the surfaces seen, light-traced into the pixels (None: read
        # from the patches as the rest of the diffuse indirect light)
        self.caustic_splats = None
        if solver.caustic is not None and settings.caustic_splats > 0:
            self.caustic_splats = CausticSplats(scene, camera, self.tracer, direct, solver.caustic, settings.seed,
                                                self.eye.pixel, lambda: self.trace_gbuffer(np.full((n, 2), 0.5)))
        #: seconds the last trace of every pixel took (None before the first)
        self.full_trace_seconds = None
        self.indirect = DiffuseIndirect(scene, solver, settings, self.trace_gbuffer, (camera.height, camera.width),
                                        self.edge_gather, self._probe_gbuffer, self.world_light is not None,
                                        self.caustic_splats is not None, lambda: self.full_trace_seconds)

    #: world samples per visible point and pass where the world alone lights the scene
    #: (``world_samples`` = -1, :meth:`automatic_world_samples`)
    WORLD_ONLY_SAMPLES = 4

    def automatic_world_samples(self, setting, direct):
        """The world samples per visible point and pass: ``setting``, or for -1
        :data:`WORLD_ONLY_SAMPLES` where a world that changes with direction is the only light
        (no first-shot lights in ``direct``), else 0.  A sky through windows is then all the
        direct light, which patches a window wide carry with their finite-element error;
        beside a sun (a lamp, or one split out of the world) the world is a small part whose
        samples mostly meet the blinds and walls."""
        if setting >= 0:
            return int(setting)
        world = self.scene.world
        return self.WORLD_ONLY_SAMPLES if world.emits and not world.is_constant and not direct.n_lights else 0

    # --------------------------------------------------------------- passes
    def trace_gbuffer(self, jitter, pixels=None):
        """The eye's rays for sub-pixel uniforms ``jitter`` in all pixels or in ``pixels``
        (:meth:`~raybundle.imaging.eye_rays.EyeRays.trace`), counted in :attr:`image_rays`."""
        before, t0 = self.eye.rays, time.perf_counter()
        g = self.eye.trace(jitter, pixels)
        self.image_rays += self.eye.rays - before
        if pixels is None:
            self.full_trace_seconds = time.perf_counter() - t0
        return g

    def surface_values(self, side_values, vert, tside, bary):
        """Side values at hit points (:func:`~raybundle.imaging.resolve.surface_values`)."""
        return surface_values(self.scene, self.solver, side_values, vert, tside, bary)

    #: the first pass's extra emission samples per pixel (at least 4; at most FIRST_EDGE_RAYS in
    #: all): the edges of lights and window bars they find get samples of their own from then on
    #: (:meth:`~raybundle.imaging.emission_seen.EmissionSeen.radiance` reads the sky beside a bar
    #: only once a pixel is known to hold one)
    FIRST_EDGE_SAMPLES = 16
    FIRST_EDGE_RAYS = 4_000_000

    def image_pass(self):
        """One jittered sample per pixel of the per-pass part: emission seen, direct light of
        the first-shot lights and the world, and (with ``glossy_gather``) the glossy lobe;
        more samples at the edges of visible lights and where the pixel's passes disagree most
        (:meth:`~raybundle.imaging.passes.PassSchedule.noisy_pixels`).  The sample's sub-pixel
        position is the next of the pixel's R_2 sequence
        (:meth:`~raybundle.imaging.eye_rays.EyeRays.subpixel_sequence`, shared with the extra
        samples), so a pixel's passes cover it evenly from the first ones on.  Keeps the
        G-buffer for :meth:`accumulate_glossy`."""
        t0 = time.perf_counter()
        u = self.pass_sampler.next()
        n = len(self.eye.pixel)
        g = self.trace_gbuffer(self.eye.subpixel_sequence(np.arange(n), 1)[1])
        self.gbuffer = g
        emitted, _ = self.emission.radiance(g)
        before_pass = self.image_rays - len(g.triangle)
        if self.passes == 0:                          # find most edges at once, a sample per pixel at a time
            edges = max(4, min(self.FIRST_EDGE_SAMPLES, self.FIRST_EDGE_RAYS // max(n, 1)))
            if self.first_edge_seconds is not None:   # a trace through deep glass can take a second
                edges = min(edges, int(self.first_edge_seconds / max(time.perf_counter() - t0, 1e-9)))
            for _ in range(edges):
                self._emission_samples(np.arange(n), 1)
        self._clocked("eye rays", t0)
        # pixels whose earlier samples disagree (the edge of a visible light, which is
        # also where a lamp lights a narrow rim) get extra samples (one R_2 sequence per pixel)
        # for both the emission average and this pass's estimate, the mean of 1 + k
        # samples: chosen from earlier passes only, so every pass stays unbiased; the pixel's
        # image is the mean of all its samples (``pass_samples``), not of its passes
        noisy, factor = self.schedule.noisy_pixels(self.pass_sum, self.pass_samples, self.pass_sq_sum, self.passes)
        extra_pix = np.union1d(self.emission.edges(), noisy)
        self.emission.add(np.arange(n), emitted)
        self._restart_solver_parts()
        value, gathered, gl, parts = self._shade(g, u, None, np.arange(n))
        k = np.full(len(extra_pix), int(self.settings.emission_edge_samples))
        k[np.searchsorted(extra_pix, noisy)] *= factor
        count = np.ones(n)                 # the samples this pass takes in each pixel
        if len(extra_pix) and k[0] > 0:
            count[extra_pix] += k
            t1 = time.perf_counter()
            pix, jitter = self.eye.subpixel_sequence(extra_pix, k)
            gx = self.trace_gbuffer(jitter, pixels=pix)
            le, _ = self.emission.radiance(gx)
            self.emission.add(pix, le)
            self._clocked("eye rays", t1)
            extra, extra_g, _, extra_parts = self._shade(gx, self.rng.random((len(pix), 2)), self.rng, pix)
            row = np.repeat(np.arange(len(extra_pix)), k)
            pairs = [(value, extra), (gathered, extra_g)] + ([] if parts is None else
                                                             [(parts[p], extra_parts[p]) for p in parts])
            for total, more in pairs:
                summed = np.stack([np.bincount(row, more[:, c], minlength=len(extra_pix)) for c in range(3)], axis=1)
                total[extra_pix] = (total[extra_pix] + summed) / (k + 1)[:, None]
        self.pass_sum += value * count[:, None]
        self.pass_samples += count
        if parts is not None:
            self.parts.add_pass(parts, count, g.bounced)
        self.gather_sum += gathered
        self.gather_passes += 1
        y = (value + gathered).sum(axis=1)
        self.pass_sq_sum += count * y * y
        if self.caustic_splats is not None:
            cs = self.caustic_splats
            before, t1 = cs.rays, time.perf_counter()
            cs.splat(int(np.ceil(self.settings.caustic_splats * n)))
            self.image_rays += cs.rays - before
            self.part_seconds["caustic splats"] += time.perf_counter() - t1
        self.schedule.passed(time.perf_counter() - t0, self.image_rays - before_pass, self.passes == 0)
        self.passes += 1
        self._glossy_pixels = gl
        if self.passes == 1:              # the first pass samples every pixel's penumbrae: its
            release_freed()               # freed temporaries would sit under every later peak

    def _restart_solver_parts(self):
        """Drop what the passes and iterations read from the solver before its running
        average restarted (after ``restart_at`` iterations, when the iterates have forgotten
        their zero start; a solver warmed up before its first iteration has 0 and never
        restarts): the glossy eye paths' sum and the glossy iterates.  Read from an average still
        rising from zero, they kept a start-up bias that fell only as 1/n.  Done at the first
        pass after the restart, so a run always keeps at least one pass."""
        solver = self.solver
        restart = getattr(solver, "restart_at", 0)
        if self._restarted or not restart or solver.stats.iterations <= restart:
            return
        self._restarted = True
        self.gather_sum[:] = 0.0
        self.gather_passes = 0
        if self.glossy_iterations > 1:
            self.glossy_sum[:] = 0.0
            self.glossy_iterations = 0

    def _shade(self, g, u_lobe, u_light, pixels):
        """Per-pass radiance (N, 3) of the samples in G-buffer ``g`` taken in ``pixels`` (N,):
        the direct light of the first-shot lights and the world (:class:`~raybundle.imaging.
        pixel_light.PixelLight`) and, with ``glossy_gather``, the glossy lobe; what the lobe
        read from the solver (N, 3), apart; the pixels left for :meth:`accumulate_glossy`; and
        with ``components`` the radiance's parts (:meth:`~raybundle.imaging.components.
        ImageComponents.split`), else None.  ``u_lobe`` (N, 2) uniforms; ``u_light`` a
        Generator for the light samples, or None for a pass's own (one per pixel)."""
        out = np.zeros((len(g.triangle), 3))
        lamps, world = (None, None) if self.parts is None else (np.zeros_like(out), np.zeros_like(out))
        clock = time.perf_counter()
        hf = g.front(self.scene)
        light = self.light
        before = light.rays
        # the diffuse texture at the points, for the lamps and the world
        lit_here = len(hf) and (self.direct.n_lights or self.world_light is not None)
        scale = self.scene.albedo_at(g.triangle[hf], g.point[hf]) if lit_here else None
        if self.direct.n_lights and len(hf):
            mis = self.glossy_material[g.material[hf]] if self.glossy_paths.light_mis else None
            lobe = None if lamps is None else np.zeros((len(hf), 3))
            lit = light.lamps(g, hf, pixels, u_light, self.passes, mis, scale, glossy_part=lobe)
            out[hf] += lit
            if lamps is not None:
                lamps[hf] += lit - lobe
        if self.direct.n_lights:          # the first-shot lights on a translucent surface's far side
            far = light.far_side(g, hf)
            out[hf] += far
            if lamps is not None:
                lamps[hf] += far
        clock = self._clocked("lamps", clock)
        gl = hf[self.glossy_material[g.material[hf]]]
        lobe_world = 0          # world samples the glossy lobes share with the diffuse one
        lobe_guide = None       # ... and the guide they were drawn by, for the lobes' MIS
        if self.world_light is not None and len(hf):
            shared = self.settings.glossy_gather and self.glossy_paths.world_light is self.world_light and len(gl)
            diffuse, sky, guide = light.world(g, hf, scale, np.searchsorted(hf, gl) if shared else None)
            if shared:
                out[gl] += sky
                lobe_world, lobe_guide = self.world_samples, guide
            out[hf] += diffuse
            if world is not None:
                world[hf] += diffuse
        clock = self._clocked("world", clock)
        self.image_rays += light.rays - before
        gathered = np.zeros_like(out)
        if self.settings.glossy_gather:
            before = self.glossy_paths.rays
            # the lamps and the world the paths meet count with the pass (kept over the solver's
            # restart); what they read from the solver with the gather (dropped at its restart)
            lamp_light, gathered[gl] = self.glossy_paths.gather(g, gl, u_lobe[gl], world_samples=lobe_world,
                                                                guide=lobe_guide)
            out[gl] += lamp_light
            self.image_rays += self.glossy_paths.rays - before
            gl = gl[:0]
        self._clocked("glossy paths", clock)
        parts = None if lamps is None else {k: g.weighted(v) for k, v in ImageComponents.split(out, lamps, world).items()}
        return g.weighted(out), g.weighted(gathered), gl, parts

    def _clocked(self, part, since):
        """Add the seconds from ``since`` to ``part``'s (:attr:`part_seconds`); returns now."""
        now = time.perf_counter()
        self.part_seconds[part] += now - since
        return now

    def _emission_samples(self, pixels, k):
        """``k`` more primary rays in each of ``pixels`` (their sub-pixel sequences), added to
        the emission average.  The average stays unbiased: which pixels get them depends only
        on earlier samples."""
        pix, jitter = self.eye.subpixel_sequence(pixels, k)
        le, _ = self.emission.radiance(self.trace_gbuffer(jitter, pixels=pix))
        self.emission.add(pix, le)

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
    def diffuse_indirect(self, e_bar=None, samples=None, gather=True, final_time=None):
        """(pixels, 3) the diffuse indirect light (:meth:`~raybundle.imaging.resolve.DiffuseIndirect.image`)."""
        return self.indirect.image(e_bar, samples, gather, final_time)

    def automatic_gather_pays(self, final_time):
        """Whether the automatic final gather would spend ``final_time``
        (:meth:`~raybundle.imaging.resolve.DiffuseIndirect.automatic_gather_pays`)."""
        return self.indirect.automatic_gather_pays(final_time)

    @property
    def gather_rays_used(self):
        """Rays per pixel of the last resolve's final gather."""
        return self.indirect.gather_rays_used

    def _probe_gbuffer(self):
        """The G-buffer the automatic gather measures on: the last image pass's, or for a
        renderer without a pass of its own (chains merged into it) the pixel centres'."""
        if self.gbuffer is None:
            self.gbuffer = self.trace_gbuffer(np.full((len(self.eye.pixel), 2), 0.5))
        return self.gbuffer

    def final_share(self):
        """The automatic final gather's share of a time-limited run (``gather_share``)."""
        return self.settings.gather_share if self.settings.gather_rays < 0 else 0.0

    def resolve(self, final_time=None):
        """The image at the end of a run or at a snapshot; in a run limited by time the
        automatic final gather may take ``final_time``."""
        return self.image(final_time=final_time)

    def image(self, diffuse=None, preview=False, final_time=None):
        """The current estimate (H, W, 3) float32; ``diffuse`` = precomputed diffuse
        indirect; ``preview``: resolve it with one sub-pixel sample (fast, aliased);
        ``final_time``: the automatic final gather's budget (:meth:`diffuse_indirect`)."""
        img = self.pass_sum / np.maximum(self.pass_samples, 1)[:, None] + self.emission.mean()
        if self.gather_passes:
            img = img + self.gather_sum / self.gather_passes
        if self.caustic_splats is not None and self.caustic_splats.samples:
            img = img + self.caustic_splats.image()
        if self.glossy_iterations:
            img = img + self.glossy_sum / self.glossy_iterations
        if diffuse is None:
            t0 = time.perf_counter()
            diffuse = self.diffuse_indirect(samples=1 if preview else None, gather=not preview,
                                            final_time=final_time)
            self.part_seconds["diffuse indirect"] += time.perf_counter() - t0
        self._diffuse = diffuse
        img = img + diffuse
        return img.reshape(self.camera.height, self.camera.width, 3).astype(np.float32)

    def components(self):
        """The last :meth:`image`'s parts, by name, and the pixels' share of glass-turned passes
        (:meth:`~raybundle.imaging.components.ImageComponents.images`), or None without
        ``settings.components``."""
        if self.parts is None or self._diffuse is None:
            return None
        glossy = self.gather_sum / max(self.gather_passes, 1)
        if self.glossy_iterations:
            glossy = glossy + self.glossy_sum / self.glossy_iterations
        caustics = self.caustic_splats.image() if self.caustic_splats is not None and self.caustic_splats.samples \
            else None
        return self.parts.images(self.pass_samples, self.emission.mean(), glossy, self._diffuse, caustics,
                                 (self.camera.height, self.camera.width))

    def step(self):
        """One solver iteration, this iterate's glossy lobe per pixel, and the image passes then
        due (:class:`~raybundle.imaging.passes.PassSchedule`; the first call also makes the first
        pass)."""
        self.indirect.forget_plan()
        solver, schedule = self.solver, self.schedule
        if self.passes == 0:
            self.image_pass()
        t0 = time.perf_counter()
        solver.step()
        if not solver.diffuse_only:
            self.accumulate_glossy()
        took = time.perf_counter() - t0
        schedule.iterated(took)
        self.part_seconds["iterations"] += took
        for _ in range(schedule.passes_due(self.passes, self.image_rays)):
            self.image_pass()

    def next_step_seconds(self):
        """What the next :meth:`step` will take [s] (:meth:`~raybundle.imaging.passes.PassSchedule.next_step_seconds`)."""
        return self.schedule.next_step_seconds(self.passes, self.image_rays)

    #: the arrays that are sums over image passes and iterations (:meth:`sums`), and the counts
    SUMS = ("pass_sum", "pass_samples", "pass_sq_sum", "glossy_sum", "gather_sum")
    COUNTS = ("passes", "glossy_iterations", "gather_passes", "image_rays")

    def sums(self):
        """Copies of the running sums and counts the image is formed from, by name (what
        independent chains pool by adding, :mod:`raybundle.app.chains`; ``shadow_flags`` by or)."""
        out = {k: getattr(self, k).copy() for k in self.SUMS}
        out.update({k: getattr(self, k) for k in self.COUNTS}, shadow_flags=self.light.shadow_flags.copy(),
                   emission_sum=self.emission.sum.copy(), emission_count=self.emission.count.copy())
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
        self.light.shadow_flags = sums["shadow_flags"].copy()
        self.emission.sum, self.emission.count = sums["emission_sum"].copy(), sums["emission_count"].copy()
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
                "image_passes": self.passes, "image_pass_seconds": round(self.schedule.pass_seconds, 4),
                "gather_rays_per_pixel": self.gather_rays_used, "world_samples": self.world_samples,
                "patches": int(self.scene.n_patches),
                "triangles": int(len(self.scene.triangles)), "resolution": [self.camera.width, self.camera.height],
                "bundle_resolution": solver.bundle_resolution, "sequence": self.settings.sequence,
                "seed": self.settings.seed, "diffuse_only": bool(solver.diffuse_only),
                "first_shot_lights": self.direct.n_lights, "light_tree": self.direct.tree is not None,
                "part_seconds": {k: round(v, 4) for k, v in self.part_seconds.items()},
                "cancelled": cancelled, **solver.report()}
