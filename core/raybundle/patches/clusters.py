"""Patches as clusters of triangles: the unknowns follow the lighting, not the mesh.

Real meshes carry far more triangles than the lighting needs (tessellated curved
surfaces, subdivided floors, sculpted detail).  A patch may hold any number of
triangles of one material and one sidedness, planar or not, sharing one radiance
variable per side.  The bundle transfer stays the Galerkin projection onto a constant
per cluster: a bundle line picks the side of the triangle it meets by *that
triangle's* normal, and its weight delta^2 is that triangle's projected area, so

    E_i = (2 pi / A_i) sum_j S_j sum_{t in i} A(t, j, d) cos_t          [W/m^2]

is the area mean over the cluster of each triangle's irradiance, whatever their
orientation (``tests/test_clusters.py``: a furnace holding a tessellated sphere stays
exact).  The first shot, the open area and the image work per triangle as before.
What is approximated: inside the iteration a cluster's glossy lobe is evaluated
about the cluster's mean normal (the normals of a glossy cluster lie within the cell of a
cube map with :data:`NORMAL_CELLS` x :data:`NORMAL_CELLS` cells per face, at most
about 15 degrees from their mean; those of a diffuse detail cluster within one face);
the image evaluates every lobe at the pixel's own triangle.

:func:`make_patches` chooses the layout for a target patch count.  With a patch size
h: triangles with an edge longer than h are cut (:func:`~raybundle.patches.layout.split_triangles`,
then along contact lines), and the pieces that another surface crowds (a floor under a stair
step h / 8 above it) cut again to h / 2 (:func:`~raybundle.patches.layout.refine_crowded`; h is then
made coarser, so that the count stays about the target); triangles smaller than h^2 / :data:`SMALL`
are grouped, and so are
slivers (area under :data:`SLIVER` x their longest edge squared: a wall fanned out around a
window), first halved along their length to pieces no longer than h
(:func:`~raybundle.patches.layout.bisect_long`: a sliver grouped whole made a cluster metres long).
They are grouped into the cells of a grid h wide, split by normal direction (the cube-map cell),
by offset along the normal (half-h slabs: a shelf does not share a patch with the floor under it),
by material, by sidedness, by whether they lie in a gap narrower than a quarter of h (the
ceiling over a lamp hanging just under it: :func:`~raybundle.patches.gaps.gap_sides`), after the
triangles that straddle such a gap are cut along the contact, and in a cell a gap carves by the
pieces that share no corner and cover a square a quarter of h wide or more (the wall on either
side of a window's frame standing just in front of it: :func:`_pieces_apart`), and, under a world that lights
the scene, by how much of the world each side sees (:func:`world_view_classes`: the facets of a
window's frame and reveal outside, in the sky, and inside, in the room's shade), by whether
each side is enclosed (:func:`enclosure_classes`: the inner sides of a window frame's box or a
cabinet's carcass), and by whether
a piece lies behind a surface its triangle pierces (:func:`~raybundle.patches.piercing.cut_where_pierced`);
the rest stay patches of their own.
Clusters smaller than h^2 / :data:`DETAIL` (the facets of a plant or a chair's legs in a cell:
in a furnished room they outnumbered the patches of walls and floor ten to one) are then
grouped again, diffuse ones by the cube face of their normal instead of its cell, in the grid
cells and half-size slabs (along that face's axis) of the detail size: the size whose count
comes nearest the target, of which h is a capped copy (:func:`patch_sizes`).  It is a sort over
the triangles: O(T log T), no per-triangle Python.

:func:`tessellate` makes the stand-in for a finely meshed Blender scene the tests and
the scale bench use: every reflecting face cut into many small triangles, each its
own input face.
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np

from ..scene.model import PatchScene
from ..tracing.sampling import Stream, frames_from_normals, stream
from ..tracing.visibility import RayTracer
from ..util.arrays import connected_components, group_ids, ranges, stable_order
from .contacts import welded_vertices
from .gaps import CONTACT_SHARE, PROBE_CHUNK, gap_sides
from .piercing import pierced_parts
from .layout import (bisect_long, cut_at_contacts, edge_for_patches, longest_edges, refine_crowded, split_triangles,
                     subdivide)

#: the patch count of a scene laid out without an explicit one (sides; the count that measured best
#: at a fixed time across scene sizes: docs/benchmarks.md, 'Measured choices behind the defaults';
#: :mod:`raybundle.app.auto`)
DEFAULT_PATCHES = 4000
#: cube-map cells per face edge for the normal direction of a cluster (150 directions; odd, so
#: that axis-aligned normals lie mid-cell, never on a border rounding could flip)
NORMAL_CELLS = 5
#: the patch size is at most this times the size that tiles the reflecting area with the target
#: count (:func:`patch_sizes`): the large surfaces keep at least a quarter of the count
SURFACE_SHARE = 2.0
#: triangles with an area under h^2 / SMALL are grouped (h = the patch size)
SMALL = 2.0
#: clusters under h^2 / DETAIL are merged by the cube face of their normals (:meth:`_Grouping.clusters`)
DETAIL = 4.0
#: triangles with an area under SLIVER x their longest edge squared are slivers (a right isosceles
#: triangle has 1/4, a 2 m x 0.4 m one 1/10)
SLIVER = 0.1
#: the fraction of cosine-distributed rays from a side that leave the scene, cut into classes
#: here (:func:`world_view_classes`): none of them, a little of the world, much of it
WORLD_VIEW_CLASSES = (0.02, 0.2)
#: cosine-distributed rays per triangle side that find its class
WORLD_VIEW_RAYS = 16
#: cosine-distributed rays per triangle side that find how enclosed it is (:func:`enclosure_classes`)
ENCLOSURE_RAYS = 4
#: ... and the share of them that leave within reach, at and above which a side is open
ENCLOSURE_CLASSES = (0.2,)
#: ... and how far they look, in patch sizes (:func:`enclosure_classes`)
ENCLOSURE_REACH = 1.5


def tessellate(scene: PatchScene, triangles) -> PatchScene:
    """``scene`` with its reflecting faces cut into about ``triangles`` triangles in all,
    each its own input face and patch (lamps made of emitting faces stay whole)."""
    if scene.texture is not None or scene.shading is not None:
        raise ValueError("tessellate: scenes with textures or shading normals are not supported")
    fine, _, _ = split_triangles(scene, edge_for_patches(scene, triangles))
    return replace(fine, triangle_source=np.arange(len(fine.triangles)))


def normal_cells(normals, cells=NORMAL_CELLS):
    """Cube-map cell (N,) int in [0, 6 cells^2) of unit ``normals`` (N, 3): the major axis
    and its sign, then a cells x cells grid over the other two components divided by it."""
    n = np.asarray(normals, float)
    axis = np.argmax(np.abs(n), axis=1)
    major = np.take_along_axis(n, axis[:, None], 1)[:, 0]
    others = np.array([(1, 2), (0, 2), (0, 1)])[axis]
    uv = np.take_along_axis(n, others, 1) / np.maximum(np.abs(major), 1e-300)[:, None]   # in [-1, 1]
    iuv = np.clip(((uv + 1.0) * 0.5 * cells).astype(np.int64), 0, cells - 1)
    return ((axis * 2 + (major > 0)) * cells + iuv[:, 0]) * cells + iuv[:, 1]


class _Grouping:
    """What the cluster keys need of a scene's triangles ``rows`` (default: all), computed
    once (``lo``: the grid's origin, the scene's lowest corner by default)."""

    def __init__(self, scene: PatchScene, lo=None, rows=None):
        self.scene = scene
        if rows is None:
            self.rows = np.arange(len(scene.triangles))
            corners, self.area, normal = np.asarray(scene.triangle_corners), scene.triangle_area, scene.triangle_normal
        else:
            self.rows = np.asarray(rows, np.int64)
            corners = scene.vertices[scene.triangles[self.rows]]
            cross = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
            self.area = 0.5 * np.linalg.norm(cross, axis=1)
            normal = cross / np.maximum(2.0 * self.area, 1e-300)[:, None]
        self.centroid = corners.mean(axis=1)
        self.lo = scene.vertices.min(axis=0) if lo is None else lo
        self.edge = longest_edges(corners)
        edges = np.roll(corners, -1, axis=1) - corners
        self.long = edges[np.arange(len(corners)), np.argmax(np.einsum("tij,tij->ti", edges, edges), axis=1)]
        self.normal = normal
        self.cell = normal_cells(normal)
        self.face = normal_cells(normal, 1)
        # offset along the triangle's own normal: constant over a plane
        self.offset = np.einsum("ij,ij->i", normal, self.centroid - self.lo)

    def small(self, h):
        """(T,) bool: triangles to group at patch size ``h``: smaller than h^2 / :data:`SMALL`, or
        slivers (area under :data:`SLIVER` x the longest edge squared, which a cut into k^2
        similar pieces would turn into k^2 slivers; they are halved along their length instead)."""
        return self.area < np.maximum(h * h / SMALL, SLIVER * self.edge ** 2)

    def clusters(self, h, small, gap=None, spread=False, world_view=None, part=None, small_rows=None,
                 detail_h=None, cell_h=None):
        """Cluster ids (S,) of the triangles ``small`` (T,) bool at patch size ``h``: in grid cells
        ``cell_h`` <= ``h`` wide (default ``h``), their details grouped at ``detail_h`` >= ``h``
        (default ``h``; both: :func:`patch_sizes`);
        ``gap`` (S, 2) bool: the triangle lies in a gap on its front / back
        (:func:`~raybundle.patches.gaps.gap_sides`), which a cluster does not straddle;
        ``world_view`` (S, K) int: classes of its sides that a cluster does not mix either (how much
        of the world its front / back sees, :func:`world_view_classes`, how enclosed they are,
        :func:`enclosure_classes`); nor the two
        sides of a plane that a surface pierces, ``part`` = (part (S,), tagged corners (K, 3)) of
        :func:`~raybundle.patches.piercing.pierced_parts` over the scene's triangles, of which
        ``small_rows`` (T,) bool are the grouping's (not with ``spread``).
        Triangles a patch wide or less are keyed by their centroid; ``spread`` keys a longer one
        at ceil(edge / h) points along its longest edge instead, as its pieces will be
        (:func:`~raybundle.patches.layout.bisect_long`): ids (P,) of those points then."""
        sc, idx = self.scene, np.nonzero(small)[0]
        centroid, area = self.centroid[idx], self.area[idx]
        if spread:
            n = np.maximum(1, np.ceil(self.edge[idx] / h - 1e-9)).astype(np.int64)
            idx = np.repeat(idx, n)
            t = (ranges(0, n) + 0.5) / np.repeat(n, n) - 0.5
            centroid = self.centroid[idx] + t[:, None] * self.long[idx]
            area = self.area[idx] / np.repeat(n, n)
        rows = self.rows[idx]
        ch = h if cell_h is None else min(float(cell_h), h)
        cell = np.floor((centroid - self.lo) / ch).astype(np.int64)
        slab = np.floor(self.offset[idx] / (0.5 * ch)).astype(np.int64)
        keys = [cell[:, 0], cell[:, 1], cell[:, 2], self.cell[idx], slab,
                sc.triangle_material[rows], sc.triangle_two_sided[rows]]
        if world_view is not None:
            keys += list(np.asarray(world_view).T)
        carved = None
        if gap is not None:
            code = gap[:, 0] * 2 + gap[:, 1]
            # the cells a gap carves: their triangles in and out of it share the other keys
            base = group_ids(keys)
            lo, hi = np.full(int(base.max()) + 1, 4), np.full(int(base.max()) + 1, -1)
            np.minimum.at(lo, base, code)
            np.maximum.at(hi, base, code)
            carved = lo[base] != hi[base]
            keys.append(code)
        ids = group_ids(keys)
        # detail: clusters under cell_h^2 / DETAIL (the facets of a plant, a lamp, a chair's legs in
        # one cell) join by the cube face of their normal instead
        detail = np.bincount(ids, area)[ids] < ch * ch / DETAIL
        if detail.any():
            # diffuse ones by the cube face (the image evaluates lobes per triangle, the iteration a
            # glossy one about the cluster's normal: glossy clusters keep their 15-degree normal cell),
            # in the cells of the detail size, in half-size slabs along the face's axis (a shelf keeps
            # off the floor under it)
            dh = h if detail_h is None else max(float(detail_h), h)
            glossy = sc.materials.is_glossy[sc.triangle_material[rows]]
            axis = self.face[idx] // 2
            height = np.take_along_axis(centroid - self.lo, axis[:, None], 1)[:, 0]
            if dh > ch:
                keys[0:3] = list(np.floor((centroid - self.lo) / dh).astype(np.int64).T)
            keys[3:5] = [np.where(glossy, self.cell[idx], -1 - self.face[idx]),
                         np.floor(height / (0.5 * dh)).astype(np.int64)]
            merged = group_ids([k[detail] for k in keys])
            kept = np.unique(ids[~detail], return_inverse=True)[1].reshape(-1)
            ids[detail] = merged
            ids[~detail] = int(merged.max()) + 1 + kept
        if carved is not None and carved.any():
            corners = sc.triangles[rows[carved]]
            welded = welded_vertices(sc, sc.vertices[corners.reshape(-1)]).reshape(corners.shape)
            ids = _pieces_apart(ids, carved, welded, area, (CONTACT_SHARE * h) ** 2)
        if part is not None:
            own, corners = part
            corners = corners[small_rows[corners[:, 0]]]
            rank = np.cumsum(small_rows) - 1                      # a scene triangle's row in ``part``
            ids = _sides_apart(ids, own[idx], rank[corners[:, 0]], corners[:, 1], corners[:, 2])
        return ids

    def count(self, h, cell_h=None):
        """Patches at size ``h``, grouped in cells ``cell_h`` wide (default ``h``): k^2 per
        triangle cut, one per cluster (a sliver's pieces spread along it), one per other triangle."""
        small = self.small(h)
        reflects = self.scene.materials.reflects[self.scene.triangle_material[self.rows]]
        k = np.where(reflects & ~small, np.maximum(1, np.ceil(self.edge / h - 1e-9)), 1.0)
        n_clusters = int(self.clusters(h, small, spread=True, cell_h=cell_h).max()) + 1 if small.any() else 0
        return int((k[~small] ** 2).sum()) + n_clusters


def patch_sizes(scene: PatchScene, patches, grouping=None, steps=12):
    """``(h, detail_h, cell_h)`` [m]: ``detail_h`` is the patch size whose patch count is closest
    to ``patches`` (within ~10% where the count allows); ``h``, the size surfaces are cut and
    grouped at, is the same but at most :data:`SURFACE_SHARE` times ``sqrt(A / patches)``, ``A``
    the reflecting area (:func:`surface_size`).  The clusters of a furnished room's details (a
    cluster per material, normal cell and slab of each chair, cup and plant) may outnumber the
    target several times over at the size that tiles its walls and floor: a size chosen for the
    count alone cuts the walls into patches as large as walls, and one capped for the walls alone
    splits the details into more patches than the whole target.  So the details (clusters under
    cell_h^2 / :data:`DETAIL`) are grouped at ``detail_h``, the rest at ``h``.  The count falls
    with h, but in jumps: where triangles stop being grouped, each is cut into k^2 instead, so h
    is bracketed and bisected in log h, each step a secant guess inside the bracket, and the best
    count seen wins.  A mesh of equal triangles (a floor subdivided n x n) jumps across the target
    at once: just above the size where its triangles become small they are grouped into cells h
    wide, h^2 each, just below it each is cut into four pieces an eighth of h^2 or less.  The
    coarse side is then taken and its small triangles grouped in cells ``cell_h`` < ``h`` wide,
    bisected the same way (:func:`cell_size`), so that the count follows the target; elsewhere
    ``cell_h`` = ``h``."""
    grouping = grouping or _Grouping(scene)
    best, coarse = _bisected(grouping.count, np.sqrt(scene.triangle_area.sum() / patches), patches, steps)
    if best[0] <= np.log(1.1) or coarse is None:
        h = min(best[1], surface_size(scene, patches, grouping))
        return h, best[1], h
    h = min(coarse[0], surface_size(scene, patches, grouping))
    return h, coarse[0], cell_size(grouping, h, patches, steps, coarse[1] if h == coarse[0] else None)


def cell_size(grouping, h, patches, steps=12, count=None):
    """The width <= ``h`` [m] of the grid cells that group the small triangles of patch size ``h``
    into about ``patches`` patches in all (``h`` where that count is ``patches`` or more, or
    within 10% of it; ``count``: the count at ``h`` where known): :func:`patch_sizes`."""
    count = grouping.count(h) if count is None else count
    if count >= patches / 1.1:
        return h
    return _bisected(lambda c: grouping.count(h, cell_h=c), h * np.sqrt(count / patches), patches, steps, top=h)[0][1]


def _bisected(count, h, patches, steps, top=np.inf):
    """The size (<= ``top``) whose ``count`` (falling with it, in jumps) comes nearest
    ``patches``: ``((|log(count / patches)|, size), coarse)``, ``coarse`` = (size, count) of the
    finest size seen whose count is under the target (None if none was)."""
    best, fine, coarse = (np.inf, h), None, None
    h = min(h, top)
    for _ in range(steps):
        n = max(count(h), 1)
        best = min(best, (abs(np.log(n / patches)), h))
        if abs(n - patches) <= 0.1 * patches:
            break
        if n > patches:
            fine = h
        else:
            coarse = (h, n)
            if h >= top:
                break
        guess = np.log(h) + 0.5 * np.log(n / patches)          # a count falls as 1 / h^2
        if fine is not None and coarse is not None:
            lo, hi = np.log(fine), np.log(coarse[0])
            if not lo + 0.05 * (hi - lo) < guess < hi - 0.05 * (hi - lo):
                guess = 0.5 * (lo + hi)
            if hi - lo < 1e-3:
                break
        h = float(min(np.exp(guess), top))
    return best, coarse


def surface_size(scene: PatchScene, patches, grouping):
    """:data:`SURFACE_SHARE` x ``sqrt(A / patches)`` [m], ``A`` the reflecting area of
    ``grouping``'s triangles (inf where nothing reflects): the coarsest patch size
    :func:`patch_sizes` takes."""
    reflects = scene.materials.reflects[scene.triangle_material[grouping.rows]]
    surfaces = float(grouping.area[reflects].sum())
    return SURFACE_SHARE * np.sqrt(surfaces / patches) if surfaces > 0 else np.inf


def make_patches(scene: PatchScene, patches=None, size=None, contacts=True, stage=None) -> PatchScene:
    """The patch layout of ``scene`` for about ``patches`` patches (or patch size ``size`` [m]):
    large triangles cut, small ones grouped (module docstring).  A scene without triangles
    smaller than a patch gets exactly :func:`~raybundle.patches.layout.subdivide`'s layout.  With
    ``contacts``, patches follow contact lines (:func:`~raybundle.patches.layout.cut_at_contacts`)
    and no cluster holds triangles both in and out of a gap narrower than a quarter of a patch
    (:func:`~raybundle.patches.gaps.gap_sides`).  ``stage(text)`` is told each step as it starts."""
    stage = stage or (lambda text: None)
    if (patches is None) == (size is None):
        raise ValueError("give exactly one of patches and size")
    grouping = _Grouping(scene)
    if patches is not None and patches >= len(scene.triangles) and not grouping.small(0.0).any():
        return subdivide(scene, patches=patches, contacts=contacts)     # fewer triangles than patches, no slivers
    h, detail_h, cell_h = (float(size),) * 3 if size is not None else patch_sizes(scene, patches, grouping)
    if not h > 0:
        raise ValueError("the patch size must be positive")
    small = grouping.small(h)
    if not small.any():
        return subdivide(scene, max_edge=h, contacts=contacts)
    # crowding is traced over the input (its pieces have the same surfaces), if a triangle is cut
    stage(f"cutting faces larger than a patch ({h:.3g} m)")
    pieces = ~small & scene.materials.reflects[scene.triangle_material]
    probe = RayTracer(scene) if pieces.any() else None
    try:
        small, fine, row, split, crowded = _cut(scene, grouping, h, probe)
        coarser = min(h * np.sqrt((patches + 3 * crowded) / patches), surface_size(scene, patches, grouping)) \
            if crowded and patches is not None else h
        if coarser > h:
            # the crowded pieces cut in four: a coarser h (more triangles small) keeps about
            # ``patches``, in finer cells where it crosses the size at which a mesh of equal
            # triangles stops being cut
            cell_h = cell_size(grouping, coarser, patches ** 2 / (patches + 3 * crowded))
            h, detail_h = coarser, max(detail_h, coarser)
            small, fine, row, split, _ = _cut(scene, grouping, h, probe)
    finally:
        if probe is not None:
            probe.close()
    lo, probe = grouping.lo, None
    del grouping                    # the cuts done, only its origin is needed: memory grows with the scene
    lit_by_world = scene.world.emits
    tracer = RayTracer(fine) if contacts or lit_by_world else None
    try:
        if contacts:
            stage("cutting patches along contacts and where surfaces pierce others")
            # cut the pieces of split faces and the triangles that straddle a contact; carry
            # each new triangle's row in ``fine`` through the cut as its source
            rows = replace(fine, triangle_source=np.arange(len(fine.triangles)))
            cut = cut_at_contacts(rows, np.nonzero(split & ~small[row])[0], h, tracer=tracer)
            row = row[cut.triangle_source]
            fine = replace(cut, triangle_source=fine.triangle_source[cut.triangle_source])
            del rows, cut               # the uncut copy and the arrays the cut cached on it
        fine_small = small[row]
        stage(f"grouping {int(fine_small.sum()):,} small triangles into patches")
        grouped = _Grouping(fine, lo=lo, rows=np.nonzero(fine_small)[0])
        gap = gap_sides(tracer, grouped.centroid, grouped.normal, CONTACT_SHARE * h) if contacts else None
        views = ([world_view_classes(tracer, grouped.centroid, grouped.normal)] if lit_by_world else []) + \
            ([enclosure_classes(tracer, grouped.centroid, grouped.normal, ENCLOSURE_REACH * h)] if contacts else [])
        view = np.concatenate(views, axis=1) if views else None
    finally:
        if tracer is not None:
            tracer.close()
    tracer = None                   # and with it the uncut scene
    part = pierced_parts(fine)
    ids = grouped.clusters(h, np.ones(int(fine_small.sum()), bool), gap, world_view=view,
                           part=None if part is None else (part[0][fine_small], part[1]), small_rows=fine_small,
                           detail_h=detail_h, cell_h=cell_h)
    n_clusters = int(ids.max()) + 1
    patch = np.empty(len(fine.triangles), np.int64)
    patch[fine_small] = ids
    others = np.unique(fine.triangle_patch[~fine_small], return_inverse=True)[1].reshape(-1)
    patch[~fine_small] = n_clusters + others
    return replace(fine, triangle_patch=patch)


def _cut(scene, grouping, h, probe):
    """The triangles of ``scene`` at patch size ``h`` (some of them small) before contacts and
    clusters, crowding traced by ``probe`` over ``scene``: ``(small (T,)
    bool, fine, row (T',), split (T',) bool, crowded)``: the triangles to group; the scene with the
    others cut to edges <= h (:func:`~raybundle.patches.layout.split_triangles`, slivers halved along
    their length: :func:`~raybundle.patches.layout.bisect_long`) and the crowded pieces cut to h / 2
    (:func:`~raybundle.patches.layout.refine_crowded`); each new triangle's row in ``scene``; whether
    it is a piece of a triangle cut (its contact lines are then still to cut); the count of
    crowded pieces."""
    small = grouping.small(h)
    fine, k, row = split_triangles(scene, h, whole=small)
    sliver = small[row] & fine.materials.reflects[fine.triangle_material] & (longest_edges(fine.triangle_corners) > h)
    if sliver.any():            # long thin triangles: pieces no longer than a patch, grouped where they lie
        fine, piece = bisect_long(fine, h, sliver)
        k, row = k[piece], row[piece]
    pieces = np.nonzero(~small[row] & fine.materials.reflects[fine.triangle_material])[0]
    fine, piece, crowded = refine_crowded(fine, pieces, h, probe)
    split = (k[piece] > 1) | (np.bincount(piece, minlength=len(k))[piece] > 1)
    return small, fine, row[piece], split, crowded


def _pieces_apart(ids, carved, welded, area, least):
    """Cluster ids (S,) with each cluster's ``carved`` (S,) bool triangles split into the pieces
    that share a corner, ``welded`` (K, 3) the corners' welded ids
    (:func:`~raybundle.patches.contacts.welded_vertices`) of the carved triangles in order;
    pieces with an ``area`` (S,) sum under ``least`` (tiles, a frame's facets) stay together.
    In a cell a gap carves (the wall behind a window's frame standing just in front of it), the
    parts on either side of the gap are apart, one lit through the window and one in the room,
    and one cluster for both gave the room's part the mean of both (the interior bench's
    bathroom: the wall beside the frame twice as bright as Cycles')."""
    rows = np.flatnonzero(carved)
    # triangles of one cluster that share a welded corner are linked
    tri = np.repeat(np.arange(len(rows)), 3)
    key = group_ids([np.repeat(ids[rows], 3), welded.reshape(-1)])
    order, key = stable_order(key)
    same = key[1:] == key[:-1]
    links = np.stack([tri[order][1:][same], tri[order][:-1][same]], axis=1)
    comp = connected_components(len(rows), links)
    comp = np.where(np.bincount(comp, area[rows])[comp] >= least, comp, -1)
    piece = np.full(len(ids), -1, np.int64)
    piece[rows] = comp
    return group_ids([ids, piece])


def _sides_apart(ids, part, row, plane, behind):
    """Cluster ids (S,) with each cluster that holds pieces on both sides of a pierced plane
    split by side (:func:`~raybundle.patches.piercing.pierced_parts`: the ``part`` (S,) of each
    triangle; per tagged corner its triangle ``row``, ``plane`` and side ``behind``), by the
    plane most of its tagged corners lie on (a cluster of a shelf through a wall, under a panel
    that stands across the wall on it, by the wall's).  A triangle's side of that plane is
    that of its part (a part never crosses the cut); triangles of no tagged part, or of a part
    that does not reach the plane, form a third group.  (Splitting by every such plane at once
    makes many more patches in furnished rooms.)"""
    # (cluster, plane) pairs as one key each, in their lexicographic order; ``behind`` is 0 or 1
    span = int(plane.max()) + 1
    cp = ids[row].astype(np.int64) * span + plane
    pair_key, count = np.unique(cp, return_counts=True)
    sides, n_sides = np.unique(np.unique(2 * cp + behind) // 2, return_counts=True)
    conflict = sides[n_sides > 1]
    if len(conflict) == 0:
        return ids
    # per conflict cluster its plane with the most tagged corners
    at = np.isin(pair_key, conflict)
    pair, count = np.stack(np.divmod(pair_key[at], span), axis=1), count[at]
    order = np.lexsort((-count, pair[:, 0]))
    first = order[np.r_[True, pair[order[1:], 0] != pair[order[:-1], 0]]]
    c_plane = np.full(int(ids.max()) + 1, -1, np.int64)
    c_plane[pair[first, 0]] = pair[first, 1]
    split = np.flatnonzero(c_plane[ids] >= 0)
    # each (part, plane)'s side: its tagged corners' ``behind`` where they agree, else 2 (apart)
    key = (part[row].astype(np.int64) + 1) * span + plane
    keys, inv = np.unique(key, return_inverse=True)
    inv = inv.reshape(-1)
    lo, hi = np.full(len(keys), np.iinfo(np.int64).max), np.full(len(keys), np.iinfo(np.int64).min)
    np.minimum.at(lo, inv, behind.astype(np.int64))
    np.maximum.at(hi, inv, behind.astype(np.int64))
    want = (part[split].astype(np.int64) + 1) * span + c_plane[ids[split]]
    at = np.minimum(np.searchsorted(keys, want), len(keys) - 1)
    known = (part[split] >= 0) & (keys[at] == want)
    side = np.where(known, np.where(lo[at] == hi[at], lo[at], 2), 2).astype(np.int64)
    # each conflict cluster's first group keeps its id, the others get new ones: still dense
    sub = group_ids([ids[split], side])
    cluster = np.zeros(int(sub.max()) + 1, np.int64)
    cluster[sub] = ids[split]
    keep = np.r_[True, cluster[1:] != cluster[:-1]]
    new_id = np.where(keep, cluster, int(ids.max()) + np.cumsum(~keep))
    out = ids.copy()
    out[split] = new_id[sub]
    return out


def world_view_classes(tracer, points, normals, rays=WORLD_VIEW_RAYS, seed=0, reach=np.inf,
                       classes=WORLD_VIEW_CLASSES):
    """(N, 2) int: how much of the world ``points`` (N, 3) see on the side their unit
    ``normals`` (N, 3) face (column 0) and on the other (column 1): the fraction of
    ``rays`` cosine-distributed rays that meet nothing within ``reach`` (default: leave the
    scene), cut at ``classes``.

    A cluster is one unknown: the facets of a window's reveal out in the sky and those
    inside the room share its mean irradiance, so the inner ones send the sky's light on
    into the room, a finite-element leak that no patch count finer than the scene's frames
    and reveals are thin removes (docs/benchmarks.md, 'Real interiors').  Clusters therefore keep sides
    of different classes apart (module docstring).

    The rays of a side are one cosine-weighted spiral (ray k at ``sin theta = sqrt((k + 1/2) /
    rays)``, azimuth k times the golden angle) turned by a random angle about the normal: a
    stratified quadrature of the open fraction, at the cost of one frame per side.  Fixed
    ``seed``: the same layout every run; the points go to the tracer
    :data:`~raybundle.patches.gaps.PROBE_CHUNK` rays at a time."""
    points, normals = np.asarray(points, float), np.asarray(normals, float)
    rng = stream(seed, Stream.OPEN_FRACTION_FRAMES)
    k = np.arange(rays) + 0.5
    sin_t, phi = np.sqrt(k / rays), np.pi * (3.0 - np.sqrt(5.0)) * k
    local = np.stack([sin_t * np.cos(phi), sin_t * np.sin(phi), np.sqrt(1.0 - sin_t * sin_t)], axis=1)
    out = np.zeros((len(points), 2), np.int64)
    step = max(1, PROBE_CHUNK // rays)
    for lo in range(0, len(points), step):
        p, nrm = points[lo:lo + step], normals[lo:lo + step]
        t, b = frames_from_normals(nrm)
        for col, sign in ((0, 1.0), (1, -1.0)):
            turn = 2.0 * np.pi * rng.random(len(p))[:, None]
            c, s = np.cos(turn), np.sin(turn)
            frame = np.stack([c * t + s * b, c * b - s * t, sign * nrm], axis=1)       # (n, 3, 3) rows t', b', n
            d = (local @ frame).reshape(-1, 3)
            # a ray leaves the scene when nothing at all lies along it (Embree's any-hit query)
            blocked = tracer.occluded(np.repeat(p + tracer.eps * sign * nrm, rays, axis=0), d,
                                      np.full(len(d), float(reach)))
            out[lo:lo + len(p), col] = np.digitize((~blocked).reshape(len(p), rays).mean(axis=1), classes)
    return out


def enclosure_classes(tracer, points, normals, reach):
    """(N, 2) int: whether the sides of ``points`` (N, 3) facing along their unit ``normals`` (N, 3)
    (column 0) and against them (column 1) are enclosed (0) or open (1): enclosed when the ray
    along the side's normal meets a surface within ``reach`` (:func:`~raybundle.patches.gaps.gap_sides`),
    and so do all but a share under :data:`ENCLOSURE_CLASSES` of :data:`ENCLOSURE_RAYS`
    cosine-distributed rays (:func:`world_view_classes`, asked only of those sides).

    A side inside a solid (a window frame's box, a cabinet's carcass, a closed mesh's inner
    faces) is enclosed, its neighbours on the room's side are not; a cluster holding both gave
    the inner sides the room's irradiance, and the light they sent into the solid was lost to
    the room.  The layout looks :data:`ENCLOSURE_REACH` patch sizes far: the two sides of a
    solid thinner than half a patch may share a grid slab of :meth:`_Grouping.clusters`, and
    within that reach its inner sides read enclosed."""
    points, normals = np.asarray(points, float), np.asarray(normals, float)
    out = np.ones((len(points), 2), np.int64)
    near = gap_sides(tracer, points, normals, reach)
    some = np.nonzero(near.any(axis=1))[0]
    if len(some):
        classes = world_view_classes(tracer, points[some], normals[some], rays=ENCLOSURE_RAYS, seed=1, reach=reach,
                                     classes=ENCLOSURE_CLASSES)
        out[some] = np.where(near[some], classes, 1)
    return out


def triangle_patches(scene: PatchScene) -> PatchScene:
    """One patch per triangle (``--patches 0``), but cut along contact lines as
    :func:`make_patches` cuts them (gaps under a quarter of the median edge count as contact):
    a triangle reaching from under a lamp into the room would leak the light trapped there."""
    edge = longest_edges(scene.triangle_corners)
    one = replace(scene, triangle_patch=np.arange(len(scene.triangles)))
    return cut_at_contacts(one, np.zeros(0, np.int64), float(np.median(edge)) if len(edge) else 1.0)
