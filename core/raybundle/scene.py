"""Patch scenes: triangles grouped into patches (the finite elements), materials,
point lights and a camera; validation, subdivision and the ``.npz`` exchange format.

A *patch* is the unit that carries one incoming-radiance variable (RGB) in the
solver.  After :func:`subdivide` every triangle is its own patch.  Patches are
one-sided: the front is where the triangle's normal
``n = normalize((v1 - v0) x (v2 - v0))`` points.
"""
from __future__ import annotations

import warnings
from dataclasses import dataclass, field
from functools import cached_property

import numpy as np

from .camera import Camera
from .materials import MaterialTable

NPZ_FORMAT_VERSION = 1


class SceneError(ValueError):
    """A scene that cannot be rendered; the message says why and what to do."""


@dataclass
class PointLights:
    """Point lights: ``position`` (L, 3) [m], ``intensity`` (L, 3) [W/sr] per channel.

    Blender's point light of power P [W] has I = P / (4 pi) W/sr (``blender.md`` §4.4).
    """

    position: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    intensity: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))

    def __len__(self):
        return len(self.position)


@dataclass
class PatchScene:
    """Triangle geometry with patches and materials.

    Attributes
    ----------
    vertices : (V, 3) float  world positions [m]
    triangles : (T, 3) int  vertex indices, counter-clockwise seen from the front
    triangle_material : (T,) int  material id
    triangle_patch : (T,) int  patch id (0 .. n_patches-1)
    triangle_source : (T,) int  index of the input face a triangle came from
    materials : MaterialTable
    point_lights : PointLights
    camera : Camera or None
    analytic_radiance : (3,) float or None  the exact radiance everywhere, when known
    name : str
    dropped_triangles : int  zero-area triangles removed at validation
    triangle_solid : (T,) bool  the triangle belongs to a closed, consistently
        oriented mesh (a solid), see :func:`closed_solid_triangles`
    """

    vertices: np.ndarray
    triangles: np.ndarray
    triangle_material: np.ndarray
    triangle_patch: np.ndarray
    triangle_source: np.ndarray
    materials: MaterialTable
    point_lights: PointLights = field(default_factory=PointLights)
    camera: Camera | None = None
    analytic_radiance: np.ndarray | None = None
    name: str = ""
    dropped_triangles: int = 0
    triangle_solid: np.ndarray | None = None

    def __post_init__(self):
        if self.triangle_solid is None:
            self.triangle_solid = closed_solid_triangles(self.vertices, self.triangles)

    # ------------------------------------------------------------- geometry
    @cached_property
    def triangle_corners(self):
        """(T, 3, 3) float: corner positions."""
        return self.vertices[self.triangles]

    @cached_property
    def _cross(self):
        c = self.triangle_corners
        return np.cross(c[:, 1] - c[:, 0], c[:, 2] - c[:, 0])

    @cached_property
    def triangle_area(self):
        """(T,) float [m^2]."""
        return 0.5 * np.linalg.norm(self._cross, axis=1)

    @cached_property
    def triangle_normal(self):
        """(T, 3) float unit front normals."""
        return self._cross / (2.0 * self.triangle_area[:, None])

    @property
    def n_patches(self):
        return int(self.triangle_patch.max()) + 1 if len(self.triangle_patch) else 0

    @cached_property
    def patch_area(self):
        """(P,) float [m^2]."""
        return np.bincount(self.triangle_patch, self.triangle_area, minlength=self.n_patches)

    @cached_property
    def patch_normal(self):
        """(P, 3) float: area-weighted unit normal (patches are planar)."""
        n = np.stack([np.bincount(self.triangle_patch, self._cross[:, k], minlength=self.n_patches)
                      for k in range(3)], axis=1)
        return n / np.linalg.norm(n, axis=1, keepdims=True)

    @cached_property
    def patch_centroid(self):
        w = self.triangle_area[:, None] * self.triangle_corners.mean(axis=1)
        c = np.stack([np.bincount(self.triangle_patch, w[:, k], minlength=self.n_patches)
                      for k in range(3)], axis=1)
        return c / self.patch_area[:, None]

    @cached_property
    def patch_material(self):
        """(P,) int: the material of each patch (that of its first triangle)."""
        m = np.zeros(self.n_patches, dtype=np.int64)
        m[self.triangle_patch[::-1]] = self.triangle_material[::-1]
        return m

    @cached_property
    def bounding_sphere(self):
        """(centre (3,), radius) of a sphere containing every vertex."""
        used = self.vertices[np.unique(self.triangles)]
        lo, hi = used.min(axis=0), used.max(axis=0)
        c = 0.5 * (lo + hi)
        return c, float(np.linalg.norm(used - c, axis=1).max())

    @cached_property
    def smooth_vertex_ids(self):
        """(T, 3) int: corners welded by position *and* normal, for interpolating
        patch values across a smooth surface without bleeding over creases."""
        _, r = self.bounding_sphere
        q = np.round(self.triangle_corners.reshape(-1, 3) / max(r * 1e-6, 1e-12)).astype(np.int64)
        nq = np.repeat(np.round(self.triangle_normal * 1e3).astype(np.int64), 3, axis=0)
        _, ids = np.unique(np.concatenate([q, nq], axis=1), axis=0, return_inverse=True)
        return ids.reshape(-1, 3)

    @property
    def is_diffuse_only(self):
        """True when no patch material has a glossy lobe (the cheaper path applies)."""
        return not self.materials.is_glossy[self.patch_material].any()

    # ------------------------------------------------------------------- io
    def save_npz(self, path):
        """Write the scene to ``path`` (``.npz``, the add-on's exchange format), atomically."""
        from .io import atomic_path

        d = {"format_version": np.array(NPZ_FORMAT_VERSION), "name": np.array(self.name),
             "vertices": self.vertices, "triangles": self.triangles,
             "triangle_material": self.triangle_material, "triangle_patch": self.triangle_patch,
             "triangle_source": self.triangle_source, "triangle_solid": self.triangle_solid,
             "point_light_position": self.point_lights.position,
             "point_light_intensity": self.point_lights.intensity}
        d.update(self.materials.to_arrays())
        if self.camera is not None:
            d.update(self.camera.to_arrays())
        if self.analytic_radiance is not None:
            d["analytic_radiance"] = np.asarray(self.analytic_radiance, float)
        with atomic_path(path) as tmp:
            with open(tmp, "wb") as f:
                np.savez_compressed(f, **d)


