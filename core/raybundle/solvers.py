"""Solvers of the rendering equation on patches.

Every solver has the same interface, so the CLI, the add-on and the bench can
drive any of them by name (:data:`SOLVERS`): ``step()`` performs one iteration,
``incoming`` / ``receive_direction`` describe the current iterate,
``mean_incoming`` the running average, and ``stats`` counts the work.

Stochastic iteration with ray bundles (thesis 3.3, bidirectional form)
--------------------------------------------------------------------
One RGB variable per patch side (:mod:`raybundle.scene`: one per one-sided
patch, two per two-sided patch), the *incoming* radiance ``E_i`` (an irradiance:
the cosine-weighted integral of the incoming radiance estimated from one
direction, [W/m^2]).  Iteration n draws a direction d uniformly on the sphere,
finds with one bundle (:mod:`raybundle.visibility`) every pair of mutually
visible patches along +-d, and transfers::

    S_j   = Le_r,j(s_j) + L1_j(s_j) + E_j^{n-1} f_j(t_j^{n-1}, s_j)     (radiance sent)
    E_i^n = (2 pi / A_i) sum_j S_j P(i, j, d)                             [W/m^2]

where ``i`` and ``j`` are sides (normal ``n`` of the side), the environment
(world) radiance is one more sender ``j`` for the first and last hits of
each bundle line, ``s_j = sign(n_j.d) d`` is the direction side j sends into,
``t_i = -sign(n_i.d) d`` the travel direction patch i receives from (uniform
on i's hemisphere, hence the 2 pi = 1/pdf), ``P(i,j,d) = A(i,j,d) cos_i`` the
projected area of the rays linking them and ``L1`` the incoming first shot of
the small lights (:mod:`raybundle.lights`).  The iterate
``L_n,i(w) = Le_i(w) + E_i^n f_i(t_i, w)`` is an unbiased random operator
applied to ``L_{n-1}``; the *image is the running average* of the iterates.

Diffuse-only scenes take the view-independent path: with ``f = kd/pi`` the
sent radiance needs no direction, and the image needs only the running
average of E.

Parameters: bundle resolution (rays per side of the grid), the random sequence
that draws the directions (``prng`` or ``pi-powers``; ``halton`` converges to a
wrong answer, thesis 1.2).  The grid's random offset and rotation come from a
separate PRNG stream.
Failure modes: glossy lobes with low roughness (fireflies, blocky reflections:
radiance is constant per patch), albedo near 1 (slow convergence), patches
much smaller than the bundle cell (they are missed in most iterations; raise
the bundle resolution).
"""
from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from .lights import PatchFirstShot
from .sampling import uniform_sphere, uniform_sphere_pdf


@dataclass
class SolverStats:
    iterations: int = 0
    seconds: float = 0.0
    rays: int = 0           # Embree queries issued by the solver (bundles)
    bundle_rays: int = 0    # grid rays (one per line of the bundles)


