"""Patch scenes: triangles grouped into patches (the finite elements), materials,
point lights and a camera; validation, subdivision and the ``.npz`` exchange format.

A *patch* is the unit of the finite-element solution.  After :func:`subdivide`
every triangle is its own patch.  The front of a triangle is where its normal
``n = normalize((v1 - v0) x (v2 - v0))`` points.

Sides.  A triangle is *one-sided* (the back is a black absorber that emits
nothing: the core's built-in scenes, and ``.npz`` files that do not say
otherwise) or *two-sided* (Blender's semantics, the add-on's export: both sides
shade with the same material and an emitter glows on both sides).  Each side of
a patch that can be lit is a *side* with its own incoming-radiance variable:
side ``p`` is the front of patch ``p``, side ``n_patches + k`` the back of the
k-th two-sided patch.  The side a ray meets is chosen by the ray's direction
against the face normal (:meth:`PatchScene.side_facing`).  Per-triangle sides
(*tsides*, numbered the same way over triangles) carry what is per triangle:
open area, first-shot samples, interpolation.  A side that no light reaches
costs memory and nothing else.
"""
from __future__ import annotations

import warnings
from dataclasses import dataclass, field
from functools import cached_property

import numpy as np

from .camera import Camera
from .materials import MaterialTable

NPZ_FORMAT_VERSION = 2
#: corners of triangles whose normals differ by less than this weld (:attr:`PatchScene.smooth_vertex_ids`;
#: Blender's default Auto Smooth angle)
SMOOTH_ANGLE = np.radians(30.0)


def unique_rows(a):
    """``np.unique(a, axis=0, return_index=True, return_inverse=True)[1:]`` for an integer
    array (N, K), by one lexsort (np.unique sorts the rows as opaque bytes: ~10 times
    slower on millions of rows).  Returns ``(first, inverse)``: the first row of each
    distinct value (in the lexicographic order of the values) and each row's value id."""
    a = np.asarray(a)
    if len(a) == 0:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    order = np.lexsort(a.T[::-1])
    s = a[order]
    new = np.ones(len(a), bool)
    new[1:] = np.any(s[1:] != s[:-1], axis=1)
    inverse = np.empty(len(a), np.int64)
    inverse[order] = np.cumsum(new) - 1
    return order[new], inverse


def group_ids(columns):
    """Dense ids (N,) of the distinct rows of integer ``columns`` (a list of (N,) arrays):
    one 1-D sort of a mixed-radix key when it fits in 63 bits, else :func:`unique_rows`."""
    cols = [np.asarray(c, np.int64) - np.min(c) for c in columns]
    spans = [int(c.max()) + 1 for c in cols]
    if np.prod([float(s) for s in spans]) < 2.0 ** 62:
        key = np.zeros(len(cols[0]), np.int64)
        for c, s in zip(cols, spans):
            key = key * s + c
        return np.unique(key, return_inverse=True)[1].reshape(-1)
    return unique_rows(np.stack(cols, axis=1))[1]


def connected_components(n, links):
    """Dense component ids (n,) of n nodes joined by ``links`` (K, 2): min-label propagation
    with pointer jumping (targets sorted once; each round one reduceat)."""
    label = np.arange(n)
    if len(links) == 0:
        return label
    src = np.concatenate([links[:, 0], links[:, 1]])
    dst = np.concatenate([links[:, 1], links[:, 0]])
    order = np.argsort(dst, kind="stable")
    src, dst = src[order], dst[order]
    start = np.flatnonzero(np.r_[True, dst[1:] != dst[:-1]])
    target = dst[start]
    while True:
        new = label.copy()
        new[target] = np.minimum(new[target], np.minimum.reduceat(label[src], start))
        new = new[new]
        if np.array_equal(new, label):
            break
        label = new
    return np.unique(label, return_inverse=True)[1].reshape(-1)


class SceneError(ValueError):
    """A scene that cannot be rendered; the message says why and what to do."""


def _rows(a, n, width, default=0.0, what="lights"):
    """``a`` as an (n, width) (or (n,) when width is 0) float array, or ``default`` filled."""
    shape = (n, width) if width else (n,)
    if a is None:
        return np.full(shape, default, float)
    try:
        return np.asarray(a, float).reshape(shape)
    except ValueError:
        raise SceneError(f"{what}: an array of shape {np.shape(a)} where {shape} is needed "
                         "(one row per light)") from None


