"""Final gather: the indirect irradiance at surface points by rays into the solution.

At a point x with unit normal n, ``rays`` cosine-distributed rays each read the
outgoing radiance of the surface they meet from the patch solution, and

    E_ind(x) = pi * mean over the rays of L(hit, -w)                  [W/m^2]

(cosine-weighted sampling of ``int L cos dw``).  ``L`` at a hit is its diffuse part,
``W_d kd/pi E``, with ``E`` the running average of the incoming radiance plus the
first shot read through the linear reconstruction
(:meth:`~raybundle.patches.reconstruction.LinearReconstruction.smooth_and_sharp`), plus its
glossy lobe from the iterate; the emission of first-shot lights is left out (the
direct light at x counts it).  The finite-element error of the patch values then
enters one bounce later and averaged over the hemisphere: next to a concave edge or
a contact, where a patch value cannot follow the fall-off, the gather is right where
the reconstruction is not.

Rays that land within ``near`` patch sizes (the square root of the hit patch's area)
land in just such a place, where the first shot's patch values are wrong most (a
wall's direct light falls to zero towards the ceiling): there the hit's direct
irradiance is estimated at the hit point itself
(:meth:`~raybundle.lights.direct.DirectLighting.irradiance`, ``near_light_samples`` shadow
rays per light and ``near_penumbra_samples`` in a penumbra, unclamped: the rays' mean is then
unbiased).  ``tests/test_baking.py`` pins the corner profile against a
brute-force integral.

Bakes gather at every vertex and corner (:func:`raybundle.imaging.baking.baked_radiance`);
images only where the patch values are not to be trusted (on the patches that
:func:`near_edge_tsides` flags on one of their triangles, :meth:`EdgeGather.near_edge`), the
rest reads the reconstruction directly.
"""
from __future__ import annotations

import time

import numpy as np

from ..tracing.sampling import Stream, cosine_directions, frames_from_normals, kronecker_alpha, stream
from ..tracing.visibility import near_surface
from ..util.memory import release_freed


