"""Path tracing: the random walk of thesis 2 and 2.1, the unbiased baseline and a reference
that needs no Blender.

Each pass traces one path per pixel (all paths of a pass advance together, one Embree
query per bounce).  At every surface point x the walk estimates

    L(x, w_o) = Le(x, w_o) + integral f(w_i, w_o) L(h(x, w_i), -w_i) cos_i dw_i

with three unbiased pieces:

* **next-event estimation**: the first-shot lights (small mesh emitters, point, spot,
  area and sun lights; :class:`~raybundle.lights.direct.DirectLighting`) by one light sample per
  light, :func:`~raybundle.lights.reflected_direct.reflected_radiance`;
* **BRDF importance sampling** of the next direction: the diffuse lobe (cosine-distributed)
  with probability ``a_d / (a_d + a_g)``, else the glossy lobes
  (:meth:`~raybundle.scene.materials.MaterialTable.sample_glossy`), ``a_d`` and ``a_g`` the
  lobes' directional albedos at ``w_o`` (RGB mean).  A glossy-lobe ray that meets a
  first-shot mesh light adds its emission with the power-heuristic weight against the
  light sample (:meth:`~raybundle.lights.direct.DirectLighting.lobe_hits_light`), so sharp lobes
  reflecting a lamp do not make fireflies; a diffuse-lobe ray adds nothing there (the
  light sample covers the whole diffuse lobe).  Emitters that are not first-shot lights
  (large glowing surfaces, the furnaces' walls) and the world count where a ray meets them;
* **Russian roulette** from :data:`ROULETTE_DEPTH` bounces on, survival probability
  ``min(1, max_rgb throughput)``.

The pixel value is the mean of the passes, each at a position in the pixel drawn from the
camera's pixel filter as Cycles draws it (:meth:`~raybundle.scene.camera.Camera.subpixel`).  Random numbers come from a PRNG or,
with ``sequence="halton"``, from a randomised quasi-Monte Carlo walk: pass ``n`` uses Halton
point ``n``, digit-scrambled once per run and shifted per pixel (Cranley-Patterson rotation), for its first
:data:`QMC_DIMENSIONS` numbers (the jitter, the first bounces), the PRNG after, so the
thesis' observation that the low-discrepancy gain shrinks as walks get long can be measured.
"""
from __future__ import annotations

import time

import numpy as np

from ..imaging.progressive import ImagePasses, ProgressiveImage
from ..lights.reflected_direct import reflected_radiance
from ..tracing.sampling import Stream, frames_from_normals, halton_permutations, halton_points, stream
from .base import Method, SolverStats

#: bounces before Russian roulette starts
ROULETTE_DEPTH = 3
#: hard cap on the walk's length (reached only with albedos near 1; the roulette ends walks first)
MAX_DEPTH = 256
#: leading random numbers of a path drawn from the Halton sequence in QMC mode
QMC_DIMENSIONS = 24


class _PassUniforms:
    """The random numbers of one pass: ``take(pix, k)`` gives (len(pix), k) numbers for the
    paths of pixels ``pix``, dimension after dimension along each path."""

    def __init__(self, rng, index=None, shift=None, permutations=None):
        self.rng, self.shift, self.dim = rng, shift, 0
        self.point = None if shift is None else halton_points(index, shift.shape[1], permutations)

    def take(self, pix, k):
        out = self.rng.random((len(pix), k))
        if self.shift is not None and self.dim < self.shift.shape[1]:
            n = min(k, self.shift.shape[1] - self.dim)
            d = slice(self.dim, self.dim + n)
            out[:, :n] = (self.point[d] + self.shift[pix, d]) % 1.0
        self.dim += k
        return out


