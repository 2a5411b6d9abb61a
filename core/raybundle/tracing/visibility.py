"""Ray casting through Embree, and global visibility for bundles of parallel rays.

A *bundle* (thesis 3.1) is a grid of parallel rays with direction d covering
the scene's bounding sphere.  Along each ray every surface hit is found (Embree
first hits, re-shot just past each hit), and each pair of *consecutive* hits
exchanges light in both directions between the sides that face each other
(:meth:`~raybundle.scene.model.PatchScene.side_facing`; the black back of a one-sided
triangle takes no part): the upstream side j sends along +d to the downstream
side i, and i sends along -d to j.  With an environment (world) radiance the first hit of
each ray also receives from the world along +d and the last hit along -d (sender
:data:`ENVIRONMENT`).  Each ray stands for the area delta^2 of the plane perpendicular to d,
so summed over a bundle the weight of a pair estimates ``P(i, j, d) = A(i, j, d) cos_i``
without bias when the grid gets a random sub-cell offset (and rotation) every time.

Hits closer than ``eps`` along a ray are one hit (``eps`` = 1e-5 of the scene radius; Embree's
hit distances carry errors of that order in single precision): a ray through a shared edge or
vertex is counted once, and walls thinner than ``eps`` behave as one surface.

Cut-outs (:class:`~raybundle.scene.textures.SurfaceTexture`'s coverage): a hit on a face
with a coverage map is kept with probability ``alpha`` at the hit point, drawn from a hash of
the ray, the layer and the query (the same for any split over threads); a ray that passes
goes on from just past the hit, in every query (first hits, shadow rays, bundle lines).
So does a hit on a transmissive surface (glass, refraction, transparency), kept with the
probability that the ray does not pass straight through (the scene's ``pass_probability``),
except in the eye's paths, which refract there instead (``first_hit(..., glass=False)``).

``embreex`` traces one ray after another in C and releases the GIL, so every
query is split into one chunk per core and run on a thread pool.  Point-wise work whose own
steps also release the GIL (compiled kernels, large NumPy steps) goes one level up:
:meth:`RayTracer.each_piece` runs it on the pool piece by piece, each piece tracing its rays on
its own thread.
"""
from __future__ import annotations

import copy
import itertools
import os
import threading
import warnings
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass

import numpy as np

from .sampling import Stream, cosine_directions, frames_from_normals, points_on_triangles, stratified_2d_sets, stream

_MAX_LAYERS = 10000
#: most surfaces a first-hit query passes through before it gives up (the ray then misses)
_MAX_PASSES = 1000
#: points per piece of :meth:`RayTracer.each_piece` (about: a call's pieces are equal), and the
#: fewest points it splits (in two)
PIECE_POINTS, PIECE_MIN = 12_000, 4_000
#: sender id of light that comes from the environment (world) in a :class:`Bundle`: along
#: ``travel_sign`` +1 it arrives from the world at -d, along -1 from the world at +d
ENVIRONMENT = -1


@dataclass
class Bundle:
    """Transfers found by one bundle: one entry per ray segment that carries light.

    Attributes
    ----------
    direction : (3,) float  the bundle direction d (unit)
    cell_area : float  delta^2 [m^2], the cross-section each ray stands for
    receiver, sender : (K,) int  side ids; light goes from sender to receiver
        (sender :data:`ENVIRONMENT` = the world)
    travel_sign : (K,) int8  +1 when the light travels along +d, -1 along -d
    n_rays : int  rays in the grid (inside the bounding disc)
    n_casts : int  Embree first-hit queries used (all layers; bundles traced together
        share their total in proportion to their grid rays)
    """

    direction: np.ndarray
    cell_area: float
    receiver: np.ndarray
    sender: np.ndarray
    travel_sign: np.ndarray
    n_rays: int
    n_casts: int

    def aggregated(self):
        """Unique (receiver, sender, travel_sign) with weight = count * delta^2 [m^2]."""
        key = np.stack([self.receiver, self.sender, self.travel_sign.astype(np.int64)], axis=1)
        if len(key) == 0:
            return np.zeros((0, 3), np.int64), np.zeros(0)
        uniq, counts = np.unique(key, axis=0, return_counts=True)
        return uniq, counts * self.cell_area


