"""Stochastic iteration with single rays (thesis 1.1): light tracing with Russian roulette,
run as an iteration whose iterate is one photon hit.

A *chain* holds one photon hit: the point y on a surface, the travel direction d of the
light that arrived there and its power Phi [W]; the iterate's total power is
``Phi_tot = Phi_e + a(y, d) Phi``, Phi_e the power all lights emit (the one piece of global
knowledge) and a the albedo.  One step of a chain draws the next iterate:

1. with probability ``p_e = m(Phi_e) / (m(Phi_e) + m(a Phi))`` (m the mean over RGB) a new
   photon leaves a light: the light drawn with probability proportional to its power, a
   point and a direction drawn from its emission (:class:`LightEmission`), power
   ``Le cos / (p_light pdf_A pdf_w) / p_e``;
2. otherwise the photon scatters: a direction w drawn from the BRDF (the diffuse lobe by
   cosine or the glossy lobes, chosen by their albedos at d), power
   ``Phi f(d, w) cos_w / pdf(w) / (1 - p_e)`` with pdf the density of that mixture, so the
   weight is exact for any BRDF, reciprocal or not;
3. the ray is traced: where it meets the lit side of a reflecting surface, that is the new
   photon hit; where it leaves the scene or meets a black back, the chain holds no power
   and its next step emits.

With exact importance sampling and a grey albedo both branches give ``Phi' = Phi_tot``: the
power a chain carries tends to ``Phi_e / (1 - a)`` and stays bounded, and a walk goes on with
probability about a (the Russian roulette is the split).  Many independent chains advance
together (one Embree query per step for all of them).

The image of an iterate is ``M L_n = M Le + M (T* L_{n-1})``: the emission seen through each
pixel (one jittered camera ray per pixel per step) plus every chain's splat, the radiance
``f(d, w_e) Phi / dA`` its photon makes y reflect towards the eye, measured by the pixel y
lands on (box filter one pixel wide):

    dP = Phi f(d, w_e) cos_y density / K        [W m^-2 sr^-1]

``density`` :meth:`~raybundle.scene.camera.Camera.project`'s pixels per unit area facing the eye
(``fx fy / (r^2 cos^3 theta)`` for a pinhole), K the number of chains, after a shadow ray
from y to the eye.  The image is the running average of the iterates; it restarts once after
``burn_in`` steps, as the bundle iteration's does (the chains start with no power).

Where it fails (algorithms.md 1.1): surfaces seen by the camera are lit by one splat per
chain per step, so the image is far noisier than a gather; an ideal mirror seen by the eye is
black (f towards the eye is 0 almost surely) and a near-mirror reflects the lights as sparse
bright splats.  It draws its random numbers from the PRNG: it has no global directions for
the direction sequences to drive.
"""
from __future__ import annotations

import time
import warnings

import numpy as np

from ..imaging.progressive import ImagePasses, ProgressiveImage
from ..imaging.splat import splat_to_camera
from ..tracing.sampling import Stream, frames_from_normals, points_on_triangles, stream, uniform_sphere
from .base import Method, SolverStats


def _cosine_directions(normal, u):
    """Cosine-distributed unit directions (N, 3) about unit ``normal`` (N, 3) from ``u`` (N, 2)
    (density cos / pi)."""
    tu, tv = frames_from_normals(normal)
    phi, s = 2.0 * np.pi * u[:, 0], np.sqrt(u[:, 1])
    return (tu * (s * np.cos(phi))[:, None] + tv * (s * np.sin(phi))[:, None]
            + normal * np.sqrt(np.maximum(0.0, 1.0 - s * s))[:, None])


def _cone_directions(axis, cos_max, u):
    """Unit directions (N, 3) uniform in the cone of ``cos_max`` about ``axis`` (N, 3)
    (density 1 / (2 pi (1 - cos_max)))."""
    cos_t = 1.0 - u[:, 0] * (1.0 - cos_max)
    sin_t = np.sqrt(np.maximum(0.0, 1.0 - cos_t * cos_t))
    a, b = frames_from_normals(axis)
    phi = 2.0 * np.pi * u[:, 1]
    return cos_t[:, None] * axis + (sin_t * np.cos(phi))[:, None] * a + (sin_t * np.sin(phi))[:, None] * b