class PathTracer(ProgressiveImage, Method):
    """Unidirectional path tracing with next-event estimation (module docstring).

    The same interface as :class:`~raybundle.imaging.renderer.Renderer` (``run``, ``step``,
    ``image``, ``stats``; ``solver.stats.iterations`` counts passes, i.e. samples per
    pixel); it has no patch solution, so it renders images but does not bake."""

    name = "path-tracing"
    #: renders images only: :func:`~raybundle.app.pipeline.make_solver` refuses it
    image_only = True
    #: ``settings.sequence`` values: the PRNG (``stratified``, the default, means it too) or
    #: randomised Halton points
    SEQUENCES = ("prng", "stratified", "halton")

    def __init__(self, scene, tracer, direct, settings, camera=None):
        camera = scene.camera if camera is None else camera
        if camera is None:
            raise ValueError("the scene has no camera; give one (Camera.from_blender / Camera.look_at)")
        settings.validate()
        if settings.sequence not in self.SEQUENCES:
            raise ValueError(f"path tracing draws its paths from {' or '.join(self.SEQUENCES)}, not "
                             f"{settings.sequence!r} (that one drives the iteration methods' directions)")
        self.scene, self.camera, self.tracer, self.direct, self.settings = scene, camera, tracer, direct, settings
        self.solver = ImagePasses(tracer, SolverStats(), name=self.name)
        self.rng = stream(settings.seed, Stream.PATH_TRACING)
        n = camera.width * camera.height
        self.qmc = settings.sequence == "halton"
        self._shift = self.rng.random((n, QMC_DIMENSIONS)) if self.qmc else None
        self._scramble = halton_permutations(QMC_DIMENSIONS, self.rng) if self.qmc else None
        py, px = np.divmod(np.arange(n), camera.width)
        self._pixel = np.stack([px, py], axis=1).astype(float)
        self.pass_sum = np.zeros((n, 3))
        self.passes = 0
        self.image_rays = 0
        self.path_vertices = 0
        mats = scene.materials
        self._reflects = mats.reflects
        self._glossy = mats.is_glossy
        self._k_light = direct.samples_per_pass(1)

    def step(self):
        self.image_pass()

    def image_pass(self):
        """One path per pixel, added to the running sum."""
        t0 = time.perf_counter()
        u = _PassUniforms(self.rng, self.passes, self._shift, self._scramble)
        n = len(self._pixel)
        pix = np.arange(n)
        jitter = u.take(pix, 2)
        pos = self._pixel + self.camera.subpixel(jitter)                     # the pixel filter's
        org, w = self.camera.rays(pos[:, 0], pos[:, 1])
        self.pass_sum += self.trace(org, w, pix, u)
        self.passes += 1
        self.solver.stats.iterations = self.passes
        self.solver.stats.seconds += time.perf_counter() - t0

    def trace(self, org, w, pix, u):
        """Radiance (N, 3) along rays ``org`` + t ``w`` (N, 3) whose paths draw their random
        numbers for pixels ``pix`` (N,) from ``u`` (:class:`_PassUniforms`)."""
        sc, mats, direct, tr = self.scene, self.scene.materials, self.direct, self.tracer
        out = np.zeros((len(org), 3))
        row = np.arange(len(org))                  # the output row of each live path
        throughput = np.ones((len(org), 3))
        prev = None                                # (point, material, normal, w_out, glossy ray) left from
        for depth in range(MAX_DEPTH):
            if len(row) == 0:
                break
            tri, t, _, _ = tr.first_hit(org, w)
            self.image_rays += len(row)
            hit = tri >= 0
            if sc.world.emits or (depth == 0 and np.any(sc.world.seen > 0)):   # the world, as the camera sees it
                np.add.at(out, row[~hit], throughput[~hit] * sc.world.radiance(w[~hit], camera=depth == 0))
            h = np.nonzero(hit)[0]
            row, pix, tri, t, w, throughput = row[h], pix[h], tri[h], t[h], w[h], throughput[h]
            x = org[h] + t[:, None] * w
            self.path_vertices += len(h)
            ts = sc.seen_tside(tri, w)
            nrm, mat, w_out = sc.tside_normal[ts], sc.triangle_material[tri], -w
            cos_o = np.einsum("ij,ij->i", nrm, w_out)
            # emission met by the ray: all of it from the eye and for emitters no light samples;
            # first-shot lights met by a glossy-lobe ray, MIS-weighted against the light sample
            le = mats.emitted_radiance(mat, cos_o)
            sampled = direct.triangle_light[tri] >= 0
            if depth > 0:
                le[sampled] = 0.0
                p_pt, p_mat, p_n, p_wo, p_glossy, p_tri = (a[h] for a in prev)
                g = np.nonzero(sampled & p_glossy)[0]
                if len(g):
                    le[g] = direct.lobe_hits_light(p_pt[g], p_mat[g], p_n[g], p_wo[g], w[g], tri[g], x[g], 1,
                                                   receivers=sc.link_groups(p_tri[g]))
            out[row] += throughput * le
            # surfaces that reflect, seen from their front
            f = np.nonzero((cos_o > 0) & self._reflects[mat])[0]
            row, pix, tri, x, nrm, mat, w_out, cos_o, throughput = (
                a[f] for a in (row, pix, tri, x, nrm, mat, w_out, cos_o, throughput))
            if len(row) == 0:
                break
            tex = None if sc.texture is None else sc.texture.at(sc.triangle_source[tri], x)
            glossy = self._glossy[mat]
            u_light = u.take(pix, 3 * self._k_light).reshape(len(pix), self._k_light, 3)
            if direct.n_lights:
                before = direct.rays
                out[row] += throughput * reflected_radiance(direct, x, nrm, mat, w_out, u_light, 1, mis=glossy,
                                                                   diffuse_scale=tex, receivers=sc.link_groups(tri))
                self.image_rays += direct.rays - before
            r = u.take(pix, 4)
            w_next, weight, take_glossy = self._next_direction(mat, nrm, w_out, cos_o, tex, r)
            throughput = throughput * weight
            if depth + 1 >= ROULETTE_DEPTH:
                p = np.minimum(1.0, throughput.max(axis=1))
                live = r[:, 3] < p
                throughput = throughput / np.maximum(p, 1e-300)[:, None]
            else:
                live = np.ones(len(row), bool)
            live &= np.any(throughput > 0, axis=1)
            k = np.nonzero(live)[0]
            prev = (x[k], mat[k], nrm[k], w_out[k], take_glossy[k], tri[k])
            org, w = x[k] + nrm[k] * tr.eps, w_next[k]
            row, pix, throughput = row[k], pix[k], throughput[k]
        return out

    def _next_direction(self, mat, nrm, w_out, cos_o, tex, r):
        """``(w, weight, glossy)`` of the paths' next rays: one lobe, chosen by its albedo
        (``glossy`` (N,) bool: the glossy one), its direction from uniforms ``r`` (N, 4; columns
        1-2) and the sample's weight ``f cos / pdf`` (N, 3)."""
        mats = self.scene.materials
        a_d = mats.albedo(mat, cos_o, glossy=False)
        if tex is not None:
            a_d = a_d * tex
        a_g = mats.albedo(mat, cos_o, diffuse=False)
        sd, sg = a_d.mean(axis=1), a_g.mean(axis=1)
        q = np.where(sd + sg > 0, sg / np.maximum(sd + sg, 1e-300), 0.0)
        take_glossy = r[:, 0] < q
        w_next = np.empty_like(w_out)
        weight = np.zeros_like(a_d)
        d = np.nonzero(~take_glossy)[0]
        if len(d):
            tu, tv = frames_from_normals(nrm[d])
            phi, s = 2.0 * np.pi * r[d, 1], np.sqrt(r[d, 2])
            w_next[d] = (tu * (s * np.cos(phi))[:, None] + tv * (s * np.sin(phi))[:, None]
                         + nrm[d] * np.sqrt(np.maximum(0.0, 1.0 - s * s))[:, None])
            weight[d] = a_d[d] / (1.0 - q[d])[:, None]         # f_d cos / pdf = W_d kd
        gi = np.nonzero(take_glossy)[0]
        if len(gi):
            w_next[gi], wg = mats.sample_glossy(mat[gi], nrm[gi], w_out[gi], r[gi, 1:3])
            weight[gi] = wg / q[gi][:, None]
        return w_next, weight, take_glossy

    def image(self, preview=False):
        """The mean of the passes (H, W, 3) float32 [W m^-2 sr^-1]."""
        img = self.pass_sum / max(self.passes, 1)
        return img.reshape(self.camera.height, self.camera.width, 3).astype(np.float32)

    def stats(self, total_seconds, resolve_seconds=0.0, cancelled=False):
        """The run's figures as a plain dict, with the keys :meth:`Renderer.stats` has."""
        return {"scene": self.scene.name, "solver": self.name, "iterations": self.passes, "samples_per_pixel": self.passes,
                "seconds": round(total_seconds, 4), "solver_seconds": round(self.solver.stats.seconds, 4),
                "resolve_seconds": round(resolve_seconds, 4), "rays_traced": int(self.image_rays),
                "image_rays": int(self.image_rays), "image_passes": self.passes,
                "mean_path_length": self.path_vertices / max(self.passes * len(self._pixel), 1),
                "patches": int(self.scene.n_patches), "triangles": int(len(self.scene.triangles)),
                "resolution": [self.camera.width, self.camera.height], "sampler": "halton" if self.qmc else "prng",
                "sequence": self.settings.sequence, "seed": self.settings.seed, "diffuse_only": False,
                "first_shot_lights": self.direct.n_lights, "light_tree": self.direct.tree is not None,
                "cancelled": cancelled}
