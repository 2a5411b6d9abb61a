"""The patch scene: triangles grouped into patches (the finite elements), their sides,
materials, lights as records, the world and a camera.

A *patch* is the unit of the finite-element solution (:mod:`raybundle.patches.layout` and
:mod:`raybundle.patches.clusters` lay them out).  The front of a triangle is where its normal
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

Lights that are not geometry are records here (:class:`PointLights`, :class:`SunLights`,
:class:`AreaLights`: arrays in Blender's units); :mod:`raybundle.lights.sources` samples them.
The scene is written and read as ``.npz`` (:meth:`PatchScene.save_npz`,
:func:`raybundle.scene.npz.load_npz`) and made from arrays by
:func:`raybundle.scene.build.build_scene`.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property

import numpy as np

from ..util.arrays import GatheredRows, connected_components, stable_order, unique_ints, unique_rows
from . import triangle_geometry
from .camera import Camera
from .materials import MaterialTable
from .transmission import pass_probability
from .world import World

NPZ_FORMAT_VERSION = 3


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
    ``radius`` (L,) Blender's ``shadow_soft_size`` [m] (soft shadows; 0 = ideal point);
    ``shadow`` (L,) 1 where the light casts shadows, 0 where nothing blocks its direct light
    (Blender's Cast Shadow off, ``Light.use_shadow``); ``link`` (L,) the light's link set
    (:mod:`raybundle.scene.linking`; 0: it lights everything and everything blocks it);
    ``profile`` (L,) the light's photometric profile in ``profiles`` (a list of
    :class:`~raybundle.scene.ies.Profile`; -1: none) and ``axes`` (L, 3, 3) its own frame (rows:
    its local X, Y and Z axes in the world, unit), in which the profile is looked up.

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
    shadow: np.ndarray = None
    link: np.ndarray = None
    profile: np.ndarray = None
    axes: np.ndarray = None
    profiles: list = None

    def __post_init__(self):
        self.position = _rows(np.zeros((0, 3)) if self.position is None else self.position, -1, 3, what="point lights")
        n = len(self.position)
        self.intensity = _rows(self.intensity, n, 3, what="point lights")
        self.spot_direction = _rows(self.spot_direction, n, 3, what="point lights")
        self.spot_cos_half_angle = _rows(self.spot_cos_half_angle, n, 0, -1.0, what="point lights")
        self.spot_blend = _rows(self.spot_blend, n, 0, what="point lights")
        self.radius = _rows(self.radius, n, 0, what="point lights")
        self.shadow = _rows(self.shadow, n, 0, 1.0, what="point lights")
        self.link = _rows(self.link, n, 0, what="point lights").astype(np.int64)
        self.profile = _rows(self.profile, n, 0, -1.0, what="point lights").astype(np.int64)
        self.axes = (np.tile(np.eye(3), (n, 1, 1)) if self.axes is None else
                     _rows(self.axes, n, 9, what="point lights").reshape(n, 3, 3))
        self.profiles = list(self.profiles or [])

    def __len__(self):
        return len(self.position)

    def spot_factor(self, k, travel):
        """(N,) the directional factor of light ``k`` (an index, or (N,) indices) for light
        travelling along ``travel`` (N, 3): Cycles' spot attenuation times the light's profile."""
        k = np.broadcast_to(k, len(travel))
        axis = self.spot_direction[k]
        c = self.spot_cos_half_angle[k]
        x = np.einsum("ij,ij->i", travel, axis) - c
        width = (1.0 - c) * self.spot_blend[k]
        t = np.clip(x / np.where(width > 0, width, 1.0), 0.0, 1.0)
        spot = np.where(width > 0, t * t * (3.0 - 2.0 * t), (x > 0).astype(float))
        out = np.where(np.any(axis != 0, axis=1), spot, 1.0)
        for p in np.unique(self.profile[k][self.profile[k] >= 0]):
            i = np.nonzero(self.profile[k] == p)[0]
            out[i] *= self.profiles[p].at(np.einsum("nij,nj->ni", self.axes[k[i]], travel[i]))
        return out

    def peak_factor(self, k):
        """An upper bound of light ``k``'s :meth:`spot_factor` (its profile's peak, or 1)."""
        p = int(self.profile[k])
        return 1.0 if p < 0 else self.profiles[p].peak

    def to_arrays(self, prefix="point_light_"):
        d = {prefix + k: getattr(self, k) for k in
             ("position", "intensity", "spot_direction", "spot_cos_half_angle", "spot_blend", "radius", "shadow",
              "link", "profile")}
        d[prefix + "axes"] = self.axes.reshape(-1, 9)
        if self.profiles:           # the profiles' grids one after another
            d[prefix + "profile_shapes"] = np.array([p.values.shape for p in self.profiles], np.int64)
            for part in ("h_angles", "v_angles", "values"):
                d[prefix + "profile_" + part] = np.concatenate([getattr(p, part).ravel() for p in self.profiles])
        return d

    @classmethod
    def from_arrays(cls, d, prefix="point_light_"):
        profiles = []
        if prefix + "profile_shapes" in d:
            from .ies import Profile

            at = np.zeros(3, np.int64)
            for nh, nv in np.asarray(d[prefix + "profile_shapes"], np.int64):
                h = d[prefix + "profile_h_angles"][at[0]:at[0] + nh]
                v = d[prefix + "profile_v_angles"][at[1]:at[1] + nv]
                profiles.append(Profile(h, v, d[prefix + "profile_values"][at[2]:at[2] + nh * nv]))
                at += (nh, nv, nh * nv)
        return cls(**{k: d.get(prefix + k) for k in
                      ("position", "intensity", "spot_direction", "spot_cos_half_angle", "spot_blend", "radius",
                       "shadow", "link", "profile", "axes")}, profiles=profiles)


@dataclass
class SunLights:
    """Distant lights: ``direction`` (L, 3) unit travel direction of the light,
    ``irradiance`` (L, 3) [W/m^2] on a plane facing the light (Blender's sun
    strength times color), ``angle`` (L,) angular diameter [rad] (soft shadows), ``shadow``
    and ``link`` (L,) as :class:`PointLights`'."""

    direction: np.ndarray = None
    irradiance: np.ndarray = None
    angle: np.ndarray = None
    shadow: np.ndarray = None
    link: np.ndarray = None

    def __post_init__(self):
        self.direction = _rows(np.zeros((0, 3)) if self.direction is None else self.direction, -1, 3, what="sun lights")
        n = len(self.direction)
        self.irradiance = _rows(self.irradiance, n, 3, what="sun lights")
        self.angle = _rows(self.angle, n, 0, what="sun lights")
        self.shadow = _rows(self.shadow, n, 0, 1.0, what="sun lights")
        self.link = _rows(self.link, n, 0, what="sun lights").astype(np.int64)

    def __len__(self):
        return len(self.direction)

    def to_arrays(self, prefix="sun_light_"):
        return {prefix + k: getattr(self, k) for k in ("direction", "irradiance", "angle", "shadow", "link")}

    @classmethod
    def from_arrays(cls, d, prefix="sun_light_"):
        return cls(**{k: d.get(prefix + k) for k in ("direction", "irradiance", "angle", "shadow", "link")})


