"""Glossy eye paths: the glossy lobe the eye sees, by lobe-sampled rays read from the solution.

At a pixel whose visible point is glossy, one eye path per image pass samples ``w_i`` from
the glossy lobes and takes the outgoing radiance of the surface it reaches from the solver
(running-average diffuse part, first shot, and either the current iterate ``E f(t, w)`` or,
for up to ``glossy_gather_depth`` glossy bounces, one more lobe-sampled ray); the mesh lights
the lobe reflects are shared with the light samples by multiple importance sampling
(power heuristic) when ``glossy_mis`` is on, and so is the world where it changes with
direction: at the visible point one world sample per path (by brightness, guided by what the
bundles brought each side from the sky: :class:`~raybundle.lights.world_light.WorldLight`)
shares the sky the lobe reflects with the path's first ray if it leaves the scene.  A path
that meets glass passes straight on or is mirrored by its interface, as the eye's own path is
(:meth:`GlossyEyePaths.trace`).  Radiance in [W m^-2 sr^-1].
"""
from __future__ import annotations

import numpy as np

from ..lights.direct import DirectLighting
from ..lights.reflected_direct import reflected_radiance
from ..scene.transmission import mirror_probability, pass_probability, scatter, solver_share


class GlossyEyePaths:
    """The glossy eye paths of a renderer: its scene, solver, direct lighting, tracer,
    settings and random numbers (shared with the renderer, whose draws they interleave);
    ``surface_values`` reads side values at hit points; ``rays`` counts the rays traced."""

    def __init__(self, scene, solver, direct, tracer, settings, rng, surface_values, world_light=None):
        self.scene, self.solver, self.direct, self.tracer = scene, solver, direct, tracer
        self.settings, self.rng, self.surface_values = settings, rng, surface_values
        # light samples and the lobe's own ray share the mesh lights (MIS)
        self.light_mis = bool(settings.glossy_gather and settings.glossy_mis)
        # ... and so do world samples (``world_light``, a world that changes with direction) and
        # the lobe's rays that leave the scene
        self.world_light = world_light if self.light_mis else None
        #: per material, the mean share of the rays its surface stops (1 where nothing passes)
        self._kept = solver_share(scene.materials)[0]
        self._vert = None           # the last side values and their vertex values (_vertex_values)
        self.rays = 0

    def gather(self, g, idx, u, world_samples=0, guide=None):
        """Glossy lobe at pixels ``idx`` by one eye path each (the remedy for sharp lobes).

        Sample ``w_i`` from the glossy lobes (GGX around the mirror of the eye
        direction, :meth:`~raybundle.scene.materials.MaterialTable.sample_glossy`),
        trace it to the surface it sees, and take that surface's outgoing
        radiance from the solver: running-average diffuse part interpolated at
        the hit, first shot, and, for its own glossy lobe, either the current
        iterate ``E f(t, w)`` or, while fewer than ``glossy_gather_depth`` glossy
        bounces were traced, one more lobe-sampled ray (the per-iteration term is
        what makes glossy-to-glossy paths spiky).  Direct light of the first-shot
        lights is left out of what the rays see: :func:`~raybundle.lights.reflected_direct.reflected_radiance`
        and the first shot count it.  ``u`` (len(idx), 2): uniforms for the first
        lobe sample.  ``world_samples`` K > 0: the caller took K world samples for these lobes
        (:meth:`WorldLight.irradiance` with ``lobe``), weighted against the path's first ray with
        the counts, so the path takes none of its own and weights the sky it meets
        ``p_g^2 / (p_g^2 + (K p_w)^2)``; ``guide``: the ``(guide, at)`` they were drawn by
        (:meth:`WorldLight.guide_at`; None: the sides' guide now).  Returns ``(light, solved)``, (len(idx), 3) each: what
        the paths took from the lamps and the world (:meth:`trace`), which does not depend on the
        solver's iterations, and what they read from the solver.

        The pixels are split into pieces run in parallel, each with random numbers of its own
        (:meth:`~raybundle.tracing.visibility.RayTracer.map_pieces`).
        """
        sc, solver = self.scene, self.solver
        e = solver.received()
        vert = self._vertex_values(e) if self.settings.smooth and len(idx) else None
        if self.world_light is not None and guide is None and len(idx):
            guide = self.world_light.guide_at(solver.world_guide, sc.tside_side[g.tside[idx]])

        def piece(paths, a, b):
            part = None if guide is None else (guide[0], guide[1][a:b])
            return paths._gather(g, idx[a:b], u[a:b], e, vert, world_samples, part)

        parts = self.tracer.map_pieces_of(self, piece, len(idx), self.rng)
        return tuple(np.concatenate([p[c] for p in parts]) for c in (0, 1))

    def _vertex_values(self, e):
        """The solver's vertex values of the side values ``e`` in 32 bits, kept while ``e`` stays
        the same (a pass gathers its own samples and its extra ones from the same solution)."""
        if self._vert is None or not np.array_equal(self._vert[0], e):
            self._vert = None                     # the old values go before the new are made
            self._vert = (e, self.solver.reconstruction.averaged(e, dtype=np.float32))
        return self._vert[1]

    def _gather(self, g, idx, u, e, vert, world_samples, guide):
        """:meth:`gather` at the pixels ``idx`` of one piece, with the side values ``e``, their
        vertex values ``vert`` and the ``(guide, at)`` of those pixels (None without world
        samples)."""
        sc = self.scene
        m, n, wo = g.material[idx], g.normal[idx], g.w_eye[idx]
        w_i, weight = sc.materials.sample_glossy(m, n, wo, u)
        if self.world_light is None or len(idx) == 0:
            return self.trace(g.point[idx], n, w_i, weight, e, vert, light_mis=(m, wo) if self.light_mis else None,
                              groups=sc.link_groups(g.triangle[idx]))
        guide, at = guide
        world_mis = (max(world_samples, 1) * self.world_light.density(w_i, guide, at),
                     sc.materials.glossy_pdf(m, n, w_i, wo))
        light, solved = self.trace(g.point[idx], n, w_i, weight, e, vert, light_mis=(m, wo), world_mis=world_mis,
                                   groups=sc.link_groups(g.triangle[idx]))
        if world_samples > 0:
            return light, solved
        return light + self.world_samples(g.point[idx], n, m, wo, guide, at), solved

    def world_samples(self, pts, n, m, wo, guide=None, at=None):
        """The sky the glossy lobes of materials ``m`` (N,) at ``pts`` (N, 3) (normals ``n``,
        viewer ``wo``) reflect, one world sample each (:meth:`WorldLight.sample`, ``guide`` for
        points on sides ``at``): ``L_w f_g(w, wo) cos / p_w``, weighted ``p_w^2 / (p_w^2 + p_g^2)``
        against the lobe's own ray (p_g :meth:`~raybundle.scene.materials.MaterialTable.glossy_pdf`),
        which :meth:`trace` weights the other way (N, 3)."""
        mats = self.scene.materials
        d, p_w, L = self.world_light.sample(self.rng.random((len(pts), 3)), guide, at)
        cos = np.einsum("ij,ij->i", n, d)
        out = np.zeros((len(pts), 3))
        live = np.nonzero((cos > 0) & (p_w > 0))[0]
        if len(live) == 0:
            return out
        f = mats.brdf(m[live], n[live], -d[live], wo[live], diffuse=False)
        go = np.any(f > 0, axis=1) & np.any(L[live] > 0, axis=1)
        live, f = live[go], f[go]
        blocked = self.tracer.occluded(pts[live] + n[live] * self.tracer.eps, d[live],
                                       np.full(len(live), self.world_light.far))
        self.rays += len(live)
        ok, f = live[~blocked], f[~blocked]
        w = DirectLighting.mis_weight(p_w[ok], mats.glossy_pdf(m[ok], n[ok], d[ok], wo[ok]))
        out[ok] = L[ok] * f * (cos[ok] / p_w[ok] * w)[:, None]
        return out

    def trace(self, pts, n, w_i, throughput, e, vert, light_mis=None, world_mis=None, groups=None):
        """Radiance (N, 3) arriving at ``pts`` (N, 3) with normals ``n`` along ``w_i`` (N, 3), times
        ``throughput`` (N, 3), as ``(light, solved)`` (N, 3) each: the lamps and the world the paths
        meet, and what they read from the solver where each ray lands (:meth:`gather`): the hit's
        outgoing radiance from the side values ``e`` (S, 3) (the diffuse lobe's incoming radiance,
        interpolated with the vertex values ``vert`` or flat when None); at glossy hits the path
        goes on along the hit's glossy lobe, up to ``glossy_gather_depth`` rays in all.  With
        ``light_mis = (materials, w_out)`` of the glossy lobes the rays were drawn from, rays that
        meet a first-shot mesh light or an area lamp add its emission, MIS-weighted against the
        light samples (:meth:`_lamps_met`); with ``world_mis = (p_w, p_g)`` (N,) each, those that
        leave the scene see the world MIS-weighted (:meth:`_world_seen`; :meth:`world_samples`
        takes the rest).  A transmissive surface's interface is followed as a mirror
        (:meth:`_interfaces`) while the path has rays left; at the last ray its patch stands in,
        less what it would throw as a caustic (:meth:`_opaque_rest`).  ``groups`` (N,) or None:
        the link groups of ``pts`` (:mod:`raybundle.scene.linking`)."""
        sc, mats, solver = self.scene, self.scene.materials, self.solver
        out = np.zeros((len(pts), 3))
        light = np.zeros((len(pts), 3))
        pix = np.arange(len(pts))                     # which output row each path belongs to
        m = wo = None
        mirrored = np.zeros(len(pts), bool)          # the path's last turn was a glass interface's mirror
        depth = max(1, int(self.settings.glossy_gather_depth))
        for bounce in range(depth):
            if len(pix) == 0:
                break
            if bounce:                                # the mirrored ones have their direction already
                self._along_lobes(np.nonzero(~mirrored)[0], w_i, throughput, m, n, wo)
            live = np.nonzero(np.any(throughput > 0, axis=1))[0]
            tri, t, bu, bv = self.tracer.first_hit(pts[live] + n[live] * self.tracer.eps, w_i[live])
            self.rays += len(live)
            hit = tri >= 0
            if light_mis is not None and len(live):      # the lobe's ray meets a lamp (MIS)
                m_from, wo_from = (light_mis[0], light_mis[1]) if bounce == 0 else (m, wo)
                le = self._lamps_met(pts[live], n[live], m_from[live], wo_from[live], w_i[live], tri, t,
                                     mirrored[live] if bounce else None, None if groups is None else groups[live])
                np.add.at(light, pix[live], throughput[live] * le)
            if sc.world.emits:      # paths that leave the scene see the world
                gone = live[~hit]
                mis = None if world_mis is None or bounce else (world_mis[0][gone], world_mis[1][gone])
                np.add.at(light, pix[gone], throughput[gone] * self._world_seen(w_i[gone], mis))
            live, tri, t = live[hit], tri[hit], t[hit]
            bary = np.stack([1 - bu - bv, bu, bv], axis=1)[hit]
            patch, e_hit, hit_m, hit_n, w_back = self._hits(e, vert, tri, bary, w_i[live])
            go_on = (mats.is_glossy[hit_m] & (np.einsum("ij,ij->i", hit_n, w_back) > 0)
                     if bounce + 1 < depth else np.zeros(len(live), bool))
            L = solver.radiance(patch, w_back, diffuse_incoming=e_hit, first_shot_emission=False,
                                glossy_iterate=False, first_shot_glossy=light_mis is None, sharp_interfaces=True)
            turn, scale = np.zeros(len(live), bool), None
            if self.tracer.glass is not None and bounce + 1 < depth:
                turn, turn_dir, turn_w, scale = self._interfaces(tri, hit_n, w_i[live], w_back)
                go_on &= ~turn
            gi = np.nonzero(go_on)[0]
            if light_mis is not None and len(gi):
                # the lamps in the glossy lobe of a hit the path goes on from: light samples, MIS-weighted
                # against the next ray (E1 f(w_mean, w) spiked where a sharp lobe lined up with w_mean)
                lit = self._lamps_in_lobe(pts[live[gi]] + t[gi, None] * w_i[live[gi]], hit_n[gi], hit_m[gi],
                                          w_back[gi], tri[gi])
                if scale is not None:
                    lit *= scale[gi, None]
                np.add.at(light, pix[live[gi]], throughput[live[gi]] * lit)
            # paths that end here use the iterate for the hit's own glossy lobe, spread evenly once a
            # lobe has been followed
            stop = np.nonzero(~go_on & ~turn)[0]
            if len(stop):
                L[stop] = solver.radiance(patch[stop], w_back[stop], diffuse_incoming=e_hit[stop],
                                          first_shot_emission=False, glossy_as_diffuse=bounce > 0, sharp_interfaces=True)
            throughput = throughput[live]
            if scale is not None:         # the opaque rest of a transmissive surface, less its interface
                self._opaque_rest(L, throughput, self.tracer.glass[tri] & ~turn, e_hit, patch, scale)
            L[turn] = 0.0
            np.add.at(out, pix[live], throughput * L)
            pts = pts[live] + t[:, None] * w_i[live]
            w_i = w_i[live]
            if turn.any():
                w_i[turn], throughput[turn] = turn_dir, throughput[turn] * turn_w
            keep = np.nonzero(go_on | turn)[0]
            pix, m, n, wo = pix[live][keep], hit_m[keep], hit_n[keep], w_back[keep]
            pts, throughput, w_i, mirrored = pts[keep], throughput[keep], w_i[keep], turn[keep]
            groups = None if groups is None else sc.link_groups(tri[keep])
        return light, out

    def _along_lobes(self, lobe, w_i, throughput, m, n, wo):
        """The paths ``lobe`` go on along their glossy lobe: a new ``w_i``, ``throughput`` times the
        sample's weight; in place."""
        w_i[lobe], weight = self.scene.materials.sample_glossy(m[lobe], n[lobe], wo[lobe],
                                                               self.rng.random((len(lobe), 2)))
        throughput[lobe] *= weight

    def _hits(self, e, vert, tri, bary, w):
        """``(side, e, material, normal, w_back)`` at the hits of rays ``w`` on triangles ``tri``
        (barycentric ``bary``): the side seen, its interpolated diffuse incoming radiance from
        ``e`` and ``vert`` (:meth:`surface_values`), the material, the normal, the way back."""
        sc = self.scene
        ts = sc.seen_tside(tri, w)
        return (sc.tside_side[ts], self.surface_values(e, vert, ts, bary), sc.triangle_material[tri],
                sc.tside_normal[ts], -w)

    def _lamps_met(self, p, n, m, wo, w, tri, t, mirrored, receivers):
        """The emission (N, 3) of the first-shot mesh lights and area lamps that lobe-sampled rays
        ``w`` from points ``p`` meet (triangle ``tri``, distance ``t``), MIS-weighted against the
        light samples (:meth:`~raybundle.lights.direct.DirectLighting.lobe_hits_light`)."""
        hit = tri >= 0
        return self.direct.lobe_hits_light(p, m, n, wo, w, tri, p + np.where(hit, t, 0.0)[:, None] * w,
                                           self.settings.light_samples, distance=np.where(hit, t, np.inf),
                                           mirrored=mirrored, receivers=receivers)

    def _world_seen(self, w, mis):
        """The world's radiance (N, 3) along rays ``w`` that leave the scene, weighted
        ``p_g^2 / (p_g^2 + p_w^2)`` against the world's samples when ``mis = (p_w, p_g)``."""
        seen = self.scene.world.radiance(w)
        if mis is not None:
            seen *= DirectLighting.mis_weight(mis[1], mis[0])[:, None]
        return seen

    def _lamps_in_lobe(self, p, n, m, w_out, tri):
        """The lamps' light (N, 3) reflected towards ``w_out`` by the glossy lobe alone at points
        ``p`` on triangles ``tri``, MIS-weighted against the lobe's next ray."""
        return reflected_radiance(self.direct, p, n, m, w_out, self.rng, self.settings.light_samples,
                                  mis=np.ones(len(p), bool), diffuse_scale=np.zeros((len(p), 3)),
                                  receivers=self.scene.link_groups(tri))

    def _opaque_rest(self, L, throughput, rest, e_hit, patch, scale):
        """At the hits ``rest`` (bool) on transmissive surfaces not followed through their
        interface: the patch's radiance ``L`` less what the interface reflects (its first and
        caustic shots left out), and the ``throughput`` times the opaque share ``scale``; in place."""
        solver = self.solver
        rest = np.nonzero(rest)[0]
        e_mirror = e_hit[rest] - solver.sharp_incoming(patch[rest])
        L[rest] = np.maximum(L[rest] - solver.mirror_over_pi[patch[rest]] * e_mirror, 0.0)
        throughput[rest] *= scale[rest, None]

    def _interfaces(self, tri, normal, travel, w_back):
        """Where the paths' rays met (and stopped on, :meth:`~raybundle.tracing.visibility.
        RayTracer.first_hit`) a transmissive surface (triangles ``tri`` (N,), seen side's
        ``normal``, along ``travel``, back ``w_back``, (N, 3) each): its interface's mirror.  A
        hit that does not pass is the interface's reflection with probability
        ``r = w_t F / (1 - P)`` (:func:`~raybundle.scene.transmission.mirror_probability`, ``P``
        :func:`~raybundle.scene.transmission.pass_probability`): the path goes on mirrored, as
        the eye's path does (:func:`~raybundle.scene.transmission.scatter`, weighted by the
        reflection tint), where the patch would spread the light its interface reflects over the
        hemisphere (a lamp-lit pane glowing in a floor's reflection).  Otherwise it ends on the
        opaque rest, whose radiance the caller weights by ``scale`` = ``kept / (1 - P - w_t F)``
        (``kept`` the patch's mean share of stopped rays,
        :func:`~raybundle.scene.transmission.solver_share`: the patch's reflectance is over it),
        so that both branches together are unbiased.  A rough interface reflects about a visible
        microfacet normal, chosen with the smooth interface's ``F``.  Returns ``(turn (N,) bool,
        directions (T, 3), weights (T, 3), scale (N,))``, ``scale`` 1 off transmissive surfaces
        (None where no ray met one)."""
        sc, mats = self.scene, self.scene.materials
        turn, scale = np.zeros(len(tri), bool), np.ones(len(tri))
        g = np.nonzero(self.tracer.glass[tri])[0]
        if len(g) == 0:
            return turn, np.zeros((0, 3)), np.zeros((0, 3)), None
        mg = sc.triangle_material[tri[g]]
        cos = np.einsum("ij,ij->i", normal[g], w_back[g])
        kept = 1.0 - pass_probability(mats, mg, cos)
        a = mirror_probability(mats, mg, cos)
        go = self.rng.random(len(g)) * kept < a
        turn[g[go]] = True
        left = kept[~go] - a[~go]
        scale[g[~go]] = np.where(left > 1e-9, self._kept[mg[~go]] / np.maximum(left, 1e-9), 0.0)
        t = g[go]
        u = np.zeros((len(t), 4))
        u[:, 2:] = self.rng.random((len(t), 2))         # u0 = u1 = 0: on the interface, reflected
        _, d, w = scatter(mats, sc.triangle_material[tri[t]], travel[t], sc.triangle_normal[tri[t]], normal[t], u)
        return turn, d, w, scale