def load_npz(path) -> PatchScene:
    """Read a scene written by :meth:`PatchScene.save_npz` (or by the add-on) and validate it.

    Required arrays: ``vertices`` (V,3), ``triangles`` (T,3), ``triangle_material`` (T,)
    and the ``material_*`` table; ``triangle_patch``, ``triangle_source``,
    ``point_light_*``, ``camera_*`` and ``analytic_radiance`` are optional.
    """
    try:
        with np.load(path, allow_pickle=False) as z:
            d = {k: z[k] for k in z.files}
    except (OSError, ValueError) as e:
        raise SceneError(f"cannot read scene file {path}: {e}") from e
    missing = [k for k in ("vertices", "triangles", "triangle_material", "material_names", "material_diffuse",
                           "material_glossy", "material_roughness", "material_glossy_weight", "material_emission")
               if k not in d]
    if missing:
        raise SceneError(f"{path}: not a raybundle scene (missing arrays {missing})")
    version = int(d.get("format_version", NPZ_FORMAT_VERSION))
    if version > NPZ_FORMAT_VERSION:
        raise SceneError(f"{path}: format version {version} is newer than this raybundle supports")
    lights = PointLights(np.asarray(d.get("point_light_position", np.zeros((0, 3))), float).reshape(-1, 3),
                         np.asarray(d.get("point_light_intensity", np.zeros((0, 3))), float).reshape(-1, 3))
    return build_scene(d["vertices"], d["triangles"], d["triangle_material"],
                       MaterialTable.from_arrays(d), point_lights=lights,
                       camera=Camera.from_arrays(d), triangle_patch=d.get("triangle_patch"),
                       triangle_source=d.get("triangle_source"), triangle_solid=d.get("triangle_solid"),
                       analytic_radiance=d.get("analytic_radiance"), name=str(d.get("name", "")))


