"""Random ray-bundle tracing (thesis 3.2): the random walk whose steps are bundles of
parallel global lines, the method the stochastic iteration (3.3) was measured against.

A walk starts from the emission: its first step sends ``R^(0) = Le_r + L1`` (the emission of
lights that are not first-shot lights, the environment, and the incoming first shot's
reflection) along a random global direction d_1; every later step sends what the previous
one brought, reflected:

    E_i^(k) = (2 pi / A_i) sum_j R_j^(k-1)(s_j) P(i, j, d_k)          [W/m^2]
    R_j^(k)(w) = E_j^(k) f_j(t_j^(k), w)                               [W m^-2 sr^-1]

with the bundle used in both directions (every line joins its consecutive hits both ways,
so each side receives from the hemisphere it faces: the factor 2 pi, as in
:mod:`raybundle.methods.patch_solution`) and the walk's steps summed: ``L = Le + sum_k R^(k)`` estimates
``Le + sum_k T^k Le``.  After each step the walk goes on with probability ``q`` (Russian
roulette, survivors weighted 1/q) or a new walk starts at the next step, so every step of
every walk enters the image: the running average over steps of ``R^(k) / (1 - q)`` (the
expected walk length 1/(1 - q) turns the sum over a walk into a mean over steps) estimates
``sum_k T^k Le``, a ratio estimator that is consistent (its bias is O(1/steps)) and needs no
burn-in.

Unlike the stochastic iteration, which re-injects the emission at every step and so starts a
new sub-walk each time (thesis 3.3: the same bundles, but no walk restarts), each emission
here feeds one walk only: expect more noise per step.  The thesis' further extension, in
which every step of a walk also starts new sub-walks weighted 1/(D - b + 1) per bounce order
b, is left out: it needs one state per bounce order, and in its limit it is the stochastic
iteration.  Glossy sides send the thesis' ``E f(t, s)`` (no lobe-sampled gather rays) and
the caustic shot is off.  That is where the walk fails: near-mirror lobes (roughness below
:data:`~raybundle.scene.materials.NEAR_MIRROR_ROUGHNESS`) make ``E f(t, s)`` heavy-tailed (a random
direction rarely falls into the lobe, and then with a huge weight); the solver warns.
"""
from __future__ import annotations

import time
import warnings

import numpy as np

from ..scene.materials import NEAR_MIRROR_ROUGHNESS
from ..tracing.sampling import Stream, stream
from .patch_solution import PatchSolution


class RayBundleWalk(PatchSolution):
    """Random walks of global ray bundles with Russian roulette (module docstring)."""

    SEPARATES_WORLD_DIRECT = False        # its own step: the world's light stays in its solution
    TINY_GATHER_RAYS = 0                  # its senders send the walk's last step, not what a gather reads

    name = "ray-bundle-walk"
    #: each step applies a random operator to the walk's previous step (thesis 1.2)
    iterates = True
    #: independent chains of walks merge exactly (:mod:`raybundle.app.chains`)
    merges_chains = True
    #: the range of the continuation probability q (the scene's mean albedo)
    Q_RANGE = (0.25, 0.95)

    #: a walk's glossy sides carry the first shot's reflection themselves
    TAKES_CAUSTIC_SHOT = False

    def __init__(self, scene, tracer, direct, settings, camera=None):
        super().__init__(scene, tracer, direct, settings)
        #: continuation probability: the scene's mean albedo (``mean_albedo``)
        self.q = float(np.clip(self.mean_albedo, *self.Q_RANGE))
        n = scene.n_sides
        self.walk_incoming = np.zeros((n, 3))      # R's incoming E^(k) (diffuse lobe), weights 1/q^k in
        self.walk_glossy = np.zeros((n, 3))        # the glossy lobe's E^(k) from walk_direction
        self.walk_direction = np.zeros((n, 3))
        self.walk_step = 0                         # steps taken by the current walk
        self.walks = 0                             # walks started
        self.roulette = stream(settings.seed, Stream.ROULETTE)
        if len(self.glossy_patches):
            rough = np.asarray(self.scene.materials.roughness)[self.patch_material[self.glossy_patches]].min()
            if rough < NEAR_MIRROR_ROUGHNESS:
                warnings.warn(f"{self.name}: a glossy lobe of roughness {rough:.3g} is nearly a mirror; the walk "
                              "sends glossy light as E f(t, s) from one random direction, which is heavy-tailed "
                              "for sharp lobes (on the built-in near-mirror scene: 67% error after 20 s against "
                              "3.8% for stochastic-iteration, which gathers glossy light by lobe-sampled rays)",
                              stacklevel=4)

    # ----------------------------------------------------------- senders
    def sent_radiance(self, send_dir):
        """R^(k-1) (S, 3) every side sends into ``send_dir``: at a walk's start the emission
        and the first shot's reflection, later the previous step's reflected light."""
        return self._walk_sent(self._all_patches, send_dir)

    def glossy_sent_radiance(self, gi, send_dir):
        """R^(k-1) of the glossy sides ``glossy_patches[gi]`` (N,) into ``send_dir`` (N, 3): the
        thesis' E f(t, s)."""
        return self._walk_sent(self.glossy_patches[gi], send_dir)

    def sent_environment(self, direction):
        return super().sent_environment(direction) if self.walk_step == 0 else np.zeros((2, 3))

    def _walk_sent(self, patch, send_dir):
        if self.walk_step == 0:
            return self.radiance(patch, send_dir, diffuse_incoming=self.first_shot.E[patch].sum(axis=1),
                                 first_shot_emission=False, glossy_iterate=False)
        mats = self.scene.materials
        pm, n = self.patch_material[patch], self.normal[patch]
        cos = np.einsum("ij,ij->i", n, send_dir)
        L = self._diffuse_weighted(self.kd_over_pi[patch] * self.walk_incoming[patch], pm, cos)
        g = np.nonzero(self.glossy_mask[patch])[0]
        if len(g):
            pg = patch[g]
            L[g] += self.walk_glossy[pg] * mats.brdf(pm[g], n[g], self.walk_direction[pg], send_dir[g],
                                                     diffuse=False)
        L[cos <= 0] = 0.0
        return L

    def report(self):
        return {"walks": self.walks, "continuation_probability": round(self.q, 4)}

    # -------------------------------------------------------------- step
    def step(self):
        """One step of the current walk (a new walk's first step after a stop), its
        contribution ``R^(k) / (1 - q)`` into the running average, then Russian roulette."""
        t0 = time.perf_counter()
        before = self.direct.rays
        self.refine_first_shot()
        if self.walk_step == 0:
            self.walks += 1
        E, e_glossy, t_glossy, bundles = self.transfer()
        length = 1.0 / (1.0 - self.q)                 # the expected number of steps per walk
        self.incoming = E * length
        if not self.diffuse_only:
            self.glossy_incoming, self.receive_direction = e_glossy * length, t_glossy
        if self.roulette.random() < self.q:           # the walk goes on, weighted 1/q
            self.walk_step += 1
            self.walk_incoming = E / self.q
            if not self.diffuse_only:
                self.walk_glossy, self.walk_direction = e_glossy / self.q, t_glossy
        else:
            self.walk_step = 0
        st = self.stats
        st.iterations += 1
        self.averaged = st.iterations
        self.mean_incoming += (self.incoming - self.mean_incoming) / self.averaged
        st.rays += self.direct.rays - before
        st.seconds += time.perf_counter() - t0
        return bundles
