"""Classical radiosity: form factors by global lines, then a deterministic solve (the O(n^2)
baseline the thesis measures itself against).

Every step casts ``directions_per_step`` bundles of parallel global lines (the same
:meth:`~raybundle.tracing.visibility.RayTracer.bundles` the stochastic iteration uses) and adds, for
every line that joins side j to side i, its weight to a dense transfer matrix, so that after
N directions

    G_ij = (2 pi / (N A_i)) sum_{lines j -> i} delta^2      [sr]

is pi times the global-line estimate of the form factor from i to j (the world is one more
sender column, each of its lines carrying the world's radiance in its own direction; sum_j
G_ij = pi for a closed scene).  The incoming radiance then solves the diffuse rendering equation on these
form factors,

    E_i = sum_j G_ij S_j,     S_j = Le_j + kd_j / pi (E_j + E1_j)

(E irradiance [W m^-2], S radiance [W m^-2 sr^-1])

by Jacobi sweeps started from the previous step's solution (``SWEEPS`` per step; the error
of a sweep shrinks by the albedo), E1 the first shot.  Its error is that of the form
factors alone: no iteration noise, but an n x n matrix (memory n^2, each sweep n^2
operations), against the bundle iteration's O(n log n) per step.  Diffuse scenes only.
"""
from __future__ import annotations

import time

import numpy as np

from ..tracing.sampling import uniform_sphere
from .patch_solution import PatchSolution


class RadiositySolver(PatchSolution):
    """Global-line form factors and Jacobi sweeps (module docstring).  The first shot, the
    open area, the reconstruction and the image are the stochastic iteration's."""

    SEPARATES_WORLD_DIRECT = False        # its own step: the world's light stays in its solution

    name = "radiosity"
    #: the directions integrate form factors; no random operator is iterated
    iterates = False
    #: independent chains' form factors and solutions merge exactly (:mod:`raybundle.app.chains`)
    merges_chains = True
    #: the dense matrix's limit: 16,384 sides take 2 GB
    MAX_SIDES = 16384
    #: Jacobi sweeps per step
    SWEEPS = 4
    #: matrix entries a sweep multiplies in the time of one traced bundle ray (rounded from a
    #: timing on `cornell`: docs/benchmarks.md, 'Measured choices behind the defaults')
    SWEEP_ENTRIES_PER_RAY = 600.0

    #: diffuse scenes only: no glossy reflection of the first shot
    TAKES_CAUSTIC_SHOT = False

    def __init__(self, scene, tracer, direct, settings, camera=None):
        n = scene.n_sides
        if n > self.MAX_SIDES:
            raise ValueError(f"radiosity keeps an n x n form-factor matrix: {n:,} patch sides is more than "
                             f"{self.MAX_SIDES:,} (use fewer patches or stochastic-iteration)")
        super().__init__(scene, tracer, direct, settings)
        if not self.diffuse_only:
            raise ValueError("radiosity handles diffuse scenes only; this scene has glossy surfaces "
                             "(use stochastic-iteration)")
        self.lines = np.zeros(n * (n + 1))            # sum of delta^2 per (receiver, sender), world last
        self.world_lines = np.zeros((n, 3))           # sum of delta^2 L_w per receiver, the world's lines
        self.form_factor_directions = 0

    def work_rays(self):
        """Traced rays plus the Jacobi sweeps in ray equivalents: a sweep's ``3 n (n + 1)``
        multiply-adds cost about what ``3 n (n + 1) / SWEEP_ENTRIES_PER_RAY`` bundle rays do, so
        the image passes keep their share of the time (with rays alone, the O(n^2) sweeps
        starved them: the direct light stayed one pass's worth of noise for a long time on
        ``cornell``; docs/benchmarks.md, 'Measured choices behind the defaults')."""
        n = len(self.area)
        return self.stats.rays + self.stats.iterations * self.SWEEPS * 3 * n * (n + 1) / self.SWEEP_ENTRIES_PER_RAY

    def form_factors(self):
        """G (S, S + 1) [sr]: pi times the current form-factor estimate, the last column the world."""
        n = len(self.area)
        scale = 2.0 * np.pi / (max(self.form_factor_directions, 1) * np.maximum(self.area, 1e-300))
        return self.lines.reshape(n, n + 1) * scale[:, None]

    def sweep(self, sweeps):
        """``sweeps`` Jacobi sweeps ``E <- G S(E)`` from the current ``incoming``; returns E (S, 3)."""
        n = len(self.area)
        lines = self.lines.reshape(n, n + 1)           # G = scale * lines, without an n^2 copy
        scale = 2.0 * np.pi / (max(self.form_factor_directions, 1) * np.maximum(self.area, 1e-300))
        for _ in range(int(sweeps)):
            self.incoming = (lines[:, :n] @ self.sent_radiance(self.normal) + self.world_lines) * scale[:, None]
        return self.incoming

    def step(self):
        """One step: ``directions_per_step`` more bundles of global lines into the form factors,
        then ``SWEEPS`` Jacobi sweeps of the radiosity equation."""
        t0 = time.perf_counter()
        before = self.direct.rays
        self.refine_first_shot()
        k_dirs = self.directions_per_step
        d = np.array([uniform_sphere(*self.sequence.next(2)) for _ in range(k_dirs)])
        g = self.grid_rng.random((k_dirs, 3))
        n = len(self.area)
        st = self.stats
        for bundle in self.tracer.bundles(d, self.bundle_resolution, offsets=g[:, :2], rotations=g[:, 2]):
            sender = np.where(bundle.sender < 0, n, bundle.sender)
            np.add.at(self.lines, bundle.receiver * (n + 1) + sender, bundle.cell_area)
            world = np.nonzero(bundle.sender < 0)[0]
            if len(world):            # the world sends L_w(-d) along +d and L_w(d) along -d
                along = self.world.radiance_along(bundle.direction)
                np.add.at(self.world_lines, bundle.receiver[world],
                          bundle.cell_area * along[(bundle.travel_sign[world] < 0).astype(int)])
            st.rays += bundle.n_casts
            st.bundle_rays += bundle.n_rays
        self.form_factor_directions += k_dirs
        E = self.sweep(self.SWEEPS)
        self.direction = d[-1]
        st.iterations += 1
        st.directions += k_dirs
        self.mean_incoming = E                 # the solution on the current form factors
        self.averaged = st.iterations
        st.rays += self.direct.rays - before
        st.seconds += time.perf_counter() - t0
