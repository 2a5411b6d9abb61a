"""Welding a scene's tside corners where its surface is smooth
(:attr:`~raybundle.scene.model.PatchScene.smooth_vertex_ids`): the vertices that side values
are interpolated over without bleeding across a crease, a contact line or to the other side."""
from __future__ import annotations

import numpy as np

from ..util.arrays import connected_components, group_ids, shared_edges, unique_ints, unique_rows

#: corners of triangles whose normals differ by less than this weld (:func:`smooth_vertex_ids`;
#: Blender's default Auto Smooth angle)
SMOOTH_ANGLE = np.radians(30.0)


def smooth_vertex_ids(scene):
    """(TS, 3) int32 (int64 beyond 2^31 vertices): ``scene``'s tside corners welded where the surface is smooth
    (:attr:`~raybundle.scene.model.PatchScene.smooth_vertex_ids`).  Memory grows with the
    tsides, a few arrays of them at a time: positions, tags and corner classes in 32 bits."""
    _, r = scene.bounding_sphere
    _, position = unique_rows(np.round(scene.vertices / max(r * 1e-6, 1e-12)).astype(np.int64))
    pos = position.astype(np.int32)[scene.triangles][scene.tside_triangle]      # (TS, 3); memory: 32 bits
    del position
    normal = group_ids([np.round(scene.tside_normal[:, k] * 1e3).astype(np.int64) for k in range(3)])
    tag = scene.triangle_corner_tag                 # in 32 bits, per triangle: the same order and equality
    if tag is not None:
        lo = int(tag.min(initial=0))
        tag = ((tag - lo).astype(np.int32) if int(tag.max(initial=0)) - lo < 2 ** 31 else
               unique_ints(tag.ravel())[2].astype(np.int32).reshape(-1, 3))[scene.tside_triangle]
    cls = group_ids([pos, normal[:, None]] + ([] if tag is None else [tag])).astype(np.int32).reshape(-1, 3)
    links = _smooth_links(pos, normal, tag, cls, scene.tside_normal)
    del pos, normal, tag
    ids = connected_components(int(cls.max(initial=-1)) + 1, links)
    return (ids.astype(np.int32) if len(ids) < 2 ** 31 else ids)[cls]


def _smooth_links(pos, normal, tag, cls, tside_normal):
    """(K, 2) pairs of corner classes ``cls`` (TS, 3) to weld (:func:`smooth_vertex_ids`:
    across edges shared by positions ``pos``, normal ids ``normal``, normals ``tside_normal``, tags
    ``tag``); a function of its own, so that its arrays are freed before the components are found."""
    # tsides sharing an edge (flat index 3 t + k: tside t's edge from corner k to corner k + 1)
    e1, e2 = shared_edges(pos)
    # tsides of one normal are welded already (same class at each shared position)
    turn = normal[e1 // 3] != normal[e2 // 3]
    e1, e2 = e1[turn], e2[turn]
    (t1, k1), (t2, k2) = np.divmod(e1, 3), np.divmod(e2, 3)
    del e1, e2, turn
    dot = tside_normal[t1, 0] * tside_normal[t2, 0]             # by components: no (K, 3) copies
    dot += tside_normal[t1, 1] * tside_normal[t2, 1]
    dot += tside_normal[t1, 2] * tside_normal[t2, 2]
    smooth = dot > np.cos(SMOOTH_ANGLE)
    del dot
    t1, k1, t2, k2 = t1[smooth], k1[smooth], t2[smooth], k2[smooth]
    # the corner of t2 at the position of t1's corner k1, and the other end
    flip = pos[t2, k2] != pos[t1, k1]
    c2a = np.where(flip, (k2 + 1) % 3, k2)
    c2b = np.where(flip, k2, (k2 + 1) % 3)
    links = []
    for c1, c2 in ((k1, c2a), ((k1 + 1) % 3, c2b)):
        ok = np.ones(len(t1), bool) if tag is None else tag[t1, c1] == tag[t2, c2]
        links.append(np.stack([cls[t1[ok], c1[ok]], cls[t2[ok], c2[ok]]], axis=1))
    return np.concatenate(links).astype(np.int64)