class RayTracer:
    """Embree acceleration structure over a :class:`~raybundle.scene.model.PatchScene`.

    Queries are threaded over ``threads`` workers (default: all cores).
    """

    def __init__(self, scene, threads=None):
        from embreex import rtcore_scene
        from embreex.mesh_construction import TriangleMesh

        self.scene = scene
        self.center, self.radius = scene.bounding_sphere
        self.eps = max(1e-5 * self.radius, 1e-9)
        self._embree = rtcore_scene.EmbreeScene()
        # Embree works in single precision: build it around the scene's centre so that
        # scenes far from the world origin keep their precision (queries are shifted too)
        TriangleMesh(self._embree, (scene.vertices - self.center).astype(np.float32),
                     scene.triangles.astype(np.int32))
        self._embree.run(np.zeros((1, 3), np.float32), np.array([[0, 0, 1]], np.float32))  # commit now
        self.threads = max(1, int(threads or os.cpu_count() or 1))
        self._pool = ThreadPoolExecutor(self.threads) if self.threads > 1 else None
        tex = scene.texture
        #: the scene's coverage maps (None: no cut-outs) and (T,) bool cut-out triangles
        self.cutouts = tex if tex is not None and tex.has_cutouts else None
        self._cut = None if self.cutouts is None else self.cutouts.cutout_faces[scene.triangle_source]
        #: (T,) bool triangles light may pass straight through (transmissive materials), or None
        glass = scene.materials.transmits[scene.triangle_material] if len(scene.triangles) else None
        self.glass = glass if glass is not None and glass.any() else None
        masks = [m for m in (self._cut, self.glass) if m is not None]
        #: (T,) bool triangles a ray may pass (cut-outs and glass), or None
        self._through = np.logical_or.reduce(masks) if masks else None
        self._queries = 0
        #: per thread: within :meth:`map_pieces`, the piece's own query numbers (else unset)
        self._piece = threading.local()

    def close(self):
        if self._pool is not None:
            self._pool.shutdown(wait=False)
            self._pool = None

    def _map_chunks(self, fn, n, min_chunk=2048, threaded=True):
        """Run fn(start, stop) over [0, n) split into one chunk per thread; list of results."""
        if self._pool is None or n < 2 * min_chunk or not threaded or self._in_piece():
            return [fn(0, n)]
        bounds = np.linspace(0, n, self.threads + 1).astype(int)
        return list(self._pool.map(fn, bounds[:-1], bounds[1:]))

    def map_pieces(self, fn, n, rng=None):
        """:meth:`each_piece`'s results as a list."""
        return list(self.each_piece(fn, n, rng))

    def each_piece(self, fn, n, rng=None):
        """Run ``fn(start, stop)`` over [0, n) split into an even number of pieces of about
        :data:`PIECE_POINTS` points (one below :data:`PIECE_MIN`), in parallel on the pool, each
        piece tracing its rays on its own thread: for point-wise work whose other steps release
        the GIL too.  The split depends on ``n`` only, and a piece's cut-out and glass choices are
        hashed from query numbers of its own (this call's, the piece's index, and its queries so
        far), so the result is the same for any number of threads and any timing.  With a
        Generator ``rng``, ``fn(start, stop, rng)``: one piece takes ``rng`` itself, several a
        Generator each, seeded by draws from ``rng``.  ``fn`` must write only its own points' rows
        of shared arrays.  An iterator of the results in order (one piece within a piece), each as
        it is ready: a caller that folds them holds a few at a time."""
        pieces = 1 if n < PIECE_MIN else max(2, 2 * round(n / (2 * PIECE_POINTS)))      # even: 2 cores
        if pieces == 1 or self._in_piece():
            return iter([fn(0, n) if rng is None else fn(0, n, rng)])
        bounds = np.linspace(0, n, pieces + 1).astype(int)
        base = self._next_query() << 32
        seeds = None if rng is None else rng.integers(0, 1 << 63, pieces)

        def piece(k):
            self._piece.queries = itertools.count(base + ((k + 1) << 24))
            try:
                a, b = bounds[k], bounds[k + 1]
                return fn(a, b) if seeds is None else fn(a, b, np.random.default_rng(seeds[k]))
            finally:
                self._piece.queries = None

        return map(piece, range(pieces)) if self._pool is None else self._pool.map(piece, range(pieces))

    def map_pieces_of(self, owner, fn, n, rng=None):
        """:meth:`map_pieces` of ``fn(part, start, stop)`` for an ``owner`` that counts its rays
        (``rays``) and draws from ``rng``: one piece runs on ``owner`` itself, several each on a
        shallow copy with a count of its own (added to ``owner``'s after) and, with ``rng``, the
        piece's Generator.  The results in order."""
        counts = []

        def piece(a, b, r=None):
            if b - a == n:
                return fn(owner, a, b)
            part = copy.copy(owner)
            part.rays = 0
            if r is not None:
                part.rng = r
            out = fn(part, a, b)
            counts.append(part.rays)
            return out

        parts = self.map_pieces(piece, n, rng)
        owner.rays += sum(counts)
        return parts

    def _in_piece(self):
        return getattr(self._piece, "queries", None) is not None

    # -------------------------------------------------------------- queries
    def _run(self, origins, directions, **kw):
        return self._embree.run(np.ascontiguousarray(origins - self.center, np.float32),
                                np.ascontiguousarray(directions, np.float32), **kw)

    def first_hit(self, origins, directions, glass=True):
        """Closest hits of rays (N, 3) from ``origins`` along unit ``directions``.

        Returns ``(triangle, t, u, v)``: triangle id (-1 = miss), distance [m] and
        Embree's barycentrics (hit = (1-u-v) v0 + u v1 + v v2).  A cut-out's hit is
        kept with the probability of its coverage there (module docstring), and with
        ``glass`` a transmissive surface's with the probability that the ray does not pass
        straight through it (the scene's ``pass_probability``; the eye's
        paths refract there instead: ``glass`` False).
        """
        origins = np.asarray(origins, float)
        directions = np.broadcast_to(np.asarray(directions, float), origins.shape)
        hits = self._first_hits(origins, directions)
        through = self._cut if not glass else self._through
        return hits if through is None else self._through_surfaces(origins, directions, *hits, glass=glass)

    def _through_surfaces(self, origins, directions, tri, t, u, v, glass=True, dist=None):
        """:meth:`first_hit`'s hits ``(tri, t, u, v)`` (changed in place) with the hits on
        cut-outs (and with ``glass`` on transmissive surfaces) that are not kept traced on from
        just past them (only up to ``dist`` (N,) where given)."""
        query = self._next_query()
        through = self._through if glass else self._cut
        todo = np.arange(len(tri))
        for layer in range(_MAX_PASSES):
            todo = todo[tri[todo] >= 0]
            todo = todo[through[tri[todo]]]
            if todo.size == 0:
                return tri, t, u, v
            go = todo[~self._kept(tri[todo], origins[todo] + t[todo, None] * directions[todo], todo, layer, query,
                                  directions[todo] if glass else None)]
            if go.size == 0:
                return tri, t, u, v
            start = t[go] + self.eps
            tri[go], dt, u[go], v[go] = self._first_hits(origins[go] + start[:, None] * directions[go],
                                                         directions[go], None if dist is None else dist[go] - start)
            t[go] = start + dt
            todo = go
        tri[todo] = -1                  # passed through more surfaces than any scene has: a miss
        return tri, t, u, v

    def _kept(self, tri, points, rays, layer, query, directions=None):
        """(N,) bool: the hits on triangles ``tri`` at ``points`` are kept: a uniform number hashed
        from ``rays``, ``layer`` and ``query`` against the coverage of a cut-out times, for rays
        along ``directions`` (None: cut-outs only), the probability of not passing a
        transmissive surface (the scene's ``pass_probability``)."""
        keep = np.ones(len(tri))
        if self._cut is not None:
            c = np.nonzero(self._cut[tri])[0]
            keep[c] = self.cutouts.alpha_at(self.scene.triangle_source[tri[c]], points[c])
        if directions is not None and self.glass is not None:
            g = np.nonzero(self.glass[tri])[0]
            cos = np.einsum("ij,ij->i", self.scene.triangle_normal[tri[g]], directions[g])
            keep[g] *= 1.0 - self.scene.pass_probability(tri[g], cos)
        return hashed_uniform(rays, layer, query) < keep

    def _next_query(self):
        if self._in_piece():
            return next(self._piece.queries)
        self._queries += 1
        return self._queries

    def _first_hits(self, origins, directions, dist=None):
        """Embree's closest hits, cut-outs or not, within ``dist`` (N,) where given: ``(triangle,
        t, u, v)``."""

        def work(a, b):
            d = None if dist is None else np.array(dist[a:b], np.float32)      # Embree writes its hits' t there
            r = self._run(origins[a:b], directions[a:b], output=1, **({} if d is None else {"dists": d}))
            return r["primID"], r["tfar"], r["u"], r["v"]

        parts = self._map_chunks(work, len(origins))
        tri = np.concatenate([p[0] for p in parts]).astype(np.int64)
        tri[tri < 0] = -1
        t = np.concatenate([p[1] for p in parts]).astype(float)
        return tri, t, np.concatenate([p[2] for p in parts]), np.concatenate([p[3] for p in parts])

    def occluded(self, origins, directions, distances, crossed=None, link=None):
        """(N,) bool: is anything hit between ``origins`` and ``distances`` along ``directions``?
        (A cut-out with the probability of its coverage where the ray meets it, a transmissive
        surface with the probability that the ray does not pass it.)  ``crossed``: an (N,) bool
        array to mark the rays that passed such a surface (the outcome was random).  ``link``
        (scalar or (N,) int, or None): the rays' light link sets, whose light only the
        triangles of the groups that block it stop (:mod:`raybundle.scene.linking`)."""
        origins = np.asarray(origins, float)
        directions = np.broadcast_to(np.asarray(directions, float), origins.shape)
        dist = np.asarray(distances, np.float32)
        linking = self.scene.linking
        if self._through is not None and (linking is None or link is None):
            # surfaces a ray may pass: closest hits within the distance, traced on past those
            # passed (one query per ray, where an occlusion query and a closest-hit one were)
            hits = self._first_hits(origins, directions, dist)
            met = hits[0] >= 0
            tri, t, _, _ = self._through_surfaces(origins, directions, *hits, dist=dist) if met.any() else hits
            hit = (tri >= 0) & (t < dist)
            if crossed is not None:
                crossed[met & ~hit] = True
            return hit

        def work(a, b):
            return self._run(origins[a:b], directions[a:b], query="OCCLUDED",
                             dists=np.ascontiguousarray(dist[a:b]))

        hit = np.concatenate(self._map_chunks(work, len(origins))) != -1
        partial = None
        if linking is not None and link is not None:      # rays some triangles do not stop
            link = np.broadcast_to(np.asarray(link, np.int64), hit.shape)
            partial = hit & ~linking.blocks[link].all(axis=1)
        if self._through is not None and hit.any():
            sel = np.nonzero(hit if partial is None else hit & ~partial)[0]
            o, d = origins[sel], directions[sel]
            tri, t, _, _ = self._through_surfaces(o, d, *self._first_hits(o, d))
            hit[sel] = (tri >= 0) & (t < dist[sel])
            if crossed is not None:
                crossed[sel[~hit[sel]]] = True
        if partial is not None and partial.any():
            sel = np.nonzero(partial)[0]
            hit[sel] = self._linked_hits(origins[sel], directions[sel], dist[sel], link[sel])
        return hit

    def _linked_hits(self, origins, directions, dist, link):
        """:meth:`occluded` for rays of link sets ``link`` (N,): traced on past every triangle
        whose group does not block their set, up to ``dist`` (N,)."""
        sc = self.scene
        blocks, group = sc.linking.blocks, sc.linking.face_group
        hit = np.zeros(len(origins), bool)
        start = np.zeros(len(origins))
        todo = np.arange(len(origins))
        for _ in range(_MAX_PASSES):
            o = origins[todo] + start[todo, None] * directions[todo]
            hits = self._first_hits(o, directions[todo])
            tri, t, _, _ = hits if self._through is None else self._through_surfaces(o, directions[todo], *hits)
            met = (tri >= 0) & (start[todo] + t < dist[todo])
            stops = met & blocks[link[todo], group[sc.triangle_source[np.maximum(tri, 0)]]]
            hit[todo[stops]] = True
            go = met & ~stops
            start[todo[go]] += t[go] + self.eps
            todo = todo[go]
            if todo.size == 0:
                break
        return hit

    def open_fraction(self, points_per_triangle=32, refine_points=512, seed=0):
        """(TS,) fraction of each triangle side's area that is not buried inside a closed solid.

        A point is buried when rays from it along its side's normal and along
        three directions tilted 60 degrees from it all meet the inside of a
        closed solid first (a back face of a :attr:`~raybundle.scene.model.PatchScene.triangle_solid`
        triangle: a box standing on a floor buries
        the floor under it; a one-sided shelf buries nothing).  Such area never
        receives light, so side averages must not be divided by it (an FE error
        otherwise: the visible rest of the patch comes out too dark).  Estimated
        from ``points_per_triangle`` stratified points per side, shared out over its triangles
        by area (:meth:`~raybundle.scene.model.PatchScene.tside_samples`); triangle sides found
        partly or wholly buried (patches cut at a solid's footprint by
        :mod:`raybundle.patches.contacts` are often wholly buried) get ``refine_points``
        more (the receiving area divides E, so its error matters).  A side found wholly
        buried keeps half a sample's area (its E is then never divided by zero).  A scene
        without solids needs no rays: everything is open.
        """
        rng = stream(seed, Stream.OPEN_AREA)
        sc = self.scene
        n_t = len(sc.tside_triangle)
        if not sc.triangle_solid.any():
            return np.ones(n_t)
        k = sc.tside_samples(points_per_triangle)
        frac = self._open_fraction(np.arange(n_t), k, rng)
        part = np.nonzero(frac < 1)[0]
        if len(part) and refine_points:
            k[part] = sc.tside_samples(refine_points)[part]
            frac[part] = self._open_fraction(part, k[part], rng)
        a = sc.triangle_area[sc.tside_triangle]
        shut = np.bincount(sc.tside_side, a * frac, minlength=sc.n_sides)[sc.tside_side] <= 0
        return np.where(shut, np.maximum(frac, 0.5 / k), frac)

    def _open_fraction(self, tsides, k, rng, chunk=1 << 18):
        """Open fractions (N,) of ``tsides`` (N,) from ``k`` (N,) stratified points each."""
        out = np.zeros(len(tsides))
        for kk in np.unique(k):
            sel = np.nonzero(k == kk)[0]
            step = max(1, chunk // int(kk))
            for lo in range(0, len(sel), step):
                s = sel[lo:lo + step]
                out[s] = self._open_fraction_k(tsides[s], int(kk), rng)
        return out

    def _open_fraction_k(self, tsides, k, rng):
        sc = self.scene
        ts = np.repeat(tsides, k)
        st = stratified_2d_sets(len(tsides), k, rng).reshape(-1, 2)
        pts = points_on_triangles(sc.triangle_corners[sc.tside_triangle[ts]], st[:, 0], st[:, 1])
        n = sc.tside_normal[ts]
        t, b = frames_from_normals(n)
        buried = np.ones(len(ts), bool)
        s60, c60 = np.sin(np.pi / 3), np.cos(np.pi / 3)
        phi0 = rng.random(len(ts)) * 2 * np.pi
        for a in (None, 0, 2 * np.pi / 3, 4 * np.pi / 3):
            live = np.nonzero(buried)[0]
            if len(live) == 0:
                break
            nl = n[live]
            if a is None:
                d = nl
            else:
                phi = phi0[live] + a
                d = c60 * nl + s60 * (np.cos(phi)[:, None] * t[live] + np.sin(phi)[:, None] * b[live])
            hit, _, _, _ = self.first_hit(pts[live] + nl * self.eps, d, glass=False)
            safe = np.maximum(hit, 0)
            back = ((hit >= 0) & sc.triangle_solid[safe]
                    & (np.einsum("ij,ij->i", sc.triangle_normal[safe], d) > 0))
            buried[live[~back]] = False
        return 1.0 - buried.reshape(-1, k).mean(axis=1)

    # --------------------------------------------------------------- bundle
    def bundle_origins(self, direction, resolution, offset, rotation):
        """Ray origins (N, 3) of a bundle grid.

        The grid has ``resolution`` x ``resolution`` cells of side
        ``delta = 2 R / resolution`` on the plane perpendicular to ``direction``
        through the bounding sphere (centre c, radius R), shifted by ``offset``
        in [0,1)^2 cells and rotated by ``rotation`` in [0,1) turns; rays outside
        the disc of radius R miss everything and are dropped.  Origins sit
        1.01 R upstream of the plane.  Returns ``(origins, delta)``.
        """
        origins, _, delta = self.grid_origins(np.asarray(direction, float)[None], resolution, [offset], [rotation])
        return origins, delta

    def grid_origins(self, directions, resolution, offsets, rotations):
        """:meth:`bundle_origins` of K grids at once: ``(origins (N, 3), counts (K,), delta)``,
        the origins of grid k following those of grids 0..k-1."""
        d = np.asarray(directions, float)
        t, b = frames_from_normals(d)
        ang = 2 * np.pi * np.asarray(rotations, float)[:, None]
        u, v = np.cos(ang) * t + np.sin(ang) * b, -np.sin(ang) * t + np.cos(ang) * b
        r = self.radius * 1.0001 + self.eps
        delta = 2.0 * r / resolution
        g = (np.arange(resolution) + 0.5) * delta - r
        off = (np.asarray(offsets, float) - 0.5) * delta                       # (K, 2)
        x = (g[None, :, None] + off[:, 0, None, None]) + np.zeros((1, 1, resolution))
        y = (g[None, None, :] + off[:, 1, None, None]) + np.zeros((1, resolution, 1))
        x, y = x.reshape(len(d), -1), y.reshape(len(d), -1)
        inside = x * x + y * y <= r * r
        counts = inside.sum(axis=1)
        x, y = x[inside], y[inside]
        # grid k's rays follow grid k-1's: per-grid vectors repeat by count
        o = (x[:, None] * np.repeat(u, counts, axis=0) + y[:, None] * np.repeat(v, counts, axis=0)
             + np.repeat(self.center - 1.01 * r * d, counts, axis=0))
        return o, counts, delta

    def all_hit_pairs(self, origins, direction, ends=False):
        """Consecutive hits along parallel rays: ``(upstream_tri, downstream_tri, ray, n_casts)``.

        Every hit along every ray is found by re-shooting ``eps`` past the previous
        hit; consecutive hits form one pair.  Triangle ids are Embree prim ids.
        ``direction`` is one (3,) for all rays or one (N, 3) per ray.
        With ``ends`` also returns the first and the last triangle hit by each ray
        that hits anything (the surfaces that see the world along -d and +d).
        """
        up, down, ray, casts, first, _, last, _ = self._hit_layers(origins, direction, ends)
        return (up, down, ray, casts) + ((first, last) if ends else ())

    def _hit_layers(self, origins, direction, ends):
        """:meth:`all_hit_pairs` with the ray ids of the first and last hits too:
        ``(up, down, ray, casts, first, first_ray, last, last_ray)``."""
        d32 = np.broadcast_to(np.asarray(direction, float), np.shape(origins)).astype(np.float32)
        eps32 = np.float32(self.eps)
        query = self._next_query()

        def work(a, b):
            # active rays are kept compact: origin (float32, scene-centred), direction,
            # start offset along it, ray index, and the last surface hit
            o32 = (origins[a:b] - self.center).astype(np.float32)
            dr = d32[a:b]
            ray = np.arange(a, b)
            start = np.zeros(len(o32), np.float32)
            last = np.full(len(o32), -1, np.int64)
            out = [[] for _ in range(7)]     # ups, downs, rays, firsts, first rays, lasts, last rays
            casts = 0
            for layer in range(_MAX_LAYERS):
                if ray.size == 0:
                    break
                casts += ray.size
                r = self._embree.run(o32 + start[:, None] * dr, dr, output=1)
                prim = r["primID"].astype(np.int64)
                hit = prim >= 0
                kept = hit.copy()
                if self._through is not None:
                    c = np.nonzero(hit)[0]
                    c = c[self._through[prim[c]]]
                    at = (o32[c] + (start[c] + r["tfar"][c])[:, None] * dr[c]).astype(float) + self.center
                    kept[c] = self._kept(prim[c], at, ray[c], layer, query, dr[c].astype(float))
                if ends:
                    first = kept & (last < 0)
                    out[3].append(prim[first])
                    out[4].append(ray[first])
                    gone = ~hit & (last >= 0)
                    out[5].append(last[gone])
                    out[6].append(ray[gone])
                o32, dr, ray, prim, prev, kept = o32[hit], dr[hit], ray[hit], prim[hit], last[hit], kept[hit]
                start = start[hit] + r["tfar"][hit] + eps32
                new = kept & (prev != prim)     # a re-hit of the same triangle is no new surface
                pair = new & (prev >= 0)
                out[0].append(prev[pair])
                out[1].append(prim[pair])
                out[2].append(ray[pair])
                last = np.where(kept, prim, prev)
            else:
                warnings.warn(f"a bundle ray met more than {_MAX_LAYERS} surfaces; it was cut off", stacklevel=4)
            return [np.concatenate(x) if x else np.zeros(0, np.int64) for x in out], casts

        parts = self._map_chunks(work, len(origins), min_chunk=1024)
        cat = [np.concatenate([p[0][k] for p in parts]) for k in range(7)]
        return (*cat[:3], sum(p[1] for p in parts), *cat[3:])

    def bundle(self, direction, resolution, offset=(0.5, 0.5), rotation=0.0) -> Bundle:
        """Global visibility in one direction: all light-carrying segments (see module doc)."""
        return self.bundles(np.asarray(direction, float)[None], resolution, [offset], [rotation])[0]

    def bundles(self, directions, resolution, offsets, rotations, crossings=False):
        """:meth:`bundle` in each of ``directions`` (K, 3) with grid ``offsets`` (K, 2) and
        ``rotations`` (K,), traced as one query: the rays of all K grids go to Embree
        together, layer by layer, split over the threads (one small grid alone, a few
        thousand rays, is not worth splitting).  With ``crossings`` also (T,) int, how many of
        the K grids' rays cross each triangle (each hit, whatever lies beyond: a one-sided
        triangle's front side takes one transfer a crossing, a two-sided triangle's sides one
        each, or none where it faces a black back or a black world)."""
        dirs = np.asarray(directions, float)
        dirs = dirs / np.linalg.norm(dirs, axis=1, keepdims=True)
        origins, counts, delta = self.grid_origins(dirs, resolution, offsets, rotations)
        bounds = np.concatenate([[0], np.cumsum(counts)])
        world = self.scene.world.emits
        up, down, ray, casts, first, first_ray, last, last_ray = self._hit_layers(
            origins, np.repeat(dirs, counts, axis=0), ends=world or crossings)
        k_dirs = len(dirs)

        def per_grid(rays, *arrays):
            """``arrays`` split by the grid their ray belongs to (one counting sort)."""
            grid = (np.searchsorted(bounds, rays, side="right") - 1).astype(np.uint16)
            order = np.argsort(grid, kind="stable")
            cuts = np.cumsum(np.bincount(grid, minlength=k_dirs))[:-1]
            return [np.split(x[order], cuts) for x in arrays]
        ups, downs = per_grid(ray, up, down)
        if world:
            (firsts,), (lasts,) = per_grid(first_ray, first), per_grid(last_ray, last)
        out = []
        for k in range(k_dirs):
            ends = (firsts[k], lasts[k]) if world else ()
            # Embree queries are shared out in proportion to the rays of each grid
            out.append(bundle_from_hits(self.scene, dirs[k], delta, ups[k], downs[k],
                                        int(counts[k]), int(round(casts * counts[k] / max(bounds[-1], 1))),
                                        *ends))
        if crossings:          # every hit is a pair's downstream one but each ray's first
            return out, np.bincount(np.concatenate([down, first]), minlength=len(self.scene.triangles))
        return out


def hashed_uniform(rays, layer, query):
    """(N,) uniform numbers in [0, 1) from the ray ids ``rays`` (N,), a ``layer`` and a
    ``query`` number (SplitMix64 of their combination): the same for the same ray wherever it
    is traced."""
    with np.errstate(over="ignore"):
        z = (np.asarray(rays, np.uint64) * np.uint64(0x9E3779B97F4A7C15)
             + np.uint64((int(layer) * 0x632BE59BD9B4E019 + int(query) * 0xD1B54A32D192ED03) % (1 << 64)))
        z = (z ^ (z >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)
        z = (z ^ (z >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)
        z = z ^ (z >> np.uint64(31))
    return (z >> np.uint64(11)).astype(np.float64) * (1.0 / (1 << 53))


def near_surface(tracer, corners, normals, reach, rng, points=None):
    """(K,) bool: a probe ray from a uniform point of each triangle ``corners`` (K, 3, 3) (or
    from ``points`` (K, 3) on them), cosine-distributed about its unit ``normal`` (K, 3) and
    starting ``eps`` above it, meets a surface within ``reach`` [m] (scalar or (K,)); ``rng``
    draws the points, then the directions.  What lies that close above a surface (a contact, a
    concave edge, a stair step over a floor) is what a constant patch value cannot tell apart
    from what lies beside it."""
    p = points_on_triangles(corners, *rng.random((2, len(corners)))) if points is None else points
    t, b = frames_from_normals(normals)
    w = cosine_directions(rng.random((len(normals), 2)), t, b, normals)
    return tracer.occluded(p + normals * tracer.eps, w, np.broadcast_to(np.asarray(reach, float), len(p)))


def bundle_from_hits(scene, d, delta, up, down, n_rays, casts, first=None, last=None):
    """The :class:`Bundle` of consecutive hit pairs ``up`` -> ``down`` (triangle ids)
    along ``d``: the side of ``up`` facing +d and the side of ``down`` facing -d
    exchange light both ways; with ``first``/``last`` (the first and last triangle
    of each ray) the world sends to their sides facing -d and +d."""
    s_up, s_down = scene.side_facing(up, d), scene.side_facing(down, -d)
    ok = (s_up >= 0) & (s_down >= 0)
    s_up, s_down = s_up[ok], s_down[ok]
    k = len(s_up)
    receiver, sender = [s_down, s_up], [s_up, s_down]
    sign = [np.ones(k, np.int8), -np.ones(k, np.int8)]
    if first is not None:
        for tris, s in ((first, 1), (last, -1)):
            side = scene.side_facing(tris, -s * d)
            side = side[side >= 0]
            receiver.append(side)
            sender.append(np.full(len(side), ENVIRONMENT))
            sign.append(np.full(len(side), s, np.int8))
    return Bundle(d, delta * delta, receiver=np.concatenate(receiver), sender=np.concatenate(sender),
                  travel_sign=np.concatenate(sign), n_rays=n_rays, n_casts=casts)
