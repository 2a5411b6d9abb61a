"""The patch layout by subdivision: triangles cut into similar triangles to a patch size
(:func:`subdivide`, :func:`split_triangles`), slivers halved along their length instead
(:func:`bisect_long`), and then cut along the lines where other surfaces
touch or cross them (:func:`cut_at_contacts`, :mod:`raybundle.patches.contacts`).
:func:`raybundle.patches.clusters.make_patches` also groups triangles much smaller than a patch."""
from __future__ import annotations

import numpy as np

from ..scene.model import PatchScene
from ..util.arrays import unique_ints, unique_rows

#: scenes with at most this many reflecting patch triangles have every one cut at contacts,
#: larger ones only their subdivided faces (:func:`subdivide`)
CONTACT_ALL_MAX = 10_000
#: a plane whose triangles add up to less than this share of ``max_edge^2`` (half a patch) is not
#: cut at contacts: the facets of a curved mesh are such planes, tens of thousands of them in a
#: furnished room, each costing a pass of its own while a leak through it is at most its area
CONTACT_MIN_PLANE = 0.5
#: cosine-distributed probe rays per side of a patch triangle that find how crowded it is (:func:`crowding`)
CROWD_RAYS = 16
#: a patch triangle is crowded where at least this share of its probe rays meets a surface ...
CROWD_SHARE = 0.25
#: ... within this share of the patch size (:func:`refine_crowded`)
CROWD_REACH = 0.25


def subdivide(scene: PatchScene, max_edge=None, patches=None, contacts=True) -> PatchScene:
    """Split every triangle into k^2 similar triangles so that edges are at most
    ``max_edge`` [m] long, or so that there are about ``patches`` patches.

    Each resulting triangle is its own patch.  k is chosen per triangle
    (``k = ceil(longest edge / max_edge)``); neighbours with different k meet at
    T-junctions, which are harmless here (patches are flat, visibility is traced).
    Triangles that reflect nothing (a lamp's Emission shader, a black body) stay
    whole: their outgoing radiance is known, and a light made of few triangles
    is sampled with less variance.  With ``contacts``, the patches of subdivided faces (of
    every reflecting face, up to :data:`CONTACT_ALL_MAX` triangles) are then cut along the
    lines where other surfaces touch or cross them, gaps narrower than a quarter of
    ``max_edge`` counting as contact (:mod:`raybundle.patches.contacts`).
    (:func:`raybundle.patches.clusters.make_patches` also groups triangles much smaller than a patch.)
    """
    if (max_edge is None) == (patches is None):
        raise ValueError("give exactly one of max_edge and patches")
    if patches is not None:
        max_edge = edge_for_patches(scene, patches)
    if not max_edge > 0:
        raise ValueError("max_edge must be positive")
    fine, k, _ = split_triangles(scene, max_edge)
    if not contacts:
        return fine
    return cut_at_contacts(fine, np.nonzero(k > 1)[0], max_edge)


def longest_edges(corners):
    """(T,) the longest edge [m] of each triangle with ``corners`` (T, 3, 3)."""
    return np.linalg.norm(corners - np.roll(corners, 1, axis=1), axis=2).max(axis=1)


def _split_edge(scene, whole=None):
    """(T,) longest edge of each triangle [m], 0 for triangles kept whole: those that reflect
    nothing and those in ``whole`` (T,) bool."""
    corners = scene.triangle_corners
    edge = longest_edges(corners)
    split = scene.materials.reflects[scene.triangle_material]
    if whole is not None:
        split = split & ~whole
    return np.where(split, edge, 0.0)


def edge_for_patches(scene, patches):
    """The ``max_edge`` [m] for which :func:`split_triangles` makes about ``patches`` patches
    (the longest edge when there are more triangles than that: nothing is split)."""
    split_edge = _split_edge(scene)
    if patches < len(scene.triangles) or not split_edge.any():
        corners = scene.triangle_corners
        return float(longest_edges(corners).max()) * 1.0001
    # bisection on the edge length for sum(k^2) ~ patches
    lo, hi = 1e-9 * split_edge.max(), split_edge.max() * 1.0001
    for _ in range(60):
        mid = np.sqrt(lo * hi)
        n = (np.maximum(1, np.ceil(split_edge / mid)) ** 2).sum()
        lo, hi = (mid, hi) if n > patches else (lo, mid)
    return hi


