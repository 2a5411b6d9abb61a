"""Stochastic iteration with ray bundles and the incoming first shot (thesis 3.3, 3.4).

Each step applies one random transport operator to the previous iterate
(:meth:`~raybundle.methods.patch_solution.PatchSolution.transfer`: ``directions_per_step``
bundles), and the image is the running average of the iterates.  The patch solution, the
transfer's equations and its failure modes are :mod:`raybundle.methods.patch_solution`'s.
"""
from __future__ import annotations

import time

from .patch_solution import PatchSolution


class StochasticIterationSolver(PatchSolution):
    """Stochastic iteration with ray bundles and incoming first shot (thesis 3.3, 3.4)."""

    name = "stochastic-iteration"
    #: each step applies a random operator to the previous iterate (thesis 1.2: the random
    #: numbers must then be completely uniformly distributed)
    iterates = True
    #: independent chains of it merge exactly (:mod:`raybundle.app.chains`)
    merges_chains = True

    def step(self):
        """One iteration: :meth:`transfer` from the current iterate, then the running average.

        The diffuse lobe receives the mean of the K transfers, ``E_i = (1/K) sum_k E_i(d_k)``
        (an unbiased iterate whatever the joint law of the d_k, as each is uniform); a
        glossy side keeps one of them, ``E_i(d_k)`` with k drawn uniformly per side, as its
        single stored direction t_i (unbiased too: its mean over k is the same average).
        """
        t0 = time.perf_counter()
        before = self.direct.rays
        self.refine_first_shot()
        E, e_glossy, t_glossy, bundles = self.transfer()
        self.incoming = E
        if not self.diffuse_only:
            self.glossy_incoming, self.receive_direction = e_glossy, t_glossy
        st = self.stats
        st.iterations += 1
        # the running average restarts once, after burn_in iterations: the iterates start from
        # zero and approach the solution like albedo^n, a start-up bias ~ 1/(n (1 - albedo))
        # that would otherwise fade only as fast as 1/n (3% after 100 iterations at albedo 0.7)
        self.averaged = st.iterations - (self.burn_in if st.iterations > self.burn_in else 0)
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