def build_scene(vertices, triangles, triangle_material, materials, point_lights=None, camera=None,
                triangle_patch=None, triangle_source=None, analytic_radiance=None, name="",
                area_epsilon=1e-14, triangle_solid=None) -> PatchScene:
    """Validate raw triangles and make a :class:`PatchScene`.

    Errors (:class:`SceneError`): non-finite vertices, bad indices, an empty
    scene, no emitter and no point light, invalid materials (albedo > 1, NaN...).
    Zero-area triangles (area <= ``area_epsilon`` m^2) are dropped and counted in
    ``dropped_triangles`` (a warning is issued).  Without ``triangle_patch`` each
    triangle is its own patch.
    """
    v = np.asarray(vertices, float).reshape(-1, 3)
    t = np.asarray(triangles).reshape(-1, 3).astype(np.int64)
    m = np.asarray(triangle_material).reshape(-1).astype(np.int64)
    if len(t) == 0:
        raise SceneError("the scene is empty: it has no triangles")
    if len(m) != len(t):
        raise SceneError(f"{len(m)} material ids for {len(t)} triangles")
    if t.min() < 0 or t.max() >= len(v):
        raise SceneError(f"triangle vertex indices must lie in [0, {len(v)})")
    bad_v = ~np.isfinite(v).all(axis=1)
    bad_t = bad_v[t].any(axis=1)
    if bad_t.any():
        raise SceneError(f"{int(bad_v.sum())} vertices are NaN or infinite (used by {int(bad_t.sum())} "
                         "triangles); fix or delete them before rendering")
    if m.min() < 0 or m.max() >= len(materials):
        raise SceneError(f"triangle material ids must lie in [0, {len(materials)})")
    try:
        materials.validate()
    except ValueError as e:
        raise SceneError(str(e)) from e
    src = np.arange(len(t)) if triangle_source is None else np.asarray(triangle_source).reshape(-1).astype(np.int64)
    patch = None if triangle_patch is None else np.asarray(triangle_patch).reshape(-1).astype(np.int64)
    for label, arr in (("triangle_source", src), ("triangle_patch", patch), ("triangle_solid", triangle_solid)):
        if arr is not None and len(np.asarray(arr).reshape(-1)) != len(t):
            raise SceneError(f"{label} has {len(np.asarray(arr).reshape(-1))} entries for {len(t)} triangles")

    c = v[t]
    area = 0.5 * np.linalg.norm(np.cross(c[:, 1] - c[:, 0], c[:, 2] - c[:, 0]), axis=1)
    keep = area > area_epsilon
    dropped = int((~keep).sum())
    if dropped:
        warnings.warn(f"dropped {dropped} zero-area triangles", stacklevel=2)
    if not keep.any():
        raise SceneError("the scene is empty: every triangle has zero area")
    t, m, src = t[keep], m[keep], src[keep]
    if patch is None:
        patch = np.arange(len(t))
    else:
        patch = np.unique(patch[keep], return_inverse=True)[1].reshape(-1)  # renumber densely
        _check_patches(v, t, m, patch)
    lights = point_lights if point_lights is not None else PointLights()
    lights = PointLights(np.asarray(lights.position, float), np.asarray(lights.intensity, float))
    if lights.position.ndim != 2 or lights.position.shape[1:] != (3,) or lights.intensity.shape != lights.position.shape:
        raise SceneError("point lights need positions (L, 3) and intensities (L, 3) of the same length")
    if not np.isfinite(lights.position).all() or not np.isfinite(lights.intensity).all() \
            or (lights.intensity < 0).any():
        raise SceneError("point lights need finite positions and non-negative finite intensities")
    has_emitter = materials.is_emitter[np.unique(m)].any()
    if not has_emitter and not (lights.intensity > 0).any():
        raise SceneError("the scene has no lights: no emitting material and no point light "
                         "(add an Emission shader or a light)")
    ar = None if analytic_radiance is None else np.asarray(analytic_radiance, float).reshape(3)
    solid = None if triangle_solid is None else np.asarray(triangle_solid, bool).reshape(-1)[keep]
    return PatchScene(v, t, m, patch, src, materials, lights, camera, ar, name, dropped, solid)


def _check_patches(v, t, m, patch):
    """A patch must be planar, face one way and have one material (one variable per patch)."""
    n_p = int(patch.max()) + 1
    first = np.full(n_p, -1)
    first[patch[::-1]] = np.arange(len(patch))[::-1]
    if np.any(m != m[first[patch]]):
        raise SceneError("a patch mixes materials: give each patch triangles of one material")
    c = v[t]
    n = np.cross(c[:, 1] - c[:, 0], c[:, 2] - c[:, 0])
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    if np.any(np.einsum("ij,ij->i", n, n[first[patch]]) < 0.999):
        raise SceneError("a patch mixes triangles that face different ways: patches must be planar")


