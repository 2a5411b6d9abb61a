"""Surfaces that pierce others, cut where they pierce.

A triangle pierces another where one of its edges passes through it (a picture frame sunk
into the wall it hangs on, a shelf through a wall, a post through a floor).  Its parts on
the two sides of the pierced plane see different worlds, so :func:`cut_where_pierced` cuts
it there and gives the pieces weld tags per plane and side (:func:`pierce_tag`);
:func:`pierced_parts` reads those tags back as the parts a cluster must not straddle.
"""
from __future__ import annotations

import numpy as np

from ..util.arrays import connected_components, group_ids, ranges, shared_edges
from .contacts import MERGED_STEP, welded_vertices
from .gaps import PROBE_CHUNK


#: hits along a triangle's edge that :func:`piercing` looks past (neighbours, surfaces in the edge's plane)
PIERCE_HITS = 4


def piercing(tracer, scene, faces):
    """``(own, other)`` (P,) int: triangles of ``faces`` that pierce another surface and the
    triangles they pierce, a pair for each (a picture frame sunk into the wall it hangs on: the
    frame's facets behind the wall see the sky, and one patch or one welded corner for both
    parts carries that light into the room).  A triangle may pierce several surfaces (a
    shelf through a wall, under a panel that stands across the wall on it).

    A triangle pierces another where one of its edges passes through it: each edge (once,
    for the triangles that share it) is traced as a ray from corner to corner, ``eps`` short
    of both ends and ``eps`` above one of the triangles; a hit counts unless the hit triangle shares a corner (welded) with the
    edge or lies in the edge's plane (the ray then goes on past it, up to
    :data:`PIERCE_HITS` hits).  Of a post through the middle of a floor triangle, the post's
    triangles are found."""
    faces = np.asarray(faces, np.int64)
    vid = welded_vertices(scene)
    eps = tracer.eps
    own, other = [np.zeros(0, np.int64)], [np.zeros(0, np.int64)]
    step = max(1, PROBE_CHUNK // 3)
    for lo in range(0, len(faces), step):
        f = faces[lo:lo + step]
        corner = vid[scene.triangles[f]]                                              # (F, 3) welded
        ends = np.sort(np.stack([corner, np.roll(corner, -1, axis=1)], axis=2).reshape(-1, 2), axis=1)
        # each edge once (edge 3 i + k of f[i] runs from corner k to k + 1), ``eps`` above its
        # triangle (Embree reports a ray along a triangle's edge as hitting it again and again)
        _, first, inv = np.unique(ends[:, 0] * (len(vid) + 1) + ends[:, 1], return_index=True, return_inverse=True)
        tri_e, k = f[first // 3], first % 3
        lift = eps * scene.triangle_normal[tri_e]
        a = scene.vertices[scene.triangles[tri_e, k]] + lift
        b = scene.vertices[scene.triangles[tri_e, (k + 1) % 3]] + lift
        e = ends[first]
        pierced = np.full(len(first), -1, np.int64)
        length = np.linalg.norm(b - a, axis=1)
        live = np.nonzero(length > 4 * eps)[0]
        d = (b[live] - a[live]) / length[live, None]
        start = np.full(len(live), eps)
        for _ in range(PIERCE_HITS):                 # past hits that do not count (a neighbour, in plane)
            tri, t, _, _ = tracer.first_hit(a[live] + start[:, None] * d, d, glass=False)
            t = t + start
            hit = np.nonzero((tri >= 0) & (t < length[live] - 2 * eps))[0]
            theirs = tri[hit]
            shares = (vid[scene.triangles[theirs]][:, :, None] == e[live[hit]][:, None, :]).any(axis=(1, 2))
            flat = np.abs(np.einsum("ij,ij->i", scene.triangle_normal[theirs], d[hit])) < 1e-3
            keep = ~shares & ~flat
            pierced[live[hit[keep]]] = theirs[keep]
            go = hit[~keep]
            live, d, start = live[go], d[go], t[go] + eps
            if len(live) == 0:
                break
        # every triangle holding a piercing edge pierces
        edge = np.nonzero(pierced[inv.reshape(-1)] >= 0)[0]
        own.append(f[edge // 3])
        other.append(pierced[inv.reshape(-1)[edge]])
    pairs = np.unique(np.stack([np.concatenate(own), np.concatenate(other)], axis=1), axis=0)
    return pairs[:, 0], pairs[:, 1]


def pierce_tag(plane, behind):
    """The weld tag of a corner on the cut along pierced ``plane`` (int) on the piece in front
    of it or ``behind`` it: negative, apart from :func:`~raybundle.patches.contacts.split_at_contacts`'s positive ones."""
    return -1 - 2 * np.asarray(plane, np.int64) - np.asarray(behind, np.int64)


def pierced_parts(scene):
    """``(part (T,), corners (K, 3))`` int, or None when nothing was cut where it pierces
    (:func:`cut_where_pierced`): the part of a pierced surface each triangle lies in (-1 for
    triangles of no such part) and, per corner tagged on such a cut, its triangle, plane and
    side (:func:`pierce_tag`).  Parts are the
    connected components of triangles that share an edge whose two ends carry the same pierce
    tags in both: a cut along a pierced plane tags its two sides apart, so the shelf's part in
    the room and its part outside are two parts, and a cluster that holds pieces on both sides
    of a plane is split by part (:mod:`raybundle.patches.clusters`), however fine the shelf's
    triangles beside the wall are.  Parts holding no tagged piece are -1."""
    tag = scene.triangle_corner_tag
    if tag is None or not (tag < 0).any():
        return None
    tag = tag.astype(np.int64)                       # pierce tags reach past 32 bits
    vid = welded_vertices(scene).astype(np.int32)
    corners = vid[scene.triangles]
    lo, hi = shared_edges(corners)                            # edges of two triangles at one place
    a = corners.reshape(-1)
    # the two triangles' pierce tags at each end of the shared edge (their own corners at that
    # position; a contact's tags, and a contact's share of a merged tag, left out: :mod:`raybundle.patches.contacts` merges them)
    pierce = np.where(tag < 0, -(-tag % (2 * MERGED_STEP)), 0)
    check = np.nonzero(pierce.any(axis=1)[lo // 3] | pierce.any(axis=1)[hi // 3])[0]
    el, eh = lo[check], hi[check]
    t, tn = pierce.ravel(), pierce[:, [1, 2, 0]].ravel()
    agree = np.ones(len(lo), bool)
    agree[check] = np.where(a[el] == a[eh], (t[el] == t[eh]) & (tn[el] == tn[eh]),      # the same way round
                            (t[el] == tn[eh]) & (tn[el] == t[eh]))
    del a, corners
    part = connected_components(len(scene.triangles), np.stack([lo[agree] // 3, hi[agree] // 3], axis=1))
    cut = np.zeros(int(part.max(initial=-1)) + 1, bool)
    cut[part[(tag < 0).any(axis=1)]] = True
    row, k = np.nonzero(pierce < 0)
    plane, behind = np.divmod(-1 - pierce[row, k], 2)
    return np.where(cut[part], part, -1).astype(np.int32), np.stack([row, plane, behind], axis=1)


def cut_where_pierced(scene, own, other):
    """``(scene, rows)``: ``scene`` with each triangle ``own`` (P,) cut by the plane of the triangle
    ``other`` (P,) it pierces (:func:`piercing`) into the piece in front of that plane and the
    piece behind it, and ``rows`` (T',) the row in ``scene`` of each new triangle.  A triangle
    that pierces several planes is cut along each in turn, its pieces again (one plane per
    triangle and round, vectorised; :func:`_cut_once`).  Triangles with a corner within
    ``1e-6`` of the scene radius of a plane are left whole by it."""
    own, other = np.asarray(own, np.int64), np.asarray(other, np.int64)
    if len(own) == 0:
        return scene, np.arange(len(scene.triangles))
    _, r = scene.bounding_sphere
    eps = 1e-6 * max(r, 1e-12)
    n = scene.triangle_normal[other]
    p0 = scene.triangle_corners[other, 0]
    off = np.einsum("ij,ij->i", n, p0)
    q = np.round(n * 1e4).astype(np.int64)
    plane = group_ids([q[:, 0], q[:, 1], q[:, 2], np.round(off / eps).astype(np.int64)])
    _, once = np.unique(np.stack([own, plane], axis=1), axis=0, return_index=True)        # a pair per plane
    own, plane, n, p0 = own[once], plane[once], n[once], p0[once]
    rows = np.arange(len(scene.triangles))
    next_id, meet = int(plane.max(initial=-1)) + 1, {}     # ids where two cuts meet (:func:`_cut_once`)
    while len(own):
        _, first = np.unique(own, return_index=True)
        scene, cut_rows = _cut_once(scene, own[first], n[first], p0[first], plane[first], eps, next_id, meet)
        rows = rows[cut_rows]
        # the planes left for a triangle apply to each of its pieces
        rest = np.ones(len(own), bool)
        rest[first] = False
        own, plane, n, p0 = own[rest], plane[rest], n[rest], p0[rest]
        order = np.argsort(cut_rows, kind="stable")
        lo = np.searchsorted(cut_rows[order], own, side="left")
        hi = np.searchsorted(cut_rows[order], own, side="right")
        count = hi - lo
        pair = np.repeat(np.arange(len(own)), count)
        own = order[ranges(lo, count)]
        plane, n, p0 = plane[pair], n[pair], p0[pair]
    return scene, rows


def _cut_once(scene, own, n, p0, plane, eps, next_id, meet):
    """``(scene, rows)``: :func:`cut_where_pierced` for distinct triangles ``own`` (P,),
    each cut by one plane (unit normal ``n`` (P, 3) through ``p0`` (P, 3), id ``plane`` (P,))
    into the piece in front of it and the piece behind it (one triangle and two).  The
    behind pieces get a patch of their own (one per patch cut), and the new corners on the cut
    a weld tag per plane and side (:func:`pierce_tag`), so the pieces share neither an unknown
    nor an interpolated corner value; pieces in front of one plane weld along the cut.  A new
    corner on an edge cut before (both ends tagged alike) lies where two cuts meet: it gets the
    tag of a plane of its own, an id from ``next_id`` on per earlier tag, plane and side (kept
    in ``meet``, a dict, through the rounds), so it welds only with pieces on its side of both."""
    from ..scene.model import PatchScene
    c = scene.triangle_corners[own]
    d = np.einsum("fkc,fc->fk", c - p0[:, None], n)                                      # (P, 3) [m]
    ok = (np.abs(d) > eps).all(axis=1) & (d.max(axis=1) > 0) & (d.min(axis=1) < 0)
    own, plane, c, d = own[ok], plane[ok], c[ok], d[ok]
    if len(own) == 0:
        return scene, np.arange(len(scene.triangles))
    pos = d > 0
    lone = np.where(pos.sum(axis=1) == 1, np.argmax(pos, axis=1), np.argmin(pos, axis=1))
    k = (lone[:, None] + np.arange(3)) % 3                                  # lone corner first, winding kept
    idx = scene.triangles[own][np.arange(len(own))[:, None], k]                         # (P, 3) A, B, C
    ca = np.take_along_axis(c, k[:, :, None], axis=1)
    da = np.take_along_axis(d, k, axis=1)
    pp = ca[:, 0] + (ca[:, 1] - ca[:, 0]) * (da[:, 0] / (da[:, 0] - da[:, 1]))[:, None]     # on AB
    qq = ca[:, 0] + (ca[:, 2] - ca[:, 0]) * (da[:, 0] / (da[:, 0] - da[:, 2]))[:, None]     # on AC
    m = len(own)
    v0 = len(scene.vertices)
    vp, vq = v0 + np.arange(m), v0 + m + np.arange(m)
    a, b, cc = idx.T
    tris = np.concatenate([np.stack([a, vp, vq], 1), np.stack([vp, b, cc], 1), np.stack([vp, cc, vq], 1)])
    src = np.tile(own, 3)
    old_tag = (scene.triangle_corner_tag if scene.triangle_corner_tag is not None
               else np.zeros((len(scene.triangles), 3), np.int64))
    ot = np.take_along_axis(old_tag[own], k, axis=1)
    lone_front = da[:, 0] > 0
    # the tags of the new corners P (on AB) and Q (on AC), on the lone corner's piece and on the others
    tag = {}
    for name, end in (("p", 1), ("q", 2)):
        crossed = np.nonzero((ot[:, 0] == ot[:, end]) & (ot[:, 0] < 0))[0]      # an earlier cut runs along the edge
        for side, behind in (("lone", ~lone_front), ("rest", lone_front)):
            ids = plane.copy()
            for i in crossed:
                ids[i] = meet.setdefault((int(ot[i, 0]), int(plane[i]), bool(behind[i])), next_id + len(meet))
            tag[name, side] = pierce_tag(ids, behind)
    tags = np.concatenate([np.stack([ot[:, 0], tag["p", "lone"], tag["q", "lone"]], 1),
                           np.stack([tag["p", "rest"], ot[:, 1], ot[:, 2]], 1),
                           np.stack([tag["p", "rest"], ot[:, 2], tag["q", "rest"]], 1)])
    # patches: the pieces behind the plane get one new patch per patch cut
    behind = np.concatenate([~lone_front, lone_front, lone_front])
    n_patch = int(scene.triangle_patch.max(initial=-1)) + 1
    patch = np.where(behind, n_patch + scene.triangle_patch[src], scene.triangle_patch[src])
    keep = np.ones(len(scene.triangles), bool)
    keep[own] = False
    keep = np.nonzero(keep)[0]
    rows = np.concatenate([keep, src])
    patch = np.unique(np.concatenate([scene.triangle_patch[keep], patch]), return_inverse=True)[1].reshape(-1)
    return PatchScene(np.concatenate([scene.vertices, pp, qq]), np.concatenate([scene.triangles[keep], tris]),
                      scene.triangle_material[rows], patch.astype(np.int64), scene.triangle_source[rows],
                      scene.materials, scene.point_lights, scene.camera, scene.analytic_radiance, scene.name,
                      scene.dropped_triangles, scene.triangle_solid[rows], scene.triangle_two_sided[rows],
                      scene.sun_lights, scene.area_lights, scene.world,
                      np.concatenate([old_tag[keep], tags]), texture=scene.texture,
                      shading=scene.shading, linking=scene.linking), rows
