"""Patches that conform to contact lines.

Where one surface touches or pierces another (a box standing on a floor, a
lamp 0.5 mm under a ceiling, a post through a floor), a patch that straddles
the contact line has one radiance variable for two parts that see different
worlds: the part under the box sees only the box's inside, the part of the
ceiling over the lamp sees only the lamp's back.  A constant over the patch
mixes them, so light leaks through the contact (the light trapped between a
two-sided lamp and the ceiling comes out as a bright ceiling patch; a room's
light leaks into a box and back).  This is the finite-element error of
*discontinuity meshing* (Heckbert 1992; Lischinski, Tampieri & Greenberg 1992):
the cure is to make patch edges follow the lines where the surface's
visibility jumps.  Contact lines are the strongest of those and cheap to find.

:func:`contact_segments` finds, for every plane holding subdivided faces, the
segments where other surfaces meet it: edges lying within ``tol`` of the plane
(the box's bottom edges, the outline of a lamp hanging just under a ceiling;
edges shared by two faces that both lie in the gap are inner edges and are
dropped), and the lines where triangles cross it.  :func:`split_at_contacts`
cuts every patch that such a segment crosses along the segment's line into
convex pieces; each piece is a patch of its own (one or more triangles).
Pieces smaller than ``min_fraction`` (0.5%) of the patch are not cut off (their
leak is that small).  A patch is cut only along lines whose segments in the plane add up to at
least :data:`~raybundle.patches.convex_cuts.CUT_SHARE` of its longest edge, the
:data:`~raybundle.patches.convex_cuts.MAX_CUTS` longest (the footprint of a small object on a
large patch tags its corners and cuts nothing: its cuts would run across the whole patch, far
from the contact, and a curved object brings a line per edge).  Corners that lie on a contact
segment get a *weld tag*
naming the segment's line and the side of it the triangle lies on, so that
smooth interpolation of patch values does not blend across the contact but
does along it; triangles that touch a contact without being cut keep their
patch and only get the tags.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..tracing.sampling import orthonormal_basis
from ..util.arrays import ranges, stable_order, unique_rows
from .convex_cuts import cut_triangles, worth_cutting


def _plane_groups(scene, faces, min_area=0.0):
    """Group triangle ids ``faces`` by their plane: list of (ids, normal, offset) of the planes
    whose triangles add up to at least ``min_area`` [m^2].  Planes closer than 1e-6 of the scene
    radius are one plane."""
    n = scene.triangle_normal[faces]
    p0 = scene.triangle_corners[faces, 0]
    # canonical orientation: two-sided faces with flipped normals share a plane
    first = np.argmax(np.abs(n) > 1e-6, axis=1)
    sign = np.where(n[np.arange(len(n)), first] < 0, -1.0, 1.0)
    n = n * sign[:, None]
    off = np.einsum("ij,ij->i", n, p0)
    _, r = scene.bounding_sphere
    key = np.concatenate([np.round(n * 1e4), np.round(off / max(r * 1e-6, 1e-12))[:, None]], axis=1).astype(np.int64)
    label = unique_rows(key)[1]
    big = np.bincount(label, scene.triangle_area[faces]) >= min_area
    order = stable_order(label)[0]
    order = order[big[label[order]]]
    cuts = np.nonzero(np.diff(label[order]))[0] + 1
    return [(faces[g], n[g[0]], float(off[g[0]])) for g in np.split(order, cuts) if len(g)]


class _BoxQuery:
    """The triangles whose bounding boxes ``lo``, ``hi`` (T, 3) overlap a query box, without
    a pass over all of them per query (a real room has tens of thousands of planes):
    sort and sweep on one ``axis`` (by default the widest).  Boxes no longer than the 99th
    percentile along it are sorted by their low end, so those that can overlap ``[a, b]`` lie in
    the window of low ends ``[a - longest, b]``; the longer ones (1%) are always tested."""

    def __init__(self, lo, hi, axis=None):
        # per axis, contiguous: :meth:`pairs` tests one axis at a time, the sweep's first (boxes
        # given as the transpose of per-axis arrays are read in place: queries along several
        # axes share them)
        self.lo, self.hi = np.ascontiguousarray(lo.T), np.ascontiguousarray(hi.T)
        if axis is None:
            axis = int(np.argmax(hi.max(axis=0) - lo.min(axis=0))) if len(lo) else 0
        self.axis = axis
        ext = hi[:, self.axis] - lo[:, self.axis]
        cut = np.quantile(ext, 0.99) if len(ext) else 0.0
        short = np.nonzero(ext <= cut)[0]
        self.long = np.nonzero(ext > cut)[0]
        self.order = short[np.argsort(lo[short, self.axis], kind="stable")]
        self.starts = lo[self.order, self.axis]
        self.longest = float(ext[short].max()) if len(short) else 0.0

    def __call__(self, lo, hi):
        """Sorted ids of the boxes overlapping ``[lo, hi]`` (3,) (touching counts)."""
        return np.sort(self.pairs(np.asarray(lo)[None], np.asarray(hi)[None])[1])

    def pairs(self, lo, hi):
        """``(query, box)`` (P,) int: every pair of a query box ``[lo[q], hi[q]]`` (Q, D) and a
        box overlapping it (touching counts), vectorised over the queries."""
        k = self.axis
        a = np.searchsorted(self.starts, lo[:, k] - self.longest, side="left")
        n = np.maximum(np.searchsorted(self.starts, hi[:, k], side="right") - a, 0)
        query = np.repeat(np.arange(len(lo)), n)
        box = self.order[ranges(a, n)]
        if len(self.long):
            query = np.concatenate([query, np.repeat(np.arange(len(lo)), len(self.long))])
            box = np.concatenate([box, np.tile(self.long, len(lo))])
        for i in [k] + [i for i in range(lo.shape[1]) if i != k]:
            ok = (self.hi[i][box] >= lo[query, i]) & (self.lo[i][box] <= hi[query, i])
            query, box = query[ok], box[ok]
        return query, box


def contact_segments(scene, faces, tol, min_plane_area=0.0):
    """Contact segments on the planes of triangles ``faces`` (ids into ``scene``) whose
    triangles add up to at least ``min_plane_area`` [m^2] in that plane.

    Returns a list of ``(group, origin, e1, e2, segments, coplanar)``: ``group`` the
    triangle ids in one plane, ``origin`` (3,) and ``e1, e2`` (3,) that plane's
    2D frame [m], ``segments`` (K, 2, 2) the contact segments in it, ``coplanar`` the ids of
    the other triangles lying in the plane (none of ``faces``).  Other
    triangles meet the plane where their edges lie within ``tol`` [m] of it,
    or where they cross it.
    """
    out = []
    if len(faces) == 0:
        return out
    corners = np.asarray(scene.triangle_corners)                # gathered once: read whole and in parts
    # the boxes per axis, contiguous, as every axis' query reads them (its own copy is then none)
    lo_all = np.ascontiguousarray(corners.min(axis=1).T).T
    hi_all = np.ascontiguousarray(corners.max(axis=1).T).T
    _, r = scene.bounding_sphere
    vid = welded_vertices(scene)
    # a plane's box is thin along its normal: sweep along the axis where it is thinnest
    overlapping = {}
    mine = np.zeros(len(scene.triangles), bool)              # the plane's own triangles
    for group, n, off in _plane_groups(scene, faces, min_plane_area):
        c = corners[group]
        lo, hi = c.reshape(-1, 3).min(axis=0) - tol, c.reshape(-1, 3).max(axis=0) + tol
        axis = int(np.argmin(hi - lo))
        if axis not in overlapping:
            overlapping[axis] = _BoxQuery(lo_all, hi_all, axis)
        cand = overlapping[axis](lo, hi)
        mine[group] = True
        cand = cand[~mine[cand]]
        mine[group] = False
        d = corners[cand] @ n - off                                   # (C, 3) signed distances
        coplanar = cand[(np.abs(d).max(axis=1) <= 1e-6 * r) & (np.abs(scene.triangle_normal[cand] @ n) > 1 - 1e-6)]
        cand_mask = (d.min(axis=1) <= tol) & (d.max(axis=1) >= -tol)
        cand, d = cand[cand_mask], d[cand_mask]
        if len(cand) == 0:
            continue
        a3, b3 = _edges_in_plane(corners[cand], d, vid[scene.triangles[cand]], tol)
        if len(a3) == 0:
            continue
        e1, e2 = orthonormal_basis(n)
        seg = _in_plane_frame(a3, b3, n * off, e1, e2, r)
        if len(seg):
            out.append((group, n * off, e1, e2, seg, coplanar))
    return out


def _edges_in_plane(p, d, tv, tol):
    """``(a, b)`` (K, 3): the segments where triangles with corners ``p`` (C, 3, 3) at signed
    distances ``d`` (C, 3) from a plane meet it: their edges lying within ``tol`` of it (but the
    inner edges, between two triangles both lying in the gap; ``tv`` (C, 3) welded corner ids),
    and the lines where they cross it."""
    near = np.abs(d) <= tol
    all_near = near.all(axis=1)
    segs = []
    for i, j in ((0, 1), (1, 2), (2, 0)):
        sel = near[:, i] & near[:, j]
        key = np.sort(np.stack([tv[:, i], tv[:, j]], axis=1), axis=1)
        segs.append((sel, p[:, i], p[:, j], key, all_near))
    keys = np.concatenate([s[3][s[0]] for s in segs])
    flat = np.concatenate([s[4][s[0]] for s in segs])
    first, inv = unique_rows(keys)
    cnt = np.bincount(inv, minlength=len(first))
    inner_count = np.bincount(inv, flat, minlength=len(first))
    drop = (cnt >= 2) & (inner_count >= 2)
    keep = ~drop[inv]
    a3 = np.concatenate([s[1][s[0]] for s in segs])[keep]
    b3 = np.concatenate([s[2][s[0]] for s in segs])[keep]
    # crossings: triangles with corners on both sides beyond tol
    cross = ~all_near & ~(near.sum(axis=1) >= 2) & (d.max(axis=1) > tol) & (d.min(axis=1) < -tol)
    if cross.any():
        ca, cb = _crossings(p[cross], d[cross], near[cross])
        a3, b3 = np.concatenate([a3, ca]), np.concatenate([b3, cb])
    return a3, b3


def _crossings(pc, dc, nc):
    """``(a, b)`` (K, 3): where triangles with corners ``pc`` (C, 3, 3), signed distances ``dc``
    and corners on the plane ``nc`` (C, 3) bool cross the plane (two points each, a corner on the
    plane or an edge through it)."""
    pts = np.zeros((len(pc), 2, 3))
    cnt_pts = np.zeros(len(pc), np.int64)
    for i in range(3):                                   # a corner on the plane
        s = nc[:, i]
        rows = np.nonzero(s)[0]
        pts[rows, np.minimum(cnt_pts[rows], 1)] = pc[rows, i]
        cnt_pts[rows] += 1
    for i, j in ((0, 1), (1, 2), (2, 0)):                # an edge through the plane
        s = ~nc[:, i] & ~nc[:, j] & (np.sign(dc[:, i]) != np.sign(dc[:, j]))
        rows = np.nonzero(s)[0]
        t = dc[rows, i] / (dc[rows, i] - dc[rows, j])
        pts[rows, np.minimum(cnt_pts[rows], 1)] = pc[rows, i] + t[:, None] * (pc[rows, j] - pc[rows, i])
        cnt_pts[rows] += 1
    ok = cnt_pts == 2
    return pts[ok, 0], pts[ok, 1]


def _in_plane_frame(a3, b3, origin, e1, e2, r):
    """(K, 2, 2): the segments ``a3 -> b3`` in the plane's frame, without those shorter than
    1e-9 of the scene radius ``r``, each once however many triangles gave it."""
    to2d = np.stack([e1, e2], axis=1)
    seg = np.stack([(a3 - origin) @ to2d, (b3 - origin) @ to2d], axis=1)
    length = np.linalg.norm(seg[:, 1] - seg[:, 0], axis=1)
    seg = seg[length > 1e-9 * max(r, 1e-12)]
    q = np.round(np.sort(seg.reshape(len(seg), 4).reshape(-1, 2, 2), axis=1).reshape(len(seg), 4)
                 / max(r * 1e-7, 1e-12)).astype(np.int64)
    return seg[unique_rows(q)[0]]


def _crosses(tri, segs, eps):
    """(P,) bool: the line of segment ``segs[p]`` (P, 2, 2) has corners of triangle ``tri[p]``
    (P, 3, 2) strictly on both sides (farther than ``eps``), as
    :func:`~raybundle.patches.convex_cuts.split_polygon` decides."""
    a, d = segs[:, 0], segs[:, 1] - segs[:, 0]
    dvec = d / np.hypot(d[:, 0], d[:, 1])[:, None]
    s = dvec[:, None, 0] * (tri[:, :, 1] - a[:, None, 1]) - dvec[:, None, 1] * (tri[:, :, 0] - a[:, None, 0])
    return ((s > eps).any(axis=1)) & ((s < -eps).any(axis=1))


def _cross2(u, v):
    return u[..., 0] * v[..., 1] - u[..., 1] * v[..., 0]


#: pairs of a triangle and a segment tested at once in :func:`split_at_contacts` (memory: about
#: 200 bytes a pair)
PAIR_CHUNK = 1 << 20
def _touching_pairs(tri2d, seg, eps):
    """``(f, k, crosses)`` (P,): the pairs, sorted by f then k, of a triangle ``tri2d[f]``
    (F, 3, 2) and a segment ``seg[k]`` (K, 2, 2) that touch, along a piece of positive length
    (:func:`_touching`) or at a corner of the triangle (:func:`_on_segment`), and whether the
    segment's line cuts the triangle (:func:`_crosses`).  Only pairs whose bounding boxes
    overlap are tested (:class:`_BoxQuery`): a floor holds thousands of triangles and the
    outlines of every chair leg on it."""
    pad = 1e3 * eps
    k, f = _BoxQuery(tri2d.min(axis=1) - pad, tri2d.max(axis=1) + pad).pairs(seg.min(axis=1), seg.max(axis=1))
    order = np.lexsort((k, f))
    f, k = f[order], k[order]
    hit, crosses = np.zeros(len(f), bool), np.zeros(len(f), bool)
    for lo in range(0, len(f), PAIR_CHUNK):
        t, sg = tri2d[f[lo:lo + PAIR_CHUNK]], seg[k[lo:lo + PAIR_CHUNK]]
        hit[lo:lo + PAIR_CHUNK] = _touching(t, sg, eps) | _on_segment(t, sg, eps).any(axis=1)
        crosses[lo:lo + PAIR_CHUNK] = _crosses(t, sg, eps)
    return f[hit], k[hit], crosses[hit]


def _touching(tri2d, seg, eps):
    """(P,) bool: segment ``seg[p]`` (P, 2, 2) meets triangle ``tri2d[p]`` (P, 3, 2) along a
    piece of positive length (crossing its interior or lying on an edge).  Cyrus-Beck clipping."""
    a, b = seg[:, 0], seg[:, 1]                                          # (P, 2)
    t0 = np.zeros(len(tri2d))
    t1 = np.ones_like(t0)
    ccw = np.sign(_cross2(tri2d[:, 1] - tri2d[:, 0], tri2d[:, 2] - tri2d[:, 0]))
    for i in range(3):
        p, q = tri2d[:, i], tri2d[:, (i + 1) % 3]                          # (P, 2)
        e = q - p
        # inside when ccw * cross(e, x - p) >= -eps
        fa = ccw * _cross2(e, a - p)
        fb = ccw * _cross2(e, b - p)
        elen = np.linalg.norm(e, axis=1)
        fa, fb = fa + eps * elen, fb + eps * elen
        den = fa - fb
        with np.errstate(divide="ignore", invalid="ignore"):
            t = fa / den
        out_both = (fa < 0) & (fb < 0)
        t1 = np.where(out_both, -1.0, t1)
        enter = (fa < 0) & (fb >= 0)
        leave = (fa >= 0) & (fb < 0)
        t0 = np.where(enter, np.maximum(t0, t), t0)
        t1 = np.where(leave, np.minimum(t1, t), t1)
    seg_len = np.linalg.norm(seg[:, 1] - seg[:, 0], axis=1)
    return (t1 - t0) * seg_len > 4 * eps


@dataclass
class _Pieces:
    """The convex pieces cut so far, as fans of triangles: their corners (arrays in 3D), and per
    fan triangle its corner indices, weld tags, source triangle and piece (patch) number."""
    points: list = field(default_factory=list)
    triangles: list = field(default_factory=list)
    tags: list = field(default_factory=list)
    source: list = field(default_factory=list)
    patch: list = field(default_factory=list)
    n_points: int = 0
    n_patches: int = 0

    def add(self, tri, poly, tags, origin, to2d):
        """One piece ``poly`` (M, 2) of triangle ``tri`` in the plane frame (``origin``, ``to2d``)
        with its corners' ``tags`` (M,); its fan keeps the triangle's winding."""
        m, base = len(poly), self.n_points
        self.points.append(origin + poly @ to2d.T)
        self.n_points += m
        for i in range(1, m - 1):
            idx = (0, i, i + 1)
            self.triangles.append([base + x for x in idx])
            self.tags.append([tags[x] for x in idx])
            self.source.append(tri)
            self.patch.append(self.n_patches)
        self.n_patches += 1


def split_at_contacts(scene, faces, tol, min_fraction=0.005, min_plane_area=0.0):
    """Cut the patches of triangles ``faces`` along contact lines (module docstring).

    ``scene`` has one patch per triangle (as :func:`raybundle.patches.layout.subdivide`
    makes); ``faces`` are the triangle ids that may be cut (the pieces of
    subdivided input faces); of those, planes holding less than ``min_plane_area`` [m^2] of
    them are left whole.  The other triangles of those planes are not cut, but their corners on
    a contact get its tags too (and those of their slivers beyond it, as of the triangles'
    slivers not cut off): a grid vertex that a lamp's outline passes through would otherwise
    weld the light trapped above the lamp to the ceiling beside it.  Returns ``(scene, n_cut)``: a new scene whose
    cut patches consist of the convex pieces' fan triangles, and the number of
    patches cut.  The new scene carries ``triangle_corner_tag`` (T, 3) int, in 32 bits where the
    tags fit (0 = no contact at that corner).
    """
    groups = contact_segments(scene, np.asarray(faces, np.int64), tol, min_plane_area)
    if not groups:
        return scene, 0
    _, r = scene.bounding_sphere
    eps = 1e-9 * max(r, 1e-12)
    T = len(scene.triangles)
    replaced = np.zeros(T, bool)
    corner_tag = (scene.triangle_corner_tag.astype(np.int64) if scene.triangle_corner_tag is not None
                  else np.zeros((T, 3), np.int64))
    out = _Pieces()
    tag_ids: dict = {}
    n_cut = 0
    seg_base = 0
    for may_cut, origin, e1, e2, seg, coplanar in groups:
        group = np.concatenate([may_cut, coplanar])              # those that may be cut first
        to2d = np.stack([e1, e2], axis=1)
        c2 = (scene.triangle_corners[group] - origin) @ to2d                 # (F, 3, 2)
        f, k, crosses = _touching_pairs(c2, seg, eps)
        lines = _lines(seg, eps)
        crosses = worth_cutting(c2, f, k, crosses, seg, lines[1])
        # triangles no touching line cuts (every corner on one side of each): only their corners' tags
        cut = np.unique(f[crosses])
        whole = ~np.isin(f, cut)
        fast, own = np.unique(f[whole], return_inverse=True)
        tg = _corner_tags(c2[fast].reshape(-1, 2), np.repeat(np.arange(len(fast)), 3), c2[fast].mean(axis=1),
                          (own.reshape(-1), k[whole]), seg, lines, seg_base, eps, tag_ids)
        corner_tag[group[fast]] = _merged(corner_tag[group[fast]], tg.reshape(-1, 3), tag_ids)
        # the others cut into convex pieces
        start = np.searchsorted(f, cut)
        count = np.searchsorted(f, cut, side="right") - start
        pieces, kept = cut_triangles(c2, cut, start, count, seg[k], crosses, eps, min_fraction,
                                     whole=np.arange(len(group)) >= len(may_cut))
        tags = _piece_tags(pieces, kept, start, count, k, seg, lines, seg_base, eps, tag_ids)
        j = 0
        for fi, polys in zip(cut.tolist(), pieces):
            tri, f_tags = group[fi], tags[j:j + len(polys)]
            j += len(polys)
            if len(polys) == 1:          # not cut: the triangle keeps its patch, its corners get their tags
                if f_tags[0].any():
                    corner_tag[tri] = _merged(corner_tag[tri], _tags_in_order(f_tags[0], polys[0], c2[fi], eps),
                                              tag_ids)
                continue
            replaced[tri] = True
            n_cut += 1
            for poly, tg in zip(polys, f_tags):
                # the tags the triangle had (a cut where it pierces a surface) stay on its pieces' corners
                out.add(tri, poly, _merged(_inherited_tags(poly, c2[fi], corner_tag[tri], eps), tg, tag_ids),
                        origin, to2d)
        seg_base += len(seg)
    if not replaced.any() and not corner_tag.any():
        return scene, 0
    return _with_pieces(scene, replaced, corner_tag, out), n_cut


def _piece_tags(pieces, kept, start, count, k, seg, lines, seg_base, eps, tag_ids):
    """The corner tags (a list of (M,) arrays, piece by piece) of ``pieces`` against the segments
    touching their triangle (:func:`_corner_tags`), and of the corners of the slivers not cut off
    along the lines ``kept`` (:func:`~raybundle.patches.convex_cuts.cut_triangles`): those lie on
    the line, the piece on its other side."""
    polys = [poly for p in pieces for poly in p]
    if not polys:
        return []
    size = np.array([len(poly) for poly in polys], np.int64)
    centroid = np.array([poly.mean(axis=0) for poly in polys]).reshape(-1, 2)
    on_line = _sliver_corners(polys, np.concatenate([[0], np.cumsum(size)[:-1]]), centroid,
                              [line for p in kept for line in p], eps)
    tri_of = np.repeat(np.arange(len(pieces)), [len(p) for p in pieces])
    tags = _corner_tags(np.concatenate(polys), np.repeat(np.arange(len(polys)), size), centroid,
                        (np.repeat(np.arange(len(polys)), count[tri_of]), k[ranges(start[tri_of], count[tri_of])]),
                        seg, lines, seg_base, eps, tag_ids, on_line)
    return np.split(tags, np.cumsum(size)[:-1])


def _sliver_corners(polys, first, centroid, kept, eps):
    """``(corner, line key, side)`` of the corners of ``polys`` (a list of (M, 2); their corners'
    flat indices from ``first``, their ``centroid`` (N, 2)) on the small side of each line
    ``(a, b, left)`` of ``kept[j]`` (the lines polygon j was not cut along): the sliver's corners,
    on the line, the polygon on the side of its centroid (as :func:`_corner_tags` keys them)."""
    rows = [(j, a, b, left) for j, lines_j in enumerate(kept) for a, b, left in lines_j]
    if not rows:
        return []
    j = np.array([r[0] for r in rows])
    ab = np.array([[r[1], r[2]] for r in rows], float)                   # (L, 2, 2)
    u, key = _lines(ab, eps)
    side = u[:, 0] * (centroid[j, 1] - ab[:, 0, 1]) - u[:, 1] * (centroid[j, 0] - ab[:, 0, 0]) > 0
    d = (ab[:, 1] - ab[:, 0]) / np.hypot(*(ab[:, 1] - ab[:, 0]).T)[:, None]
    out = []
    for i, (jj, _, _, left) in enumerate(rows):
        p = polys[jj]
        s = d[i, 0] * (p[:, 1] - ab[i, 0, 1]) - d[i, 1] * (p[:, 0] - ab[i, 0, 0])
        line, sd = tuple(key[i].tolist()), bool(side[i])
        out += [(int(first[jj] + m), line, sd) for m in np.nonzero((s > eps) if left else (s < -eps))[0].tolist()]
    return out


def _with_pieces(scene, replaced, corner_tag, pieces):
    """``scene`` with the triangles ``replaced`` (T,) bool replaced by the fans of ``pieces``
    (:class:`_Pieces`) and the corner tags ``corner_tag`` (T, 3) of those it keeps."""
    from ..scene.model import PatchScene

    _, r = scene.bounding_sphere
    keep = np.nonzero(~replaced)[0]
    pts = np.concatenate(pieces.points) if pieces.points else np.zeros((0, 3))
    # weld the new corners that coincide, among themselves and with the corners of the
    # triangles they replace (which their neighbours keep); the other vertices stay as they are
    # (welding the whole scene again cost seconds at millions of triangles)
    old_ids = np.unique(scene.triangles[replaced])
    cand = np.concatenate([scene.vertices[old_ids], pts])
    first, inv = unique_rows(np.round(cand / max(r * 1e-7, 1e-12)).astype(np.int64))
    at_old = first < len(old_ids)
    own = old_ids[np.minimum(first, len(old_ids) - 1)] if len(old_ids) else np.zeros(len(first), np.int64)
    vertex_of = np.where(at_old, own, len(scene.vertices) + np.cumsum(~at_old) - 1)
    v = np.concatenate([scene.vertices, cand[first[~at_old]]])
    new_t = vertex_of[inv[len(old_ids):]][np.asarray(pieces.triangles, np.int64).reshape(-1, 3)]
    t = np.concatenate([scene.triangles[keep], new_t])
    src = np.concatenate([keep, np.asarray(pieces.source, np.int64)])
    tags = np.concatenate([corner_tag[keep], np.asarray(pieces.tags, np.int64).reshape(-1, 3)])
    if tags.size and -2 ** 31 <= tags.min() and tags.max() < 2 ** 31:      # held in 32 bits where they fit
        tags = tags.astype(np.int32)
    # patches: untouched triangles keep theirs (renumbered), pieces get new ids
    old_patch = scene.triangle_patch[keep]
    _, old_patch = np.unique(old_patch, return_inverse=True)
    n_old = int(old_patch.max()) + 1 if len(old_patch) else 0
    patch = np.concatenate([old_patch.reshape(-1), n_old + np.asarray(pieces.patch, np.int64)]).astype(np.int64)
    # pieces that welding or a sliver cut flattened to zero area carry nothing (their
    # normal would be NaN): drop them, and renumber the patches densely
    c = v[new_t]
    area2 = np.linalg.norm(np.cross(c[:, 1] - c[:, 0], c[:, 2] - c[:, 0]), axis=1)
    ok = np.concatenate([np.ones(len(keep), bool), area2 > (r * 1e-9) ** 2])
    if not ok.all():
        t, src, tags = t[ok], src[ok], tags[ok]
        patch = np.unique(patch[ok], return_inverse=True)[1].reshape(-1).astype(np.int64)
    return PatchScene(v, t, scene.triangle_material[src], patch, scene.triangle_source[src], scene.materials,
                      scene.point_lights, scene.camera, scene.analytic_radiance, scene.name,
                      scene.dropped_triangles, scene.triangle_solid[src], scene.triangle_two_sided[src],
                      scene.sun_lights, scene.area_lights, scene.world, tags, texture=scene.texture,
                      shading=scene.shading, linking=scene.linking)


def _lines(seg, eps):
    """The contact line of each segment ``seg`` (K, 2, 2): ``(u (K, 2), key (K, 3) int)``, its
    unit direction, one of the two per line, and that direction and the line's offset from the
    origin rounded, so that collinear segments (a floor's subdivided edge along a wall) get one
    key and weld along their line."""
    a, d = seg[:, 0], seg[:, 1] - seg[:, 0]
    u = d / np.hypot(d[:, 0], d[:, 1])[:, None]
    flip = (u[:, 0] < -1e-9) | ((np.abs(u[:, 0]) <= 1e-9) & (u[:, 1] < 0))
    u[flip] = -u[flip]
    offset = np.round((u[:, 0] * a[:, 1] - u[:, 1] * a[:, 0]) / (1e3 * eps)).astype(np.int64)
    return u, np.concatenate([np.round(u * 1e6).astype(np.int64), offset[:, None]], axis=1)


def _on_segment(points, seg, eps):
    """(P, M) bool: point ``points[p, m]`` (P, M, 2) lies on segment ``seg[p]`` (P, 2, 2)
    (within 1000 ``eps``)."""
    a, d = seg[:, 0], seg[:, 1] - seg[:, 0]
    length = np.hypot(d[:, 0], d[:, 1])[:, None]
    q = points - a[:, None]
    off = np.abs(d[:, None, 0] * q[:, :, 1] - d[:, None, 1] * q[:, :, 0]) / length
    along = (q[:, :, 0] * d[:, None, 0] + q[:, :, 1] * d[:, None, 1]) / length
    return (off <= 1e3 * eps) & (along >= -1e3 * eps) & (along <= length + 1e3 * eps)


#: :func:`_merged`: a pierce tag merged with a contact tag moves by multiples of twice this
#: (beyond any pierce tag's magnitude), keeping its sign
MERGED_STEP = 1 << 32


def _merged(old, new, tag_ids):
    """Weld tags (int64 arrays of one shape) of corners that had ``old`` and get ``new``: the
    one that is not 0, and where both are, one id per pair (from ``tag_ids``, as the contact
    tags), so corners weld only where both tags agree.  A pierce tag (negative,
    :func:`~raybundle.patches.piercing.pierce_tag`) stays negative, as :func:`~raybundle.patches.piercing.pierced_parts` reads it."""
    old, new = np.asarray(old, np.int64), np.asarray(new, np.int64)
    out = np.where(new == 0, old, new)
    for i in zip(*np.nonzero((old != 0) & (new != 0))):
        k = tag_ids.setdefault(("merged", int(old[i]), int(new[i])), len(tag_ids) + 1)
        out[i] = old[i] - 2 * MERGED_STEP * k if old[i] < 0 else k
    return out


def _inherited_tags(poly, tri2d, tags, eps):
    """The tags (M,) the corners of ``poly`` (M, 2), a piece of the triangle ``tri2d`` (3, 2)
    whose corners had ``tags`` (3,), keep from it: a corner's at the triangle's corners, and on
    an edge whose two ends carry the same tag (a cut along a pierced plane runs along it) that
    tag; else 0."""
    out = np.zeros(len(poly), np.int64)
    if not np.any(tags):
        return out
    tol = 1e3 * eps
    d = np.linalg.norm(poly[:, None] - tri2d[None], axis=2)                      # (M, 3)
    at = d.min(axis=1) <= tol
    out[at] = tags[np.argmin(d[at], axis=1)]
    for j in range(3):
        if tags[j] != 0 and tags[j] == tags[(j + 1) % 3]:
            a, e = tri2d[j], tri2d[(j + 1) % 3] - tri2d[j]
            t = (poly - a) @ e / np.dot(e, e)
            on = ~at & (t >= 0.0) & (t <= 1.0) & (np.linalg.norm(a + t[:, None] * e - poly, axis=1) <= tol)
            out[on] = tags[j]
    return out


def _tags_in_order(tags, poly, tri2d, eps):
    """Tags of the corners of an uncut triangle, in the triangle's corner order
    (:func:`~raybundle.patches.convex_cuts.without_collinear` may have rotated the polygon)."""
    out = [0, 0, 0]
    for tg, p in zip(tags, poly):
        out[int(np.argmin(np.linalg.norm(tri2d - p, axis=1)))] = tg
    return out


def _corner_tags(points, polygon, centroid, pairs, seg, lines, seg_base, eps, tag_ids, on_line=()):
    """Weld tag (M,) int per corner ``points`` (M, 2) of convex polygons (``polygon`` (M,) the
    corner's polygon, ascending; ``centroid`` (N, 2) theirs): which contact lines the corner lies
    on, and on which side of each its polygon lies; 0 for none.  A line, not a segment: the
    collinear segments of one contact (a floor's subdivided edge along a wall) weld along it
    (:func:`_lines`, of ``seg`` (K, 2, 2)).  ``pairs`` ``(polygon, segment)`` (P,) int, sorted
    by polygon: the segments each polygon's corners are tested against (those touching it; a
    floor triangle under a chair may touch hundreds).  ``on_line``: more ``(corner, line key, side)``
    that hold whatever the segments say (a sliver's corners, :func:`_piece_tags`).  Ids come from
    ``tag_ids`` in corner order, so equal keys give one tag in every call."""
    u, key = lines
    own, k = pairs
    first = np.searchsorted(own, np.arange(len(centroid)))
    n = np.bincount(own, minlength=len(centroid))[polygon]
    corner = np.repeat(np.arange(len(points)), n)                                 # (Q,) a corner and
    k = k[ranges(first[polygon], n)]                                              # a segment to test
    a = seg[k, 0]
    on = _on_segment(points[corner, None], seg[k], eps)[:, 0]
    c = centroid[polygon[corner[on]]]
    side = u[k[on], 0] * (c[:, 1] - a[on, 1]) - u[k[on], 1] * (c[:, 0] - a[on, 0]) > 0
    keys: dict = {}
    for m, line, sd in zip(corner[on].tolist(), key[k[on]].tolist(), side.tolist()):
        keys.setdefault(m, set()).add(((seg_base, *line), sd))
    for m, line, sd in on_line:
        keys.setdefault(m, set()).add(((seg_base, *line), sd))
    out = np.zeros(len(points), np.int64)
    for m in sorted(keys):
        out[m] = tag_ids.setdefault(tuple(sorted(keys[m])), len(tag_ids) + 1)
    return out


def welded_vertices(scene, vertices=None):
    """(V,) int: ids of the scene's vertices (or of ``vertices`` (V, 3), points in it) welded
    where positions agree to 1e-7 of the scene's radius."""
    _, r = scene.bounding_sphere
    v = scene.vertices if vertices is None else vertices
    return unique_rows(np.round(v / max(r * 1e-7, 1e-12)).astype(np.int64))[1]