def split_triangles(scene: PatchScene, max_edge, whole=None):
    """Every reflecting triangle (but those in ``whole`` (T,) bool) cut into k^2 similar
    ones, ``k = ceil(longest edge / max_edge)``, each its own patch (:func:`subdivide`
    without contacts).  Returns ``(scene, k, row)``: ``k`` (T',) the k of the triangle
    each new triangle came from and ``row`` (T',) that triangle's index."""
    corners = scene.triangle_corners
    k_all = np.maximum(1, np.ceil(_split_edge(scene, whole) / max_edge - 1e-9)).astype(np.int64)
    verts, tris, rows = [scene.vertices], [], []
    base = len(scene.vertices)
    for k in np.unique(k_all):
        sel = np.nonzero(k_all == k)[0]
        rows.append(np.repeat(sel, k * k))
        if k == 1:                  # whole triangles keep their corners
            tris.append(scene.triangles[sel])
            continue
        # barycentric lattice points (i, j) with i + j <= k
        ij = np.array([(i, j) for i in range(k + 1) for j in range(k + 1 - i)])
        index = {tuple(p): n for n, p in enumerate(ij)}
        up = [(index[i, j], index[i + 1, j], index[i, j + 1]) for i in range(k) for j in range(k - i)]
        down = [(index[i + 1, j], index[i + 1, j + 1], index[i, j + 1])
                for i in range(k) for j in range(k - 1 - i)]
        local = np.array(up + down, dtype=np.int64)
        c = corners[sel]
        b1, b2 = ij[:, 0] / k, ij[:, 1] / k
        pts = (c[:, None, 0] + b1[None, :, None] * (c[:, None, 1] - c[:, None, 0])
               + b2[None, :, None] * (c[:, None, 2] - c[:, None, 0]))
        verts.append(pts.reshape(-1, 3))
        offs = base + np.arange(len(sel))[:, None, None] * len(ij)
        tris.append((local[None] + offs).reshape(-1, 3))
        base += len(sel) * len(ij)
    row = np.concatenate(rows)
    return _rebuilt(scene, np.concatenate(verts), np.concatenate(tris), row), k_all[row], row


def bisect_long(scene: PatchScene, max_edge, which):
    """The triangles ``which`` (T,) bool halved at the middle of their longest edge until no
    edge is longer than ``max_edge`` [m], each half its own patch; the others kept.

    Unlike :func:`split_triangles`' k^2 similar pieces, this refines a sliver (a long, thin
    triangle: a wall fanned out around a window) only along its length: a needle L long makes
    about 2 L / max_edge pieces, not (L / max_edge)^2, and a fat triangle about twice
    (its area / max_edge^2); the smallest angle stays above half the triangle's own.  Returns
    ``(scene, row)``: ``row`` (T',) the input triangle each new one came from."""
    corners = scene.triangle_corners
    keep = np.nonzero(~np.asarray(which, bool))[0]
    todo = np.nonzero(which)[0]
    c, origin = corners[todo], todo
    pieces, rows = [], []
    for level in range(128):            # each two levels at least halve the longest edge
        if not len(c):
            break
        edge = np.linalg.norm(np.roll(c, -1, axis=1) - c, axis=2)          # edge j: corner j -> j + 1
        j = np.argmax(edge, axis=1)
        done = ~(edge[np.arange(len(c)), j] > max_edge) | (level == 127)
        pieces.append(c[done])
        rows.append(origin[done])
        c, j, origin = c[~done], j[~done], origin[~done]
        n = np.arange(len(c))
        a, b, o = c[n, j], c[n, (j + 1) % 3], c[n, (j + 2) % 3]
        m = 0.5 * (a + b)                                  # the same point from both triangles of an edge
        c = np.concatenate([np.stack([a, m, o], axis=1), np.stack([m, b, o], axis=1)])
        origin = np.concatenate([origin, origin])
    c = np.concatenate(pieces) if pieces else np.zeros((0, 3, 3))
    row = np.concatenate([keep] + rows)
    tris = np.concatenate([scene.triangles[keep], len(scene.vertices) + np.arange(3 * len(c)).reshape(-1, 3)])
    return _rebuilt(scene, np.concatenate([scene.vertices, c.reshape(-1, 3)]), tris, row), row


def _rebuilt(scene: PatchScene, vertices, triangles, row) -> PatchScene:
    """``scene`` made of new ``triangles`` (T', 3) over ``vertices`` (coincident ones welded,
    unused ones dropped), each its own patch, with the material, source face, solidity and
    sidedness of triangle ``row`` (T',) of ``scene``."""
    _, r = scene.bounding_sphere
    # (a vertex no triangle uses may be NaN: build_scene checks only those in use)
    q = np.round(np.where(np.isfinite(vertices), vertices, 0.0) / max(r * 1e-7, 1e-12)).astype(np.int64)
    first, inv = unique_rows(q)
    used, _, t = unique_ints(inv[triangles])                     # only the corners in use
    return PatchScene(vertices[first[used]], t.reshape(-1, 3), scene.triangle_material[row], np.arange(len(row)),
                      scene.triangle_source[row], scene.materials, scene.point_lights, scene.camera,
                      scene.analytic_radiance, scene.name, scene.dropped_triangles, scene.triangle_solid[row],
                      scene.triangle_two_sided[row], scene.sun_lights, scene.area_lights, scene.world,
                      texture=scene.texture, shading=scene.shading, linking=scene.linking)