class StochasticIterationSolver:
    """Stochastic iteration with ray bundles and incoming first shot (thesis 3.3, 3.4)."""

    name = "stochastic-iteration"

    def __init__(self, scene, tracer, direct, sequence, bundle_resolution=0, seed=0):
        self.scene = scene
        self.tracer = tracer
        self.direct = direct
        self.sequence = sequence
        self.bundle_resolution = int(bundle_resolution) or auto_bundle_resolution(scene)
        mats = scene.materials
        # the unknowns are patch sides: normals, materials and areas are per side
        pm = scene.side_material
        self.patch_material = pm
        self.normal = scene.side_normal
        # receiving area: the side's area less what is buried inside solids
        self.tside_open_area = tracer.open_fraction() * scene.triangle_area[scene.tside_triangle]
        self.area = np.bincount(scene.tside_side, self.tside_open_area, minlength=scene.n_sides)
        self.kd_over_pi = mats.diffuse_reflectance[pm] / np.pi          # (P, 3)
        self.glossy_mask = mats.is_glossy[pm]
        self.layered_sides = np.nonzero(mats.has_layer[pm])[0]      # diffuse lobe under a specular layer
        self.glossy_patches = np.nonzero(self.glossy_mask)[0]
        self.diffuse_only = len(self.glossy_patches) == 0
        # incoming first shot, refined by a few shadow rays every iteration
        self.first_shot = PatchFirstShot(direct, np.random.default_rng([seed, 7]), receiving_area=self.area)
        self.grid_rng = np.random.default_rng([seed, 3])   # bundle grid offset and rotation
        self.first_shot_refine = max(64, len(self.first_shot.receiving_tsides) // 16) if direct.n_lights else 0
        self.environment = np.asarray(scene.environment, float)
        n = scene.n_sides
        self._all_patches = np.arange(n)
        self.incoming = np.zeros((n, 3))
        self.receive_direction = np.zeros((n, 3))   # t_i of the current iterate
        self.mean_incoming = np.zeros((n, 3))
        self.direction = None
        self.stats = SolverStats()

    # ------------------------------------------------------------------ step
    def sent_radiance(self, send_dir):
        """Radiance S_j (P, 3) that each patch sends into ``send_dir`` (P, 3) [W m^-2 sr^-1]:
        the current iterate without the emission of first-shot lights (their light
        enters the iteration as the first shot)."""
        return self.radiance(self._all_patches, send_dir, first_shot_emission=False)

    def step(self):
        """One iteration: draw d, trace a bundle, transfer, update the running average."""
        t0 = time.perf_counter()
        before = self.direct.rays
        self.first_shot.refine(self.first_shot_refine)
        u = self.sequence.next(2)
        d = uniform_sphere(u[0], u[1])
        g = self.grid_rng.random(3)
        bundle = self.tracer.bundle(d, self.bundle_resolution, offset=(g[0], g[1]), rotation=g[2])
        side = np.sign(self.normal @ d)
        # the last row is the world's radiance: sender ENVIRONMENT (-1) indexes it
        S = np.vstack([self.sent_radiance(side[:, None] * d), self.environment])
        # t_i is uniform on the receiver's hemisphere: pdf = 2 / (4 pi) = 1 / (2 pi)
        w = bundle.cell_area / (2.0 * uniform_sphere_pdf())
        n = len(self.area)
        E = np.stack([np.bincount(bundle.receiver, S[bundle.sender, k], minlength=n) for k in range(3)],
                     axis=1).astype(float)       # an empty bundle gives integer zeros
        E *= w / self.area[:, None]
        self.incoming = E
        self.receive_direction = -side[:, None] * d
        self.direction = d
        st = self.stats
        st.iterations += 1
        self.mean_incoming += (E - self.mean_incoming) / st.iterations
        st.rays += bundle.n_casts + self.direct.rays - before
        st.bundle_rays += bundle.n_rays
        st.seconds += time.perf_counter() - t0
        return bundle

    # ------------------------------------------------------------- estimates
    def radiance(self, patch, w_out, diffuse_incoming=None, first_shot_emission=True, glossy_iterate=True):
        """Outgoing radiance (N, 3) of the sides ``patch`` (N,) towards ``w_out`` (N, 3):

        ``Le + W_d(w_out) kd/pi (E + E1) + E f_g(t, w_out) + sum_l E1_l f_g(w_l, w_out)``, with E
        the current iterate (or ``diffuse_incoming`` (N, 3) for the diffuse lobe,
        e.g. the running average interpolated at hit points), E1 the first shot and
        W_d the diffuse weight of a Principled layer (1 without one,
        :meth:`~raybundle.materials.MaterialTable.diffuse_weight`).
        ``first_shot_emission=False`` leaves out the emission of first-shot lights
        (for estimators that already count direct light); ``glossy_iterate=False``
        leaves out ``E f_g(t, w_out)`` (for estimators that trace that lobe further).
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
        fs = self.first_shot
        e = self.incoming[sel] + fs.E[sel].sum(axis=1) if diffuse_incoming is None else diffuse_incoming
        L += self._diffuse_weighted(self.kd_over_pi[sel] * e, pm, cos)
        g = np.nonzero(self.glossy_mask[sel])[0]
        if len(g):
            m, ng, w, pg = pm[g], n[g], w_out[g], patch[g]
            if self.direction is not None and glossy_iterate:
                L[g] += self.incoming[pg] * mats.brdf(m, ng, self.receive_direction[pg], w, diffuse=False)
            for li in range(fs.n_lights):
                L[g] += fs.E[pg, li] * mats.brdf(m, ng, fs.direction[pg, li], w, diffuse=False)
        L[cos <= 0] = 0.0
        return L

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
        diffuse = self.kd_over_pi * (self.mean_incoming + self.first_shot.E.sum(axis=1))
        return le + self._diffuse_weighted(diffuse, self.patch_material, cos)

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


SOLVERS = {StochasticIterationSolver.name: StochasticIterationSolver}