class FinalGather:
    """The gather of one solution state (its vertex values computed once)."""

    def __init__(self, solver, near=1.0, near_light_samples=1, caustic=True, world=True, image_values=None,
                 bounce=False, near_penumbra_samples=None):
        """``bounce``: a ray landing within ``near`` patch sizes gathers its hit's indirect light by one
        more ray (:meth:`_bounced`) rather than read it from the patches (bakes); its direct light is
        sampled there either way, with ``near_penumbra_samples`` shadow rays a light in a penumbra
        (None: :meth:`~raybundle.lights.direct.DirectLighting.irradiance`'s default; an image's
        pixels average so many hits that one is enough)."""
        sc, rec = solver.scene, solver.reconstruction
        self.bounce = bool(bounce)
        self.solver, self.scene, self.rec = solver, sc, rec
        # rays that leave the scene read the world (``world`` False: left out, for an image
        # that samples the world's direct light itself, :class:`~raybundle.lights.world_light.WorldLight`)
        self.world = bool(world)
        indirect = solver.indirect_incoming()
        sharp = solver.caustic.E if solver.caustic is not None else None
        self.near = float(near) if solver.direct.n_lights else 0.0
        # the vertex values the rays read, and ``image_values`` (side values, sharp part) of the
        # image's own reconstruction (``image_vert``), in one projection
        pairs = [(indirect + solver.first_shot.E.sum(axis=1), sharp)] + \
            ([(indirect, sharp)] if self.near > 0 else []) + ([image_values] if image_values is not None else [])
        verts = rec.smooth_and_sharp_many(pairs, np.float32)      # read at hits: single precision
        self.vert = verts[0]
        self.vert_indirect = verts[1] if self.near > 0 else None
        self.image_vert = verts[-1] if image_values is not None else None
        self.near_light_samples = int(near_light_samples)
        self.near_penumbra_samples = near_penumbra_samples
        self.hit_size = np.sqrt(sc.patch_area[sc.triangle_patch])      # per triangle [m]
        # the rays that landed near so far, and the shadow rays their light samples traced
        self.near_hits, self.near_shadow_rays = 0, 0
        # the first shot's glossy reflections arrive by the caustic shot, read where the gather
        # is (``caustic`` False: left out, for an image that light-traces it into its pixels,
        # :meth:`~raybundle.imaging.caustic_splats.CausticSplats.splat`)
        self.first_shot_glossy = sharp is None
        self.vert_caustic = rec.averaged(sharp, dtype=np.float32) if sharp is not None and caustic else None

    def irradiance(self, points, normals, rays, rng, shift=None, first=0, at=None, chunk_rays=1 << 15,
                   variance=False):
        """E_ind (N, 3) [W/m^2] at ``points`` (N, 3) with unit ``normals`` (N, 3), by
        ``rays`` rays each (one count, or (N,) per point, at least 1): point i's ray k takes the
        Kronecker (R_2) point ``shift_i + (first_i + k) alpha`` (``shift`` (N, 2), default random
        from ``rng``; ``first`` one index or (N,)), so calls with ``first`` = 0, rays, 2 rays, ...
        on one point continue one stratified set (an image spreads a pixel's gather over its
        sub-pixel samples).  The rays go about ``chunk_rays`` at a time (each holds a few hundred
        bytes of hits and radiance meanwhile).  With ``variance``, ``(E_ind, var, near)``: also the
        variance (N, 3) of one ray's estimate ``pi L`` about the mean, per point of at least two
        rays (0 at the others), and the share (N,) of its rays that landed near.

        With a caustic first shot (:mod:`raybundle.lights.caustics`), the rays leave out the first
        shot's glossy reflection at the glossy sides they meet (``E1_l f_g(w_l, -w)`` for the
        one mean direction ``w_l`` per side: single rays 3,000 times the mean where a sharp
        lobe lines up, 52% of that term in its top 10 of 200,000 rays on ``cornell-glossy``),
        as the iteration does, and the caustic shot's ``E_c`` read at ``at`` = (tside (N,),
        barycentrics (N, 3)) of the points takes its place (unless the gather was made
        without it)."""
        caustic = self.vert_caustic is not None
        if caustic and at is None:
            raise ValueError("a gather with a caustic first shot needs the points' sides: at=(tside, bary)")
        points = np.asarray(points, float)
        normals = np.asarray(normals, float)
        shift = rng.random((len(points), 2)) if shift is None else np.asarray(shift, float)
        counts = np.broadcast_to(np.asarray(rays, np.int64), len(points))
        if len(counts) and counts.min() < 1:
            raise ValueError("a final gather takes at least one ray a point")
        first = np.broadcast_to(np.asarray(first, np.int64), len(points))
        ends = np.cumsum(counts)
        out = np.zeros((len(points), 3))
        var, near = (np.zeros((len(points), 3)), np.zeros(len(points))) if variance else (None, None)
        lo = 0
        while lo < len(points):
            start = ends[lo - 1] if lo else 0
            hi = max(lo + 1, int(np.searchsorted(ends, start + chunk_rays, side="right")))
            c = counts[lo:hi]
            origin, w = self._rays(points[lo:hi], normals[lo:hi], c, shift[lo:hi], first[lo:hi])
            L, landed = self._ray_radiance(origin, w, rng)
            begin = ends[lo:hi] - c - start                                  # each point's first ray in L
            total = np.add.reduceat(L, begin, axis=0)
            out[lo:hi] = np.pi * total / c[:, None]
            if variance:
                spread = np.pi ** 2 * (np.add.reduceat(L * L, begin, axis=0) - total ** 2 / c[:, None])
                var[lo:hi] = np.where(c[:, None] > 1, np.maximum(spread, 0) / np.maximum(c - 1, 1)[:, None], 0.0)
                near[lo:hi] = np.add.reduceat(landed.astype(float), begin) / c
            lo = hi
        if caustic:
            out += self.rec.at(self.vert_caustic, at[0], at[1])
        release_freed()              # its pieces' space, left scattered, would sit under the image's peak
        return (out, var, near) if variance else out

    def _rays(self, points, normals, counts, shift, first):
        """The origins and directions (M, 3) of :meth:`irradiance`'s rays for ``points`` (P, 3)
        with unit ``normals``, ``counts`` (P,) rays each (M in all, point by point): ray k of
        point i along the cosine direction of the R_2 point ``shift_i + (first_i + k) alpha``."""
        t, b = frames_from_normals(normals)
        alpha = kronecker_alpha(2)
        lift = points + normals * self.solver.tracer.eps
        if np.all(counts == counts[0]):                    # one count: the frames broadcast
            k = first[:, None, None] + np.arange(counts[0])[None, :, None]
            u = (shift[:, None, :] + k * alpha) % 1                          # (P, R, 2)
            w = cosine_directions(u, t[:, None], b[:, None], normals[:, None]).reshape(-1, 3)
            return np.repeat(lift, counts[0], axis=0), w
        own = np.repeat(np.arange(len(points)), counts)
        index = first[own] + np.arange(len(own)) - np.repeat(np.cumsum(counts) - counts, counts)
        u = (shift[own] + index[:, None] * alpha) % 1
        return lift[own], cosine_directions(u, t[own], b[own], normals[own])

    def _ray_radiance(self, origin, w, rng):
        """``(L, near)``: L (M, 3) [W m^-2 sr^-1] that :meth:`irradiance`'s rays from ``origin``
        (M, 3) along ``w`` (M, 3) read, and (M,) bool, those that landed within ``near`` patch
        sizes (their hit's light sampled there); counted in :meth:`near_cost`'s figures."""
        sv, sc, rec = self.solver, self.scene, self.rec
        tri, dist, bu, bv = sv.tracer.first_hit(origin, w)
        L = np.zeros((len(w), 3))
        near = np.zeros(len(w), bool)
        hit = np.nonzero(tri >= 0)[0]
        if len(hit):
            ts = sc.seen_tside(tri[hit], w[hit])
            bary = np.stack([1 - bu[hit] - bv[hit], bu[hit], bv[hit]], axis=1)
            e_hit = rec.at(self.vert, ts, bary)
            if self.vert_indirect is not None:
                c = np.nonzero(dist[hit] < self.near * self.hit_size[tri[hit]])[0]
                if len(c):
                    h, shadow_rays = hit[c], sv.direct.rays
                    near[h] = True
                    at_hit = origin[h] + w[h] * dist[h, None]
                    e_ind = self._bounced(at_hit, sc.tside_normal[ts[c]], rng) if self.bounce else \
                        rec.at(self.vert_indirect, ts[c], bary[c])
                    e_hit[c] = e_ind + sv.direct.irradiance(at_hit, sc.tside_normal[ts[c]], rng,
                                                            self.near_light_samples,
                                                            penumbra_samples=self.near_penumbra_samples,
                                                            receivers=sc.link_groups(tri[h]), clamp=False)
                    self.near_hits += len(h)
                    self.near_shadow_rays += sv.direct.rays - shadow_rays
            L[hit] = sv.radiance(sc.tside_side[ts], -w[hit], diffuse_incoming=e_hit, first_shot_emission=False,
                                 glossy_iterate=False, first_shot_glossy=self.first_shot_glossy)
            L[hit] += self.glossy_reflected(origin[hit] + w[hit] * dist[hit, None], ts, -w[hit], rng)
        if self.world and sc.world.emits:
            L[tri < 0] = sc.world.radiance(w[tri < 0])
        return L, near

    def near_cost(self):
        """What a ray that lands near costs beyond a plain one, in rays: the shadow rays its hit's
        light samples traced, on average so far (0 before any near hit).  Counted, not timed: a
        run of given iterations stays reproducible."""
        return self.near_shadow_rays / self.near_hits if self.near_hits else 0.0

    def _bounced(self, points, normals, rng):
        """E_ind (N, 3) [W/m^2] at ``points`` (N, 3) with unit ``normals`` by one cosine-distributed
        ray each, reading at its hit what the solution's patches send, as :meth:`glossy_reflected`
        reads its hits (their first-shot emission left out: the caller samples the lights at the
        points; a glossy lobe as if it spread its light evenly)."""
        sv, sc = self.solver, self.scene
        t, b = frames_from_normals(normals)
        w = cosine_directions(rng.random((len(points), 2)), t, b, normals)
        tri, dist, bu, bv = sv.tracer.first_hit(points + normals * sv.tracer.eps, w)
        L = np.zeros((len(points), 3))
        hit = np.nonzero(tri >= 0)[0]
        if len(hit):
            ts = sc.seen_tside(tri[hit], w[hit])
            bary = np.stack([1 - bu[hit] - bv[hit], bu[hit], bv[hit]], axis=1)
            L[hit] = sv.radiance(sc.tside_side[ts], -w[hit], diffuse_incoming=self.rec.at(self.vert, ts, bary),
                                 first_shot_emission=False, glossy_as_diffuse=True)
        if self.world and sc.world.emits:
            L[tri < 0] = sc.world.radiance(w[tri < 0])
        return np.pi * L

    def glossy_reflected(self, points, tside, w_out, rng):
        """What the glossy lobes of the sides ``tside`` (N,) at ``points`` (N, 3) reflect
        towards ``w_out`` (N, 3) of the light the solution carries [W m^-2 sr^-1] (N, 3),
        by one lobe-sampled ray each: ``weight * L(next hit)``, with ``L`` the next hit's
        diffuse part from the vertex values and its own glossy lobe spread evenly
        (``glossy_as_diffuse``), first-shot emission left out (``E1_l f_g`` at the
        glossy side counts it).  Zero at sides without a glossy lobe or seen from behind.

        The iterate's ``E f_g(t, w_out)`` would be the plain choice, but a gather reads it
        once, from one direction ``t``: a sharp lobe lined up with ``t`` makes single
        gather rays hundreds of times too bright, and unlike the image's per-iteration
        terms nothing averages them."""
        sv, sc = self.solver, self.scene
        out = np.zeros((len(points), 3))
        mat = sc.triangle_material[sc.tside_triangle[tside]]
        n = sc.tside_normal[tside]
        g = np.nonzero(sc.materials.is_glossy[mat] & (np.einsum("ij,ij->i", n, w_out) > 0))[0]
        if len(g) == 0:
            return out
        w_i, weight = sc.materials.sample_glossy(mat[g], n[g], w_out[g], rng.random((len(g), 2)))
        keep = np.any(weight > 0, axis=1)
        live, w_i, weight = g[keep], w_i[keep], weight[keep]
        tri, dist, bu, bv = sv.tracer.first_hit(points[live] + n[live] * sv.tracer.eps, w_i)
        hit = np.nonzero(tri >= 0)[0]
        if len(hit):
            ts = sc.seen_tside(tri[hit], w_i[hit])
            bary = np.stack([1 - bu[hit] - bv[hit], bu[hit], bv[hit]], axis=1)
            L = sv.radiance(sc.tside_side[ts], -w_i[hit], diffuse_incoming=self.rec.at(self.vert, ts, bary),
                            first_shot_emission=False, glossy_as_diffuse=True)
            out[live[hit]] = weight[hit] * L
        if sc.world.emits:
            miss = np.nonzero(tri < 0)[0]
            out[live[miss]] = weight[miss] * sc.world.radiance(w_i[miss])
        return out


