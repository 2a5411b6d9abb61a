"""Baking: the view-independent radiance of the solution at given surface points.

A bake asks for the outgoing radiance at points of the *input* faces (mesh
vertices, face corners, lightmap texels), each given as an input face id (the
values of :attr:`~raybundle.scene.model.PatchScene.triangle_source`) and barycentrics
on it.  :func:`locate_points` finds the patch triangle under each point;
:func:`baked_radiance` evaluates, on the side the face's normal points to (as
Cycles' bake does),

    L(x) = Le(x) + W_d kd(x) / pi * (E_ind(x) + E_dir(x))      [W m^-2 sr^-1]

with ``kd(x)`` the diffuse reflectance at the point (a texture's texel there,
:mod:`raybundle.scene.textures`), ``E_ind`` the running average of the incoming (indirect) irradiance
interpolated linearly from the patch values (the image's reconstruction:
:meth:`~raybundle.patches.reconstruction.LinearReconstruction.projected`, the caustic
first shot by :meth:`~raybundle.patches.reconstruction.LinearReconstruction.averaged`),
``E_dir`` the direct irradiance of the first-shot lights estimated *at the point*, about
its shading normal on smooth-shaded faces, their shadow rays lifted off the facets as Cycles'
shadow terminator lifts them (:mod:`raybundle.scene.shading`, as Cycles' bake and the image),
with ``light_samples`` shadow rays per area light
(:meth:`~raybundle.lights.direct.DirectLighting.irradiance`), so shadows and the fall-off
under a lamp are as sharp as the bake's resolution, and ``W_d`` the diffuse weight
of a Principled layer seen along the normal.  Glossy lobes are view-dependent and
left out: a bake holds the diffuse (view-independent) part and the emission.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..scene.shading import ShadowTerminator, sided_normals
from ..tracing.sampling import triangle_barycentrics
from .gather import FinalGather

#: how far a bake point is pulled from a face's corner or edge towards its centroid
#: (relative), so that it lies inside one patch and shadow rays do not start on a
#: neighbouring face's plane
INSET = 1e-4


@dataclass
class SurfacePoints:
    """Located bake points: patch triangle (N,) (-1 = not found: the input face was
    degenerate and dropped), its front tside (N,), barycentrics on it (N, 3), the
    point [m] (N, 3) and the face's unit normal (N, 3)."""

    triangle: np.ndarray
    tside: np.ndarray
    bary: np.ndarray
    point: np.ndarray
    normal: np.ndarray

    @property
    def found(self):
        return self.triangle >= 0


def input_rows(input_scene, face):
    """(N,) the rows of ``input_scene`` holding input faces ``face`` (N,) (the values of
    its ``triangle_source``), -1 for faces it does not hold (degenerate, dropped) or bad ids."""
    face = np.asarray(face, np.int64)
    src = input_scene.triangle_source
    row = np.full(int(max(src.max(initial=-1), face.max(initial=-1))) + 1, -1, np.int64)
    row[src] = np.arange(len(src))
    return np.where(face >= 0, row[np.maximum(face, 0)], -1)


def locate_points(input_scene, scene, tracer, face, bary, chunk=1 << 22):
    """Patch triangles of ``scene`` (the subdivided ``input_scene``) under points
    given by input face ids ``face`` (N,) and barycentrics ``bary`` (N, 3) on them.

    Each point is first pulled :data:`INSET` towards its face's centroid (a vertex or
    edge point then lies inside the face), then found by a ray along the face's
    normal checked against ``triangle_source``; the few points a ray does not find
    (a coplanar face on top) are found by testing every patch triangle of their face.
    Returns :class:`SurfacePoints`.
    """
    face = np.asarray(face, np.int64)
    bary = np.asarray(bary, float)
    n = len(face)
    r = input_rows(input_scene, face)
    ok = np.nonzero(r >= 0)[0]
    corners = input_scene.triangle_corners[r[ok]]
    p = np.einsum("nk,nkc->nc", bary[ok], corners)
    p += INSET * (corners.mean(axis=1) - p)
    normal = np.zeros((n, 3))
    normal[ok] = input_scene.triangle_normal[r[ok]]
    point = np.zeros((n, 3))
    point[ok] = p
    tri = np.full(n, -1, np.int64)
    fb = np.zeros((n, 3))
    eps = tracer.eps
    todo = ok
    for sign in (1.0, -1.0):                 # from just in front, then from just behind
        if len(todo) == 0:
            break
        nn = normal[todo]
        t_hit, t, _, _ = tracer.first_hit(point[todo] + sign * 2 * eps * nn, -sign * nn, glass=False)
        good = (t_hit >= 0) & (t < 4 * eps)
        good[good] = scene.triangle_source[t_hit[good]] == face[todo[good]]
        tri[todo[good]] = t_hit[good]
        todo = todo[~good]
    hit = np.nonzero(tri >= 0)[0]          # barycentrics in double precision (Embree's are float32)
    fb[hit] = triangle_barycentrics(scene.triangle_corners[tri[hit]], point[hit])
    if len(todo):
        _locate_by_search(scene, face, point, todo, tri, fb, chunk)
    ts = np.full(n, -1, np.int64)
    hit = tri >= 0
    ts[hit] = scene.seen_tside(tri[hit], -normal[hit])
    return SurfacePoints(tri, ts, fb, point, normal)


