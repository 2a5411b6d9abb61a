"""The planar parts of a mesh light and their outlines.

A lamp modelled as a grid of many triangles is, for sampling and for Lambert's analytic
irradiance, a few planar parts with convex outlines: :func:`light_planes` groups a mesh
light's triangles by plane and finds each part's boundary (collinear edges merged), and
:func:`plane_fans` turns parts with one convex outline into fans of triangles sampled by
area or solid angle (:class:`~raybundle.lights.sources.MeshLight`).
"""
from __future__ import annotations

import numpy as np


def _merge_collinear(vertices, directed):
    """Directed boundary edges (B, 2) (vertex ids) -> edge end points (B', 2, 3), chains of
    collinear edges merged into one (the outline of a light cut into a grid of triangles
    has 4 edges, not 4 n: Lambert's sum over a straight edge does not depend on how it is
    split).  Outlines whose loops cannot be walked (a vertex with two outgoing edges) stay as they are."""
    nxt = {}
    for a, b in directed.tolist():
        if a in nxt:
            return vertices[directed]
        nxt[a] = b
    out, seen = [], set()
    for start in list(nxt):
        if start in seen:
            continue
        loop = [start]
        seen.add(start)
        v = nxt[start]
        while v != start and v in nxt and v not in seen:
            loop.append(v)
            seen.add(v)
            v = nxt[v]
        pts = vertices[loop]
        d_in = pts - np.roll(pts, 1, axis=0)
        d_out = np.roll(pts, -1, axis=0) - pts
        cross = np.linalg.norm(np.cross(d_in, d_out), axis=1)
        scale = np.linalg.norm(d_in, axis=1) * np.linalg.norm(d_out, axis=1)
        corner = (cross > 1e-9 * scale) | (np.einsum("ij,ij->i", d_in, d_out) < 0)
        keep = pts[corner] if corner.sum() >= 3 else pts
        out.append(np.stack([keep, np.roll(keep, -1, axis=0)], axis=1))
    return np.concatenate(out) if out else vertices[directed]


#: mesh lights with more planar parts than this (a tessellated sphere) are sampled and
#: integrated triangle by triangle
MAX_PLANES = 64


def light_planes(light):
    """The planar parts of a mesh light: a list of (triangle rows into ``light.triangles``,
    unit normal, a point of the plane, two-sided, bounding-box corners (8, 3), directed
    boundary edges (B, 2, 3) or None when the triangles do not form a consistently
    oriented, T-junction-free surface, whose outline cannot stand for them); None for a
    light of more than :data:`MAX_PLANES` parts."""
    sc = light.scene
    tri = light.triangles
    nrm = sc.triangle_normal[tri]
    p0 = sc.triangle_corners[tri, 0]
    _, r = sc.bounding_sphere
    key = np.concatenate([np.round(nrm * 1e5), np.round((nrm * p0).sum(axis=1) / max(r * 1e-7, 1e-12))[:, None],
                          light.two_sided[:, None]], axis=1).astype(np.int64)
    _, label = np.unique(key, axis=0, return_inverse=True)
    n_planes = int(label.max()) + 1 if len(label) else 0
    if n_planes > MAX_PLANES:
        return None
    planes = []
    for g in range(n_planes):
        rows = np.nonzero(label.reshape(-1) == g)[0]
        ids = sc.triangles[tri[rows]]
        corners = sc.triangle_corners[tri[rows]]
        lo, hi = corners.reshape(-1, 3).min(axis=0), corners.reshape(-1, 3).max(axis=0)
        box = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])
        e = np.concatenate([ids[:, [0, 1]], ids[:, [1, 2]], ids[:, [2, 0]]])
        und = np.sort(e, axis=1)
        uniq, inv, cnt = np.unique(und, axis=0, return_inverse=True, return_counts=True)
        inv = inv.reshape(-1)
        edges = None
        once = cnt[inv] == 1
        twice_ok = np.all(cnt <= 2)
        if twice_ok:
            # interior edges must be traversed both ways (consistent winding)
            fwd = (e[:, 0] == und[:, 0]).astype(int)
            per = np.bincount(inv, fwd, minlength=len(uniq))
            if np.all(per[cnt == 2] == 1):
                edges = _merge_collinear(sc.vertices, e[once])      # (B, 2, 3)
                # the outline's area vector must equal the triangles' total area (no T-junctions)
                area_vec = 0.5 * np.cross(edges[:, 0], edges[:, 1]).sum(axis=0)
                total = sc.triangle_area[tri[rows]].sum()
                if abs(area_vec @ nrm[rows[0]] - total) > 1e-6 * total:
                    edges = None
        planes.append((rows, nrm[rows[0]], p0[rows[0]], bool(light.two_sided[rows[0]]), box, edges))
    return planes