def cut_at_contacts(scene: PatchScene, cut, max_edge, tracer=None) -> PatchScene:
    """The patches of triangles ``cut`` (the pieces of subdivided faces) cut along contact
    lines (:mod:`raybundle.patches.contacts`, gaps under a quarter of ``max_edge`` count as contact); so is
    every reflecting triangle when there are at most :data:`CONTACT_ALL_MAX` of them, and
    beyond that every one that straddles such a gap (:func:`~raybundle.patches.gaps.straddling`,
    probed with ``tracer``, a :class:`~raybundle.tracing.visibility.RayTracer` over ``scene``, or
    one built here), and every one that pierces another surface is first cut along that
    surface's plane (:func:`~raybundle.patches.piercing.piercing`,
    :func:`~raybundle.patches.piercing.cut_where_pierced`)."""
    from .contacts import split_at_contacts
    from .gaps import CONTACT_SHARE, straddling
    from .piercing import cut_where_pierced, piercing
    # faces the user meshed finer than the patches are cut too: a ceiling cut into a grid over
    # a lamp hanging under it must still trap the lamp's upper light.  Up to CONTACT_ALL_MAX
    # triangles all of them (crossings too: a post through a floor); beyond, the cut is a
    # per-triangle loop, too slow for every triangle of a large scene (docs/benchmarks.md, 'Where the method
    # is weak'), so only those found straddling a gap or piercing a surface.
    tol = CONTACT_SHARE * max_edge
    todo = np.zeros(len(scene.triangles), bool)
    todo[np.asarray(cut, np.int64)] = True
    pierced = None
    reflects = scene.materials.reflects[scene.triangle_material]
    if reflects.sum() <= CONTACT_ALL_MAX:
        todo |= reflects
    else:
        rest = np.nonzero(reflects & ~todo)[0]
        if len(rest):
            from ..tracing.visibility import RayTracer
            probe = tracer if tracer is not None else RayTracer(scene)
            try:
                todo[rest[straddling(probe, scene, rest, tol)]] = True
                # and those that pierce another surface, cut along its plane first (a frame sunk
                # into a wall); the cut's pieces need no tracer
                pierced = piercing(probe, scene, rest)
            finally:
                if probe is not tracer:
                    probe.close()
    if pierced is not None and len(pierced[0]):
        scene, rows = cut_where_pierced(scene, *pierced)
        todo = todo[rows]
    return split_at_contacts(scene, np.nonzero(todo)[0], tol=tol, min_plane_area=CONTACT_MIN_PLANE * max_edge ** 2)[0]


def crowding(tracer, scene, which, reach, rays=CROWD_RAYS, seed=0):
    """(W,) the share of ``rays`` cosine-distributed rays from uniform points of each triangle
    ``which`` (W,) that meet a surface within ``reach`` [m] (for a two-sided triangle the larger
    of its two sides' shares), traced by ``tracer`` over ``scene``; a fixed ``seed``, so a
    layout is the same on every run.  Under an unbounded parallel plate at height d < reach
    it is 1 - (d / reach)^2: a cosine-distributed ray meets the plate within reach when its
    angle to the normal has cos >= d / reach, and sin^2 of that widest angle is its probability."""
    from ..tracing.sampling import points_on_triangles
    from ..tracing.visibility import near_surface
    which = np.asarray(which, np.int64)
    out = np.zeros(len(which))
    if not len(which):
        return out
    rng = np.random.default_rng(seed)
    own = np.repeat(np.arange(len(which)), rays)
    tri = which[own]
    p = points_on_triangles(scene.triangle_corners[tri], *rng.random((2, len(tri))))      # both sides' points
    for sign in (1.0, -1.0):
        sel = np.arange(len(tri)) if sign > 0 else np.nonzero(scene.triangle_two_sided[tri])[0]
        if not len(sel):
            continue
        blocked = near_surface(tracer, scene.triangle_corners[tri[sel]], sign * scene.triangle_normal[tri[sel]],
                               reach, rng, points=p[sel])
        out = np.maximum(out, np.bincount(own[sel], blocked, minlength=len(which)) / rays)
    return out


def refine_crowded(scene: PatchScene, which, h, tracer):
    """The patch triangles ``which`` (W,) that are crowded (:func:`crowding`: at least
    :data:`CROWD_SHARE` of their probe rays meet a surface within :data:`CROWD_REACH` x ``h``,
    the patch size [m]) cut again to edges of at most h / 2; the others kept.

    A patch is one value over its area: a floor patch h wide reaching under a stair step
    h / 8 above it averages the lit floor in front with the dark floor beneath, and the step's
    underside, which sees only that floor, is lit by the average.
    ``tracer``: a :class:`~raybundle.tracing.visibility.RayTracer` over ``scene``'s surfaces.  Returns ``(scene, row, crowded)``: ``row`` (T',) the triangle of ``scene`` each new
    one came from, ``crowded`` the count of triangles cut."""
    which = np.asarray(which, np.int64)
    if not len(which):
        return scene, np.arange(len(scene.triangles)), 0
    share = crowding(tracer, scene, which, CROWD_REACH * h)
    whole = np.ones(len(scene.triangles), bool)
    whole[which[share >= CROWD_SHARE]] = False
    if whole.all():
        return scene, np.arange(len(scene.triangles)), 0
    fine, _, row = split_triangles(scene, 0.5 * h, whole=whole)
    return fine, row, int((~whole).sum())
