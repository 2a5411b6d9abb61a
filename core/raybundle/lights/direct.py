"""Direct illumination by the small lights, per point: the generalized (incoming) first shot.

Thesis 3.4: small and point lights are hard for bundles (a bundle hits a small
light with probability ~ its solid angle / 4 pi, and never hits a point light).
Their emission ``Le_s`` is therefore taken out of the iteration: the incoming
radiance they create is computed first, by shadow rays, and the iteration then
solves ``L~ = (Le_r + L1) + T L~`` with ``L1 = T Le_s`` as extra emission.

:class:`DirectLighting` holds the first-shot lights of a scene
(:mod:`raybundle.lights.sources`) and estimates, per pixel at the visible point, the
reflected direct radiance with fresh shadow rays every image pass, so shadows and glossy
highlights are sharp (:func:`raybundle.lights.reflected_direct.reflected_radiance`); per patch, the first shot
is :class:`raybundle.lights.first_shot.PatchFirstShot`.
"""
from __future__ import annotations

import threading
from functools import partial

import numpy as np

from ..tracing.sampling import kronecker_alpha
from ..util import compiled
from . import compiled_lights
from .light_tree import build_light_tree
from .polygon import light_polygon_irradiance
from .sources import MeshLight, PointLight, ShapeLight, SunLight, sample_point_lights, small_emitters

#: guards the shadow-ray count: pieces of a query run on threads (RayTracer.map_pieces)
_COUNTING = threading.Lock()
#: a light mask with every light's bit set (:func:`light_bits`)
ALL_LIGHTS = np.uint64(0xFFFF_FFFF_FFFF_FFFF)
def light_bits(n):
    """(n,) uint64: the bit of each of ``n`` lights in per-light masks (shadow flags), light
    ``l``'s bit ``min(l, 63)``: lights past the 64th share the last bit, which then stands
    for any of them (a per-pixel mask stays 8 bytes, however many lamps)."""
    return np.left_shift(np.uint64(1), np.minimum(np.arange(n), 63).astype(np.uint64))


def may_light(light, points, normals):
    """(N,) bool: some sample of ``light`` may light ``points`` (N, 3) with unit ``normals``
    (N, 3): part of the light lies above their tangent planes, and a one-sided area light
    faces them.  Elsewhere every sample's ``e cos_x`` is 0."""
    if isinstance(light, ShapeLight) and compiled.use():
        return compiled_lights.shape_reach(light, points, normals)
    ok = light.in_front(points, normals)
    if isinstance(light, ShapeLight):
        ok &= (points - light.center) @ light.normal > 0
    return ok


def seen_blocked(e, free):
    """(N,) bool each: the sample reached its light (``e`` (N, 3), shadowed estimate);
    it faced the light but was blocked (``free``, the unshadowed estimate)."""
    seen = np.any(e > 0, axis=1)
    return seen, np.any(free > 0, axis=1) & ~seen


class TreeLights:
    """The light tree's lamps as one light for the estimators that take every light on its own
    (the per-patch first shot and its caustics, bakes, the far side of translucent surfaces):
    each sample an emitter chosen at its point (:meth:`DirectLighting.tree_sample`), so their
    cost does not grow with the lamps."""

    def __init__(self, direct):
        self.direct = direct

    def in_front(self, origin, normal):
        return np.ones(len(origin), bool)