class LightEmission:
    """Every light of a scene as a source of photons: emitting triangles (both sides of
    two-sided ones), point and spot lights, Blender area lights, suns and the world.

    ``power`` (S,) is each source's emitted power [W] (mean over RGB; for emission that
    grows where the albedo falls, ``Le + c (1 - a)``, its bound ``Le + c``); sources are drawn
    in proportion to it, and :meth:`sample` returns photons whose powers are unbiased
    estimates of the power all lights emit, ``Phi_e``."""

    def __init__(self, scene, tracer):
        self.scene, self.tracer = scene, tracer
        mats = scene.materials
        self.radius = tracer.radius * 1.0001 + tracer.eps     # photons from afar start on this sphere
        sources = []                                          # (kind, index, power)
        tri = np.nonzero(mats.is_emitter[scene.triangle_material])[0]
        if len(tri):
            # one source for all emitting triangle sides, each drawn by its area x emission bound
            back = scene.triangle_back_tside[tri]
            self.emitting_tside = np.concatenate([tri, back[back >= 0]])
            t = scene.tside_triangle[self.emitting_tside]
            m = scene.triangle_material[t]
            bound = (mats.emission[m] + mats.emission_albedo_complement[m]).mean(axis=1)
            w = scene.triangle_area[t] * bound
            self.tside_cdf = np.cumsum(w) / w.sum()
            sources.append(("mesh", 0, np.pi * w.sum()))
        pl = scene.point_lights
        for k in range(len(pl)):
            cos_max = self._spot_cos(k)
            sources.append(("point", k, 2 * np.pi * (1 - cos_max) * float(np.mean(pl.intensity[k]))))
        al = scene.area_lights
        for k in range(len(al)):
            sources.append(("area", k, np.pi * float(al.area[k]) * float(np.mean(al.radiance[k]))))
        sl = scene.sun_lights
        for k in range(len(sl)):
            sources.append(("sun", k, np.pi * self.radius ** 2 * float(np.mean(sl.irradiance[k]))))
        env = float(np.mean(scene.world.mean()))
        if env > 0:
            sources.append(("world", 0, 4 * np.pi ** 2 * self.radius ** 2 * env))
        sources = [s for s in sources if s[2] > 0]
        if not sources:
            raise ValueError("the scene emits no light: nothing for light tracing to start from")
        self.sources = [(kind, k) for kind, k, _ in sources]
        self.power = np.array([p for _, _, p in sources])
        self.total = float(self.power.sum())
        self.cdf = np.cumsum(self.power) / self.total

    def _spot_cos(self, k):
        """cos of the half-angle of point light ``k``'s cone (-1: a point light, every direction)."""
        pl = self.scene.point_lights
        return float(pl.spot_cos_half_angle[k]) if np.any(pl.spot_direction[k] != 0) else -1.0

    def sample(self, n, rng):
        """``n`` photons leaving the lights: ``(origin (n, 3), direction (n, 3), power (n, 3))``,
        power [W] with ``E[power] = Phi_e`` (RGB), origins just off the emitting surface."""
        sc, eps, R = self.scene, self.tracer.eps, self.radius
        org, d, power = np.zeros((n, 3)), np.zeros((n, 3)), np.zeros((n, 3))
        src = np.minimum(np.searchsorted(self.cdf, rng.random(n), side="right"), len(self.cdf) - 1)
        p_src = np.diff(self.cdf, prepend=0.0)
        u = rng.random((n, 4))
        for s, (kind, k) in enumerate(self.sources):
            i = np.nonzero(src == s)[0]
            if not len(i):
                continue
            v = u[i]
            if kind == "mesh":
                j = np.minimum(np.searchsorted(self.tside_cdf, v[:, 0], side="right"), len(self.tside_cdf) - 1)
                p_ts = np.diff(self.tside_cdf, prepend=0.0)[j]
                ts = self.emitting_tside[j]
                t = sc.tside_triangle[ts]
                nrm = sc.tside_normal[ts]
                x = points_on_triangles(sc.triangle_corners[t], v[:, 1], rng.random(len(i)))
                w = _cosine_directions(nrm, v[:, 2:4])
                le = sc.materials.emitted_radiance(sc.triangle_material[t], np.einsum("ij,ij->i", nrm, w))
                org[i], d[i] = x + nrm * eps, w
                power[i] = le * (np.pi * sc.triangle_area[t] / p_ts)[:, None]
            elif kind == "point":
                pl = sc.point_lights
                cos_max = self._spot_cos(k)
                axis = pl.spot_direction[k] if cos_max > -1 else np.array([0.0, 0.0, 1.0])
                w = _cone_directions(np.broadcast_to(axis, (len(i), 3)), cos_max, v[:, :2])
                a, b = frames_from_normals(w)              # a disc of the light's radius facing w
                r, phi = float(pl.radius[k]) * np.sqrt(v[:, 2]), 2 * np.pi * v[:, 3]
                org[i] = pl.position[k] + (r * np.cos(phi))[:, None] * a + (r * np.sin(phi))[:, None] * b
                d[i] = w
                power[i] = (2 * np.pi * (1 - cos_max) * pl.spot_factor(k, w))[:, None] * pl.intensity[k]
            elif kind == "area":
                al = sc.area_lights
                if al.shape[k] == 1:
                    r, phi = np.sqrt(v[:, 0]), 2 * np.pi * v[:, 1]
                    a, b = r * np.cos(phi), r * np.sin(phi)
                else:
                    a, b = 2 * v[:, 0] - 1, 2 * v[:, 1] - 1
                nrm = np.broadcast_to(al.normal[k], (len(i), 3))
                org[i] = al.center[k] + a[:, None] * al.axis_u[k] + b[:, None] * al.axis_v[k] + nrm * eps
                d[i] = _cosine_directions(nrm, v[:, 2:4])
                power[i] = np.pi * float(al.area[k]) * al.radiance[k]
            else:                                          # sun or world: parallel light through a disc
                if kind == "sun":
                    sl = sc.sun_lights
                    w = _cone_directions(np.broadcast_to(sl.direction[k], (len(i), 3)),
                                         np.cos(0.5 * float(sl.angle[k])), v[:, :2])
                    power[i] = np.pi * R ** 2 * sl.irradiance[k]
                else:
                    w = uniform_sphere(v[:, 0], v[:, 1])
                    power[i] = 4 * np.pi ** 2 * R ** 2 * sc.world.radiance(-w)    # arriving from -w
                a, b = frames_from_normals(w)
                r, phi = R * np.sqrt(v[:, 2]), 2 * np.pi * v[:, 3]
                org[i] = (self.tracer.center - 1.01 * R * w + (r * np.cos(phi))[:, None] * a
                          + (r * np.sin(phi))[:, None] * b)
                d[i] = w
            power[i] /= p_src[s]
        return org, d, power


