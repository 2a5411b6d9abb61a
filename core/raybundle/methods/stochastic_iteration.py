"""Stochastic iteration with ray bundles and the incoming first shot (thesis 3.3, 3.4).

Each step applies one random transport operator to the previous iterate
(:meth:`~raybundle.methods.patch_solution.PatchSolution.transfer`: ``directions_per_step``
bundles), and the image is the running average of the iterates.  The patch solution itself is
:mod:`raybundle.methods.patch_solution`'s.

Stochastic iteration with ray bundles (thesis 3.3, bidirectional form)
--------------------------------------------------------------------
One RGB variable per patch side (:mod:`raybundle.scene.model`: one per one-sided
patch, two per two-sided patch), the *incoming* radiance ``E_i`` (an irradiance:
the cosine-weighted integral of the incoming radiance estimated from one
direction, [W/m^2]).  Iteration n draws a direction d uniformly on the sphere,
finds with one bundle (:mod:`raybundle.tracing.visibility`) every pair of mutually
visible patches along +-d, and transfers::

    S_j   = Le_r,j(s_j) + L1_j(s_j) + E_j^{n-1} f_j(t_j^{n-1}, s_j)     (radiance sent)
    E_i^n = (2 pi / A_i) sum_j S_j P(i, j, d)                             [W/m^2]

where ``i`` and ``j`` are sides (normal ``n`` of the side), the world is one
more sender ``j`` for the first and last hits of each bundle line, sending the
radiance ``L_w(-d)`` along +d and ``L_w(d)`` along -d (:mod:`raybundle.scene.world`:
one look-up per direction for the whole bundle), ``s_j = sign(n_j.d) d`` is the
direction side j sends into,
``t_i = -sign(n_i.d) d`` the travel direction patch i receives from (uniform
on i's hemisphere, hence the 2 pi = 1/pdf), ``P(i,j,d) = A(i,j,d) cos_i`` the
projected area of the rays linking them and ``L1`` the incoming first shot of
the small lights (:mod:`raybundle.lights.sources`).  The iterate
``L_n,i(w) = Le_i(w) + E_i^n f_i(t_i, w)`` is an unbiased random operator
applied to ``L_{n-1}``; the *image is the running average* of the iterates.

Diffuse-only scenes take the view-independent path: with ``f = kd/pi`` the
sent radiance needs no direction, and the image needs only the running
average of E.

An iteration may use K directions (``directions_per_step``, default 16): the
diffuse lobe receives the mean of their K transfers (still an unbiased random
operator), a glossy side keeps one of them drawn at random; the K bundles go
to Embree as one threaded query and everything else per iteration (first-shot
refinement, sent radiance of diffuse sides) is shared, which on the Cornell box measured
more directions per second and a lower image error at a fixed time than one direction per
iteration (docs/benchmarks.md, 'Measured choices behind the defaults').
The first shot's glossy reflection leaves glossy sides by lobe-sampled rays
(:mod:`raybundle.lights.caustics`), not through the bundles.

Parameters: bundle resolution (rays per side of the grid), the random sequence
that draws the directions (``stratified`` (default), ``prng`` or ``pi-powers``;
``halton`` converges to a wrong answer, thesis 1.2).  The grid's random offset
and rotation come from a separate PRNG stream.
Failure modes: glossy lobes with low roughness (fireflies, blocky reflections:
radiance is constant per patch), albedo near 1 (slow convergence), patches
much smaller than the bundle cell (a line meets them rarely, and then with cell / area times
their share: they gather their light by rays of their own instead, :meth:`~raybundle.methods.patch_solution.PatchSolution._gather_tiny`).
"""
from __future__ import annotations

import time

import numpy as np

from ..tracing.sampling import Stream, stream, uniform_sphere
from .energy_balance import RAYS_PER_SIDE, balanced_level, side_capture
from .patch_solution import PatchSolution