class DirectLighting:
    """First-shot lights of a scene and the direct-illumination estimators."""

    def __init__(self, scene, tracer, first_shot="auto", small_fraction=0.1, light_tree="auto"):
        if first_shot not in ("auto", "none"):
            raise ValueError("first_shot must be 'auto' or 'none'")
        if light_tree not in ("auto", "on", "off"):
            raise ValueError("light_tree must be 'auto', 'on' or 'off'")
        self.scene = scene
        self.tracer = tracer
        self.rays = 0  # shadow rays traced so far
        # area_lights: sampled ``samples_per_light`` times per point (mesh and shape lights);
        # point_lights: one sample per point (point, spot and sun lights)
        mats = scene.materials
        self.first_shot_material = np.zeros(len(mats), bool)
        self.area_lights: list[MeshLight] = []
        if first_shot == "auto":
            emitter = (None if scene.linking is None else
                       scene.linking.face_emitter[scene.triangle_source])     # each face's link set
            for m in small_emitters(scene, small_fraction):
                every = np.nonzero(scene.triangle_material == m)[0]
                self.first_shot_material[m] = True
                sets = np.zeros(len(every), np.int64) if emitter is None else emitter[every]
                for s in np.unique(sets):         # one light per link set of the material's faces
                    tri = every[sets == s]
                    cdf = np.cumsum(scene.triangle_area[tri])
                    light = MeshLight(int(m), tri, cdf / cdf[-1], float(scene.triangle_area[tri].sum()),
                                      mats.emission[m].astype(float), scene.triangle_two_sided[tri], scene)
                    light.link = int(s)
                    self.area_lights.append(light)
        pl = scene.point_lights
        self.point_lights = [PointLight(pl.position[k], pl.intensity[k] * pl.peak_factor(k), pl, k)
                             for k in range(len(pl))
                             if np.any(pl.intensity[k] > 0)]
        al = scene.area_lights
        self.area_lights += [ShapeLight(al.center[k], al.axis_u[k], al.axis_v[k], al.normal[k], bool(al.shape[k] == 1),
                                        float(al.area[k]), al.radiance[k], bool(al.shadow[k] > 0), int(al.link[k]))
                             for k in range(len(al))
                             if np.any(al.radiance[k] > 0)]
        # mesh-light triangles: which light (index into light_list()) and which of its triangles
        self.triangle_light = np.full(len(scene.triangles), -1, np.int64)
        self.triangle_light_k = np.zeros(len(scene.triangles), np.int64)
        for li, light in enumerate(self.area_lights):
            if isinstance(light, MeshLight):
                self.triangle_light[light.triangles] = li
                self.triangle_light_k[light.triangles] = np.arange(len(light.triangles))
        sl = scene.sun_lights
        far = 4.0 * tracer.radius + 1.0
        self.point_lights += [SunLight(sl.direction[k], sl.irradiance[k], float(sl.angle[k]), far, bool(sl.shadow[k] > 0),
                                       int(sl.link[k]))
                              for k in range(len(sl)) if np.any(sl.irradiance[k] > 0)]
        #: lamps and emitting triangles chosen by their contribution (:mod:`raybundle.lights.light_tree`)
        #: in :func:`~raybundle.lights.reflected_direct.reflected_radiance`, or None: each light sampled on its own
        self.tree = None
        lights = self.light_list()
        #: per light of :meth:`light_list`, whether anything blocks its direct light (Cast Shadow)
        self.casts_shadow = np.array([light.shadow for light in lights], bool)
        #: per light of :meth:`light_list`, its link set, and the scene's linking (None when no light
        #: is linked: every light lights every surface)
        self.light_link = np.array([light.link for light in lights], np.int64)
        self.linking = scene.linking if self.light_link.any() else None
        self._index = {id(light): li for li, light in enumerate(lights)}
        self.suns = [li for li, light in enumerate(lights) if isinstance(light, SunLight)]
        if light_tree == "on" or (light_tree == "auto" and self.wants_tree(lights)):
            self.tree = build_light_tree(lights)
        if self.tree is not None:
            #: per light, its first emitter in the tree (a mesh light's triangle k is first + k)
            self.tree_first = np.searchsorted(self.tree.light, np.arange(len(lights)))
            bits = light_bits(len(lights))
            self.tree_mask = np.bitwise_or.reduce(bits[[li for li in range(len(lights)) if li not in self.suns]])
            #: per emitter, its radiance (N, 3) (0 for point lights, which no ray meets)
            radiance = np.array([getattr(light, "radiance", np.zeros(3)) for light in lights], float)
            self.tree_radiance = radiance[self.tree.light]
            #: per light, its row of the scene's point lights (-1: not a point light)
            self._point_row = np.array([light.k if isinstance(light, PointLight) else -1 for light in lights])

    @property
    def n_lights(self):
        return len(self.area_lights) + len(self.point_lights)

    #: :meth:`wants_tree`: a light tree where there are more lamps than this
    TREE_MIN_LIGHTS = 16

    @classmethod
    def wants_tree(cls, lights):
        """Whether ``light_tree='auto'`` builds a light tree: many lamps, each of which would
        otherwise cost a shadow ray at every point.  A few lamps are each sampled at every
        point: the tree's one choice among them ignores the BRDF, so a sharp lobe's small bright
        lamp, chosen rarely, is left to the lobe's rays (docs/benchmarks.md, the table of methods)."""
        return sum(not isinstance(light, SunLight) for light in lights) > cls.TREE_MIN_LIGHTS

    def tree_sample(self, points, normals, u):
        """One sample of the tree's lights for each point (N, 3) with unit ``normals``, from
        uniforms ``u`` (N, 3): an emitter chosen by the tree with probability P (``u[:, 0]``),
        then sampled on its own (``u[:, 1:]``).  Returns ``(y (N, 3), e (N, 3), emitter (N,))``,
        ``e`` the emitter's unshadowed estimate divided by P (0 where the tree gives the point
        nothing, ``emitter`` -1 there): as :meth:`~raybundle.lights.sources.MeshLight.sample`."""
        tree, lights = self.tree, self.light_list()
        em, p, u0 = tree.sample(points, normals, u[:, 0])
        y, e = np.zeros((len(points), 3)), np.zeros((len(points), 3))
        em = np.where(p > 0, em, -1)
        lid = np.where(em >= 0, tree.light[np.maximum(em, 0)], -1)
        row = np.where(lid >= 0, self._point_row[np.maximum(lid, 0)], -1)
        i = np.nonzero(row >= 0)[0]
        if len(i):                  # the point lights at once
            y[i], e[i] = sample_point_lights(self.scene.point_lights, row[i], points[i], u[i, 1:])
        for li in np.unique(lid[(lid >= 0) & (row < 0)]):      # the others light by light
            light = lights[li]
            i = np.nonzero(lid == li)[0]
            if isinstance(light, MeshLight):
                y[i], e[i] = light.sample_triangle(points[i], tree.k[em[i]], u[i, 1], u[i, 2])
            else:
                y[i], e[i] = light.sample(points[i], np.stack([u[i, 1], u[i, 2], u0[i]], axis=1))
        e /= np.where(p > 0, p, 1.0)[:, None]
        return y, e, em

    def tree_pdf(self, lights_hit, k, points, normals, y):
        """(N,) the density [1/sr] with which :meth:`tree_sample` draws, from ``points`` (N, 3)
        with unit ``normals``, the direction to ``y`` (N, 3) on light ``lights_hit`` (N,)
        (its triangle ``k`` for a mesh light): the tree's probability times the emitter's own."""
        lights = self.light_list()
        em = self.tree_first[lights_hit] + k
        out = self.tree.pdf(em, points, normals)
        for li in np.unique(lights_hit):
            i = np.nonzero(lights_hit == li)[0]
            light = lights[li]
            out[i] *= light.triangle_pdf(points[i], k[i], y[i]) if isinstance(light, MeshLight) else \
                light.pdf(points[i], y[i])
        return out

    def light_samples_at(self, points, normals, light, u, unshadowed=False, crossed=None, receivers=None,
                         origins=None, terminator=None):
        """One sample of every point's irradiance from one light.

        Returns ``(E (N,3) [W/m^2], travel (N,3), cos_x (N,))`` where E already
        includes visibility, so ``E f(travel, w_out)`` is the reflected radiance;
        with ``unshadowed``, also E without the visibility test (4th item).  ``crossed``: an
        (N,) bool array to mark the points whose shadow ray passed a cut-out or glass.
        ``receivers``: the points' link groups (:meth:`~raybundle.scene.model.PatchScene.link_groups`)
        or None.  A light that casts no shadow (:attr:`casts_shadow`) is not blocked; a linked
        light lights only the groups it reaches and is blocked only by those that block it
        (:mod:`raybundle.scene.linking`).  ``origins`` (N, 3): where the shadow rays leave from, when not
        ``points`` (where the light is sampled and its cosine taken); ``terminator`` as
        :meth:`shadowed`'s.
        """
        if isinstance(light, TreeLights):
            y, e, em = self.tree_sample(points, normals, u)
            ids = np.where(em >= 0, self.tree.light[np.maximum(em, 0)], -1)
        else:
            y, e = light.sample(points, u)
            ids = self._index[id(light)]
        return self.shadowed(points, normals, y, e, unshadowed, crossed, ids, receivers, origins, terminator)

    def shadowed(self, points, normals, y, e, unshadowed=False, crossed=None, lights=None, receivers=None,
                 origins=None, terminator=None):
        """:meth:`light_samples_at` for light samples ``y``, ``e`` (N, 3) drawn already from
        ``lights`` (an index into :meth:`light_list`, or (N,) of them, -1 for none; None: lights
        that cast shadows and are not linked).  ``terminator``: the points'
        :class:`~raybundle.scene.shading.ShadowTerminator` or None: the shadow rays of lights
        grazing the facet leave from Cycles' lifted origin."""
        unblocked = link = None
        if lights is not None:
            ids = np.maximum(lights, 0)
            if not self.casts_shadow.all():
                unblocked = ~self.casts_shadow[ids]
            if self.linking is not None:
                link = self.light_link[ids]
                if receivers is not None:
                    e *= self.linking.receives[link, receivers][:, None]
        if compiled.use():
            w, cos_x, live, org_all, dir_all, t_all, e = compiled_lights.shadow_geometry(points, normals, y, e,
                                                                                       self.tracer.eps)
            free = e.copy() if unshadowed else None
        else:
            v = y - points
            r = np.sqrt(np.maximum(np.einsum("ij,ij->i", v, v), 1e-300))
            w = v / r[:, None]                      # from the point towards the light
            cos_x = np.einsum("ij,ij->i", normals, w)
            e *= np.maximum(cos_x, 0.0)[:, None]
            free = e.copy() if unshadowed else None
            live = np.any(e > 0, axis=1)
            org_all = None
        if origins is not None:                     # the shadow rays leave from elsewhere
            org_all, points = None, origins
        if terminator is not None:
            lifted = terminator.origins(points, w, cos_x)
            if lifted is not None:
                org_all, points = None, lifted
        if unblocked is not None:
            live &= ~np.broadcast_to(unblocked, live.shape)
        if live.any():
            if org_all is None:
                eps = self.tracer.eps
                # shadow ray from just above the surface *to the light sample itself*
                # (a ray shifted parallel would meet a grazing light plane early)
                org = points[live] + normals[live] * eps
                seg = y[live] - org
                dist = np.linalg.norm(seg, axis=1)
                direction, t_max = seg / np.maximum(dist, 1e-300)[:, None], np.maximum(dist - 2 * eps, 0.0)
            else:
                org, direction, t_max = org_all[live], dir_all[live], t_all[live]
            with _COUNTING:
                self.rays += int(live.sum())
            through = None if crossed is None else np.zeros(len(org), bool)
            blocked = self.tracer.occluded(org, direction, t_max, crossed=through,
                                           link=None if link is None else np.broadcast_to(link, live.shape)[live])
            if through is not None:
                crossed[np.nonzero(live)[0][through]] = True
            idx = np.nonzero(live)[0][blocked]
            e[idx] = 0.0
        return (e, -w, cos_x, free) if unshadowed else (e, -w, cos_x)

    def light_list(self):
        return self.area_lights + self.point_lights

    def sampled_lights(self):
        """The lights the per-light estimators sample apart: :meth:`light_list`, or with a light
        tree, its lamps as one (:class:`TreeLights`) and the suns."""
        if self.tree is None:
            return self.light_list()
        lights = self.light_list()
        return [TreeLights(self)] + [lights[li] for li in self.suns]

    def sampled_apart(self):
        """The light masks (:func:`light_bits`) sampled apart in :func:`~raybundle.lights.reflected_direct.reflected_radiance`:
        one per light, or with a light tree, the tree's lights as one and each sun."""
        bits = light_bits(self.n_lights)
        return list(bits) if self.tree is None else [self.tree_mask] + [bits[li] for li in self.suns]

    def samples_per_pass(self, samples_per_light=1):
        """How many light samples :func:`~raybundle.lights.reflected_direct.reflected_radiance` draws per point."""
        if self.tree is not None:
            return samples_per_light + len(self.suns)
        return samples_per_light * len(self.area_lights) + len(self.point_lights)

    def irradiance(self, points, normals, rng, samples_per_light=16, penumbra_samples=None, receivers=None,
                   footprint=None, clamp=True, terminator=None):
        """Direct irradiance (N, 3) [W/m^2] of the first-shot lights at surface points
        with unit ``normals`` (N, 3), for bakes, where a point's value is final.

        Each light's estimate has two stages.  ``samples_per_light`` shadow rays first find
        whether a point is lit, shadowed or in a penumbra (some of them blocked, some not); the
        estimate then takes shadow rays of its own: ``penumbra_samples`` (default 16 times
        ``samples_per_light``) in a penumbra, where the estimate's error dominated the bake's
        (docs/benchmarks.md, 'Measured choices behind the defaults'); elsewhere a quarter as many
        (at least one) for a polygonal light, whose estimate is exact unless a ray is blocked, and
        as many for other lights.  Since the first stage decides only which estimator and how many
        rays, the estimate is unbiased (but for its clamp at 0); estimated from the first stage's
        own rays, a point that a small occluder shades partly but whose few rays all passed read
        as wholly lit.

        Polygonal lights (mesh lights, rectangular area lights;
        :func:`light_polygon_irradiance`) take the exact unoccluded ``Le I(x)`` (``I`` the
        cosine-weighted solid angle, :func:`polygon_irradiance`) less the estimated blocked part,
        ``E = Le I(x) - mean_s e_s (1 - V_s)`` (a control variate: exact where no ray is blocked),
        where the first stage saw at least half of the light, and the mean ``mean_s e_s V_s``
        elsewhere (exactly 0 in an umbra).  With ``clamp`` an estimate below 0 is 0, for a point
        whose value is final; that clamp is biased up where a blocked sample's ``e_s`` can exceed
        ``Le I(x)`` (a point close to the lamp, few rays), so an estimator that averages many
        points' estimates (the final gather's rays) takes them unclamped.  Other lights: the mean.
        One shadow ray per point light of radius 0 and per sun of angle 0 (exact with one, but over a footprint), and
        ``penumbra_samples`` in all where it passed glass or a cut-out (whose outcome is random).
        A point's rays: a randomly shifted Kronecker (R_3) set per stage, stratified over the light's
        triangles by area.  ``rng``: a Generator; ``receivers``: :meth:`light_samples_at`'s.
        ``footprint``: a :class:`~raybundle.tracing.footprint.Footprint` per point (lightmap texels), or
        None: each shadow ray then leaves from a point of the footprint (a randomly shifted Kronecker
        (R_2) set a point) towards a sample drawn for the centre, so the estimate is the centre's
        unoccluded light times its share visible from the footprint, averaged as Cycles' bake
        averages a texel's.  ``terminator``: the points' shadow terminator, as :meth:`shadowed`'s
        (with a footprint, each of its points lifted as its centre)."""
        out = np.zeros((len(points), 3))
        for light in self.sampled_lights():
            sharp = footprint is None and (
                (isinstance(light, PointLight) and float(light.lights.radius[light.k]) == 0.0)
                or (isinstance(light, SunLight) and light.angle == 0.0))
            n_s = 1 if sharp else max(1, int(samples_per_light))
            shift = rng.random((len(points), 3))
            analytic = None if sharp else light_polygon_irradiance(light, points, normals)
            fp = None if footprint is None else (footprint, rng.random((len(points), 2)))
            sums = partial(self._shadow_sums, light, points, normals, receivers=receivers, terminator=terminator)
            seen, total, penumbra = sums(shift, 0, n_s, footprint=fp)
            n_penumbra = 16 * n_s if penumbra_samples is None else int(penumbra_samples)
            if sharp:                 # one ray finds the light exactly, but where it passed glass or a cut-out
                more = np.nonzero(penumbra)[0] if n_penumbra > 1 else []
                if len(more):
                    s_more, _, _ = sums(shift, 1, n_penumbra, which=more, footprint=fp)
                    seen[more] = (seen[more] + s_more) / n_penumbra
                out += seen
                continue
            exact_i, ok = analytic if analytic is not None else (None, np.zeros(len(points), bool))
            cv = ok & (np.sum(seen, axis=1) >= 0.5 * np.sum(total, axis=1))
            # the estimate's own rays, independent of the decisions above: a quarter as many where
            # the control variate is exact unless a ray is blocked, all of them where not
            n_pts = np.where(penumbra, max(n_penumbra, 1), np.where(ok, max(1, n_s // 4), n_s))
            shift = rng.random((len(points), 3))
            fp = None if footprint is None else (footprint, rng.random((len(points), 2)))
            first = int(n_pts.min())
            seen, total, _ = sums(shift, 0, first, footprint=fp)
            for n_more in np.unique(n_pts[n_pts > first]):
                more = np.nonzero(n_pts == n_more)[0]
                s_more, t_more, _ = sums(shift, first, int(n_more), which=more, footprint=fp)
                seen[more] += s_more
                total[more] += t_more
            mean = seen / n_pts[:, None]
            if cv.any():
                blocked = (total[cv] - seen[cv]) / n_pts[cv, None]
                mean[cv] = exact_i[cv, None] * np.asarray(light.radiance, float) - blocked
                if clamp:
                    mean[cv] = np.maximum(mean[cv], 0.0)
            out += mean
        return out

    def _shadow_sums(self, light, points, normals, shift, first, last, which=None, receivers=None, footprint=None,
                     terminator=None):
        """Sums of the shadowed and unshadowed estimates of ``light``'s samples first..last-1 (a
        Kronecker (R_3) set shifted by ``shift`` (N, 3) a point) at the points ``which`` (None: all),
        and whether some sample was seen and some blocked or passed a cut-out or glass (whose outcome
        was random: a point whose few samples all passed by chance would keep them).  ``footprint``:
        ``(Footprint, shifts (N, 2))`` whose points (an R_2 set) the shadow rays leave from, or None: a
        sample then weighs the light as the centre sees it by its visibility from the footprint.
        ``terminator`` as :meth:`shadowed`'s."""
        if which is not None:
            points, normals, shift = points[which], normals[which], shift[which]
            receivers = None if receivers is None else receivers[which]
            terminator = None if terminator is None else terminator.take(which)
            footprint = None if footprint is None else (footprint[0].subset(which), footprint[1][which])
        alpha, alpha_2 = kronecker_alpha(3), kronecker_alpha(2)
        seen, total = np.zeros((len(points), 3)), np.zeros((len(points), 3))
        lit, shade = np.zeros(len(points), bool), np.zeros(len(points), bool)
        for s in range(first, last):
            at = None if footprint is None else footprint[0].points(points, (footprint[1] + s * alpha_2) % 1.0)
            e, _, _, free = self.light_samples_at(points, normals, light, (shift + s * alpha) % 1.0, unshadowed=True,
                                                  crossed=shade, receivers=receivers, origins=at,
                                                  terminator=terminator)
            seen += e
            total += free
            reached, blocked = seen_blocked(e, free)
            lit |= reached
            shade |= blocked
        return seen, total, lit & shade

    def far_side_irradiance(self, points, normals, rng, receivers=None, terminator=None):
        """(N, 3) [W/m^2] one sample per light of the first-shot lights' direct irradiance on the
        far side of surfaces at ``points`` seen along ``normals`` (N, 3): what a translucent
        surface lets through (shadow rays from just behind it); ``receivers`` as
        :meth:`light_samples_at`'s, ``terminator`` as :meth:`shadowed`'s (for the far side)."""
        out = np.zeros((len(points), 3))
        for light in self.sampled_lights():
            out += self.light_samples_at(points, -normals, light, rng.random((len(points), 3)), receivers=receivers,
                                         terminator=terminator)[0]
        return out

    @staticmethod
    def mis_weight(p_a, p_b):
        """Power-heuristic weight of strategy a against b: ``p_a^2 / (p_a^2 + p_b^2)``."""
        a2, b2 = p_a * p_a, p_b * p_b
        return np.where(a2 > 0, a2 / np.maximum(a2 + b2, 1e-300), 0.0)

    def lobe_hits_light(self, origins, mats, normals, w_out, w_in, triangles, hits, samples_per_light=1,
                        distance=None, mirrored=None, receivers=None):
        """Emitted radiance (N, 3) of first-shot mesh lights met by lobe-sampled rays,
        MIS-weighted against light sampling (:func:`~raybundle.lights.reflected_direct.reflected_radiance`,
        ``mis``):
        ``Le w_g``, ``w_g = p_g^2 / (p_g^2 + (n p_l)^2)``.  ``origins``, ``normals``,
        ``w_out``, ``w_in`` (N, 3) at the surface the rays leave along ``w_in``;
        ``triangles`` (N,) the triangles met (-1 none) at points ``hits`` (N, 3).  With
        ``distance`` (N,) [m] (inf where nothing is met), also the area lights (not geometry)
        the rays meet before it (:meth:`~raybundle.lights.sources.ShapeLight.hit`).  ``mirrored``
        (N,) bool or None: rays a glass interface reflected, which no light sample takes: weight 1.
        ``receivers`` (N,) or None: the link groups of the points the rays leave; a linked area
        light counts only where it lights them."""
        out = np.zeros((len(origins), 3))
        for li, light in enumerate(self.area_lights if distance is not None else ()):
            if not isinstance(light, ShapeLight):
                continue
            met, y = light.hit(origins, w_in, distance)
            if self.linking is not None and receivers is not None:
                met &= self.linking.receives[light.link, receivers]
            i = np.nonzero(met)[0]
            if len(i):
                p_l = samples_per_light * (light.pdf(origins[i], y[i]) if self.tree is None else self.tree_pdf(
                    np.full(len(i), li), np.zeros(len(i), np.int64), origins[i],
                    normals[i], y[i]))
                p_g = self.scene.materials.glossy_pdf(mats[i], normals[i], w_in[i], w_out[i])
                w = self.mis_weight(p_g, p_l)
                out[i] += (w if mirrored is None else np.where(mirrored[i], 1.0, w))[:, None] * light.radiance
        li = np.where(triangles >= 0, self.triangle_light[np.maximum(triangles, 0)], -1)
        for l_id in np.unique(li[li >= 0]):
            light = self.area_lights[l_id]
            i = np.nonzero(li == l_id)[0]
            tri = triangles[i]
            cos_l = np.einsum("ij,ij->i", self.scene.triangle_normal[tri], -w_in[i])
            lit = np.where(light.two_sided[self.triangle_light_k[tri]], cos_l != 0, cos_l > 0)
            k = self.triangle_light_k[tri]
            p_l = samples_per_light * (light.pdf(origins[i], k, hits[i]) if self.tree is None else
                                       self.tree_pdf(np.full(len(i), l_id), k, origins[i], normals[i], hits[i]))
            p_g = self.scene.materials.glossy_pdf(mats[i], normals[i], w_in[i], w_out[i])
            w = self.mis_weight(p_g, p_l)
            if self.linking is not None and receivers is not None:
                lit = lit & self.linking.receives[light.link, receivers[i]]
            out[i] += (lit * (w if mirrored is None else np.where(mirrored[i], 1.0, w)))[:, None] * light.radiance
        return out
