"""The patch solution that every patch method shares, and the bundles' transfer.

Every patch method (:class:`PatchSolution`'s subclasses) has the same interface, so the CLI, the add-on and the bench can
drive any of them by name (:data:`raybundle.methods.registry.SOLVERS`): ``step()`` performs one iteration,
``incoming`` / ``receive_direction`` describe the current iterate,
``mean_incoming`` the running average, and ``stats`` counts the work.

The transfer along bundle lines (:meth:`PatchSolution.transfer`), its equations, parameters
and failure modes are those of stochastic iteration (:mod:`raybundle.methods.stochastic_iteration`),
which every iterating method applies; sides much smaller than a bundle cell gather their light by
rays of their own instead (:meth:`PatchSolution._gather_tiny`).
"""
from __future__ import annotations

import abc

import numpy as np

from ..lights.caustics import CausticShot
from ..lights.first_shot import PatchFirstShot
from ..lights.world_light import SideSums, guide_cell
from ..patches.reconstruction import LinearReconstruction
from ..patches.side_points import SidePoints
from ..scene.transmission import solver_share
from ..tracing.sampling import (Stream, cosine_directions, frames_from_normals, make_sequence, stream,
                                uniform_sphere, uniform_sphere_pdf)
from . import gather_rays
from .base import Method, SolverStats
from .control_variate import controlled


