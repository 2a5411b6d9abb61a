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
leak is that small).  Corners that lie on a contact segment get a *weld tag*
naming the segment's line and the side of it the triangle lies on, so that
smooth interpolation of patch values does not blend across the contact but
does along it; triangles that touch a contact without being cut keep their
patch and only get the tags.
"""
from __future__ import annotations

import math

import numpy as np

from ..tracing.sampling import orthonormal_basis
from ..util.arrays import connected_components, group_ids, ranges, shared_edges, unique_rows


def _plane_groups(scene, faces):
    """Group triangle ids ``faces`` by their plane: list of (ids, normal, offset).
    Planes closer than 1e-6 of the scene radius are one plane."""
    n = scene.triangle_normal[faces]
    p0 = scene.triangle_corners[faces, 0]
    # canonical orientation: two-sided faces with flipped normals share a plane
    first = np.argmax(np.abs(n) > 1e-6, axis=1)
    sign = np.where(n[np.arange(len(n)), first] < 0, -1.0, 1.0)
    n = n * sign[:, None]
    off = np.einsum("ij,ij->i", n, p0)
    _, r = scene.bounding_sphere
    key = np.concatenate([np.round(n * 1e4), np.round(off / max(r * 1e-6, 1e-12))[:, None]], axis=1).astype(np.int64)
    _, label = np.unique(key, axis=0, return_inverse=True)
    label = label.reshape(-1)
    order = np.argsort(label, kind="stable")
    cuts = np.nonzero(np.diff(label[order]))[0] + 1
    return [(faces[g], n[g[0]], float(off[g[0]])) for g in np.split(order, cuts)]


class _BoxQuery:
    """The triangles whose bounding boxes ``lo``, ``hi`` (T, 3) overlap a query box, without
    a pass over all of them per query (a real room has tens of thousands of planes):
    sort and sweep on one ``axis`` (by default the widest).  Boxes no longer than the 99th
    percentile along it are sorted by their low end, so those that can overlap ``[a, b]`` lie in
    the window of low ends ``[a - longest, b]``; the longer ones (1%) are always tested."""

    def __init__(self, lo, hi, axis=None):
        self.lo, self.hi = lo, hi
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
        ok = np.all((self.hi[box] >= lo[query]) & (self.lo[box] <= hi[query]), axis=1)
        return query[ok], box[ok]


def contact_segments(scene, faces, tol, min_plane_area=0.0):
    """Contact segments on the planes of triangles ``faces`` (ids into ``scene``) whose
    triangles add up to at least ``min_plane_area`` [m^2] in that plane.

    Returns a list of ``(group, origin, e1, e2, segments)``: ``group`` the
    triangle ids in one plane, ``origin`` (3,) and ``e1, e2`` (3,) that plane's
    2D frame [m], ``segments`` (K, 2, 2) the contact segments in it.  Other
    triangles meet the plane where their edges lie within ``tol`` [m] of it,
    or where they cross it.
    """
    out = []
    if len(faces) == 0:
        return out
    corners = scene.triangle_corners
    lo_all, hi_all = corners.min(axis=1), corners.max(axis=1)
    _, r = scene.bounding_sphere
    vid = _welded(scene)
    # a plane's box is thin along its normal: sweep along the axis where it is thinnest
    overlapping = {}
    for group, n, off in _plane_groups(scene, faces):
        if min_plane_area > 0 and scene.triangle_area[group].sum() < min_plane_area:
            continue
        c = corners[group]
        lo, hi = c.reshape(-1, 3).min(axis=0) - tol, c.reshape(-1, 3).max(axis=0) + tol
        axis = int(np.argmin(hi - lo))
        if axis not in overlapping:
            overlapping[axis] = _BoxQuery(lo_all, hi_all, axis)
        cand = np.setdiff1d(overlapping[axis](lo, hi), group)
        d = corners[cand] @ n - off                                   # (C, 3) signed distances
        cand_mask = (d.min(axis=1) <= tol) & (d.max(axis=1) >= -tol)
        cand, d = cand[cand_mask], d[cand_mask]
        e1, e2 = orthonormal_basis(n)
        origin = n * off
        if len(cand) == 0:
            continue
        p = corners[cand]
        near = np.abs(d) <= tol
        all_near = near.all(axis=1)
        segs = []
        # edges lying in the plane (within tol); inner edges of a surface lying in the gap are dropped
        tv = vid[scene.triangles[cand]]
        for i, j in ((0, 1), (1, 2), (2, 0)):
            sel = near[:, i] & near[:, j]
            key = np.sort(np.stack([tv[:, i], tv[:, j]], axis=1), axis=1)
            segs.append((sel, p[:, i], p[:, j], key, all_near))
        keys = np.concatenate([s[3][s[0]] for s in segs])
        flat = np.concatenate([s[4][s[0]] for s in segs])
        kk, inv, cnt = np.unique(keys, axis=0, return_inverse=True, return_counts=True)
        inner_count = np.bincount(inv.reshape(-1), flat, minlength=len(kk))
        drop = (cnt >= 2) & (inner_count >= 2)
        keep = ~drop[inv.reshape(-1)]
        a3 = np.concatenate([s[1][s[0]] for s in segs])[keep]
        b3 = np.concatenate([s[2][s[0]] for s in segs])[keep]
        # crossings: triangles with corners on both sides beyond tol
        cross = ~all_near & ~(near.sum(axis=1) >= 2) & (d.max(axis=1) > tol) & (d.min(axis=1) < -tol)
        if cross.any():
            pc, dc, nc = p[cross], d[cross], near[cross]
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
            a3 = np.concatenate([a3, pts[ok, 0]])
            b3 = np.concatenate([b3, pts[ok, 1]])
        if len(a3) == 0:
            continue
        to2d = np.stack([e1, e2], axis=1)
        seg = np.stack([(a3 - origin) @ to2d, (b3 - origin) @ to2d], axis=1)
        length = np.linalg.norm(seg[:, 1] - seg[:, 0], axis=1)
        seg = seg[length > 1e-9 * max(r, 1e-12)]
        # the same segment from several triangles counts once
        q = np.round(np.sort(seg.reshape(len(seg), 4).reshape(-1, 2, 2), axis=1).reshape(len(seg), 4)
                     / max(r * 1e-7, 1e-12)).astype(np.int64)
        seg = seg[np.unique(q, axis=0, return_index=True)[1]]
        if len(seg):
            out.append((group, origin, e1, e2, seg))
    return out


def _split(poly, a, b, eps):
    """Split the convex polygon ``poly`` (M corners [x, y], a list) by the line through the
    points a, b: (left, right) polygons (lists), either None when the line misses the interior."""
    # Python floats: the same IEEE arithmetic as on arrays, without numpy's cost per call on
    # polygons of three to six corners (called once per piece and line: 95k times for 270k triangles)
    ax, ay = float(a[0]), float(a[1])
    dx, dy = float(b[0]) - ax, float(b[1]) - ay
    h = math.hypot(dx, dy)
    if not h > 0:                                # a point, not a line (on arrays: NaN, no split)
        return None, None
    ux, uy = dx / h, dy / h
    pts = poly
    s = [ux * (p[1] - ay) - uy * (p[0] - ax) for p in pts]                     # signed distance [m]
    s = [0.0 if abs(v) <= eps else v for v in s]
    if not any(v > 0 for v in s) or not any(v < 0 for v in s):
        return None, None
    left, right = [], []
    m = len(pts)
    for i in range(m):
        j = (i + 1) % m
        p, q, sp, sq = pts[i], pts[j], s[i], s[j]
        if sp >= 0:
            left.append(p)
        if sp <= 0:
            right.append(p)
        if sp * sq < 0:
            t = sp / (sp - sq)
            x = [p[0] + t * (q[0] - p[0]), p[1] + t * (q[1] - p[1])]
            left.append(x)
            right.append(x)
    return left, right


def _without_collinear(poly, eps):
    """The convex polygon ``poly`` (a list of [x, y], as :func:`_split` makes) as an (M, 2)
    array without the corners lying on the line through their neighbours (they would give
    zero-area fan triangles)."""
    keep = []
    m = len(poly)
    for i in range(m):
        (ax, ay), (px, py), (bx, by) = poly[i - 1], poly[i], poly[(i + 1) % m]
        length = math.hypot(bx - ax, by - ay)
        if length > 0 and abs((bx - ax) * (py - ay) - (by - ay) * (px - ax)) / length > eps:
            keep.append(poly[i])
    return np.array(keep, float).reshape(-1, 2)


def _crosses(tri, segs, eps):
    """(P,) bool: the line of segment ``segs[p]`` (P, 2, 2) has corners of triangle ``tri[p]``
    (P, 3, 2) strictly on both sides (farther than ``eps``), as :func:`_split` decides."""
    a, d = segs[:, 0], segs[:, 1] - segs[:, 0]
    dvec = d / np.hypot(d[:, 0], d[:, 1])[:, None]
    s = dvec[:, None, 0] * (tri[:, :, 1] - a[:, None, 1]) - dvec[:, None, 1] * (tri[:, :, 0] - a[:, None, 0])
    return ((s > eps).any(axis=1)) & ((s < -eps).any(axis=1))


def _area(poly):
    """The area of the polygon ``poly`` (M corners [x, y], a list): the shoelace formula."""
    m = len(poly)
    return 0.5 * abs(sum(poly[i][0] * poly[(i + 1) % m][1] - poly[i][1] * poly[(i + 1) % m][0] for i in range(m)))


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


def split_at_contacts(scene, faces, tol, min_fraction=0.005, min_plane_area=0.0):
    """Cut the patches of triangles ``faces`` along contact lines (module docstring).

    ``scene`` has one patch per triangle (as :func:`raybundle.patches.layout.subdivide`
    makes); ``faces`` are the triangle ids that may be cut (the pieces of
    subdivided input faces); of those, planes holding less than ``min_plane_area`` [m^2] of
    them are left whole.  Returns ``(scene, n_cut)``: a new scene whose
    cut patches consist of the convex pieces' fan triangles, and the number of
    patches cut.  The new scene carries ``triangle_corner_tag`` (T, 3) int64
    (0 = no contact at that corner).
    """
    from ..scene.model import PatchScene

    groups = contact_segments(scene, np.asarray(faces, np.int64), tol, min_plane_area)
    if not groups:
        return scene, 0
    _, r = scene.bounding_sphere
    eps = 1e-9 * max(r, 1e-12)
    T = len(scene.triangles)
    replaced = np.zeros(T, bool)
    corner_tag = (scene.triangle_corner_tag.copy() if scene.triangle_corner_tag is not None
                  else np.zeros((T, 3), np.int64))
    new_pts, new_tris, new_from, new_patch_local, new_tags = [], [], [], [], []
    tag_ids: dict = {}
    n_cut = 0
    n_new_patches = 0
    n_new_pts = 0
    seg_base = 0
    for group, origin, e1, e2, seg in groups:
        to2d = np.stack([e1, e2], axis=1)
        c2 = (scene.triangle_corners[group] - origin) @ to2d                 # (F, 3, 2)
        f, k, crosses = _touching_pairs(c2, seg, eps)
        lines = _lines(seg, eps)
        # triangles no touching line cuts (every corner on one side of each): only their corners' tags
        cut = np.unique(f[crosses])
        whole = ~np.isin(f, cut)
        fast, own = np.unique(f[whole], return_inverse=True)
        tg = _corner_tags(c2[fast].reshape(-1, 2), np.repeat(np.arange(len(fast)), 3), c2[fast].mean(axis=1),
                          (own.reshape(-1), k[whole]), seg, lines, seg_base, eps, tag_ids)
        corner_tag[group[fast]] = _merged(corner_tag[group[fast]], tg.reshape(-1, 3), tag_ids)
        # the others cut into convex pieces, as lists of [x, y] (numpy's cost per call on 3-6 corners)
        start = np.searchsorted(f, cut)
        count = np.searchsorted(f, cut, side="right") - start
        pieces = []
        for fi, lo, n in zip(cut.tolist(), start.tolist(), count.tolist()):
            polys = [c2[fi].tolist()]
            least = min_fraction * _area(polys[0])
            # a line that leaves the triangle's corners on one side misses every piece of it
            for a, b in seg[k[lo:lo + n][crosses[lo:lo + n]]].tolist():
                nxt = []
                for poly in polys:
                    lft, rgt = _split(poly, a, b, eps)
                    if lft is None or min(_area(lft), _area(rgt)) < least:
                        nxt.append(poly)
                    else:
                        nxt += [lft, rgt]
                polys = nxt
            pieces.append([_without_collinear(poly, eps) for poly in polys])
        # the pieces' corner tags, against the segments touching their triangle
        polys = [poly for p in pieces for poly in p]
        size = np.array([len(poly) for poly in polys], np.int64)
        tri_of = np.repeat(np.arange(len(cut)), [len(p) for p in pieces])
        tags = _corner_tags(np.concatenate(polys) if polys else np.zeros((0, 2)), np.repeat(np.arange(len(polys)), size),
                            np.array([poly.mean(axis=0) for poly in polys]).reshape(-1, 2),
                            (np.repeat(np.arange(len(polys)), count[tri_of]), k[ranges(start[tri_of], count[tri_of])]),
                            seg, lines, seg_base, eps, tag_ids)
        tags = np.split(tags, np.cumsum(size)[:-1]) if polys else []
        j = 0
        for fi, polys in zip(cut.tolist(), pieces):
            tri, f_tags = group[fi], tags[j:j + len(polys)]
            j += len(polys)
            if len(polys) == 1:          # not cut: the triangle keeps its patch, its corners get their tags
                if f_tags[0].any():
                    corner_tag[tri] = _merged(corner_tag[tri], _tags_in_order(f_tags[0], polys[0], c2[fi], eps), tag_ids)
                continue
            # the tags the triangle had (a cut where it pierces a surface) stay on its pieces' corners
            f_tags = [_merged(_inherited_tags(poly, c2[fi], corner_tag[tri], eps), tg, tag_ids)
                      for poly, tg in zip(polys, f_tags)]
            replaced[tri] = True
            n_cut += len(polys) > 1
            for poly, tg in zip(polys, f_tags):
                m = len(poly)
                base = n_new_pts
                new_pts.append(origin + poly @ to2d.T)
                n_new_pts += m
                for i in range(1, m - 1):
                    idx = (0, i, i + 1)               # pieces keep the triangle's winding
                    new_tris.append([base + x for x in idx])
                    new_tags.append([tg[x] for x in idx])
                    new_from.append(tri)
                    new_patch_local.append(n_new_patches)
                n_new_patches += 1
        seg_base += len(seg)
    if not replaced.any() and not corner_tag.any():
        return scene, 0
    keep = np.nonzero(~replaced)[0]
    pts = np.concatenate(new_pts) if new_pts else np.zeros((0, 3))
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
    new_t = vertex_of[inv[len(old_ids):]][np.asarray(new_tris, np.int64).reshape(-1, 3)]
    t = np.concatenate([scene.triangles[keep], new_t])
    src = np.concatenate([keep, np.asarray(new_from, np.int64)])
    tags = np.concatenate([corner_tag[keep], np.asarray(new_tags, np.int64).reshape(-1, 3)])
    # patches: untouched triangles keep theirs (renumbered), pieces get new ids
    old_patch = scene.triangle_patch[keep]
    _, old_patch = np.unique(old_patch, return_inverse=True)
    n_old = int(old_patch.max()) + 1 if len(old_patch) else 0
    patch = np.concatenate([old_patch.reshape(-1), n_old + np.asarray(new_patch_local, np.int64)]).astype(np.int64)
    # pieces that welding or a sliver cut flattened to zero area carry nothing (their
    # normal would be NaN): drop them, and renumber the patches densely
    c = v[new_t]
    area2 = np.linalg.norm(np.cross(c[:, 1] - c[:, 0], c[:, 2] - c[:, 0]), axis=1)
    ok = np.concatenate([np.ones(len(keep), bool), area2 > (r * 1e-9) ** 2])
    if not ok.all():
        t, src, tags = t[ok], src[ok], tags[ok]
        patch = np.unique(patch[ok], return_inverse=True)[1].reshape(-1).astype(np.int64)
    out = PatchScene(v, t, scene.triangle_material[src], patch, scene.triangle_source[src], scene.materials,
                     scene.point_lights, scene.camera, scene.analytic_radiance, scene.name,
                     scene.dropped_triangles, scene.triangle_solid[src], scene.triangle_two_sided[src],
                     scene.sun_lights, scene.area_lights, scene.world, tags, texture=scene.texture,
                     shading=scene.shading, linking=scene.linking)
    return out, n_cut


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
_MERGED_STEP = 1 << 32


def _merged(old, new, tag_ids):
    """Weld tags (int64 arrays of one shape) of corners that had ``old`` and get ``new``: the
    one that is not 0, and where both are, one id per pair (from ``tag_ids``, as the contact
    tags), so corners weld only where both tags agree.  A pierce tag (negative,
    :func:`pierce_tag`) stays negative, as :func:`pierced_parts` reads it."""
    old, new = np.asarray(old, np.int64), np.asarray(new, np.int64)
    out = np.where(new == 0, old, new)
    for i in zip(*np.nonzero((old != 0) & (new != 0))):
        k = tag_ids.setdefault(("merged", int(old[i]), int(new[i])), len(tag_ids) + 1)
        out[i] = old[i] - 2 * _MERGED_STEP * k if old[i] < 0 else k
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
    (``_without_collinear`` may have rotated the polygon)."""
    out = [0, 0, 0]
    for tg, p in zip(tags, poly):
        out[int(np.argmin(np.linalg.norm(tri2d - p, axis=1)))] = tg
    return out