class SingleRayIteration(ProgressiveImage, Method):
    """Stochastic iteration with single rays, i.e. light tracing (module docstring).

    The interface of :class:`~raybundle.methods.path_tracing.PathTracer`: ``step`` advances every
    chain once, ``solver.stats.iterations`` counts the steps; it renders images only."""

    name = "single-ray-iteration"
    #: renders images only: :func:`~raybundle.app.pipeline.make_solver` refuses it
    image_only = True
    #: each step applies a random operator to the previous iterate
    iterates = True
    #: ``settings.sequence`` values it takes (the PRNG; ``stratified``, the default, means it)
    SEQUENCES = ("prng", "stratified")
    #: chains advanced per step: one per pixel, at least this many
    MIN_CHAINS = 4096
    #: the fewest steps left out of the running average (as the bundle iteration's)
    BURN_IN = 8

    def __init__(self, scene, tracer, direct, settings, camera=None):
        camera = scene.camera if camera is None else camera
        if camera is None:
            raise ValueError("the scene has no camera; give one (Camera.from_blender / Camera.look_at)")
        settings.validate()
        if settings.sequence not in self.SEQUENCES:
            raise ValueError(f"{self.name} draws its photons from the PRNG, not {settings.sequence!r} "
                             "(the direction sequences drive the bundle methods' global directions)")
        self.scene, self.camera, self.tracer, self.direct, self.settings = scene, camera, tracer, direct, settings
        if direct.linking is not None or not direct.casts_shadow.all():
            warnings.warn(f"{self.name} traces every lamp's photons to every surface: light linking and Cast Shadow "
                          "off are not honoured (the other methods honour them)", stacklevel=2)
        self.emission = LightEmission(scene, tracer)
        self.solver = ImagePasses(tracer, SolverStats(), name=self.name)
        self.rng = stream(settings.seed, Stream.LIGHT_TRACING)
        n_pix = camera.width * camera.height
        self.chains = max(self.MIN_CHAINS, n_pix)
        k = self.chains
        self.point, self.travel, self.normal = np.zeros((k, 3)), np.zeros((k, 3)), np.zeros((k, 3))
        self.triangle = np.zeros(k, np.int64)
        self.power = np.zeros((k, 3))                 # 0: the chain holds no photon, it emits next
        mats = scene.materials
        area = scene.triangle_area
        albedo = mats.albedo(scene.triangle_material, np.full(len(area), 0.7)).max(axis=1)
        mean_albedo = float(np.clip((area * albedo).sum() / max(area.sum(), 1e-300), 0.0, 0.999))
        self.burn_in = int(np.clip(np.ceil(np.log(0.01) / np.log(max(mean_albedo, 1e-3))), self.BURN_IN, 1000))
        py, px = np.divmod(np.arange(n_pix), camera.width)
        self._pixel = np.stack([px, py], axis=1).astype(float)
        self._emits = bool(mats.is_emitter.any() or np.any(scene.world.seen > 0))
        self.mean_image = np.zeros((n_pix, 3))
        self.passes = 0                  # steps (iterates) so far
        self.averaged = 0
        self.image_rays = 0
        self.emitted = 0                 # photons that left a light
        self.scattered = 0               # photons that scattered

    def step(self):
        self.image_pass()

    def image_pass(self):
        """Every chain one step, and this iterate's image into the running average."""
        t0 = time.perf_counter()
        iterate = self._seen_emission() + self._advance()
        self.passes += 1
        self.averaged = self.passes - (self.burn_in if self.passes > self.burn_in else 0)
        self.mean_image += (iterate - self.mean_image) / self.averaged
        st = self.solver.stats
        st.iterations = self.passes
        st.seconds += time.perf_counter() - t0

    def _seen_emission(self):
        """M Le (n_pix, 3): the emission one jittered camera ray per pixel meets."""
        out = np.zeros((len(self._pixel), 3))
        if not self._emits:
            return out
        sc = self.scene
        jitter = self.rng.random((len(self._pixel), 2))
        pos = self._pixel + self.camera.subpixel(jitter)                     # the pixel filter's
        org, w = self.camera.rays(pos[:, 0], pos[:, 1])
        tri, _, _, _ = self.tracer.first_hit(org, w)
        self.image_rays += len(org)
        hit = tri >= 0
        out[~hit] = sc.world.radiance(w[~hit], camera=True)
        h = np.nonzero(hit)[0]
        nrm = sc.tside_normal[sc.seen_tside(tri[h], w[h])]
        out[h] = sc.materials.emitted_radiance(sc.triangle_material[tri[h]], -np.einsum("ij,ij->i", nrm, w[h]))
        return out

    def _advance(self):
        """Every chain's next photon hit (module docstring, steps 1-3) and its splat, (n_pix, 3)."""
        sc, mats, tr = self.scene, self.scene.materials, self.tracer
        k = self.chains
        phi, held = self.power, np.any(self.power > 0, axis=1)
        mat = sc.triangle_material[self.triangle]
        cos_in = -np.einsum("ij,ij->i", self.normal, self.travel)
        tex = (np.ones((k, 3)) if sc.texture is None else
               sc.texture.at(sc.triangle_source[self.triangle], self.point))
        a_d = np.where(held[:, None], mats.albedo(mat, cos_in, glossy=False) * tex, 0.0)
        a_g = np.where(held[:, None], mats.albedo(mat, cos_in, diffuse=False), 0.0)
        reflected = ((a_d + a_g) * phi).mean(axis=1)
        p_emit = self.emission.total / (self.emission.total + reflected)
        u = self.rng.random((k, 4))
        emit = u[:, 0] < p_emit
        org, w, power = np.zeros((k, 3)), np.zeros((k, 3)), np.zeros((k, 3))
        e = np.nonzero(emit)[0]
        if len(e):
            org[e], w[e], power[e] = self.emission.sample(len(e), self.rng)
            power[e] /= p_emit[e][:, None]
            self.emitted += len(e)
        s = np.nonzero(~emit)[0]
        if len(s):
            org[s], w[s], power[s] = self._scatter(s, mat[s], a_d[s].mean(axis=1), a_g[s].mean(axis=1), tex[s],
                                                   u[s, 1:])
            power[s] /= (1.0 - p_emit[s])[:, None]
            self.scattered += len(s)
        # trace every chain's ray; the lit side of a reflecting surface holds the new photon
        tri, t, _, _ = tr.first_hit(org, w)
        self.image_rays += k
        hit = tri >= 0
        ts = sc.seen_tside(np.where(hit, tri, 0), w)
        nrm = sc.tside_normal[ts]
        lit = hit & (np.einsum("ij,ij->i", nrm, w) < 0) & mats.reflects[sc.triangle_material[np.where(hit, tri, 0)]]
        self.power = np.where(lit[:, None], power, 0.0)
        self.point = org + np.where(hit, t, 0.0)[:, None] * w
        self.travel, self.normal, self.triangle = w, nrm, np.where(hit, tri, 0)
        return self._splat(np.nonzero(lit)[0])

    def _scatter(self, s, mat, sd, sg, tex, u):
        """Chains ``s`` scatter their photons: ``(origin, direction, Phi f cos_w / pdf(w))``,
        the lobe drawn by the albedos ``sd``, ``sg`` (mean RGB) and pdf the mixture's density."""
        mats = self.scene.materials
        nrm, d, x = self.normal[s], self.travel[s], self.point[s]
        q = np.where(sd + sg > 0, sg / np.maximum(sd + sg, 1e-300), 0.0)
        take_glossy = u[:, 0] < q
        w = np.empty((len(s), 3))
        dl = np.nonzero(~take_glossy)[0]
        w[dl] = _cosine_directions(nrm[dl], u[dl, 1:3])
        gl = np.nonzero(take_glossy)[0]
        if len(gl):
            w[gl], _ = mats.sample_glossy(mat[gl], nrm[gl], -d[gl], u[gl, 1:3])
        cos_w = np.einsum("ij,ij->i", nrm, w)
        pdf = (1.0 - q) * np.maximum(cos_w, 0.0) / np.pi
        g = np.nonzero(q > 0)[0]
        if len(g):
            pdf[g] += q[g] * mats.glossy_pdf(mat[g], nrm[g], w[g], -d[g])
        f = mats.brdf(mat, nrm, d, w, diffuse_scale=tex)
        ok = (cos_w > 0) & (pdf > 0)
        weight = np.where(ok[:, None], f * (np.maximum(cos_w, 0.0) / np.maximum(pdf, 1e-300))[:, None], 0.0)
        return x + nrm * self.tracer.eps, w, self.power[s] * weight

    def _splat(self, h):
        """The image (n_pix, 3) of the photon hits ``h``: each one's reflected radiance towards
        the eye, ``Phi f(d, w_e) cos_y density / K``, where a shadow ray reaches the eye."""
        out = np.zeros((len(self._pixel), 3))
        pix, value, rays = splat_to_camera(self.scene, self.camera, self.tracer, self.point[h], self.normal[h],
                                           self.triangle[h], self.travel[h], self.power[h] / self.chains)
        self.image_rays += rays
        for k in range(3):
            out[:, k] = np.bincount(pix, value[:, k], minlength=len(out))
        return out

    def image(self, preview=False):
        """The running average of the iterates (H, W, 3) float32 [W m^-2 sr^-1]."""
        return self.mean_image.reshape(self.camera.height, self.camera.width, 3).astype(np.float32)

    def stats(self, total_seconds, resolve_seconds=0.0, cancelled=False):
        """The run's figures as a plain dict, with the keys :meth:`Renderer.stats` has."""
        return {"scene": self.scene.name, "solver": self.name, "iterations": self.passes,
                "seconds": round(total_seconds, 4), "solver_seconds": round(self.solver.stats.seconds, 4),
                "resolve_seconds": round(resolve_seconds, 4), "rays_traced": int(self.image_rays),
                "image_rays": int(self.image_rays), "image_passes": self.passes, "photon_chains": self.chains,
                "burn_in": self.burn_in, "photons_emitted": int(self.emitted),
                "mean_path_length": (self.emitted + self.scattered) / max(self.emitted, 1),
                "patches": int(self.scene.n_patches), "triangles": int(len(self.scene.triangles)),
                "resolution": [self.camera.width, self.camera.height], "sampler": "prng",
                "sequence": self.settings.sequence, "seed": self.settings.seed, "diffuse_only": False,
                "lights": len(self.emission.sources), "cancelled": cancelled}