class StochasticIterationSolver(PatchSolution):
    """Stochastic iteration with ray bundles and incoming first shot (thesis 3.3, 3.4)."""

    name = "stochastic-iteration"
    #: each step applies a random operator to the previous iterate (thesis 1.2: the random
    #: numbers must then be completely uniformly distributed)
    iterates = True
    #: independent chains of it merge exactly (:mod:`raybundle.app.chains`)
    merges_chains = True

    #: at most this many warm-up transfers; a scene whose transient needs more also restarts its
    #: running average once, after the rest (:attr:`restart_at`)
    MAX_WARM_UP = 128
    #: the warm-up ends when the start-up transient, about ``mean_albedo^n``, is below this share
    #: of the solution
    WARM_UP_TRANSIENT = 1e-3
    #: the warm-up's bundles have this many times fewer rays a side than the iterations'
    WARM_UP_COARSER = 4

    def __init__(self, scene, tracer, direct, settings, camera=None):
        super().__init__(scene, tracer, direct, settings)
        #: the transfers that bring the iterate near the solution before the running average
        #: starts (:meth:`warm_up`)
        steps = np.ceil(np.log(self.WARM_UP_TRANSIENT) / np.log(max(self.mean_albedo, 1e-3)))
        self.warm_up_steps = int(min(max(steps, self.burn_in), self.MAX_WARM_UP))
        self.restart_at = max(self.burn_in - self.warm_up_steps, 0)
        self.warmed_up = False
        #: (3,) the factor :meth:`balance_level` scaled the warm-up's iterate by (1: not scaled)
        self.level_scale = np.ones(3)

    def warm_up(self, stop=None):
        """Bring the iterate near the solution before the running average starts.

        The iterates start from zero and approach the solution like ``mean_albedo^n``: averaged
        from the first, a run of n iterations is dark by about ``1 / (n (1 - albedo))``.  Here
        :attr:`warm_up_steps` transfers apply the same random operator to the iterate until the
        transient is below :data:`WARM_UP_TRANSIENT`, and are not averaged: a transient ``t`` left
        makes a run of n iterations dark by ``t albedo (1 - albedo^n) / (n (1 - albedo))`` of the
        indirect light, and the scene's slower modes decay more slowly than its mean albedo.
        Each takes the iterations' number of directions (from a stream of their own,
        ``Stream.WARM_UP``, so the averaged iterations keep the sequence's), whose mean keeps the
        iterate's total light steady (with one direction a transfer, it is a product of random
        factors), but bundles of :data:`WARM_UP_COARSER` squared times fewer rays a side, and the tiny
        sides' gathers as many times fewer (at least one ray a side).  Meanwhile the
        solver's readers of the running average (the glossy senders' and tiny sides' gathers) read
        the current iterate.
        The last iterate's shape is near the solution's, but its level carries the noise of those
        coarse transfers, many times one fine transfer's: a diffuse solution's is then set by the energy balance
        (:meth:`balance_level`).  The first iteration's transfer takes the control variate of
        this start, on the sides of at least a bundle cell (:meth:`step`).
        ``stop`` (a callable) ends it early; the iteration then goes on from where it got."""
        if self.warmed_up:
            return
        res = max(8, self.bundle_resolution // self.WARM_UP_COARSER)
        rng = stream(self.seed, Stream.WARM_UP)
        t0, before = time.perf_counter(), self.direct.rays
        for _ in range(self.warm_up_steps):
            if stop is not None and stop():
                break
            d = uniform_sphere(*rng.random((2, self.directions_per_step)))
            E, e_glossy, t_glossy, _ = self.transfer(d, resolution=res)
            self._store(E, e_glossy, t_glossy)
            self.mean_incoming = E.copy()
            if self.separates_world:
                self.mean_world_incoming = self.world_incoming.copy()
            self.stats.warm_up += 1
        if self.diffuse_only and self.stats.warm_up and not (stop is not None and stop()):
            self.balance_level()
        self.warmed_up = True
        self.stats.rays += self.direct.rays - before
        self.stats.seconds += time.perf_counter() - t0

    def balance_level(self):
        """Scale the iterate (and the running average it starts) to the level the energy balance
        of its shape gives (:mod:`~raybundle.methods.energy_balance`), per colour channel; the
        factor is kept as :attr:`level_scale` (3,)."""
        capture, sky = side_capture(self.scene, self.tracer, stream(self.seed, Stream.ENERGY_BALANCE))
        self.stats.rays += RAYS_PER_SIDE * self.scene.n_sides
        sent = self.sent_radiance(self.normal)
        iterate, self.incoming = self.incoming, np.zeros_like(self.incoming)
        fixed = self.sent_radiance(self.normal)
        self.level_scale = balanced_level(self.area, iterate, fixed, sent - fixed, capture, sky)
        self.incoming = iterate * self.level_scale
        self.mean_incoming = self.incoming.copy()

    def _store(self, E, e_glossy, t_glossy):
        """Make the transfer's result the iterate."""
        self.incoming = E
        if not self.diffuse_only:
            self.glossy_incoming, self.receive_direction = e_glossy, t_glossy

    def step(self):
        """One iteration: :meth:`transfer` from the current iterate, then the running average.

        The diffuse lobe receives the mean of the K transfers, ``E_i = (1/K) sum_k E_i(d_k)``
        (an unbiased iterate whatever the joint law of the d_k, as each is uniform); a
        glossy side keeps one of them, ``E_i(d_k)`` with k drawn uniformly per side, as its
        single stored direction t_i (unbiased too: its mean over k is the same average).
        """
        if not self.warmed_up:
            self.warm_up()
        t0 = time.perf_counter()
        before = self.direct.rays
        self.refine_first_shot()
        control = self.mean_incoming
        if not self.averaged and self.stats.warm_up:
            # the warm-up's iterate, a side's whole history being its last coarse transfer: on a side
            # smaller than a bundle cell, which a line's hit gives cell / area times its share, it
            # can be many times the side's mean, and there its control variate would add that error
            # rather than take out noise
            control = np.where((self.area >= self.cell_area)[:, None], control, 0.0)
        E, e_glossy, t_glossy, bundles = self.transfer(control=control)
        self._store(E, e_glossy, t_glossy)
        st = self.stats
        st.iterations += 1
        # the running average starts after the warm-up; a scene whose transient outlasts it
        # restarts the average once, after restart_at iterations
        self.averaged = st.iterations - (self.restart_at if st.iterations > self.restart_at else 0)
        self.mean_incoming += (E - self.mean_incoming) / self.averaged
        if self._tiny is not None and len(self._tiny):
            # a side much smaller than a bundle line's cross-section receives, when a line meets it,
            # cell / area times its mean share: sent on as it is, that spike is multiplied again
            # by the next receivers (the living room of the interior bench, sides a thousandth of
            # a cell: the image 70 times too bright after 300 s); such sides send their running
            # average instead, which the iterates still feed without bias
            self.incoming[self._tiny] = self.mean_incoming[self._tiny]       # E, already averaged
        if self.separates_world:
            self.mean_world_incoming += (self.world_incoming - self.mean_world_incoming) / self.averaged
        st.rays += self.direct.rays - before
        st.seconds += time.perf_counter() - t0
        return bundles