def subdivide(scene: PatchScene, max_edge=None, patches=None) -> PatchScene:
    """Split every triangle into k^2 similar triangles so that edges are at most
    ``max_edge`` [m] long, or so that there are about ``patches`` patches.

    Each resulting triangle is its own patch.  k is chosen per triangle
    (``k = ceil(longest edge / max_edge)``); neighbours with different k meet at
    T-junctions, which are harmless here (patches are flat, visibility is traced).
    """
    if (max_edge is None) == (patches is None):
        raise ValueError("give exactly one of max_edge and patches")
    corners = scene.triangle_corners
    edge = np.linalg.norm(corners - np.roll(corners, 1, axis=1), axis=2).max(axis=1)
    if patches is not None:
        if patches < len(scene.triangles):
            max_edge = float(edge.max()) * 1.0001
        else:
            # bisection on the edge length for sum(k^2) ~ patches
            lo, hi = 1e-9 * edge.max(), edge.max() * 1.0001
            for _ in range(60):
                mid = np.sqrt(lo * hi)
                n = (np.ceil(edge / mid) ** 2).sum()
                lo, hi = (mid, hi) if n > patches else (lo, mid)
            max_edge = hi
    if not max_edge > 0:
        raise ValueError("max_edge must be positive")
    k_all = np.maximum(1, np.ceil(edge / max_edge - 1e-9)).astype(np.int64)
    verts, tris, mats, srcs = [], [], [], []
    base = 0
    for k in np.unique(k_all):
        sel = np.nonzero(k_all == k)[0]
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
        mats.append(np.repeat(scene.triangle_material[sel], len(local)))
        srcs.append(np.repeat(scene.triangle_source[sel], len(local)))
        base += len(sel) * len(ij)
    v = np.concatenate(verts)
    t = np.concatenate(tris)
    # weld coincident vertices so that triangles of one face share corners
    _, r = scene.bounding_sphere
    q = np.round(v / max(r * 1e-7, 1e-12)).astype(np.int64)
    _, first, inv = np.unique(q, axis=0, return_index=True, return_inverse=True)
    v, t = v[first], inv.reshape(-1)[t]
    solid = np.concatenate([np.repeat(scene.triangle_solid[np.nonzero(k_all == k)[0]], k * k)
                            for k in np.unique(k_all)])
    return PatchScene(v, t, np.concatenate(mats), np.arange(len(t)), np.concatenate(srcs),
                      scene.materials, scene.point_lights, scene.camera, scene.analytic_radiance,
                      scene.name, scene.dropped_triangles, solid)


def closed_solid_triangles(vertices, triangles, tol=1e-7):
    """(T,) bool: triangles of connected components that are closed and consistently
    oriented (every directed edge u->v has exactly one twin v->u).  Such components
    bound solids; what lies inside them can never receive light.  Vertices closer
    than ``tol`` times the scene size are welded first.  After :func:`subdivide`
    (T-junctions) use the flags computed before it.
    """
    t = np.asarray(triangles, np.int64)
    if len(t) == 0:
        return np.zeros(0, bool)
    v = np.asarray(vertices, float)
    scale = max(float(np.abs(v).max()), 1e-12) * tol
    _, weld = np.unique(np.round(v / scale).astype(np.int64), axis=0, return_inverse=True)
    t = weld.reshape(-1)[t]
    nv = int(t.max()) + 1
    a, b = t.ravel(), np.roll(t, -1, axis=1).ravel()        # directed edges a->b, 3 per triangle
    key, rev = a * nv + b, b * nv + a
    uniq, inv, count = np.unique(key, return_inverse=True, return_counts=True)
    pos = np.clip(np.searchsorted(uniq, rev), 0, len(uniq) - 1)
    twin = (uniq[pos] == rev)
    ok_edge = (count[inv.reshape(-1)] == 1) & twin & (count[pos] == 1)
    tri_ok = ok_edge.reshape(-1, 3).all(axis=1)
    # connected components over shared (undirected) edges, by min-label propagation
    und = np.minimum(a, b) * nv + np.maximum(a, b)
    order = np.argsort(und, kind="stable")
    same = und[order][1:] == und[order][:-1]
    e1, e2 = order[:-1][same] // 3, order[1:][same] // 3
    label = np.arange(len(t))
    while True:
        m = np.minimum(label[e1], label[e2])
        new = label.copy()
        np.minimum.at(new, e1, m)
        np.minimum.at(new, e2, m)
        new = new[new]
        if np.array_equal(new, label):
            break
        label = new
    bad = np.bincount(label, ~tri_ok, minlength=len(t)) > 0
    return ~bad[label]
