"""A light tree: lamps and emitting triangles chosen by their contribution at a shading point.

Conty Estevez and Kulla, "Importance sampling of many lights with adaptive tree splitting"
(HPG 2018), the scheme Cycles' light tree follows.  Every emitter (a triangle of a mesh
light, a point or spot light, an area light; suns stay apart) is a leaf with a bounding box,
an orientation cone (axis, ``theta_o`` the spread of the emitting normals, ``theta_e`` the
spread of the emission about them: pi/2 for a Lambertian emitter) and its intensity
``Phi`` [W/sr, mean of RGB]: ``Le A`` for an emitter of radiance Le and area A, ``I`` for a
point light.  An inner node bounds its two children.

A node's importance at a point x with normal n is an upper bound of the irradiance it
can give there, in the bounding sphere (centre c, radius r) seen from x under
``theta_u`` (``sin theta_u = r / |c - x|``):

    I = Phi cos(max(theta_i - theta_u, 0)) cos(max(theta - theta_o - theta_u, 0)) / max(|c - x|, r)^2,

``theta_i`` the angle between n and the direction to c, ``theta`` that between the cone's
axis and the direction from c to x; 0 where the sphere lies wholly below x's horizon or x
lies outside every emitter's emission (``theta - theta_o - theta_u >= theta_e``).  Both
tests are conservative, so a node of importance 0 gives x nothing, and the choice is
unbiased.  A sample walks from the root, taking child j with probability
``I_j / (I_left + I_right)``; its probability is the product along the path
(:meth:`LightTree.sample`, :meth:`LightTree.pdf`).

The tree is built top-down, each node's emitters cut at the median of their centroids
along the widest axis (a balanced tree of depth ``ceil(log2 E)``), and its bounds are
merged bottom-up, cones by the cone union of the paper.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .sources import MeshLight, PointLight, ShapeLight


@dataclass
class LightTree:
    """Nodes ``(M,)``; emitters ``(E,)`` with ``light`` (index into the first-shot lights) and
    ``k`` (the light's triangle, or 0).  ``left``/``right`` are -1 at leaves, ``emitter`` -1 at
    inner nodes; ``leaf`` (E,) is each emitter's node.  Node 0 is the root."""

    light: np.ndarray
    k: np.ndarray
    left: np.ndarray
    right: np.ndarray
    parent: np.ndarray
    emitter: np.ndarray
    leaf: np.ndarray
    center: np.ndarray
    radius: np.ndarray
    axis: np.ndarray
    theta_o: np.ndarray
    theta_e: np.ndarray
    energy: np.ndarray

    def __post_init__(self):
        self._cos_o, self._sin_o = np.cos(self.theta_o), np.sin(self.theta_o)
        self._cos_oe = np.cos(np.minimum(self.theta_o + self.theta_e, np.pi))
        self._wide = self.theta_o + self.theta_e >= np.pi
        self.depth = _depth(self.parent)

    @property
    def n_emitters(self):
        return len(self.light)

    def importance(self, nodes, points, normals):
        """(N,) the importance of ``nodes`` (N,) at ``points`` with unit ``normals`` (N, 3)
        (the module's bound; 0 only where the node surely gives nothing)."""
        v = self.center[nodes] - points
        d2 = np.einsum("ij,ij->i", v, v)
        d = np.sqrt(d2)
        r = self.radius[nodes]
        inside = d <= r
        w = v / np.where(d > 0, d, 1.0)[:, None]
        sin_u = np.where(inside, 0.0, r / np.where(inside, 1.0, d))
        cos_u = np.where(inside, -1.0, np.sqrt(np.maximum(1.0 - sin_u * sin_u, 0.0)))
        cos_i = np.einsum("ij,ij->i", normals, w)
        sin_i = np.sqrt(np.maximum(1.0 - cos_i * cos_i, 0.0))
        cos_in = np.where(cos_i >= cos_u, 1.0, cos_i * cos_u + sin_i * sin_u)
        cos_t = -np.einsum("ij,ij->i", self.axis[nodes], w)
        sin_t = np.sqrt(np.maximum(1.0 - cos_t * cos_t, 0.0))
        cos_tu = cos_t * cos_u + sin_t * sin_u              # cos(theta - theta_u), theta > theta_u
        sin_tu = np.sqrt(np.maximum(1.0 - cos_tu * cos_tu, 0.0))
        full = (cos_t >= cos_u) | (cos_tu >= self._cos_o[nodes])
        part = self._wide[nodes] | (cos_tu > self._cos_oe[nodes])
        cos_out = np.where(full, 1.0, np.where(part, cos_tu * self._cos_o[nodes] + sin_tu * self._sin_o[nodes], 0.0))
        return self.energy[nodes] * np.maximum(cos_in, 0.0) * np.maximum(cos_out, 0.0) / np.maximum(d2, r * r)

    def _left_chance(self, nodes, points, normals):
        """(N,) the probability of the left child of inner ``nodes`` at the points; 0.5 where
        neither child gives anything; and (N,) bool: the node gives something."""
        a = self.importance(self.left[nodes], points, normals)
        b = self.importance(self.right[nodes], points, normals)
        total = a + b
        return np.where(total > 0, a / np.where(total > 0, total, 1.0), 0.5), total > 0

    def sample(self, points, normals, u):
        """Emitters (N,) drawn at ``points`` (N, 3) with unit ``normals`` from uniforms ``u``
        (N,), their probabilities (N,) (0 where the tree gives the point nothing), and ``u``
        rescaled into [0, 1) again (free for the emitter's own sample)."""
        n = len(points)
        node = np.zeros(n, np.int64)
        p = np.ones(n)
        u = np.array(u, float)
        live = np.nonzero(self.left[node] >= 0)[0]
        while len(live):
            c, ok = self._left_chance(node[live], points[live], normals[live])
            p[live[~ok]] = 0.0
            go_left = u[live] < c
            u[live] = np.where(go_left, u[live] / np.maximum(c, 1e-300), (u[live] - c) / np.maximum(1.0 - c, 1e-300))
            p[live] *= np.where(go_left, c, 1.0 - c)
            node[live] = np.where(go_left, self.left[node[live]], self.right[node[live]])
            live = live[self.left[node[live]] >= 0]
        return self.emitter[node], p, np.clip(u, 0.0, 1.0 - 1e-12)

    def pdf(self, emitters, points, normals):
        """(N,) the probability with which :meth:`sample` draws ``emitters`` (N,) at ``points``
        with unit ``normals`` (N, 3): the product of the choices from the leaf up to the root
        (0 where a node on the way gives nothing, as :meth:`sample` has it)."""
        node = self.leaf[emitters]
        p = np.ones(len(node))
        live = np.nonzero(self.parent[node] >= 0)[0]
        while len(live):
            up = self.parent[node[live]]
            c, ok = self._left_chance(up, points[live], normals[live])
            p[live] *= np.where(self.left[up] == node[live], c, 1.0 - c) * ok
            node[live] = up
            live = live[self.parent[up] >= 0]
        return p


def _depth(parent):
    depth = np.zeros(len(parent), np.int64)
    for i in range(1, len(parent)):          # parents come before their children
        depth[i] = depth[parent[i]] + 1
    return depth


def emitter_bounds(lights):
    """Per emitter of the first-shot ``lights`` (not suns): light index, k, box (E, 2, 3),
    cone axis (E, 3), theta_o, theta_e (E,), intensity (E,) [W/sr, mean of RGB]."""
    rows = []
    for li, light in enumerate(lights):
        if isinstance(light, MeshLight):
            sc = light.scene
            c = sc.triangle_corners[light.triangles]
            k = np.arange(len(light.triangles))
            box = np.stack([c.min(axis=1), c.max(axis=1)], axis=1)
            axis = sc.triangle_normal[light.triangles]
            theta_o = np.where(light.two_sided, np.pi, 0.0)
            energy = float(np.mean(light.radiance)) * sc.triangle_area[light.triangles]
        elif isinstance(light, ShapeLight):
            corners = light.corners()
            k, box = np.zeros(1, np.int64), np.stack([corners.min(axis=0), corners.max(axis=0)])[None]
            axis, theta_o = light.normal[None], np.zeros(1)
            energy = np.array([float(np.mean(light.radiance)) * light.area])
        elif isinstance(light, PointLight):
            r = float(light.lights.radius[light.k])
            k = np.zeros(1, np.int64)
            box = np.stack([light.position - r, light.position + r])[None]
            axis, theta_o = np.array([[0.0, 0.0, 1.0]]), np.full(1, np.pi)
            energy = np.array([float(np.mean(light.intensity))])
        else:
            continue
        rows.append((np.full(len(k), li), k, box, axis, theta_o, np.full(len(k), np.pi / 2), energy))
    return [np.concatenate(col) for col in zip(*rows)] if rows else None


def build_light_tree(lights):
    """The :class:`LightTree` of the first-shot ``lights`` (suns left out), or None if none."""
    bounds = emitter_bounds(lights)
    if bounds is None:
        return None
    light, k, box, axis, theta_o, theta_e, energy = bounds
    n = len(light)
    centroid = box.mean(axis=1)
    # top-down: each level's segments of ``order`` cut at their median along the widest axis
    order = np.arange(n)
    m = 2 * n - 1
    left, right, parent = np.full(m, -1), np.full(m, -1), np.full(m, -1)
    emitter = np.full(m, -1)
    seg_lo, seg_hi, seg_node = np.array([0]), np.array([n]), np.array([0])
    next_node = 1
    while len(seg_lo):
        size = seg_hi - seg_lo
        leaf = size == 1
        emitter[seg_node[leaf]] = order[seg_lo[leaf]]
        lo, hi, node = seg_lo[~leaf], seg_hi[~leaf], seg_node[~leaf]
        if len(lo) == 0:
            break
        seg_of = np.repeat(np.arange(len(lo)), hi - lo)
        pos = _ranges(lo, hi)
        cen = centroid[order[pos]]
        ext = np.maximum.reduceat(cen, np.r_[0, np.cumsum(hi - lo)[:-1]]) - \
            np.minimum.reduceat(cen, np.r_[0, np.cumsum(hi - lo)[:-1]])
        key = cen[np.arange(len(pos)), np.argmax(ext, axis=1)[seg_of]]
        order[pos] = order[pos[np.lexsort((key, seg_of))]]
        mid = lo + (hi - lo + 1) // 2
        a = next_node + 2 * np.arange(len(lo))
        left[node], right[node] = a, a + 1
        parent[a], parent[a + 1] = node, node
        next_node += 2 * len(lo)
        seg_lo, seg_hi, seg_node = np.r_[lo, mid], np.r_[mid, hi], np.r_[a, a + 1]
    # bottom-up bounds (children have larger ids than their parents)
    lo_b, hi_b = np.zeros((m, 3)), np.zeros((m, 3))
    ax, t_o, t_e, en = np.zeros((m, 3)), np.zeros(m), np.zeros(m), np.zeros(m)
    is_leaf = emitter >= 0
    e = emitter[is_leaf]
    lo_b[is_leaf], hi_b[is_leaf] = box[e, 0], box[e, 1]
    ax[is_leaf], t_o[is_leaf], t_e[is_leaf], en[is_leaf] = axis[e], theta_o[e], theta_e[e], energy[e]
    depth = _depth(parent)
    for level in range(int(depth.max()) - 1, -1, -1):
        nd = np.nonzero((depth == level) & ~is_leaf)[0]
        a, b = left[nd], right[nd]
        lo_b[nd], hi_b[nd] = np.minimum(lo_b[a], lo_b[b]), np.maximum(hi_b[a], hi_b[b])
        en[nd] = en[a] + en[b]
        t_e[nd] = np.maximum(t_e[a], t_e[b])
        ax[nd], t_o[nd] = cone_union(ax[a], t_o[a], ax[b], t_o[b])
    leaf_of = np.zeros(n, np.int64)
    leaf_of[emitter[is_leaf]] = np.nonzero(is_leaf)[0]
    center = 0.5 * (lo_b + hi_b)
    return LightTree(light, k, left, right, parent, emitter, leaf_of, center,
                     np.linalg.norm(hi_b - center, axis=1), ax, t_o, t_e, en)


def _ranges(lo, hi):
    """The concatenated ranges lo[i] .. hi[i] - 1."""
    size = hi - lo
    start = np.repeat(lo - np.r_[0, np.cumsum(size)[:-1]], size)
    return start + np.arange(size.sum())


def cone_union(axis_a, theta_a, axis_b, theta_b):
    """The smallest cone (axis (N, 3), half-angle (N,)) holding the cones a and b (N each):
    the wider one when it holds the other, else the cone spanning both, its axis turned
    from the wider one's towards the other's."""
    swap = theta_b > theta_a
    a = np.where(swap[:, None], axis_b, axis_a)
    b = np.where(swap[:, None], axis_a, axis_b)
    ta, tb = np.where(swap, theta_b, theta_a), np.where(swap, theta_a, theta_b)
    cos_d = np.clip(np.einsum("ij,ij->i", a, b), -1.0, 1.0)
    theta_d = np.arccos(cos_d)
    theta = 0.5 * (ta + theta_d + tb)
    ortho = b - cos_d[:, None] * a
    norm = np.linalg.norm(ortho, axis=1)
    turn = theta - ta
    axis = np.where((norm > 1e-12)[:, None],
                    np.cos(turn)[:, None] * a + np.sin(turn)[:, None] * ortho / np.maximum(norm, 1e-300)[:, None], a)
    held = np.minimum(theta_d + tb, np.pi) <= ta
    full = ~held & ((theta >= np.pi) | ((norm <= 1e-12) & (cos_d < 0)))
    axis = np.where(held[:, None], a, axis)
    theta = np.where(held, ta, np.where(full, np.pi, theta))
    return axis / np.linalg.norm(axis, axis=1)[:, None], theta