def _locate_by_search(scene, face, point, todo, tri, fb, chunk):
    """For points ``todo``: the patch triangle of their face whose barycentrics are
    least negative (every one of the face's triangles is tested; fills ``tri``, ``fb``)."""
    order = np.argsort(scene.triangle_source, kind="stable")
    src = scene.triangle_source[order]
    start = np.searchsorted(src, face[todo], "left")
    count = np.searchsorted(src, face[todo], "right") - start
    has = count > 0
    todo, start, count = todo[has], start[has], count[has]
    bounds = np.concatenate([[0], np.cumsum(count)])
    lo = 0
    while lo < len(todo):                    # chunks of at most ``chunk`` point-triangle pairs
        hi = max(lo + 1, int(np.searchsorted(bounds, bounds[lo] + chunk, "right")) - 1)
        hi = min(hi, len(todo))
        c = count[lo:hi]
        pt = np.repeat(np.arange(lo, hi), c)
        cand = order[np.repeat(start[lo:hi] - bounds[lo:hi], c) + np.arange(int(c.sum())) + bounds[lo]]
        b = triangle_barycentrics(scene.triangle_corners[cand], point[todo[pt]])
        score = b.min(axis=1)
        # best candidate per point: sort by (point, score) and take each point's last
        best = np.lexsort((score, pt))
        last = np.concatenate([np.nonzero(np.diff(pt[best]))[0], [len(best) - 1]])
        pick = best[last]
        tri[todo[pt[pick]]] = cand[pick]
        fb[todo[pt[pick]]] = np.clip(b[pick], 0.0, 1.0) / np.clip(b[pick], 0.0, 1.0).sum(axis=1, keepdims=True)
        lo = hi


@dataclass
class BakedParts:
    """The parts of the view-independent radiance at N located points (module docstring), zero at
    points not found: ``emitted`` Le (N, 3), ``reflectance`` W_d kd / pi (N, 3), ``direct`` E_dir
    (N, 3) [W/m^2] and ``through`` (N, 3), what a translucent side lets through;
    :meth:`radiance` adds the indirect irradiance."""

    emitted: np.ndarray
    reflectance: np.ndarray
    direct: np.ndarray
    through: np.ndarray

    def radiance(self, indirect):
        """L (N, 3) [W m^-2 sr^-1] with the indirect irradiance ``indirect`` (N, 3) [W/m^2]."""
        return self.emitted + self.reflectance * (self.direct + indirect) + self.through