@dataclass
class PointLights:
    """Point and spot lights.

    ``position`` (L, 3) [m], ``intensity`` (L, 3) [W/sr] per channel;
    ``spot_direction`` (L, 3) the unit axis the light travels along (zeros: a
    point light, the same in every direction); ``spot_cos_half_angle`` (L,)
    cos(spot_size / 2); ``spot_blend`` (L,) Blender's blend in [0, 1];
    ``radius`` (L,) Blender's ``shadow_soft_size`` [m] (soft shadows; 0 = ideal point).

    Blender's point or spot light of power P [W] has I = P / (4 pi) W/sr; the
    cone does not renormalise it (``blender.md`` §4.4).  A spot's intensity
    towards ``w`` is ``I * smoothstep((w.axis - cos_half) / ((1 - cos_half) * blend))``,
    Cycles' spot attenuation (``smoothstep(x) = 3x^2 - 2x^3`` on [0, 1]).
    """

    position: np.ndarray = None
    intensity: np.ndarray = None
    spot_direction: np.ndarray = None
    spot_cos_half_angle: np.ndarray = None
    spot_blend: np.ndarray = None
    radius: np.ndarray = None

    def __post_init__(self):
        self.position = _rows(np.zeros((0, 3)) if self.position is None else self.position, -1, 3, what="point lights")
        n = len(self.position)
        self.intensity = _rows(self.intensity, n, 3, what="point lights")
        self.spot_direction = _rows(self.spot_direction, n, 3, what="point lights")
        self.spot_cos_half_angle = _rows(self.spot_cos_half_angle, n, 0, -1.0, what="point lights")
        self.spot_blend = _rows(self.spot_blend, n, 0, what="point lights")
        self.radius = _rows(self.radius, n, 0, what="point lights")

    def __len__(self):
        return len(self.position)

    def spot_factor(self, k, travel):
        """(N,) Cycles' spot attenuation of light ``k`` for light travelling along ``travel`` (N, 3)."""
        axis = self.spot_direction[k]
        if not np.any(axis):
            return np.ones(len(travel))
        c = self.spot_cos_half_angle[k]
        x = travel @ axis - c
        width = (1.0 - c) * self.spot_blend[k]
        if width <= 0:
            return (x > 0).astype(float)
        t = np.clip(x / width, 0.0, 1.0)
        return t * t * (3.0 - 2.0 * t)

    def to_arrays(self, prefix="point_light_"):
        return {prefix + k: getattr(self, k) for k in
                ("position", "intensity", "spot_direction", "spot_cos_half_angle", "spot_blend", "radius")}

    @classmethod
    def from_arrays(cls, d, prefix="point_light_"):
        return cls(**{k: d.get(prefix + k) for k in
                      ("position", "intensity", "spot_direction", "spot_cos_half_angle", "spot_blend", "radius")})


@dataclass
class SunLights:
    """Distant lights: ``direction`` (L, 3) unit travel direction of the light,
    ``irradiance`` (L, 3) [W/m^2] on a plane facing the light (Blender's sun
    strength times color), ``angle`` (L,) angular diameter [rad] (soft shadows)."""

    direction: np.ndarray = None
    irradiance: np.ndarray = None
    angle: np.ndarray = None

    def __post_init__(self):
        self.direction = _rows(np.zeros((0, 3)) if self.direction is None else self.direction, -1, 3, what="sun lights")
        n = len(self.direction)
        self.irradiance = _rows(self.irradiance, n, 3, what="sun lights")
        self.angle = _rows(self.angle, n, 0, what="sun lights")

    def __len__(self):
        return len(self.direction)

    def to_arrays(self, prefix="sun_light_"):
        return {prefix + k: getattr(self, k) for k in ("direction", "irradiance", "angle")}

    @classmethod
    def from_arrays(cls, d, prefix="sun_light_"):
        return cls(**{k: d.get(prefix + k) for k in ("direction", "irradiance", "angle")})