_AREA_FIELDS = ("center", "axis_u", "axis_v", "normal", "shape", "radiance", "shadow", "link")


@dataclass
class AreaLights:
    """Blender area lights: flat one-sided Lambertian emitters that are not geometry
    (they never occlude and the camera does not see them).

    ``center`` (L, 3) [m]; ``axis_u``, ``axis_v`` (L, 3) half-extent vectors along
    the light's local X and Y [m]; ``normal`` (L, 3) the emitting direction
    (Blender: local -Z); ``shape`` (L,) 0 = rectangle, 1 = ellipse;
    ``radiance`` (L, 3) [W m^-2 sr^-1]; ``shadow`` and ``link`` (L,) as :class:`PointLights`'.  Blender's
    area light of power P has L = P / (pi A) with A = 4 |u| |v| (rectangle) or pi |u| |v| (ellipse).
    """

    center: np.ndarray = None
    axis_u: np.ndarray = None
    axis_v: np.ndarray = None
    normal: np.ndarray = None
    shape: np.ndarray = None
    radiance: np.ndarray = None
    shadow: np.ndarray = None
    link: np.ndarray = None

    def __post_init__(self):
        self.center = _rows(np.zeros((0, 3)) if self.center is None else self.center, -1, 3, what="area lights")
        n = len(self.center)
        self.axis_u = _rows(self.axis_u, n, 3, what="area lights")
        self.axis_v = _rows(self.axis_v, n, 3, what="area lights")
        self.normal = _rows(self.normal, n, 3, what="area lights")
        self.shape = _rows(self.shape, n, 0, what="area lights").astype(np.int64)
        self.radiance = _rows(self.radiance, n, 3, what="area lights")
        self.shadow = _rows(self.shadow, n, 0, 1.0, what="area lights")
        self.link = _rows(self.link, n, 0, what="area lights").astype(np.int64)

    def __len__(self):
        return len(self.center)

    @property
    def area(self):
        """(L,) [m^2]."""
        uv = np.linalg.norm(self.axis_u, axis=1) * np.linalg.norm(self.axis_v, axis=1)
        return np.where(self.shape == 1, np.pi * uv, 4.0 * uv)

    def to_arrays(self, prefix="area_light_"):
        return {prefix + k: getattr(self, k) for k in _AREA_FIELDS}

    @classmethod
    def from_arrays(cls, d, prefix="area_light_"):
        return cls(**{k: d.get(prefix + k) for k in _AREA_FIELDS})


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
    world : :class:`~raybundle.scene.world.World`  the radiance arriving from around the
        scene [W m^-2 sr^-1] by direction (Blender's World; a constant world is a 1 x 1 image)
    triangle_corner_tag : (T, 3) int or None  weld tags of corners on contact
        lines (:mod:`raybundle.patches.contacts`); corners weld only when their tags agree
    texture : :class:`~raybundle.scene.textures.SurfaceTexture` or None  image textures on
        the diffuse albedo of the input faces (kept through subdivision)
    linking : :class:`~raybundle.scene.linking.LightLinking` or None  which input faces each
        lamp lights and which block it (Blender's light and shadow linking)
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
    world: World | None = None
    triangle_corner_tag: np.ndarray | None = None
    texture: object = None
    #: :class:`~raybundle.scene.shading.ShadingNormals` of smooth-shaded faces, or None
    shading: object = None
    linking: object = None

    def __post_init__(self):
        if self.triangle_two_sided is None:
            self.triangle_two_sided = np.zeros(len(self.triangles), bool)
        if self.triangle_solid is None:
            self.triangle_solid = closed_solid_triangles(self.vertices, self.triangles) & ~self.triangle_two_sided
        if self.world is None:
            self.world = World.constant()
        elif not isinstance(self.world, World):
            self.world = World.constant(self.world)

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
        """(T, 3, 3) float: corner positions, gathered from the vertices where indexed
        (:class:`~raybundle.util.arrays.GatheredRows`), not held."""
        return GatheredRows(self.vertices, self.triangles)

    # not cached: a (T, 3) array that nothing reads once the areas and normals are made
    def _cross(self):
        return triangle_geometry.cross(self.vertices, self.triangles)

    @cached_property
    def triangle_area(self):
        """(T,) float [m^2]."""
        return triangle_geometry.areas(self.vertices, self.triangles)

    @cached_property
    def triangle_normal(self):
        """(T, 3) float unit front normals."""
        return triangle_geometry.normals(self.vertices, self.triangles, self.triangle_area)

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
        n = np.stack([np.bincount(self.triangle_patch, column, minlength=self.n_patches)
                      for column in self._cross().T], axis=1)
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

    def albedo_at(self, triangles, points):
        """(N, 3) the texture's modulation of the diffuse reflectance at ``points`` (N, 3) on
        patch ``triangles`` (N,) (:mod:`raybundle.scene.textures`), None for an untextured scene."""
        tex = self.texture
        return None if tex is None else tex.at(self.triangle_source[triangles], points)

    def pass_probability(self, triangles, cos):
        """(N,) probability that a ray meeting ``triangles`` (N,) at ``|cos|`` (N,) of its angle
        to their normals passes straight through (:func:`.transmission.pass_probability`)."""
        return pass_probability(self.materials, self.triangle_material[triangles], cos)

    @cached_property
    def bounding_sphere(self):
        """(centre (3,), radius) of a sphere containing every vertex."""
        seen = np.zeros(len(self.vertices), bool)
        seen[self.triangles.ravel()] = True
        used = self.vertices[seen]
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
        :data:`~raybundle.scene.welding.SMOOTH_ANGLE` (tags agreeing): a tessellated sphere (or the clusters of its
        triangles, :mod:`raybundle.patches.clusters`) is one smooth surface, a box's edges are creases
        (:func:`~raybundle.scene.welding.smooth_vertex_ids`)."""
        from .welding import smooth_vertex_ids

        return smooth_vertex_ids(self)

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
    def side_opposite(self):
        """(S,) int: the other side of each side's patch, -1 for one-sided patches."""
        return np.concatenate([self.patch_back_side, np.nonzero(self.patch_two_sided)[0]]).astype(np.int64)

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
        """(TS, 3) float: unit normal of each tside (a back tside's the negated front's),
        gathered where indexed (:class:`~raybundle.util.arrays.GatheredRows`), not held."""
        return GatheredRows(self.triangle_normal, self.tside_triangle, flip_from=len(self.triangles))

    @cached_property
    def tside_side(self):
        """(TS,) int: the (patch) side each tside belongs to."""
        t = self.tside_triangle
        p = self.triangle_patch[t]
        return np.where(np.arange(len(t)) < len(self.triangles), p, self.patch_back_side[p])

    def tside_samples(self, k):
        """(TS,) sample counts per tside that give each side about ``k`` in all, shared by
        area: ``clip(ceil(k A_t / A_side), 1, k)`` (``k`` each for one-triangle patches; one
        each for the small triangles of a cluster, :mod:`raybundle.patches.clusters`)."""
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

    def link_groups(self, triangles):
        """(N,) the link groups (:mod:`raybundle.scene.linking`) of ``triangles`` (N,), or None when
        the scene has no light linking."""
        if self.linking is None:
            return None
        return self.linking.face_group[self.triangle_source[np.asarray(triangles, np.int64)]]

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
        from ..util.io import atomic_path

        d = {"format_version": np.array(NPZ_FORMAT_VERSION), "name": np.array(self.name),
             "vertices": self.vertices, "triangles": self.triangles,
             "triangle_material": self.triangle_material, "triangle_patch": self.triangle_patch,
             "triangle_source": self.triangle_source, "triangle_solid": self.triangle_solid,
             "triangle_two_sided": self.triangle_two_sided}
        d.update(self.world.to_arrays())
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
        if self.shading is not None:
            d.update(self.shading.to_arrays())
        if self.linking is not None:
            d.update(self.linking.to_arrays())
        with atomic_path(path) as tmp:
            with open(tmp, "wb") as f:
                np.savez_compressed(f, **d)


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
    uniq, _, inv = unique_ints(key)
    count = np.bincount(inv)                                # every id has an element
    pos = np.clip(np.searchsorted(uniq, rev), 0, len(uniq) - 1)
    ok_edge = (count[inv] == 1) & (uniq[pos] == rev) & (count[pos] == 1)      # one twin each way
    tri_ok = ok_edge.reshape(-1, 3).all(axis=1)
    # connected components over shared (undirected) edges
    und = np.minimum(a, b) * nv + np.maximum(a, b)
    order, und = stable_order(und)
    same = und[1:] == und[:-1]
    label = connected_components(len(t), np.stack([order[:-1][same] // 3, order[1:][same] // 3], axis=1))
    bad = np.bincount(label, ~tri_ok, minlength=len(t)) > 0
    return ~bad[label]