def baked_parts(solver, points: SurfacePoints, light_samples=16, rng=None, penumbra_samples=None,
                footprint=None) -> BakedParts:
    """:class:`BakedParts` of located ``points``: all but the indirect light.  ``solver``, ``rng``,
    ``light_samples`` and ``penumbra_samples`` as in :func:`baked_radiance`; ``footprint``: a
    :class:`~raybundle.tracing.footprint.Footprint` per point whose direct light is averaged over it
    (lightmap texels), or None."""
    sc = solver.scene
    rng = np.random.default_rng(0) if rng is None else rng
    parts = BakedParts(*(np.zeros((len(points.triangle), 3)) for _ in range(4)))
    idx = np.nonzero(points.found)[0]
    if len(idx) == 0:
        return parts
    ts, tri = points.tside[idx], points.triangle[idx]
    m = sc.triangle_material[tri]
    n = sc.tside_normal[ts]
    mats = sc.materials
    ones = np.ones(len(idx))
    parts.emitted[idx] = mats.emitted_radiance(m, ones)
    direct = solver.direct
    if direct.n_lights:         # about the shading normal of a smooth-shaded face, as the image's
        src = sc.triangle_source[tri]
        n_s = n if sc.shading is None else sided_normals(sc.shading, src, points.point[idx], n)
        terminator = None if sc.shading is None else ShadowTerminator(sc.shading, src, points.point[idx], n)
        if sc.texture is not None and sc.texture.has_normal_maps:     # and of a normal or bump map
            n_s = sc.texture.shading_normals(src, points.point[idx], n_s)
        parts.direct[idx] = direct.irradiance(points.point[idx], n_s, rng, light_samples, penumbra_samples,
                                              receivers=sc.link_groups(tri),
                                              footprint=None if footprint is None else footprint.subset(idx),
                                              terminator=terminator)
    kd = mats.diffuse_reflectance[m]
    if sc.texture is not None:                  # the texel's albedo: texture detail stays sharp
        kd = kd * sc.texture.at(sc.triangle_source[tri], points.point[idx])
    parts.reflectance[idx] = mats.diffuse_weight(m, ones) * kd / np.pi
    if len(getattr(solver, "translucent_sides", ())):      # what a translucent side lets through
        rec = solver.reconstruction
        through = solver.translucent_radiance(solver.indirect_incoming())
        parts.through[idx] = rec.at(rec.averaged(through), ts, points.bary[idx])
        kt = mats.translucent[m]
        far = np.nonzero(np.any(kt > 0, axis=1))[0]
        if direct.n_lights and len(far):               # the first-shot lights on its far side
            parts.through[idx[far]] += kt[far] / np.pi * direct.irradiance(
                points.point[idx[far]], -n[far], rng, light_samples, penumbra_samples,
                receivers=sc.link_groups(tri[far]))
    return parts


def interpolated_indirect(solver, points: SurfacePoints, vert=None):
    """E_ind (N, 3) [W/m^2] at located ``points`` interpolated linearly from the patch values (the
    image's reconstruction, module docstring); zero at points not found.  ``vert``: the
    reconstruction's vertex values of the indirect light if made already
    (:attr:`~raybundle.imaging.gather.FinalGather.vert_indirect`), else made here."""
    out = np.zeros((len(points.triangle), 3))
    idx = np.nonzero(points.found)[0]
    if not len(idx):
        return out
    rec = solver.reconstruction
    if vert is None:
        e_bar = solver.indirect_incoming()
        if not np.any(e_bar):
            return out
        vert = rec.smooth_and_sharp(e_bar, solver.caustic.E if solver.caustic is not None else None)
    out[idx] = rec.at(vert, points.tside[idx], points.bary[idx])
    return out


def baked_radiance(solver, points: SurfacePoints, light_samples=16, rng=None, gather_rays=0,
                   penumbra_samples=None):
    """View-independent outgoing radiance (N, 3) [W m^-2 sr^-1] at located ``points``
    (the module docstring's L(x)); points not found are 0.

    ``solver``: a :class:`~raybundle.methods.stochastic_iteration.StochasticIterationSolver` (its running
    average and its :class:`~raybundle.lights.direct.DirectLighting`); ``light_samples``:
    shadow rays per area light per point, ``penumbra_samples`` where they find a penumbra
    (default 16 times as many); ``rng``: a Generator (default: seeded 0);
    ``gather_rays``: 0 = the indirect light interpolated from the patches, else gathered by
    that many rays per point, all at once, as :class:`~raybundle.imaging.bake_gather.BakeGather`
    gathers them in slices within a bake's budget (:class:`~raybundle.imaging.gather.FinalGather`
    with ``bounce``).
    """
    rng = np.random.default_rng(0) if rng is None else rng
    parts = baked_parts(solver, points, light_samples, rng, penumbra_samples)
    if not gather_rays:
        return parts.radiance(interpolated_indirect(solver, points))
    e = np.zeros((len(points.triangle), 3))
    idx = np.nonzero(points.found)[0]
    if len(idx):
        ts = points.tside[idx]
        e[idx] = FinalGather(solver, bounce=True).irradiance(points.point[idx], solver.scene.tside_normal[ts],
                                                             int(gather_rays), rng, at=(ts, points.bary[idx]))
    return parts.radiance(e)