def _corner_tags(points, polygon, centroid, pairs, seg, lines, seg_base, eps, tag_ids):
    """Weld tag (M,) int per corner ``points`` (M, 2) of convex polygons (``polygon`` (M,) the
    corner's polygon, ascending; ``centroid`` (N, 2) theirs): which contact lines the corner lies
    on, and on which side of each its polygon lies; 0 for none.  A line, not a segment: the
    collinear segments of one contact (a floor's subdivided edge along a wall) weld along it
    (:func:`_lines`, of ``seg`` (K, 2, 2)).  ``pairs`` ``(polygon, segment)`` (P,) int, sorted
    by polygon: the segments each polygon's corners are tested against (those touching it; a
    floor triangle under a chair may touch hundreds).  Ids come from ``tag_ids`` in corner order,
    so equal keys give one tag in every call."""
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
    out = np.zeros(len(points), np.int64)
    for m in sorted(keys):
        out[m] = tag_ids.setdefault(tuple(sorted(keys[m])), len(tag_ids) + 1)
    return out


#: gaps narrower than this share of the patch size count as contact
#: (:func:`~raybundle.patches.layout.cut_at_contacts`, :func:`~raybundle.patches.clusters.make_patches`)
CONTACT_SHARE = 0.05
#: probe rays per chunk in :func:`gap_sides` (memory: about 100 bytes a ray)
PROBE_CHUNK = 1 << 20