#: :func:`near_edge_tsides`' probe rays per triangle side
PROBES = 32


def near_edge_tsides(scene, tracer, rng, tsides=None, probes=PROBES, reach=1.0, chunk=1 << 16):
    """(N,) bool for triangle sides ``tsides`` (N,) (default: all): sides where the patch
    values are not to be trusted, because something else lies within ``reach`` patch sizes
    above them (a concave edge, a contact, an object close by): any of ``probes`` (one count,
    or (N,) per side) cosine-distributed rays from uniformly random points of the side meets
    a surface within that distance.  Sides that reflect no diffuse light are never flagged.
    Traced about ``chunk`` rays at a time (a ray's temporaries are a few hundred bytes): an image
    asks only for the sides its pixels see, whatever the scene's size."""
    tsides = np.arange(len(scene.tside_triangle)) if tsides is None else np.asarray(tsides, np.int64)
    counts = np.broadcast_to(np.asarray(probes, np.int64), len(tsides))
    kd = scene.materials.diffuse_reflectance[scene.triangle_material[scene.tside_triangle[tsides]]]
    todo = np.nonzero(np.any(kd > 0, axis=1) & (counts > 0))[0]
    flag = np.zeros(len(tsides), bool)
    rays = np.cumsum(counts[todo])
    lo = 0
    while lo < len(todo):
        hi = max(lo + 1, int(np.searchsorted(rays, (rays[lo - 1] if lo else 0) + chunk, side="right")))
        sel = todo[lo:hi]
        own = np.repeat(np.arange(len(sel)), counts[sel])                   # each ray's side in sel
        ts = tsides[sel][own]
        tri = scene.tside_triangle[ts]
        blocked = near_surface(tracer, scene.triangle_corners[tri], scene.tside_normal[ts],
                               reach * np.sqrt(scene.patch_area[scene.triangle_patch[tri]]), rng)
        flag[sel] = np.bincount(own, blocked, minlength=len(sel)) > 0
        lo = hi
    return flag