# ------------------------------------------------------------- refinement
@dataclass
class RefinedTriangles:
    """Input triangles cut where the lighting needs it: sub-triangle ``k`` lies on input
    face ``face[k]`` with corner barycentrics ``bary[k]`` (3, 3) (row j: corner j)."""

    face: np.ndarray
    bary: np.ndarray
    capped: bool = False        # stopped early: one more level would pass ``max_triangles``


def refine_by_lighting(solver, input_scene, faces, max_level=3, tolerance=0.05, light_samples=8, rng=None,
                       max_triangles=2_000_000):
    """Cut input ``faces`` (their ids, :attr:`~raybundle.scene.model.PatchScene.triangle_source`
    values of the prepared scene) into 4 at their edge midpoints, again and again (at most
    ``max_level`` times), wherever the bake's linear interpolation along an edge misses
    the value at its midpoint: ``|L(m) - (L(a) + L(b)) / 2| > tolerance * (Lbar(a, b) + L0)``,
    with ``L`` the view-independent radiance (:func:`baked_radiance`, the indirect part
    interpolated from the patches, ``light_samples`` shadow rays), ``Lbar`` the mean of
    the two ends' luminance and ``L0`` 2% of the mean over the faces' corners.  A
    triangle whose edges all interpolate is kept.  Returns :class:`RefinedTriangles`.

    Neighbours may end at different levels (a T-junction: the finer side's extra vertex
    lies on the coarser edge, whose interpolation missed it by less than the tolerance).
    A level that would make more than ``max_triangles`` in all is not cut (``capped``)."""
    rng = np.random.default_rng(0) if rng is None else rng
    faces = np.asarray(faces, np.int64)
    face = faces.copy()
    bary = np.broadcast_to(np.eye(3), (len(faces), 3, 3)).copy()
    done_face, done_bary = [], []
    capped = False

    def luminance(f, b):
        pts = locate_points(input_scene, solver.scene, solver.tracer, f, b)
        return baked_radiance(solver, pts, light_samples, rng) @ np.array([0.2126, 0.7152, 0.0722])

    corner = luminance(np.repeat(face, 3), bary.reshape(-1, 3)).reshape(-1, 3)
    floor = 0.02 * max(float(corner.mean()), 1e-12) if len(face) else 0.0
    for level in range(max_level + 1):
        if len(face) == 0:
            break
        mid = 0.5 * (bary + bary[:, [1, 2, 0]])                              # edge j: corners j, j+1
        lum = np.concatenate([corner, luminance(np.repeat(face, 3), mid.reshape(-1, 3)).reshape(-1, 3)], axis=1)
        ends = 0.5 * (lum[:, :3] + lum[:, [1, 2, 0]])
        miss = np.abs(lum[:, 3:] - ends) > tolerance * (ends + floor)
        split = miss.any(axis=1) if level < max_level else np.zeros(len(face), bool)
        if sum(map(len, done_face)) + len(face) + 3 * int(split.sum()) > max_triangles:
            capped, split = bool(split.any()), np.zeros(len(face), bool)
        done_face.append(face[~split])
        done_bary.append(bary[~split])
        f, b, m = face[split], bary[split], mid[split]
        # the four children: corner j with the midpoints of its two edges, and the middle one
        kids = np.stack([np.stack([b[:, 0], m[:, 0], m[:, 2]], 1), np.stack([m[:, 0], b[:, 1], m[:, 1]], 1),
                         np.stack([m[:, 2], m[:, 1], b[:, 2]], 1), np.stack([m[:, 0], m[:, 1], m[:, 2]], 1)], 1)
        face, bary = np.repeat(f, 4), kids.reshape(-1, 3, 3)
        # the children's corners are the parent's corners and midpoints, already evaluated
        corner = lum[split][:, [0, 3, 5, 3, 1, 4, 5, 4, 2, 3, 4, 5]].reshape(-1, 3)
    return RefinedTriangles(np.concatenate(done_face) if done_face else faces[:0],
                            np.concatenate(done_bary) if done_bary else np.zeros((0, 3, 3)), capped)