def gap_sides(tracer, points, normals, tol):
    """(N, 2) bool: another surface lies within ``tol`` [m] of ``points`` (N, 3) along
    their unit ``normals`` (column 0) and against them (column 1).

    A point in such a gap (the ceiling over a lamp hanging 0.5 mm under it, the floor
    under a rug) sees only that surface on that side, a world apart from its neighbours
    outside the gap: a patch must not hold both (module docstring)."""
    points, normals = np.asarray(points, float), np.asarray(normals, float)
    out = np.zeros((len(points), 2), bool)
    eps = tracer.eps
    for lo in range(0, len(points), PROBE_CHUNK // 2):
        p, n = points[lo:lo + PROBE_CHUNK // 2], normals[lo:lo + PROBE_CHUNK // 2]
        for col, sign in ((0, 1.0), (1, -1.0)):
            d = sign * n
            out[lo:lo + len(p), col] = tracer.occluded(p + eps * d, d, np.full(len(p), max(tol - eps, eps)))
    return out


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
    vid = _welded(scene)
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


def _welded(scene):
    """(V,) int: vertex ids welded where positions agree to 1e-7 of the scene's radius."""
    _, r = scene.bounding_sphere
    return unique_rows(np.round(scene.vertices / max(r * 1e-7, 1e-12)).astype(np.int64))[1]


def pierce_tag(plane, behind):
    """The weld tag of a corner on the cut along pierced ``plane`` (int) on the piece in front
    of it or ``behind`` it: negative, apart from :func:`split_at_contacts`'s positive ones."""
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
    vid = _welded(scene).astype(np.int32)
    corners = vid[scene.triangles]
    lo, hi = shared_edges(corners)                            # edges of two triangles at one place
    a = corners.reshape(-1)
    # the two triangles' pierce tags at each end of the shared edge (their own corners at that
    # position; a contact's tags, and a contact's share of a merged tag, left out: :func:`_merged`)
    pierce = np.where(tag < 0, -(-tag % (2 * _MERGED_STEP)), 0)
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


def straddling(tracer, scene, faces, tol):
    """(F,) bool: triangles ``faces`` part of which lies in a gap narrower than ``tol`` [m]
    and part not: the triangles :func:`split_at_contacts` must cut.  :func:`gap_sides` at
    every centroid first; where a triangle's flags differ from those of a triangle it shares
    a corner with (or it shares none), at its three corners pulled 1% towards the centroid
    too, and the triangle straddles where its four points disagree."""
    faces = np.asarray(faces, np.int64)
    if len(faces) == 0:
        return np.zeros(0, bool)
    c = scene.triangle_corners[faces]
    flags = gap_sides(tracer, c.mean(axis=1), scene.triangle_normal[faces], tol)
    code = flags[:, 0] * 2 + flags[:, 1]
    corner = scene.triangles[faces]
    lo = np.full(len(scene.vertices), 4)
    hi = np.full(len(scene.vertices), -1)
    users = np.zeros(len(scene.vertices), np.int64)
    np.minimum.at(lo, corner, code[:, None])
    np.maximum.at(hi, corner, code[:, None])
    np.add.at(users, corner, 1)
    near = np.any(lo[corner] != hi[corner], axis=1) | np.all(users[corner] == 1, axis=1)
    out = np.zeros(len(faces), bool)
    sel = np.nonzero(near)[0]
    step = max(1, PROBE_CHUNK // 8)
    for start in range(0, len(sel), step):
        f = sel[start:start + step]
        mid = c[f].mean(axis=1, keepdims=True)
        pts = mid + 0.99 * (c[f] - mid)                                           # (F, 3, 3)
        n = np.repeat(scene.triangle_normal[faces[f]], 3, axis=0)
        at = gap_sides(tracer, pts.reshape(-1, 3), n, tol).reshape(len(f), 3, 2)
        out[f] = (at != flags[f, None, :]).any(axis=(1, 2))
    return out