class EdgeGather:
    """A renderer's final gather where patch values are not to be trusted: the sides
    (patches) one of whose triangle sides lies next to a concave edge or a contact
    (:func:`near_edge_tsides`, each side probed once, when a pixel first sees it), the
    pixels an automatic gather would serve, and how many rays per pixel a budget of seconds
    buys (the cost per ray measured on a few of them); ``points`` counts the points gathered."""

    #: the fewest automatic gather rays per pixel (more where the bias they would remove is
    #: small against their noise: :meth:`automatic_rays`)
    MIN_GATHER_RAYS = 32
    #: how many times ``v / b^2`` rays the gather needs to pay (:meth:`automatic_rays`).  The
    #: gather's rays are stratified, so its noise falls faster than ``v / n``, and a probe's
    #: rays miss the rare bright ones, so ``v`` comes out low: the two about cancel
    NOISE_MARGIN = 1.0
    #: the probe: up to this many points on flagged sides, this many gather rays each (16 rays
    #: left the estimate of ``b^2``, a difference of two near numbers, so noisy that ``v / b^2``
    #: spread from 48 to inf on ``cornell`` and from 35 to 161 in the dining room)
    PROBE_POINTS, PROBE_RAYS = 512, 64

    def __init__(self, scene, tracer, seed):
        self.scene, self.tracer, self.seed = scene, tracer, seed
        self._flags = np.full(scene.n_sides, -1, np.int8)      # per side; -1: not probed yet
        self._by_area = None
        self.rng = stream(seed, Stream.EDGE_GATHER)
        self.points = 0
        self.last_needed = None                   # rays per pixel the last automatic gather needed

    def near_edge(self, tsides):
        """(N,) bool: the side of each of ``tsides`` (N,) has a triangle side that
        :func:`~raybundle.imaging.gather.near_edge_tsides` flags; each side is probed once, when
        a pixel first sees it: the triangle sides seen with :data:`PROBES` rays each, its other
        triangle sides with :data:`PROBES` rays in all, shared by area
        (:meth:`~raybundle.scene.model.PatchScene.tside_samples`).  A patch's value (a cluster's linear
        fit) averages what an edge does to its triangles beside the edge, so it is wrong on its
        triangles away from the edge too (docs/benchmarks.md, 'Measured choices')."""
        sc, known = self.scene, self._flags
        side = sc.tside_side[tsides]
        new = np.unique(side[known[side] < 0])
        if len(new):
            probe = np.nonzero(np.isin(sc.tside_side, new))[0]
            if self._by_area is None:
                self._by_area = sc.tside_samples(PROBES)
            count = np.where(np.isin(probe, tsides), PROBES, self._by_area[probe])
            hit = np.zeros(sc.n_sides, bool)
            hit[sc.tside_side[probe[near_edge_tsides(sc, self.tracer, self.rng, probe, probes=count)]]] = True
            known[new] = hit[new]
        return known[side] > 0

    def flagged(self, g):
        """(F,) the pixels of G-buffer ``g`` whose front-facing point lies on a side
        :meth:`near_edge` flags: the points an automatic gather would serve."""
        h = g.front(self.scene)
        return h[self.near_edge(g.tside[h])]

    def affordable(self, g, final_time):
        """Whether the automatic gather has a budget (``final_time``) and points to spend
        it on: checked before the gather's vertex values are made, which on millions of
        triangles take seconds."""
        return bool(final_time) and len(self.flagged(g)) > 0

    def automatic_rays(self, final, g, k, final_time, patch_values=None):
        """Gather rays per sub-pixel sample that ``final_time`` buy for ``k`` sub-pixel
        samples, or 0 where the gather would not pay.  Measured on up to :data:`PROBE_POINTS`
        (512) of ``g``'s points on flagged sides, one gather ray at a time, :data:`PROBE_RAYS`
        (64) each: the cost per ray (and the count
        of such points gives the rays per pixel), each point's variance per ray ``v`` and, from
        ``patch_values(tsides, bary)`` (N, 3) (what the image reads there without the gather),
        its bias ``b^2 = (mean - patch value)^2 - v / R`` (R the probe's rays), in luminance,
        averaged over the points before it is clipped at 0 (clipped point by point, the noise
        of the R-ray mean came out as bias).  With ``n`` rays the gather's error is about ``v / n`` against ``b^2``
        without it: it runs only if ``n`` is above :data:`NOISE_MARGIN` ``mean v / mean b^2`` (and
        :data:`MIN_GATHER_RAYS`).  A box whose patches follow the light well needs a hundred
        rays and more; a real room, where patches average thin detail next to windows, pays at
        a few dozen."""
        f = self.flagged(g)
        if len(f) == 0:
            return 0
        probe, probe_rays = f[:: max(1, len(f) // self.PROBE_POINTS)], self.PROBE_RAYS
        rep = np.repeat(probe, probe_rays)
        ts, bary = g.tside[rep], g.bary[rep]
        t0 = time.perf_counter()
        one = final.irradiance(g.point[rep], self.scene.tside_normal[ts], 1, stream(self.seed, Stream.EDGE_GATHER_PROBE),
                               at=(ts, bary)).sum(axis=1).reshape(len(probe), probe_rays)
        cost = (time.perf_counter() - t0) / (len(probe) * probe_rays)          # seconds per ray and point
        left = final_time - (time.perf_counter() - t0)
        per_pixel = left / (cost * len(f))
        needed = self.MIN_GATHER_RAYS
        if patch_values is not None:
            var = one.var(axis=1, ddof=1)
            patch = patch_values(g.tside[probe], g.bary[probe]).sum(axis=1)
            bias2 = max(((one.mean(axis=1) - patch) ** 2 - var / probe_rays).mean(), 0.0)
            needed = max(needed, self.NOISE_MARGIN * var.mean() / bias2 if bias2 > 0 else np.inf)
        self.last_needed = needed
        return self.rays_bought(per_pixel, needed, k)

    @staticmethod
    def rays_bought(per_pixel, needed, k):
        """Gather rays per sub-pixel sample for ``k`` samples when a budget buys ``per_pixel``
        rays per pixel and the gather pays from ``needed`` rays on: 0 below that."""
        if per_pixel < needed:
            return 0
        return int(min(per_pixel, 65536) // k)
