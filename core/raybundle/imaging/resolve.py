"""The diffuse indirect light of the image, resolved from the solution, and the final gather.

``W_d kd / pi * E_bar`` is linear in the running average ``E_bar`` of the patches' incoming
radiance, so it is resolved once from the final average at ``resolve_samples`` sub-pixel
positions in each pixel (the first points of the Sobol (0, 2)-sequence, with a random digital
shift of the pixel's own: a thin bar covering a share of every pixel along it is seen in each to
within two of the positions, neither lost nor doubled along its whole length), with ``E_bar``
interpolated linearly over each smooth surface from vertex values that are the L2 projection of
the patch values onto hat functions
(:meth:`~raybundle.patches.reconstruction.LinearReconstruction.projected`), or flat per patch.
Next to concave edges and contacts, where patch values cannot follow the light, a final gather
reads the solution where its rays land instead (:mod:`raybundle.imaging.gather`).
"""
from __future__ import annotations

import time

import numpy as np

from ..tracing.sampling import Stream, sobol_points, stream
from ..util.memory import release_freed
from .gather import FinalGather
from .gather_allocation import GatherAllocation


def surface_values(scene, solver, side_values, vert, tside, bary):
    """Side values (S, C) at hit points on triangle sides ``tside`` (N,) of ``scene``:
    interpolated from welded-vertex values ``vert`` (V, C) with barycentrics (N, 3) by the
    ``solver``'s reconstruction, or flat per side when ``vert`` is None."""
    if vert is None:
        return side_values[scene.tside_side[tside]]
    return solver.reconstruction.at(vert, tside, bary)


def sample_gather_rays(per_sample, seconds_left, seconds_per_sample):
    """The automatic gather's rays for the next sub-pixel sample: all ``per_sample`` while the
    budget left holds a sample at the pace so far, else none (:meth:`DiffuseIndirect.image`).
    Never a few: a gather thinned below what the probe found it needs adds more noise than
    the bias it removes."""
    return int(per_sample) if seconds_left >= seconds_per_sample else 0