@dataclass
class AreaLights:
    """Blender area lights: flat one-sided Lambertian emitters that are not geometry
    (they never occlude and the camera does not see them).

    ``center`` (L, 3) [m]; ``axis_u``, ``axis_v`` (L, 3) half-extent vectors along
    the light's local X and Y [m]; ``normal`` (L, 3) the emitting direction
    (Blender: local -Z); ``shape`` (L,) 0 = rectangle, 1 = ellipse;
    ``radiance`` (L, 3) [W m^-2 sr^-1].  Blender's area light of power P has
    L = P / (pi A) with A = 4 |u| |v| (rectangle) or pi |u| |v| (ellipse).
    """

    center: np.ndarray = None
    axis_u: np.ndarray = None
    axis_v: np.ndarray = None
    normal: np.ndarray = None
    shape: np.ndarray = None
    radiance: np.ndarray = None

    def __post_init__(self):
        self.center = _rows(np.zeros((0, 3)) if self.center is None else self.center, -1, 3, what="area lights")
        n = len(self.center)
        self.axis_u = _rows(self.axis_u, n, 3, what="area lights")
        self.axis_v = _rows(self.axis_v, n, 3, what="area lights")
        self.normal = _rows(self.normal, n, 3, what="area lights")
        self.shape = _rows(self.shape, n, 0, what="area lights").astype(np.int64)
        self.radiance = _rows(self.radiance, n, 3, what="area lights")

    def __len__(self):
        return len(self.center)

    @property
    def area(self):
        """(L,) [m^2]."""
        uv = np.linalg.norm(self.axis_u, axis=1) * np.linalg.norm(self.axis_v, axis=1)
        return np.where(self.shape == 1, np.pi * uv, 4.0 * uv)

    def to_arrays(self, prefix="area_light_"):
        return {prefix + k: getattr(self, k) for k in ("center", "axis_u", "axis_v", "normal", "shape", "radiance")}

    @classmethod
    def from_arrays(cls, d, prefix="area_light_"):
        return cls(**{k: d.get(prefix + k) for k in ("center", "axis_u", "axis_v", "normal", "shape", "radiance")})


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
    dropped_triangles : int  zero-area and repeated triangles removed at validation
        (:func:`coincident_triangles`)
    triangle_solid : (T,) bool  the triangle belongs to a closed, consistently
        oriented one-sided mesh (a solid: its inside is behind the black backs),
        see :func:`closed_solid_triangles`.  Two-sided meshes are never solids
        (a closed two-sided mesh may be a room seen from inside).
    triangle_two_sided : (T,) bool  both sides shade and emit (module docstring)
    sun_lights, area_lights : SunLights, AreaLights
    environment : (3,) float  constant radiance of the world around the scene
        [W m^-2 sr^-1] (Blender's world color times strength)
    triangle_corner_tag : (T, 3) int or None  weld tags of corners on contact
        lines (:mod:`raybundle.contacts`); corners weld only when their tags agree
    texture : :class:`~raybundle.textures.SurfaceTexture` or None  image textures on
        the diffuse albedo of the input faces (kept through subdivision)
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
    triangle_two_sided: np.ndarray | None = None
    sun_lights: SunLights = field(default_factory=SunLights)
    area_lights: AreaLights = field(default_factory=AreaLights)
    environment: np.ndarray | None = None
    triangle_corner_tag: np.ndarray | None = None
    texture: object = None

    def __post_init__(self):
        if self.triangle_two_sided is None:
            self.triangle_two_sided = np.zeros(len(self.triangles), bool)
        if self.triangle_solid is None:
            self.triangle_solid = closed_solid_triangles(self.vertices, self.triangles) & ~self.triangle_two_sided
        self.environment = np.zeros(3) if self.environment is None else np.asarray(self.environment, float)

    def release_caches(self):
        """Forget the derived arrays (corners, normals, areas, sides...): they are made again
        when asked for.  A scene kept only for its input arrays (an export whose prepared copy
        renders) then holds no more than those."""
        for name, attr in type(self).__dict__.items():
            if isinstance(attr, cached_property):
                self.__dict__.pop(name, None)

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
        """(TS, 3) int: tside corners welded where the surface is smooth, for interpolating
        side values across it without bleeding over a crease, from one side of a surface to
        the other, or across a contact line.  Corners at one position weld when their tsides
        have the same normal and contact weld tag (a plane, T-junctions included), and when
        their tsides share an edge across which the normal turns by less than
        :data:`SMOOTH_ANGLE` (tags agreeing): a tessellated sphere (or the clusters of its
        triangles, :mod:`raybundle.clusters`) is one smooth surface, a box's edges are creases."""
        _, r = self.bounding_sphere
        _, position = unique_rows(np.round(self.vertices / max(r * 1e-6, 1e-12)).astype(np.int64))
        pos = position[self.triangles[self.tside_triangle]]                    # (TS, 3)
        _, normal = unique_rows(np.round(self.tside_normal * 1e3).astype(np.int64))
        tag = self.triangle_corner_tag[self.tside_triangle] if self.triangle_corner_tag is not None else None
        cls = group_ids([pos.ravel(), np.repeat(normal, 3)] + ([] if tag is None else [tag.ravel()])).reshape(-1, 3)
        # tsides sharing an edge: its two end positions (sorted) as one key per tside edge
        # (flat index 3 t + k: tside t's edge from corner k to corner k + 1); consecutive
        # entries of one key are neighbours across it
        n_pos = int(position.max(initial=0)) + 1
        key = np.empty(pos.size, np.int64)
        for k in range(3):
            a, b = pos[:, k], pos[:, (k + 1) % 3]
            key[k::3] = np.minimum(a, b) * n_pos + np.maximum(a, b)
        order = np.argsort(key, kind="stable")
        key = key[order]
        same = np.flatnonzero(key[1:] == key[:-1])
        del key
        e1, e2 = order[same], order[same + 1]
        del order, same
        # tsides of one normal are welded already (same class at each shared position)
        turn = normal[e1 // 3] != normal[e2 // 3]
        e1, e2 = e1[turn], e2[turn]
        t1, k1 = np.divmod(e1, 3)
        t2, k2 = np.divmod(e2, 3)
        smooth = np.einsum("ij,ij->i", self.tside_normal[t1], self.tside_normal[t2]) > np.cos(SMOOTH_ANGLE)
        t1, k1, t2, k2 = t1[smooth], k1[smooth], t2[smooth], k2[smooth]
        # the corner of t2 at the position of t1's corner k1, and the other end
        flip = pos[t2, k2] != pos[t1, k1]
        c2a = np.where(flip, (k2 + 1) % 3, k2)
        c2b = np.where(flip, k2, (k2 + 1) % 3)
        links = []
        for c1, c2 in ((k1, c2a), ((k1 + 1) % 3, c2b)):
            ok = np.ones(len(t1), bool) if tag is None else tag[t1, c1] == tag[t2, c2]
            links.append(np.stack([cls[t1[ok], c1[ok]], cls[t2[ok], c2[ok]]], axis=1))
        return connected_components(int(cls.max(initial=-1)) + 1, np.concatenate(links))[cls]

    # ---------------------------------------------------------------- sides
    @cached_property
    def patch_two_sided(self):
        """(P,) bool: the patch's triangles are two-sided."""
        return np.bincount(self.triangle_patch, self.triangle_two_sided, minlength=self.n_patches) > 0

    @cached_property
    def patch_back_side(self):
        """(P,) int: the side id of each patch's back, -1 for one-sided patches."""
        two = self.patch_two_sided
        back = np.full(self.n_patches, -1, np.int64)
        back[two] = self.n_patches + np.arange(int(two.sum()))
        return back

    @property
    def n_sides(self):
        return self.n_patches + int(self.patch_two_sided.sum())

    @cached_property
    def side_patch(self):
        """(S,) int: the patch each side belongs to."""
        return np.concatenate([np.arange(self.n_patches), np.nonzero(self.patch_two_sided)[0]])

    @cached_property
    def side_normal(self):
        """(S, 3) float: unit normal of each side (the patch normal, negated for backs)."""
        sign = np.where(np.arange(self.n_sides) < self.n_patches, 1.0, -1.0)
        return self.patch_normal[self.side_patch] * sign[:, None]

    @cached_property
    def side_material(self):
        return self.patch_material[self.side_patch]

    @cached_property
    def triangle_back_tside(self):
        """(T,) int: the tside id of each triangle's back, -1 for one-sided triangles."""
        two = self.triangle_two_sided
        back = np.full(len(self.triangles), -1, np.int64)
        back[two] = len(self.triangles) + np.arange(int(two.sum()))
        return back

    @cached_property
    def tside_triangle(self):
        """(TS,) int: the triangle of each triangle side (tside)."""
        return np.concatenate([np.arange(len(self.triangles)), np.nonzero(self.triangle_two_sided)[0]])

    @cached_property
    def tside_normal(self):
        """(TS, 3) float: unit normal of each tside."""
        sign = np.where(np.arange(len(self.tside_triangle)) < len(self.triangles), 1.0, -1.0)
        return self.triangle_normal[self.tside_triangle] * sign[:, None]

    @cached_property
    def tside_side(self):
        """(TS,) int: the (patch) side each tside belongs to."""
        t = self.tside_triangle
        p = self.triangle_patch[t]
        return np.where(np.arange(len(t)) < len(self.triangles), p, self.patch_back_side[p])

    def tside_samples(self, k):
        """(TS,) sample counts per tside that give each side about ``k`` in all, shared by
        area: ``clip(ceil(k A_t / A_side), 1, k)`` (``k`` each for one-triangle patches; one
        each for the small triangles of a cluster, :mod:`raybundle.clusters`)."""
        a = self.triangle_area[self.tside_triangle]
        side_area = np.bincount(self.tside_side, a, minlength=self.n_sides)[self.tside_side]
        return np.clip(np.ceil(k * a / side_area - 1e-9), 1, k).astype(np.int64)

    def tside_facing(self, triangle, direction):
        """(N,) tside ids of ``triangle`` (N,) whose normal has a positive dot product
        with ``direction`` ((3,) or (N, 3)); -1 where that is the black back of a
        one-sided triangle or the direction lies in the triangle's plane."""
        n = self.triangle_normal[triangle]
        nd = n @ direction if np.ndim(direction) == 1 else np.einsum("ij,ij->i", n, direction)
        ts = np.where(nd > 0, triangle, self.triangle_back_tside[triangle])
        return np.where(nd != 0, ts, -1)

    def side_facing(self, triangle, direction):
        """(N,) side ids of ``triangle`` facing ``direction`` (see :meth:`tside_facing`), -1 for none."""
        ts = self.tside_facing(triangle, direction)
        return np.where(ts >= 0, self.tside_side[np.maximum(ts, 0)], -1)

    def seen_tside(self, triangle, ray_direction):
        """(N,) the tside a ray travelling along ``ray_direction`` meets on ``triangle``.
        The back of a one-sided triangle maps to its front (whose normal then faces
        away from the ray: it reflects and emits nothing towards it)."""
        ts = self.tside_facing(triangle, -np.asarray(ray_direction, float))
        return np.where(ts >= 0, ts, triangle)

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
             "triangle_two_sided": self.triangle_two_sided, "environment": self.environment}
        d.update(self.point_lights.to_arrays())
        d.update(self.sun_lights.to_arrays())
        d.update(self.area_lights.to_arrays())
        d.update(self.materials.to_arrays())
        if self.camera is not None:
            d.update(self.camera.to_arrays())
        if self.analytic_radiance is not None:
            d["analytic_radiance"] = np.asarray(self.analytic_radiance, float)
        if self.texture is not None:
            d.update(self.texture.to_arrays())
        with atomic_path(path) as tmp:
            with open(tmp, "wb") as f:
                np.savez_compressed(f, **d)


def load_npz(path) -> PatchScene:
    """Read a scene written by :meth:`PatchScene.save_npz` (or by the add-on) and validate it.

    Required arrays: ``vertices`` (V,3), ``triangles`` (T,3), ``triangle_material`` (T,)
    and the ``material_*`` table; ``triangle_patch``, ``triangle_source``,
    ``triangle_two_sided`` (T,) bool (absent: one-sided, as files of format 1),
    ``point_light_*``, ``sun_light_*``, ``area_light_*``, ``environment`` (3,),
    ``camera_*``, ``analytic_radiance`` and the ``texture_*`` arrays
    (:meth:`~raybundle.textures.SurfaceTexture.to_arrays`) are optional.  A file that
    cannot be read or holds malformed arrays raises :class:`SceneError` (one line).
    """
    import zipfile

    try:
        # our own file object: np.load leaks the one it opens when the zip is broken
        with open(path, "rb") as f, np.load(f, allow_pickle=False) as z:
            d = {k: z[k] for k in z.files}
    except FileNotFoundError:
        raise SceneError(f"{path}: no such file") from None
    except (OSError, ValueError, EOFError, zipfile.BadZipFile, KeyError, TypeError) as e:
        raise SceneError(f"cannot read scene file {path}: {str(e) or type(e).__name__} (empty, truncated "
                         "or not an .npz file)") from None
    try:
        return _scene_from_arrays(path, d)
    except SceneError:
        raise
    except (ValueError, TypeError, IndexError, KeyError, AttributeError) as e:
        raise SceneError(f"{path}: malformed scene file ({type(e).__name__}: {e})") from None


def _scene_from_arrays(path, d):
    """:func:`load_npz`'s scene from the file's arrays ``d``."""
    from .textures import SurfaceTexture

    missing = [k for k in ("vertices", "triangles", "triangle_material", "material_names", "material_diffuse",
                           "material_glossy", "material_roughness", "material_glossy_weight", "material_emission")
               if k not in d]
    if missing:
        raise SceneError(f"{path}: not a raybundle scene (missing arrays {missing})")
    version = int(d.get("format_version", NPZ_FORMAT_VERSION))
    if version > NPZ_FORMAT_VERSION:
        raise SceneError(f"{path}: format version {version} is newer than this raybundle supports")
    lights = (PointLights.from_arrays(d), SunLights.from_arrays(d), AreaLights.from_arrays(d))
    return build_scene(d["vertices"], d["triangles"], d["triangle_material"],
                       MaterialTable.from_arrays(d), point_lights=lights[0], sun_lights=lights[1],
                       area_lights=lights[2], environment=d.get("environment"),
                       camera=Camera.from_arrays(d), triangle_patch=d.get("triangle_patch"),
                       triangle_source=d.get("triangle_source"), triangle_solid=d.get("triangle_solid"),
                       two_sided=d.get("triangle_two_sided", False),
                       analytic_radiance=d.get("analytic_radiance"), name=str(d.get("name", "")),
                       texture=SurfaceTexture.from_arrays(d))


def build_scene(vertices, triangles, triangle_material, materials, point_lights=None, camera=None,
                triangle_patch=None, triangle_source=None, analytic_radiance=None, name="",
                area_epsilon=1e-14, triangle_solid=None, two_sided=False,
                sun_lights=None, area_lights=None, environment=None, texture=None) -> PatchScene:
    """Validate raw triangles and make a :class:`PatchScene`.

    ``texture``: a :class:`~raybundle.textures.SurfaceTexture` whose faces are the
    input triangles (indexed like ``triangle_source``).

    ``two_sided``: bool or (T,) bool, Blender's semantics when true (module
    docstring); the default, one-sided, is the core's own convention.
    Errors (:class:`SceneError`): non-finite vertices, bad indices, an empty
    scene, no light at all (no emitter, light or environment), invalid
    materials (albedo > 1, NaN...) or lights.  Zero-area triangles (area <=
    ``area_epsilon`` m^2) are dropped and counted in ``dropped_triangles`` (a
    warning is issued).  Without ``triangle_patch`` each triangle is its own patch.
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
    two = np.broadcast_to(np.asarray(two_sided, bool), (len(t),)) if np.ndim(two_sided) == 0 \
        else np.asarray(two_sided, bool).reshape(-1)
    for label, arr in (("triangle_source", src), ("triangle_patch", patch), ("triangle_solid", triangle_solid),
                       ("two_sided", two)):
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
    t, m, src, two = t[keep], m[keep], src[keep], np.array(two[keep])
    single, merge = coincident_triangles(v, t, m, two, merge=patch is None)
    if not single.all() or merge.any():
        warnings.warn(f"dropped {int((~single).sum())} triangles that repeat another's corners (they would "
                      f"z-fight); {int(merge.sum())} one-sided triangles with a reversed copy became two-sided",
                      stacklevel=2)
        two[merge] = True
        dropped += int((~single).sum())
        keep[np.nonzero(keep)[0][~single]] = False
        t, m, src, two = t[single], m[single], src[single], two[single]
    if patch is None:
        patch = np.arange(len(t))
    else:
        patch = np.unique(patch[keep], return_inverse=True)[1].reshape(-1)  # renumber densely
        _check_patches(v, t, m, patch, two)
    point_lights = PointLights() if point_lights is None else PointLights(**vars(point_lights))
    sun_lights = SunLights() if sun_lights is None else SunLights(**vars(sun_lights))
    area_lights = AreaLights() if area_lights is None else AreaLights(**vars(area_lights))
    _check_lights(point_lights, sun_lights, area_lights)
    env = np.zeros(3) if environment is None else np.broadcast_to(np.asarray(environment, float), (3,)).copy()
    if not np.isfinite(env).all() or (env < 0).any():
        raise SceneError(f"the environment (world) radiance must be finite and non-negative, got {env.tolist()}")
    has_emitter = materials.is_emitter[np.unique(m)].any()
    has_light = any((np.asarray(x) > 0).any() for x in (point_lights.intensity, sun_lights.irradiance,
                                                       area_lights.radiance, env))
    if not has_emitter and not has_light:
        raise SceneError("the scene has no lights: no emitting material, no light and a black world "
                         "(add an Emission shader, a light or a world color)")
    ar = None if analytic_radiance is None else np.asarray(analytic_radiance, float).reshape(3)
    solid = None if triangle_solid is None else np.asarray(triangle_solid, bool).reshape(-1)[keep] & ~two
    return PatchScene(v, t, m, patch, src, materials, point_lights, camera, ar, name, dropped, solid,
                      two, sun_lights, area_lights, env, texture=texture)


def coincident_triangles(v, t, m, two_sided, merge=True):
    """Triangles with the same three corner positions as another (duplicated faces).

    Along a bundle line, hits closer than the tracer's ``eps`` are one surface: only one of
    two coincident triangles takes part in each line's transfer, so a duplicated face
    receives on about half of its lines (a furnace's duplicated block came out 35% dark),
    and for a one-sided face with a reversed copy behind it (a sheet seen from both sides),
    eye rays and bundle lines meet the black back half of the time (half the sheet black,
    in the path tracer too).  Returns ``(keep (T,) bool, make_two_sided (T,) bool)``: of
    each group of coincident triangles the first is kept, and later copies are dropped
    where they add nothing: a same-facing copy of a one-sided triangle, any copy of a
    two-sided one; a reversed one-sided copy of the same material makes the first
    two-sided (``merge``; a reversed copy of another material stays, as it would in
    Blender, and z-fights).  Positions are compared to 1e-9 of the scene's extent."""
    keep = np.ones(len(t), bool)
    make_two = np.zeros(len(t), bool)
    c = v[t]
    scale = max(float(np.ptp(v, axis=0).max()), 1e-300) * 1e-9
    q = np.round(c / scale).astype(np.int64)                               # (T, 3, 3) integer corners
    # candidates: an order-free hash of the corners (int64 arithmetic wraps) met more than once
    with np.errstate(over="ignore"):
        h = q.sum(axis=1) @ np.array([0x9E3779B97F4A7C15 - (1 << 64), 0xC2B2AE3D27D4EB4F - (1 << 64),
                                      0x165667B19E3779F9], np.int64)
    hs = np.sort(h)
    repeated = hs[1:][hs[1:] == hs[:-1]]
    cand = np.nonzero(np.isin(h, repeated))[0]
    if not len(cand):
        return keep, make_two
    # exact check: the candidates' corners sorted, as one row each
    flat = q[cand].reshape(-1, 3)
    tri = np.repeat(np.arange(len(cand)), 3)
    key = flat[np.lexsort((flat[:, 2], flat[:, 1], flat[:, 0], tri))].reshape(len(cand), 9)
    _, group = unique_rows(key)
    n = np.cross(c[cand, 1] - c[cand, 0], c[cand, 2] - c[cand, 0])
    axis = np.argmax(np.abs(n) > 1e-9 * np.abs(n).max(axis=1, keepdims=True), axis=1)
    facing = n[np.arange(len(cand)), axis] > 0                           # orientation against a canonical normal
    # each group's first triangle is its head; the others are dropped where they add nothing
    order = np.argsort(group, kind="stable")
    g = group[order]
    start = np.ones(len(g), bool)
    start[1:] = g[1:] != g[:-1]
    head_pos = np.maximum.accumulate(np.where(start, np.arange(len(g)), 0))
    k, head = cand[order], cand[order][head_pos]
    f_k, f_head = facing[order], facing[order][head_pos]
    later = ~start
    merged = later & ~two_sided[head] & (m[k] == m[head]) & merge & (two_sided[k] | (f_k != f_head))
    drop = later & (two_sided[head] | merged | ((f_k == f_head) & ~two_sided[k]))
    keep[k[drop]] = False
    make_two[head[merged]] = True
    make_two &= ~two_sided
    return keep, make_two


def _check_lights(point, sun, area):
    """Lights must be finite, non-negative, and have usable directions and sizes."""
    for label, group in (("point/spot", point), ("sun", sun), ("area", area)):
        for k, a in vars(group).items():
            a = np.asarray(a, float)
            if not np.isfinite(a).all():
                raise SceneError(f"{label} light {k} has non-finite values")
    if (point.intensity < 0).any() or (point.radius < 0).any() or (sun.irradiance < 0).any() \
            or (sun.angle < 0).any() or (area.radiance < 0).any():
        raise SceneError("light intensities, irradiances, radiances and sizes must be non-negative")
    for label, dirs, live in (("sun", sun.direction, np.ones(len(sun), bool)),
                              ("area light", area.normal, np.ones(len(area), bool)),
                              ("spot", point.spot_direction, np.any(point.spot_direction != 0, axis=1))):
        norm = np.linalg.norm(dirs, axis=1)
        if np.any(live & (np.abs(norm - 1) > 1e-3)):
            raise SceneError(f"{label} directions must be unit vectors")
    if len(area) and np.any(area.area <= 0):
        raise SceneError("an area light has zero size")


def _check_patches(v, t, m, patch, two_sided):
    """A patch must have one material and one sidedness (one variable per side), and
    its triangles must face within 60 degrees of its mean normal (a cluster,
    :mod:`raybundle.clusters`; a patch whose sides face opposite ways has no side)."""
    n_p = int(patch.max()) + 1
    first = np.full(n_p, -1)
    first[patch[::-1]] = np.arange(len(patch))[::-1]
    if np.any(m != m[first[patch]]):
        raise SceneError("a patch mixes materials: give each patch triangles of one material")
    if np.any(two_sided != two_sided[first[patch]]):
        raise SceneError("a patch mixes one-sided and two-sided triangles")
    c = v[t]
    cross = np.cross(c[:, 1] - c[:, 0], c[:, 2] - c[:, 0])
    mean = np.stack([np.bincount(patch, cross[:, k], minlength=n_p) for k in range(3)], axis=1)
    mean /= np.maximum(np.linalg.norm(mean, axis=1, keepdims=True), 1e-300)
    n = cross / np.linalg.norm(cross, axis=1, keepdims=True)
    if np.any(np.einsum("ij,ij->i", n, mean[patch]) < 0.5):
        raise SceneError("a patch mixes triangles that face more than 60 degrees from its mean normal: "
                         "split it (patches may be curved, not folded)")


#: scenes with at most this many reflecting patch triangles have every one cut at contacts,
#: larger ones only their subdivided faces (:func:`subdivide`)
CONTACT_ALL_MAX = 10_000


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
    lines where other surfaces touch or cross them, gaps narrower than 5% of
    ``max_edge`` counting as contact (:mod:`raybundle.contacts`).
    (:func:`raybundle.clusters.make_patches` also groups triangles much smaller than a patch.)
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
    verts, tris, mats, srcs = [scene.vertices], [], [], []
    base = len(scene.vertices)
    for k in np.unique(k_all):
        sel = np.nonzero(k_all == k)[0]
        mats.append(np.repeat(scene.triangle_material[sel], k * k))
        srcs.append(np.repeat(scene.triangle_source[sel], k * k))
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
    v = np.concatenate(verts)
    t = np.concatenate(tris)
    # weld coincident vertices so that triangles of one face share corners
    _, r = scene.bounding_sphere
    # (a vertex no triangle uses may be NaN: build_scene checks only those in use)
    q = np.round(np.where(np.isfinite(v), v, 0.0) / max(r * 1e-7, 1e-12)).astype(np.int64)
    first, inv = unique_rows(q)
    used, t = np.unique(inv[t], return_inverse=True)     # only the corners in use
    v, t = v[first[used]], t.reshape(-1, 3)
    per_tri = [np.concatenate([np.repeat(a[np.nonzero(k_all == k)[0]], k * k) for k in np.unique(k_all)])
               for a in (scene.triangle_solid, scene.triangle_two_sided, k_all, np.arange(len(k_all)))]
    fine = PatchScene(v, t, np.concatenate(mats), np.arange(len(t)), np.concatenate(srcs),
                      scene.materials, scene.point_lights, scene.camera, scene.analytic_radiance,
                      scene.name, scene.dropped_triangles, *per_tri[:2], scene.sun_lights, scene.area_lights,
                      scene.environment, texture=scene.texture)
    return fine, per_tri[2], per_tri[3]


def cut_at_contacts(scene: PatchScene, cut, max_edge, tracer=None) -> PatchScene:
    """The patches of triangles ``cut`` (the pieces of subdivided faces) cut along contact
    lines (:mod:`raybundle.contacts`, gaps under 5% of ``max_edge`` count as contact); so is
    every reflecting triangle when there are at most :data:`CONTACT_ALL_MAX` of them, and
    beyond that every one that straddles such a gap (:func:`~raybundle.contacts.straddling`,
    probed with ``tracer``, a :class:`~raybundle.visibility.RayTracer` over ``scene``, or
    one built here)."""
    from .contacts import CONTACT_SHARE, split_at_contacts, straddling
    # faces the user meshed finer than the patches are cut too: a ceiling cut into a grid over
    # a lamp hanging under it must still trap the lamp's upper light.  Up to CONTACT_ALL_MAX
    # triangles all of them (crossings too: a post through a floor); beyond, the cut is a
    # per-triangle loop (~0.5 ms a triangle), so only those found straddling a gap.
    tol = CONTACT_SHARE * max_edge
    todo = np.zeros(len(scene.triangles), bool)
    todo[np.asarray(cut, np.int64)] = True
    reflects = scene.materials.reflects[scene.triangle_material]
    if reflects.sum() <= CONTACT_ALL_MAX:
        todo |= reflects
    else:
        rest = np.nonzero(reflects & ~todo)[0]
        if len(rest):
            from .visibility import RayTracer
            probe = tracer if tracer is not None else RayTracer(scene)
            try:
                todo[rest[straddling(probe, scene, rest, tol)]] = True
            finally:
                if probe is not tracer:
                    probe.close()
    return split_at_contacts(scene, np.nonzero(todo)[0], tol=tol)[0]


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
    _, weld = unique_rows(np.round(v / scale).astype(np.int64))
    t = weld.reshape(-1)[t]
    nv = int(t.max()) + 1
    a, b = t.ravel(), np.roll(t, -1, axis=1).ravel()        # directed edges a->b, 3 per triangle
    key, rev = a * nv + b, b * nv + a
    uniq, inv, count = np.unique(key, return_inverse=True, return_counts=True)
    pos = np.clip(np.searchsorted(uniq, rev), 0, len(uniq) - 1)
    twin = (uniq[pos] == rev)
    ok_edge = (count[inv.reshape(-1)] == 1) & twin & (count[pos] == 1)
    tri_ok = ok_edge.reshape(-1, 3).all(axis=1)
    # connected components over shared (undirected) edges
    und = np.minimum(a, b) * nv + np.maximum(a, b)
    order = np.argsort(und, kind="stable")
    same = und[order][1:] == und[order][:-1]
    label = connected_components(len(t), np.stack([order[:-1][same] // 3, order[1:][same] // 3], axis=1))
    bad = np.bincount(label, ~tri_ok, minlength=len(t)) > 0
    return ~bad[label]