def plane_fans(light):
    """Sampling tables of a mesh light whose planar parts (``light.planes``) each
    have one convex outline: per part its area, probability ``A_g / A`` and CDF, normal,
    sidedness, bounding sphere, and the fan triangles of its outline (``fan`` (F, 3, 3),
    ``fan_group``, ``fan_key`` = group + area CDF within it, each part's ``fan_start`` and
    ``fan_count`` in ``fan``); ``tri_group`` maps the
    light's triangles to parts.  None when a part's outline is not one convex loop (or
    there are more than :data:`MAX_PLANES` parts): the light is then sampled triangle by triangle."""
    planes = light.planes
    if not planes:
        return None
    sc = light.scene
    fans, fan_group, areas, normals, two, cents, radii = [], [], [], [], [], [], []
    tri_group = np.zeros(len(light.triangles), np.int64)
    for gi, (rows, nrm, _, two_sided, _, edges) in enumerate(planes):
        if edges is None or len(edges) < 3 or not np.allclose(edges[:, 1], np.roll(edges[:, 0], -1, axis=0)):
            return None
        pts = edges[:, 0]
        d = np.roll(pts, -1, axis=0) - pts
        turn = np.cross(d, np.roll(d, -1, axis=0)) @ nrm
        scale = np.linalg.norm(d, axis=1) * np.linalg.norm(np.roll(d, -1, axis=0), axis=1)
        if not (np.all(turn >= -1e-9 * scale) or np.all(turn <= 1e-9 * scale)):
            return None                                    # not convex
        fan = np.stack([np.broadcast_to(pts[0], (len(pts) - 2, 3)), pts[1:-1], pts[2:]], axis=1)
        fa = 0.5 * np.linalg.norm(np.cross(fan[:, 1] - fan[:, 0], fan[:, 2] - fan[:, 0]), axis=1)
        area = float(sc.triangle_area[light.triangles[rows]].sum())
        if abs(fa.sum() - area) > 1e-6 * area:
            return None
        fans.append(fan)
        fan_group.append(np.full(len(fan), gi))
        areas.append(area)
        normals.append(nrm)
        two.append(two_sided)
        c = pts.mean(axis=0)
        cents.append(c)
        radii.append(float(np.linalg.norm(pts - c, axis=1).max()))
        tri_group[rows] = gi
    fan = np.concatenate(fans)
    fan_group = np.concatenate(fan_group)
    fa = 0.5 * np.linalg.norm(np.cross(fan[:, 1] - fan[:, 0], fan[:, 2] - fan[:, 0]), axis=1)
    areas = np.array(areas)
    within = np.zeros(len(fan))
    for gi in range(len(areas)):
        sel = fan_group == gi
        within[sel] = np.cumsum(fa[sel]) / fa[sel].sum()
    p = areas / areas.sum()
    count = np.bincount(fan_group, minlength=len(areas))
    return {"area": areas, "p": p, "cdf": np.cumsum(p), "normal": np.array(normals), "two_sided": np.array(two),
            "centroid": np.array(cents), "radius": np.array(radii), "fan": fan, "fan_group": fan_group,
            "fan_key": fan_group + within, "tri_group": tri_group,
            "fan_start": np.cumsum(count) - count, "fan_count": count}