class DiffuseIndirect:
    """The image's diffuse indirect light from ``solver``'s solution, through the eye's rays
    ``trace`` (:meth:`~raybundle.imaging.eye_rays.EyeRays.trace`, counted) at the pixels of an
    image of ``shape`` (height, width).  ``edge_gather``
    (:class:`~raybundle.imaging.gather.EdgeGather`) flags the sides that gather; ``probe()``
    gives the G-buffer the automatic gather measures its cost on.
    ``world_sampled``: the world's direct light is sampled per pixel (not read from the
    patches); ``caustic_splatted``: the caustic shot is light-traced into the pixels;
    ``trace_seconds()``: what a trace of every pixel took last (None: not known)."""

    def __init__(self, scene, solver, settings, trace, shape, edge_gather, probe, world_sampled, caustic_splatted,
                 trace_seconds=lambda: None):
        self.scene, self.solver, self.settings, self.trace = scene, solver, settings, trace
        self.shape, self.pixels = tuple(shape), int(shape[0]) * int(shape[1])
        self.trace_seconds = trace_seconds
        self.edge_gather, self.probe = edge_gather, probe
        self.world_sampled, self.caustic_splatted = world_sampled, caustic_splatted
        self.rng = stream(settings.seed, Stream.RESOLVE)
        self._planned = None                # automatic_gather_pays' plan for the next image
        self.gather_rays_used = 0           # rays per pixel of the last resolve's gather

    def forget_plan(self):
        """Drop the plan :meth:`automatic_gather_pays` kept: the solution has moved on."""
        self._planned = None

    def image(self, e_bar=None, samples=None, gather=True, final_time=None):
        """(N, 3) W_d kd/pi * E_bar at the pixels (W_d: the diffuse weight under a
        Principled layer, 1 without), box-filtered with ``samples`` (default
        ``resolve_samples``) sub-pixel samples a pixel (module docstring).

        ``e_bar`` (S, 3) defaults to the solver's
        :meth:`~raybundle.methods.patch_solution.PatchSolution.indirect_incoming`.
        With ``smooth``, the bundles' running average and the caustic first shot are
        interpolated by :meth:`~raybundle.patches.reconstruction.LinearReconstruction.smooth_and_sharp`.
        With ``gather`` (and ``e_bar`` the solver's own), points on the sides
        :meth:`~raybundle.imaging.gather.EdgeGather.near_edge` flags gather their indirect light
        instead (:class:`~raybundle.imaging.gather.FinalGather`): ``gather_rays`` rays per pixel on
        average, spread over its sub-pixel samples as one stratified set, the first sample's
        alike in every pixel and the rest shared by their noise
        (:mod:`~raybundle.imaging.gather_allocation`).  With ``gather_rays`` = -1
        the count is what ``final_time`` buy (the run loop gives ``gather_share`` of a timed
        run's iteration seconds, :meth:`~raybundle.imaging.renderer.Renderer.resolve`; none: no automatic
        gather), from the gather's
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
        n = self.pixels
        out = np.zeros((n, 3))
        k = self.samples(samples, final_time)
        final, per_sample, rays = None, 0, self.settings.gather_rays
        own, cache = e_bar is None, {}
        if e_bar is None:
            planned, self._planned = self._planned, None
            if planned is not None and planned[0] == (final_time, k):
                e_bar, vert, final, per_sample = planned[1]
                t_start -= planned[2]                 # the probe's time counts against the gather's budget
            else:
                e_bar, vert, final, per_sample = self._indirect_plan(gather, final_time, k)
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
        digits = self.rng.integers(0, 1 << 32, size=(n, 2), dtype=np.uint64)   # new at every resolve
        if final is not None:
            shift = self.rng.random((n, 2))
            share = GatherAllocation(*self.shape, per_sample, self.rng)
        t_loop = time.perf_counter()
        for j in range(k):
            g = self.trace(sobol_points(np.full(n, j), digits))
            h = g.front(sc)
            e = surface_values(sc, self.solver, e_bar, vert, g.tside[h], g.bary[h])
            m = g.material[h]
            w_d = sc.materials.diffuse_weight(m, np.einsum("ij,ij->i", g.normal[h], g.w_eye[h]))
            scale = sc.albedo_at(g.triangle[h], g.point[h])
            factor = g.weighted(w_d * kd[m] / np.pi * (1.0 if scale is None else scale), h)
            if final is not None:
                rays_j = per_sample
                if rays < 0 and j > 0:     # the automatic gather keeps to its budget: none once it is spent
                    now = time.perf_counter()
                    rays_j = sample_gather_rays(per_sample, final_time - (now - t_start), (now - t_loop) / j)
                if rays_j:
                    self._gather(final, share, g, h, e, factor, shift)
                self.gather_rays_used += rays_j
            if own:
                e = self._reflected_caustic(e, g, h, cache)
            value = factor * e
            if through is not None:
                value += g.weighted(surface_values(sc, self.solver, through, through_vert, g.tside[h], g.bary[h]), h)
            out[h] += value
        return out / k

    def _gather(self, final, share, g, h, e, factor, shift):
        """Gather ``e`` (N, 3) at the points ``h`` of G-buffer ``g`` on flagged sides, in place,
        with the rays ``share`` (:class:`~raybundle.imaging.gather_allocation.GatherAllocation`)
        gives each pixel; the first gather measures one ray's variance in the pixels' values
        (``factor`` (N, 3) times the irradiance) and its cost (a ray that lands near costs
        :meth:`~raybundle.imaging.gather.FinalGather.near_cost` more) for ``share`` to divide the
        rest by."""
        sc = self.scene
        f = np.nonzero(self.edge_gather.near_edge(g.tside[h]))[0]
        if len(f) == 0:
            return
        px = h[f]
        r = share.rays(px)
        ts = g.tside[px]
        got = final.irradiance(g.point[px], sc.tside_normal[ts], r, self.rng, shift=shift[px], first=share.used[px],
                               at=(ts, g.bary[px]), variance=share.measuring)
        share.used[px] += r
        if share.measuring:
            got, var, near = got
            share.measure(px, np.sum(factor[f] ** 2 * var, axis=1), 1.0 + final.near_cost() * near)
        e[f] = got
        self.edge_gather.points += len(f)

    def samples(self, samples, final_time):
        """The sub-pixel samples of an :meth:`image`: ``samples`` (default ``resolve_samples``),
        in a run limited by time no more traces of every pixel than ``final_time`` holds at the
        pace of the last one (at least one): a path through a chain of glass panes can take a
        second."""
        k = max(1, int(samples or self.settings.resolve_samples))
        seconds = self.trace_seconds()
        if final_time is not None and seconds:
            k = min(k, max(1, int(final_time / seconds)))
        return k

    def _reflected_caustic(self, e, g, h, cache):
        """The incoming light ``e`` (N, 3) at the hits ``h`` of G-buffer ``g``, plus the caustic
        first shot at those the eye saw in a mirror or reflected by glass, where the caustic is
        light-traced into the pixels (:mod:`~raybundle.imaging.caustic_splats`: its splats go
        straight to the camera and miss them); ``cache`` (a dict) keeps its vertex values for
        the rest of the image."""
        caustic = self.solver.caustic
        if caustic is None or not self.caustic_splatted or g.reflected is None:
            return e
        r = np.nonzero(g.reflected[h])[0]
        if len(r) == 0:
            return e
        if "vert" not in cache:
            cache["vert"] = self.solver.reconstruction.averaged(caustic.E, dtype=np.float32) \
                if self.settings.smooth else None
        e[r] += surface_values(self.scene, self.solver, caustic.E, cache["vert"], g.tside[h[r]], g.bary[h[r]])
        return e

    def _indirect_plan(self, gather, final_time, k):
        """What :meth:`image` reads from the solver: ``(e_bar, vert, final,
        per_sample)``, the solver's E_bar (S, 3) for the image, its vertex values (with
        ``smooth``, else None), the :class:`~raybundle.imaging.gather.FinalGather` or None
        and its rays per sub-pixel sample for ``k`` sub-pixel samples (the automatic count
        is probed: :meth:`~raybundle.imaging.gather.EdgeGather.automatic_rays`)."""
        solver = self.solver
        release_freed()                   # the vertex values below peak on what the run left
        caustic = solver.caustic is not None and not self.caustic_splatted
        # a caustic light-traced into the pixels (caustic_splats) is left out here
        e_bar = solver.image_incoming(caustic=caustic, world=not self.world_sampled)
        sharp = solver.caustic.E if caustic else None
        rays, final, per_sample = self.settings.gather_rays, None, 0
        if gather and self.scene.n_patches and (rays > 0 or (rays < 0 and final_time and
                                                             self.edge_gather.affordable(self.probe(),
                                                                                         final_time))):
            # at hits within a patch size the lamps' light is sampled where they land, one
            # shadow ray a light even in a penumbra: a pixel averages many such hits
            final = FinalGather(solver, near_penumbra_samples=1, caustic=caustic, world=not self.world_sampled,
                                image_values=(e_bar, sharp) if self.settings.smooth else None)
        vert = final.image_vert if final is not None else None
        if vert is None and self.settings.smooth and np.any(e_bar):
            vert = solver.reconstruction.smooth_and_sharp(e_bar, sharp, np.float32)
        if final is not None:
            per_sample = (-(-int(rays) // k) if rays > 0 else
                          self.edge_gather.automatic_rays(final, self.probe(), k, final_time,
                                                          lambda ts, bary: surface_values(self.scene, solver, e_bar, vert, ts, bary)))
            if per_sample == 0:
                final = None
        return e_bar, vert, final, per_sample

    def automatic_gather_pays(self, final_time):
        """Whether the automatic final gather (``gather_rays`` -1) would spend ``final_time``
        on the image: a timed run whose gather would not pay gives the seconds it kept for it
        to more iterations (:meth:`~raybundle.imaging.progressive.ProgressiveImage.run`).  When it pays, the probe's plan is kept for the
        :meth:`image` that follows."""
        t0 = time.perf_counter()                  # probing the sides for edges counts too
        if self.settings.gather_rays != -1 or not final_time or not self.scene.n_patches or \
                not self.edge_gather.affordable(self.probe(), final_time):
            return False
        k = self.samples(None, final_time)
        plan = self._indirect_plan(True, final_time, k)
        self._planned = ((final_time, k), plan, time.perf_counter() - t0) if plan[2] is not None else None
        return plan[2] is not None