class PatchSolution(Method, abc.ABC):
    """The abstract base of the patch methods: the solution per patch side, its first shot and
    caustic shot, its running averages, what it sends along bundle lines (:meth:`transfer`) and
    what the images and bakes read from it.  Each method defines :meth:`step`."""
    #: the fewest iterations left out of the running average (``burn_in``, set per scene)
    BURN_IN = 8
    #: its step can keep the running average of the light straight from the world apart (:attr:`world_direct`)
    SEPARATES_WORLD_DIRECT = True
    #: sides smaller than a bundle cell / TINY_SIDE gather their incoming light (:meth:`_gather_tiny`)
    #: and send their running average (:meth:`step`)
    TINY_SIDE = 16.0
    #: rays a tiny side gathers by per iteration (0: none, the bundles' estimate stays)
    TINY_GATHER_RAYS = 4
    #: the glossy sides' send rays traced in one batch, at most (several bundle directions at once):
    #: a batch's temporaries (its rays' hits and the radiance they read) are a few hundred bytes a ray
    GLOSSY_SEND_BATCH = 1 << 16

    #: it takes the first shot's glossy reflection by lobe-sampled rays (``settings.caustics``)
    TAKES_CAUSTIC_SHOT = True

    def __init__(self, scene, tracer, direct, settings, camera=None):
        """Every method's constructor (:class:`~raybundle.methods.base.Method`): the prepared
        ``scene``, its ``tracer``, its first-shot lights ``direct`` and the
        :class:`~raybundle.imaging.settings.RenderSettings` (validated); a patch method needs no
        ``camera``."""
        settings.validate()
        self.scene = scene
        self.tracer = tracer
        self.direct = direct
        self.seed = int(settings.seed)
        self.sequence = make_sequence(settings.sequence, settings.seed)
        self.bundle_resolution = int(settings.bundle_resolution) or auto_bundle_resolution(scene)
        self.directions_per_step = int(settings.directions_per_step)
        self.glossy_send_rays = int(settings.glossy_send_rays)
        open_area = self._set_sides(scene, tracer, settings.seed)
        self._set_glossy_sides(scene.materials, self.patch_material)
        self._set_shots(scene, tracer, direct, settings.seed, open_area, settings.caustics and self.TAKES_CAUSTIC_SHOT)
        self._set_iterate()

    def _set_sides(self, scene, tracer, seed):
        """The sides' materials, normals, receiving areas (less what solids bury, cut-outs and
        glass do not keep) and diffuse reflectance; returns the sides' open area, which the
        first shot averages over."""
        mats = scene.materials
        # the unknowns are patch sides: normals, materials and areas are per side
        pm = scene.side_material
        self.patch_material = pm
        self.normal = scene.side_normal
        # receiving area: the side's area less what is buried inside solids, times a cut-out's
        # coverage (the light a cut-out patch receives lands on its covered part only)
        self.tside_open_area = tracer.open_fraction() * scene.triangle_area[scene.tside_triangle]
        # the first shot averages the irradiance at points of the surface itself (a cut-out's
        # holes take no samples): its sides' area is the open one, without the coverage
        open_area = np.bincount(scene.tside_side, self.tside_open_area, minlength=scene.n_sides)
        if tracer.cutouts is not None:
            cover = tracer.cutouts.triangle_coverage(scene, seed)[scene.tside_triangle]
            self.tside_open_area *= np.maximum(cover, 1e-6)      # a side cut out everywhere receives nothing
        kd = mats.diffuse_reflectance
        #: (S, 3) or None: kd / pi of the light a transmissive side's interface reflects, which
        #: leaves out the first shot's (a caustic: :mod:`raybundle.scene.transmission`)
        self.mirror_over_pi = None
        if tracer.glass is not None:          # glass: the rays it does not let through, as a cut-out's
            kept, kd, mirror = solver_share(mats)
            self.tside_open_area *= kept[scene.triangle_material[scene.tside_triangle]]
            self.mirror_over_pi = mirror[pm] / np.pi
            #: (S,) bool: the sides whose interface reflects (``mirror_over_pi`` > 0)
            self.transmissive_side = np.any(self.mirror_over_pi > 0, axis=1)
        self.area = np.bincount(scene.tside_side, self.tside_open_area, minlength=scene.n_sides)
        #: (S,) the sides' whole areas, and (S,) bool the sides open all over (nothing of them buried,
        #: cut out or glass): those the control variate serves (:mod:`.control_variate`)
        self.full_area = scene.patch_area[scene.side_patch]
        self.wholly_open = self.area >= self.full_area * (1.0 - 1e-9)
        self.reconstruction = LinearReconstruction(scene, self.tside_open_area)
        self.kd_over_pi = kd[pm] / np.pi          # (P, 3)
        if scene.texture is not None:         # a textured patch reflects with its mean albedo
            self.kd_over_pi = self.kd_over_pi * scene.texture.side_means(scene, seed)
        # translucent sides: kt / pi (S, 3) of the light their patch's other side receives
        self.translucent_sides = np.nonzero(np.any(mats.translucent[pm] > 0, axis=1) & (scene.side_opposite >= 0))[0]
        self.kt_over_pi = mats.translucent[pm[self.translucent_sides]] / np.pi
        return open_area

    def _set_glossy_sides(self, mats, pm):
        """The glossy sides, which of them send their lobe's light by gather rays, the mean
        albedo and the iterations left out of the running average."""
        self.glossy_mask = mats.is_glossy[pm]
        self.layered_sides = np.nonzero(mats.has_layer[pm])[0]      # diffuse lobe under a specular layer
        self.glossy_patches = np.nonzero(self.glossy_mask)[0]
        #: per glossy side: its lobe's light is sent by gather rays (a sharp or strong lobe)
        #: rather than from the iterate (:meth:`glossy_sent_radiance`)
        self.traced_lobe = self.sharp_lobes(mats, pm[self.glossy_patches])
        #: (S,) bool: the sides whose glossy lobe is traced: sent by gather rays, and followed by
        #: one more ray where a gather ray meets it (:meth:`_gather`)
        self.traced_side = np.zeros(self.scene.n_sides, bool)
        self.traced_side[self.glossy_patches[self.traced_lobe]] = True
        self._glossy_points = SidePoints(self.scene, self.traced_side)    # for glossy_sent_radiance
        gpm = pm[self.glossy_patches]
        rho_g = mats.albedo(gpm, np.full(len(gpm), 0.7), diffuse=False).max(axis=1)
        rho_d = np.pi * self.kd_over_pi[self.glossy_patches].max(axis=1)
        #: per glossy side: the chance its traced lobe is gathered along a direction
        #: (:meth:`glossy_sent_radiance`), its lobe's share of what it reflects over GATHER_SHARE
        self.gather_chance = np.clip(rho_g / np.maximum(rho_g + rho_d, 1e-12) / self.GATHER_SHARE,
                                     self.LEAST_GATHER_CHANCE, 1.0)
        self.diffuse_only = len(self.glossy_patches) == 0
        albedo = self.kd_over_pi * np.pi
        if len(self.glossy_patches):
            gpm = pm[self.glossy_patches]
            albedo[self.glossy_patches] += mats.albedo(gpm, np.full(len(gpm), 0.7), diffuse=False)
        #: the area-weighted mean of each side's largest albedo (glossy lobe at cos 0.7): the
        #: rate at which the iterates forget their start
        self.mean_albedo = float(np.clip((self.area * albedo.max(axis=1)).sum() / max(self.area.sum(), 1e-300),
                                         0.0, 0.999))
        #: iterations left out of the running average: until the start-up transient,
        #: about mean_albedo^n, is below 1% (at least BURN_IN, at most 1,000)
        self.burn_in = int(np.clip(np.ceil(np.log(0.01) / np.log(max(self.mean_albedo, 1e-3))), self.BURN_IN, 1000))
        #: iterations after which the running average restarts once (0: it never does)
        self.restart_at = self.burn_in

    def _set_shots(self, scene, tracer, direct, seed, open_area, caustics):
        """The first shot of the small lights and its caustic shot, and how many rays refine
        each per iteration."""
        # incoming first shot, refined by a few shadow rays every iteration
        self.first_shot = PatchFirstShot(direct, stream(seed, Stream.FIRST_SHOT), receiving_area=open_area,
                                         directed=self.glossy_mask)
        self.grid_rng = stream(seed, Stream.BUNDLE_GRID)
        # a sixteenth of the lit sides' worth of shadow rays per iteration (per side, not per
        # triangle: a cluster's many small triangles share one estimate)
        lit_sides = len(np.unique(scene.tside_side[self.first_shot.receiving_tsides]))
        self.first_shot_refine = max(64, lit_sides // 16) if direct.n_lights else 0
        # the first shot's glossy reflection goes by lobe-sampled rays, not by bundles
        self.caustic = CausticShot(scene, tracer, self.first_shot, self.area, stream(seed, Stream.CAUSTIC_SHOT),
                                   self.glossy_patches) if caustics else None
        if self.caustic is not None and not self.caustic.active:
            self.caustic = None
        self.caustic_refine = (max(1024, len(np.unique(scene.tside_side[self.caustic.tsides])))
                               if self.caustic is not None else 0)
        if self.caustic is not None:       # lit at set-up as the first shot is: the warm-up carries it on
            self.caustic.refine(self.caustic_refine)

    def _set_iterate(self):
        """The iterate, its running averages and the world's part of them, all zero."""
        self.world = self.scene.world
        #: the method can keep the iterates' part that came straight from the world apart
        #: (a world that changes with direction and a step that keeps that average)
        self.world_direct = self.SEPARATES_WORLD_DIRECT and self.world.emits and not self.world.is_constant
        #: it does (:meth:`separate_world`): for an image that takes the world's direct light at
        #: its visible points (:class:`~raybundle.lights.world_light.WorldLight`, ``world_samples``)
        self.separates_world = False
        n = self.scene.n_sides
        self._all_patches = np.arange(n)
        self.incoming = np.zeros((n, 3))
        self.glossy_incoming = self.incoming        # E_i(d_k) of glossy sides, received from t_i
        self.receive_direction = np.zeros((n, 3))   # t_i of the current iterate
        self.mean_incoming = np.zeros((n, 3))
        self.world_incoming = np.zeros((n, 3))      # the iterate's part straight from the world
        self.mean_world_incoming = np.zeros((n, 3))
        #: :class:`~raybundle.lights.world_light.SideSums` or None: per side, the world light the bundles
        #: brought it from each guide cell of the sky, summed over the iterations (its rows: the sides it reached)
        self.world_guide = None
        self._tiny = None                           # sides smaller than a bundle cell (set at the first step)
        self.averaged = 0                           # iterations in mean_incoming
        self.direction = None
        self.stats = SolverStats()

    # ------------------------------------------------------------------ step
    def sent_radiance(self, send_dir):
        """Radiance S_j (S, 3) that each side sends into ``send_dir`` (S, 3) [W m^-2 sr^-1]:
        the current iterate without the emission of first-shot lights (their light
        enters the iteration as the first shot)."""
        return self.radiance(self._all_patches, send_dir, first_shot_emission=False,
                             first_shot_glossy=self.caustic is None)

    #: a traced lobe that reflects less than this share of what its side reflects (a white
    #: plastic's 5% specular over its diffuse lobe) is gathered along a direction only with
    #: chance share / GATHER_SHARE (at least LEAST_GATHER_CHANCE), weighted by the inverse
    GATHER_SHARE = 0.25
    LEAST_GATHER_CHANCE = 1.0 / 16.0

    #: a glossy lobe is sent from the iterate (thesis 3.3) where its albedo (at cos 0.7) over
    #: alpha^2 is at most this, by gather rays where it is more (:meth:`sharp_lobes`)
    ITERATE_LOBE_PEAK = 2.0

    @classmethod
    def sharp_lobes(cls, mats, m):
        """(len(m),) bool: the glossy lobes of materials ``m`` whose sent radiance goes by gather
        rays.  The iterate's ``E_j f_g(t_j, s_j)`` has a tail that grows with the lobe's peak,
        about ``rho_g / (pi alpha^2)``; a weak, rough lobe (the clear coat of a varnished floor or
        panelling: rho_g 5%, alpha 0.15-0.2) has a peak below its diffuse lobe's, and its rays
        had cost most of an iteration (the interior bench's living room: 17k such sides, 32 rays
        each per iteration)."""
        m = np.asarray(m)
        rho = mats.albedo(m, np.full(len(m), 0.7), diffuse=False).max(axis=1)
        return rho > cls.ITERATE_LOBE_PEAK * mats.alpha[m] ** 2

    def glossy_sent_radiance(self, gi, send_dir):
        """Radiance (N, 3) the glossy sides ``glossy_patches[gi]`` (N,) send into ``send_dir``
        (N, 3), one row each (an iteration's directions batched together): their diffuse
        lobe from the iterate; a sharp glossy lobe (:meth:`sharp_lobes`) by the mean of
        ``glossy_send_rays`` lobe-sampled gather rays each (2 rather than 1, which measured
        ahead on ``cornell-glossy``; 4 gained nothing more: docs/benchmarks.md, 'Measured choices behind the
        defaults'), a weak rough one from the iterate, ``E_j f_g(t_j, s_j)`` (thesis 3.3).  A
        traced lobe that is a small share of what its side reflects is gathered only with the
        side's ``gather_chance`` q, its gathered part weighted 1 / q (Russian roulette: unbiased;
        a white plastic's 5% specular lobe needs its gather rays in a fifth of the directions).

        ``S_j = Le_j + W_d kd/pi (E_j + E1_j + Ec_j) + weight L(y, -w_i)`` with ``w_i`` drawn
        from side j's glossy lobe for the viewer direction ``s_j`` (``weight = f cos / pdf``,
        at most the lobe's albedo), y a uniform point of side j and ``L(x, -w_i)`` the
        radiance of the surface the ray meets there: running-average diffuse part, first
        shot (with its glossy reflection: the caustic shot leaves out light that reaches
        j's lobe), caustic and its own glossy iterate; the emission of first-shot lights is
        left out (j's first shot and caustic shot carry it).  The
        thesis' ``E_j f(t_j, s_j)`` is unbiased too, but heavy-tailed for sharp lobes: a
        random pair (t_j, s_j) rarely falls into the lobe, and then with a value ~ 1/alpha^2.
        """
        gp_k = self.glossy_patches[gi]
        fsg = self.caustic is None
        traced = self.traced_lobe[gi]
        out = np.empty((len(gp_k), 3))
        by_iterate = ~traced
        out[by_iterate] = self.radiance(gp_k[by_iterate], send_dir[by_iterate], first_shot_emission=False,
                                        first_shot_glossy=fsg)
        chance = self.gather_chance[gi][traced]
        rows = np.nonzero(traced)[0]
        gp_k, send_dir = gp_k[traced], send_dir[traced]
        out[rows] = self.radiance(gp_k, send_dir, first_shot_emission=False, first_shot_glossy=fsg,
                                  glossy_iterate=False)
        go = np.nonzero(self.grid_rng.random(len(rows)) < chance)[0]      # the lobes gathered this time
        rows, gp_k, send_dir = rows[go], gp_k[go], send_dir[go]
        sc = self.scene
        m = self.glossy_send_rays
        gp_m, send_m = np.tile(gp_k, m), np.tile(send_dir, (m, 1))
        u = self.grid_rng.random((len(gp_m), 5))
        pts, n = self._glossy_points.draw(gp_m, u[:, :3])
        w_i, weight = sc.materials.sample_glossy(self.patch_material[gp_m], n, send_m, u[:, 3:])
        live = np.nonzero(np.any(weight > 0, axis=1))[0]
        got, _ = self._gather(pts[live], n[live], w_i[live])
        gathered = np.zeros((len(gp_m), 3))
        gathered[live] = weight[live] * got
        out[rows] += gathered.reshape(m, len(gp_k), 3).mean(axis=0) / chance[go, None]
        return out

    def _gather(self, points, normals, w):
        """The radiance (N, 3) that reaches ``points`` (N, 3) on surfaces of (triangle) normals
        ``normals`` from ``w`` (N, 3, unit, leaving the surface), and which of the rays left the
        scene (N,) (:func:`~raybundle.methods.gather_rays.gather`)."""
        return gather_rays.gather(self, points, normals, w)

    def _gather_tiny(self, E, e_glossy, t_glossy, resolution):
        """Put a gathered estimate in place of the bundles' one for the sides much smaller than a
        bundle cell (``_tiny``), in ``E`` (S, 3), the glossy iterate ``e_glossy``, ``t_glossy``
        (S, 3, or None) and the world's part: ``E_i = (pi / m) sum_k L(y_k, -w_k)`` by m cosine-distributed
        rays ``w_k`` from uniform points ``y_k`` of side i (:meth:`_gather`), m = ``TINY_GATHER_RAYS`` times
        the share of a side's rays that bundles of ``resolution`` take (at least one); a glossy side
        keeps ``pi L`` of its first ray and that ray's travel direction.

        A bundle line meets such a side rarely and then brings it cell / area times its mean
        share: over the iterations its average is heavy-tailed (the interior bench's hall, 4,388
        of 12,420 sides below a sixteenth of a cell, some a ten-thousandth: single sides thousands
        of times their neighbours' radiance after 30 iterations, read by the reconstruction's
        fits, the final gather and the eye's glossy gathers).  A gather's variance does not grow
        as the side shrinks.  Both are unbiased estimates of the same transfer, so the iteration
        stays an unbiased random operator."""
        tiny = self._tiny
        m = max(1, round(self.TINY_GATHER_RAYS * (resolution / self.bundle_resolution) ** 2))
        side = np.repeat(tiny, m)
        u = self.grid_rng.random((len(side), 5))
        pts, n = self._tiny_points.draw(side, u[:, :3])
        t, b = frames_from_normals(n)
        w = cosine_directions(u[:, 3:], t, b, n)
        got, sky = self._gather(pts, n, w)
        got = got.reshape(len(tiny), m, 3)
        E[tiny] = np.pi * got.mean(axis=1)
        if self.separates_world:
            self.world_incoming[tiny] = np.pi * (got * sky.reshape(len(tiny), m, 1)).mean(axis=1)
        if e_glossy is not None:
            g = np.nonzero(self.glossy_mask[tiny])[0]
            e_glossy[tiny[g]] = np.pi * got[g, 0]
            t_glossy[tiny[g]] = -w.reshape(len(tiny), m, 3)[g, 0]

    @abc.abstractmethod
    def step(self):
        """One iteration of the method: what each patch method defines."""

    def refine_first_shot(self):
        """A few more shadow rays into the first shot (and lobe-sampled rays into the caustic shot)."""
        self.first_shot.refine(self.first_shot_refine)
        if self.caustic is not None:
            rays = self.caustic.rays
            self.caustic.refine(self.caustic_refine)
            self.stats.rays += self.caustic.rays - rays

    def sent_environment(self, direction):
        """Radiance (2, 3) the world sends into the bundle lines along ``direction`` that leave
        the scene: travelling along -d (from the world at +d) and along +d (from -d)
        (:meth:`~raybundle.scene.world.World.radiance_along`, reversed), one look-up per direction."""
        return self.world.radiance_along(direction)[::-1]

    def transfer(self, d=None, resolution=None, control=None):
        """One random transport operator: ``directions_per_step`` directions d_k from the sequence
        (or the unit ``d`` (K, 3) given), one bundle each of ``bundle_resolution`` rays a side
        (or ``resolution``; traced together), every side's received ``E_i(d_k)`` from what the
        senders send now (:meth:`sent_radiance`, :meth:`glossy_sent_radiance`,
        :meth:`sent_environment`).  Returns ``(E, e_glossy, t_glossy, bundles)``: the diffuse
        lobe's mean over the K transfers (S, 3), each glossy side's one drawn transfer and its
        travel direction t_i (S, 3; None for diffuse-only scenes).  Counts directions and rays,
        sets ``direction``; the caller stores the iterate.  With ``control`` (S, 3), an estimate
        of E made before the directions were drawn, E is taken less its control variate
        (:mod:`~raybundle.methods.control_variate`)."""
        if d is None:
            d = np.array([uniform_sphere(*self.sequence.next(2)) for _ in range(self.directions_per_step)])
        k_dirs = len(d)
        g = self.grid_rng.random((k_dirs, 3))
        res = resolution or self.bundle_resolution
        bundles = self.tracer.bundles(d, res, offsets=g[:, :2], rotations=g[:, 2], crossings=control is not None)
        if control is not None:
            bundles, crossed = bundles
        n = len(self.area)
        if self._tiny is None and len(bundles):
            self._find_tiny(bundles[0].cell_area * (res / self.bundle_resolution) ** 2)
        # diffuse senders send the same radiance into every direction they face (a bundle
        # pairs only sides that face each other): one evaluation serves all K bundles, and
        # only glossy sides are evaluated per direction
        s_fixed = np.vstack([self.sent_radiance(self.normal), np.zeros((2, 3))])
        directional = not self.world.is_constant
        gp = self.glossy_patches
        if len(gp):
            used, start, s_glossy = self._glossy_sent(d, bundles)
        E = np.zeros((n, 3))
        e_glossy = t_glossy = None
        if not self.diffuse_only:     # the new glossy iterate (senders use the old one)
            pick = self.grid_rng.integers(k_dirs, size=len(self.glossy_patches))
            e_glossy, t_glossy = np.zeros((n, 3)), np.zeros((n, 3))
        st = self.stats
        for k, bundle in enumerate(bundles):
            side = np.sign(self.normal @ d[k])
            # the last two rows are the world's radiance along -d and +d: sender ENVIRONMENT (-1)
            # indexes the last, and travelling along -d the one before it
            S = s_fixed                   # rows that change with d are set anew for each d
            S[-2:] = self.sent_environment(d[k])
            if len(gp):
                S[gp[used[k]]] = s_glossy[start[k]:start[k + 1]]
            sender = bundle.sender
            if directional:
                sender = np.where((sender < 0) & (bundle.travel_sign < 0), -2, sender)
            # t_i is uniform on the receiver's hemisphere: pdf = 2 / (4 pi) = 1 / (2 pi)
            w = bundle.cell_area / (2.0 * uniform_sphere_pdf())
            e_k = np.stack([np.bincount(bundle.receiver, S[sender, c], minlength=n) for c in range(3)],
                           axis=1) * (w / self.area[:, None])
            E += e_k
            if self.separates_world:
                sky = np.nonzero(sender < 0)[0]
                world_e = np.stack([np.bincount(bundle.receiver[sky], S[sender[sky], c], minlength=n)
                                    for c in range(3)], axis=1) * (w / self.area[:, None])
                self.world_incoming = world_e if k == 0 else self.world_incoming + world_e
                self._guide(bundle, sender, S, d[k], w)
            if not self.diffuse_only:
                mine = self.glossy_patches[pick == k]
                e_glossy[mine] = e_k[mine]
                t_glossy[mine] = -side[mine, None] * d[k]
            st.rays += bundle.n_casts
            st.bundle_rays += bundle.n_rays
        E /= k_dirs
        if control is not None:
            E = controlled(self, E, bundles, crossed, control)
        if self.separates_world:
            self.world_incoming = self.world_incoming / k_dirs
        if self._tiny is not None and len(self._tiny) and self.TINY_GATHER_RAYS:
            self._gather_tiny(E, e_glossy, t_glossy, res)
        self.direction = d[-1]
        st.directions += k_dirs
        return E, e_glossy, t_glossy, bundles

    def _glossy_sent(self, d, bundles):
        """What the glossy sides send along each of the directions ``d`` (K, 3), for those a line
        of its bundle leaves from (most small sides send along none of an iteration's few
        directions), in batches: ``(used, start, sent)``, per direction the glossy sides' indices
        and where their rows of ``sent`` (U, 3) start."""
        gp = self.glossy_patches
        place = np.full(len(self.area), -1)
        place[gp] = np.arange(len(gp))
        used = [place[np.unique(b.sender[b.sender >= 0])] for b in bundles]
        used = [u[u >= 0] for u in used]
        start = np.concatenate([[0], np.cumsum([len(u) for u in used])])
        gi = np.concatenate(used)
        dk = d[np.repeat(np.arange(len(d)), np.diff(start))]
        toward = np.sign(np.einsum("ij,ij->i", self.normal[gp[gi]], dk))[:, None] * dk
        per = max(1, self.GLOSSY_SEND_BATCH // self.glossy_send_rays)
        sent = np.concatenate([self.glossy_sent_radiance(gi[i:i + per], toward[i:i + per])
                               for i in range(0, len(gi), per)] + [np.zeros((0, 3))])
        return used, start, sent

    def _find_tiny(self, cell_area):
        """The sides smaller than a cell (``cell_area``, kept) of the iterations' bundles over
        :data:`TINY_SIDE` (:meth:`_gather_tiny`), and their points."""
        self.cell_area, self._tiny = cell_area, np.nonzero(self.area < cell_area / self.TINY_SIDE)[0]
        self._tiny_points = SidePoints(self.scene, np.isin(np.arange(len(self.area)), self._tiny))

    def _guide(self, bundle, sender, S, d, w):
        """Add what the bundle along ``d`` brought each side straight from the sky, by the sky's
        guide cell (-d for sender -1, +d for -2): ``max_c L_w * cell_area * w / A_i``, the
        brightest channel of its irradiance share, as the world light samples by."""
        if self.world_guide is None:
            self.world_guide = SideSums(len(self.area))
        cells = guide_cell(np.stack([-d, d]), *self.world.image.shape[:2])
        for sender_id, cell in ((-1, cells[0]), (-2, cells[1])):
            lum = S[sender_id].max()
            if lum > 0:
                got = np.bincount(bundle.receiver[sender == sender_id], minlength=len(self.area))
                s = np.nonzero(got)[0]
                self.world_guide.add(s, cell, got[s] * (lum * w) / self.area[s])

    # ------------------------------------------------------------- estimates
    def radiance(self, patch, w_out, diffuse_incoming=None, first_shot_emission=True, glossy_iterate=True,
                 first_shot_glossy=True, glossy_as_diffuse=False, sharp_interfaces=False):
        """Outgoing radiance (N, 3) of the sides ``patch`` (N,) towards ``w_out`` (N, 3):

        ``Le + W_d(w_out) kd/pi (E + E1 + Ec) + E f_g(t, w_out) + sum_l E1_l f_g(w_l, w_out)
        + Ec f_g(w_c, w_out)``, with E the current iterate (or ``diffuse_incoming`` (N, 3)
        for the diffuse lobe, e.g. the running average with Ec interpolated at hit points),
        E1 the first shot, Ec the caustic first shot (:mod:`raybundle.lights.caustics`) and
        W_d the diffuse weight of a Principled layer (1 without one,
        :meth:`~raybundle.scene.materials.MaterialTable.diffuse_weight`).
        ``first_shot_emission=False`` leaves out the emission of first-shot lights
        (for estimators that already count direct light); ``glossy_iterate=False``
        leaves out ``E f_g(t, w_out)`` and ``Ec f_g`` (for estimators that trace that lobe further);
        ``first_shot_glossy=False`` leaves out ``E1_l f_g`` (carried by the caustic shot).
        A transmissive side's interface reflects its incoming light less ``E1 + Ec``, which
        it would send as a caustic (``mirror_over_pi``; the iterate and the caustic shot agree on
        that); with ``diffuse_incoming`` it does so only with ``sharp_interfaces``, the sides'
        own ``E1 + Ec`` (:meth:`sharp_incoming`) taken out of it (the radiance kept at least 0
        where ``diffuse_incoming`` is interpolated), and otherwise reflects all of it.
        ``glossy_as_diffuse``: the glossy terms as if the lobe spread its incoming light
        evenly, ``rho_g(w_out) / pi (E + sum_l E1_l + Ec)`` (E over all of this iterate's
        directions) with ``rho_g`` the lobe's
        directional albedo: the end of an eye path that has already followed glossy lobes,
        where ``E f_g(t, w_out)`` for one direction ``t`` is heavy-tailed (a near-mirror lobe
        lined up with ``t`` makes single pixels far too bright: docs/benchmarks.md, 'Measured choices behind
        the defaults').
        """
        mats = self.scene.materials
        # the whole-scene call (every iteration) uses views, not fancy-indexed copies
        sel = slice(None) if patch is self._all_patches else np.asarray(patch)
        patch = self._all_patches[sel]
        pm = self.patch_material[sel]
        n = self.normal[sel]
        cos = np.einsum("ij,ij->i", n, w_out)
        L = mats.emitted_radiance(pm, cos)
        if not first_shot_emission:
            L[self.direct.first_shot_material[pm]] = 0.0
        fs, cs = self.first_shot, self.caustic
        if diffuse_incoming is None:
            e = self.incoming[sel] + fs.E[sel].sum(axis=1)
            if cs is not None:
                e = e + cs.E[sel]
        else:
            e = diffuse_incoming
        L += self._diffuse_weighted(self.kd_over_pi[sel] * e, pm, cos)
        if self.mirror_over_pi is not None and diffuse_incoming is None:    # the iterate sent on
            L -= self.mirror_over_pi[sel] * self.sharp_incoming(sel)
        elif self.mirror_over_pi is not None and sharp_interfaces:
            i = np.nonzero(self.transmissive_side[patch])[0]
            L[i] = np.maximum(L[i] - self.mirror_over_pi[patch[i]] * self.sharp_incoming(patch[i]), 0.0)
        if len(self.translucent_sides):       # the iterate's light on the other side, or the running average's
            source = self.received() if diffuse_incoming is not None else (
                self.incoming + fs.E.sum(axis=1) + (0.0 if cs is None else cs.E))
            L += self.translucent_radiance(source)[sel]
        g = np.nonzero(self.glossy_mask[sel])[0]
        if len(g) and glossy_as_diffuse:
            pg = patch[g]
            e = self.incoming[pg] + fs.E[pg].sum(axis=1)       # this iterate's mean over its directions
            if cs is not None:
                e = e + cs.E[pg]
            L[g] += mats.albedo(pm[g], cos[g], diffuse=False) / np.pi * e
        elif len(g):
            m, ng, w, pg = pm[g], n[g], w_out[g], patch[g]
            if self.direction is not None and glossy_iterate:
                L[g] += self.glossy_incoming[pg] * mats.brdf(m, ng, self.receive_direction[pg], w, diffuse=False)
            for li in range(fs.n_lights if first_shot_glossy else 0):
                L[g] += fs.E[pg, li] * mats.brdf(m, ng, fs.direction[pg, li], w, diffuse=False)
            if cs is not None and glossy_iterate:      # a traced lobe finds this light itself
                L[g] += cs.E[pg] * mats.brdf(m, ng, cs.direction[pg], w, diffuse=False)
        L[cos <= 0] = 0.0
        return L

    def work_rays(self):
        """The solver's work so far in rays (what the image passes' share is measured against):
        its traced rays."""
        return self.stats.rays

    def report(self):
        """Figures of this method beyond :class:`SolverStats` for the run's stats (none here)."""
        return {}

    def iterate_radiance(self, w_out):
        """Radiance of the current iterate L_n,i(w_out) (P, 3) of every patch towards
        ``w_out`` (P, 3), all lobes, first shot and emission included."""
        return self.radiance(self._all_patches, w_out)

    def patch_radiance(self, w_out=None):
        """Running-average radiance of each side (S, 3) towards its normal
        (or towards ``w_out`` (S, 3)), diffuse part only plus emission: the
        view-independent estimate written back as color attributes."""
        cos = np.ones(len(self.normal)) if w_out is None else np.einsum("ij,ij->i", self.normal, w_out)
        le = self.scene.materials.emitted_radiance(self.patch_material, cos)
        received = self.received()
        out = le + self._diffuse_weighted(self.kd_over_pi * received, self.patch_material, cos)
        return out + self.translucent_radiance(received) if len(self.translucent_sides) else out

    def received(self):
        """(S, 3) [W/m^2] all the light each side receives, running average: :meth:`indirect_incoming`
        plus the first shot."""
        return self.indirect_incoming() + self.first_shot.E.sum(axis=1)

    def sharp_incoming(self, sides=slice(None)):
        """(S, 3) [W/m^2] the part of :meth:`received` that comes straight from the first-shot
        lights or by the caustic shot, ``E1 + Ec``, of all sides or of ``sides`` (N,)."""
        fs, cs = self.first_shot, self.caustic
        return fs.E[sides].sum(axis=1) + (0.0 if cs is None else cs.E[sides])

    def translucent_radiance(self, received):
        """(S, 3) [W m^-2 sr^-1] the radiance each translucent side sends on from what its
        patch's other side receives (``received`` (S, 3)): ``kt / pi E(opposite)``, 0 elsewhere."""
        out = np.zeros((len(self.area), 3))
        t = self.translucent_sides
        out[t] = self.kt_over_pi * received[self.scene.side_opposite[t]]
        return out

    def indirect_incoming(self):
        """(S, 3) [W/m^2] the view-independent incoming radiance an image resolves per
        pixel: the running average of the iterates plus the caustic first shot."""
        return self.mean_incoming if self.caustic is None else self.mean_incoming + self.caustic.E

    def image_incoming(self, caustic=True, world=True):
        """(S, 3) [W/m^2] what an image reads from the patches for the diffuse lobe at its
        visible points: :meth:`indirect_incoming` (without the caustic shot when not
        ``caustic``), less the running average of what came straight from the world when not
        ``world`` (an image that samples that light itself; needs :meth:`separate_world`)."""
        e = self.indirect_incoming() if caustic else self.mean_incoming
        if world:
            return e
        if not self.separates_world:
            raise ValueError(f"{self.name} keeps no separate average of the world's direct light")
        return e - self.mean_world_incoming

    def separate_world(self):
        """Keep the running average of the light straight from the world apart from now on
        (before the first step: the image then reads the rest, :meth:`image_incoming`); False
        where the method cannot (:attr:`world_direct`)."""
        if self.world_direct and self.stats.iterations == 0:
            self.separates_world = True
        return self.separates_world

    def _diffuse_weighted(self, diffuse, pm, cos):
        """``diffuse`` (N, 3) of sides with materials ``pm`` (N,) times W_d(cos) where a
        Principled layer sits over the diffuse lobe (in place; returns it)."""
        if len(self.layered_sides) == 0:
            return diffuse
        lay = np.nonzero(self.scene.materials.has_layer[pm])[0]
        if len(lay):
            diffuse[lay] *= self.scene.materials.diffuse_weight(pm[lay], cos[lay])
        return diffuse


def auto_bundle_resolution(scene, lo=32, hi=512):
    """Grid rays per side so that the cell is about one mean patch wide:
    ``2 R / sqrt(mean patch area)``, clipped to [lo, hi].  Finer grids cost
    time per iteration; coarser ones leave more patches without a ray."""
    _, r = scene.bounding_sphere
    return int(np.clip(np.ceil(2 * r / np.sqrt(scene.patch_area.mean())), lo, hi))
