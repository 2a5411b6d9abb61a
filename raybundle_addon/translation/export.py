"""Evaluated depsgraph -> a :class:`raybundle.scene.model.PatchScene` (arrays only; no rendering).

Geometry
    Every mesh-like object instance of ``depsgraph.object_instances`` (objects,
    collection instances, geometry-node instances, particles) with its modifiers
    applied, in world space (``DepsgraphObjectInstance.matrix_world``, copied at
    once: the iterator reuses its items).  Faces are the mesh's loop triangles,
    read with ``foreach_get`` (``attributes["position"]``, ``.corner_vert``,
    ``loop_triangle_polygons``, the ``material_index`` attribute); a mesh shared by
    many instances is read once.  Surfaces are **two-sided**, as in Blender: both
    sides shade with the same material and emitters glow on both sides, so normal
    directions do not matter.  Objects invisible to every ray type are skipped;
    other per-ray-type visibility settings are not modelled (warned).

Materials
    :mod:`.shaders` (node trees -> Lambert + GGX / Principled parameters).

Lights (Blender's units, as Cycles converts them; ``blender.md`` §4.4)
    Every light's color is ``color x 2**exposure`` (x ``temperature_color`` when
    ``use_temperature`` is on), times:

    ============  =====================================================================
    point, spot   intensity ``I = P / (4 pi)`` [W/sr]; the spot cone (``spot_size``,
                  ``spot_blend``) masks it and does **not** renormalise it
    sun           irradiance ``E = strength`` [W/m^2] on a plane facing the sun
    area          radiance ``L = P / (pi A)`` [W m^-2 sr^-1], one-sided (local -Z),
                  ``A`` the world-space area: ``size x size_y`` (square, rectangle)
                  or ``pi/4 size x size_y`` (disk, ellipse), object scale included
    ============  =====================================================================

    With ``normalize`` off (Cycles' "unnormalized" lights) the area factor is
    dropped: area ``L = P / pi``, point/spot ``I = P r^2 / 4`` for radius r > 0, sun
    ``E = strength x pi tan^2(angle / 2)`` for angle > 0.

    A light's own node tree scales its color (:mod:`.light_nodes`).  With Cast Shadow off
    (``use_shadow``) nothing blocks its direct light, as in Cycles; its light and shadow linking
    is :mod:`.light_linking`'s.

    A light portal (an area light with Portal on) guides Cycles' sampling of the world and
    emits nothing: it is left out (noted once), since bundles reach the world through the
    openings without it.

Materials override
    The view layer's Material Override replaces every object's materials, emitters'
    included, as in Cycles (a clay render).

World
    :mod:`.world`: a constant Background is read directly, any other node tree is
    evaluated by Blender into an equirectangular image; no world is black.  A view layer's
    World Override replaces the scene's world, as in Cycles.

Settings that change Cycles' image and are not modeled are warned when they differ from
Blender's defaults (:func:`_unmodeled_settings`): bounce limits, clamping, caustics off, Fast
GI, culling, a texture size limit, the world's ray visibility and shadows, the view layer's
Environment and Surfaces filters, Freestyle, multi-view; per object and lamp, shadow terminator
offsets and a lamp's max bounces.

Camera
    Lens, sensor size and fit, shift, pixel aspect, clip start, resolution x
    percentage, render border; perspective and orthographic (panoramic: an error).
"""
from __future__ import annotations

import math
import time
import warnings as _warnings
from dataclasses import dataclass, field

import numpy as np

from .light_linking import LinkSets
from .light_nodes import light_node_factor
from .node_graphs import start_graph_bake
from .shaders import MaterialConverter
from .world import camera_view, start_world_export

#: object types that become triangles (through their evaluated mesh)
GEOMETRY_TYPES = {"MESH", "CURVE", "SURFACE", "FONT", "META", "CURVES_LEGACY"}
#: object types that render in Cycles but not here (one warning each)
UNMODELED_TYPES = {"CURVES": "hair curves", "POINTCLOUD": "point clouds (e.g. Geometry Nodes points)",
                   "VOLUME": "volumes"}


def _unmodeled_features(ob, warn):
    """Warn about what Cycles renders on object ``ob`` (an original mesh-like object) that the
    export leaves out: hair particles drawn as strands."""
    for ps in getattr(ob, "particle_systems", ()):
        st = ps.settings
        if st.type == "HAIR" and st.render_type == "PATH":
            warn(f"object {ob.name!r}: hair particles ({ps.name!r}) are not rendered")


@dataclass
class ObjectInfo:
    """One exported object instance; its triangles are
    ``first_triangle .. first_triangle + n_triangles`` of the export arrays."""

    name: str                 # the (instanced) object's name
    original: str             # the original object's name (for write-back)
    mesh: str                 # the evaluated mesh's name
    is_instance: bool
    instancer: str | None
    first_triangle: int
    n_triangles: int
    n_polygons: int
    n_loops: int
    matrix_world: np.ndarray  # (4, 4)


@dataclass
class ExportResult:
    """What :func:`export_scene` returns.

    ``scene`` is the validated, two-sided :class:`~raybundle.scene.model.PatchScene`
    (not yet subdivided); ``scene.triangle_source`` indexes the export arrays
    ``triangle_object`` (T,) int32 (into ``objects``), ``triangle_polygon`` (T,)
    int32 and ``triangle_loops`` (T, 3) int32 (the object's evaluated mesh
    polygon and corners); ``warnings`` are one-line messages for the user (a deferred
    world's render adds its own when :meth:`attach_world` finishes it);
    ``border`` is the render border ``(x0, y0, w, h)`` in pixels from the
    bottom-left (None = the full frame).
    """

    scene: object
    warnings: list
    objects: list
    triangle_object: np.ndarray
    triangle_polygon: np.ndarray
    triangle_loops: np.ndarray
    material_names: list
    resolution: tuple
    border: tuple | None = None
    seconds: float = 0.0
    counts: dict = field(default_factory=dict)
    #: with ``defer_world``: the world's render under way (:class:`~raybundle_addon.translation.world.PendingWorld`)
    world_render: object = None

    def attach_world(self, *scenes):
        """Wait for the world's render (``export_scene(..., defer_world=True)``) and give the
        world to :attr:`scene` and ``scenes`` (its laid-out copies), in place
        (:func:`raybundle.scene.build.attach_world`).  Returns the seconds waited."""
        from raybundle.scene.build import attach_world

        pending, self.world_render = self.world_render, None
        if pending is None:
            return 0.0
        world = pending.finish()
        for sc in {id(s): s for s in (self.scene, *scenes)}.values():
            attach_world(sc, world)
        return pending.waited

    def cancel_world(self):
        """Stop the world's render, if one is under way (a cancelled or failed render)."""
        pending, self.world_render = self.world_render, None
        if pending is not None:
            pending.cancel()


class _Warnings(list):
    def __call__(self, message):
        if message not in self:
            self.append(message)


# ------------------------------------------------------------------ geometry
def _mesh_arrays(me):
    """Local arrays of an evaluated mesh: positions (V, 3) f32, triangle corners
    (T, 3) i32 (vertex ids), loops (T, 3) i32, triangle -> polygon (T,) i32,
    polygon material index (P,) i32, corner normals (L, 3) f32 (Blender's shading normals:
    smooth, auto smooth and custom normals; None where the API lacks them)."""
    nv = len(me.vertices)
    pos = np.empty(nv * 3, np.float32)
    pa = me.attributes.get("position")
    if pa is not None:
        pa.data.foreach_get("vector", pos)
    else:
        me.vertices.foreach_get("co", pos)
    nt = len(me.loop_triangles)
    loops = np.empty(nt * 3, np.int32)
    me.loop_triangles.foreach_get("loops", loops)
    cv_attr = me.attributes.get(".corner_vert")
    if cv_attr is not None:
        cv = np.empty(len(me.loops), np.int32)
        cv_attr.data.foreach_get("value", cv)
        tri = cv[loops]
    else:
        tri = np.empty(nt * 3, np.int32)
        me.loop_triangles.foreach_get("vertices", tri)
    tp = np.empty(nt, np.int32)
    me.loop_triangle_polygons.foreach_get("value", tp)
    mi_attr = me.attributes.get("material_index")
    if mi_attr is not None and mi_attr.domain == "FACE" and mi_attr.data_type == "INT":
        mi = np.empty(len(me.polygons), np.int32)
        mi_attr.data.foreach_get("value", mi)
    else:
        mi = np.zeros(len(me.polygons), np.int32)
    cn = None
    if hasattr(me, "corner_normals"):
        cn = np.empty(len(me.loops) * 3, np.float32)
        me.corner_normals.foreach_get("vector", cn)
        cn = cn.reshape(-1, 3)
    return pos.reshape(-1, 3), tri.reshape(-1, 3), loops.reshape(-1, 3), tp, mi, cn


def world_normals(n, M):
    """Normals ``n`` (..., 3) of an object with matrix ``M`` (4, 4) in world space, unit
    length: by the inverse transpose of its 3 x 3 part (a non-uniform scale tilts them)."""
    out = n @ np.linalg.pinv(M[:3, :3]).astype(np.float32)
    return out / np.maximum(np.linalg.norm(out, axis=-1, keepdims=True), 1e-30)


#: Cycles' defaults of its bounce limits: below them a file cuts light paths short on purpose
_BOUNCES = {"max_bounces": 12, "diffuse_bounces": 4, "glossy_bounces": 4, "transmission_bounces": 12,
            "transparent_max_bounces": 8}


def _unmodeled_settings(scene, view_layer, world, warn):
    """Warn about the scene, view layer and world settings that change Cycles' image and are not
    modeled, where they differ from Blender's defaults (the module docstring lists them)."""
    cy = getattr(scene, "cycles", None)
    if cy is not None:
        low = [f"{k.replace('_', ' ')} {getattr(cy, k)}" for k, d in _BOUNCES.items() if getattr(cy, k, d) < d]
        if low:
            warn(f"Cycles' bounce limits below its defaults ({', '.join(low)}) are not applied: raybundle renders "
                 "every bounce")
        if getattr(cy, "sample_clamp_direct", 0) > 0 or 0 < getattr(cy, "sample_clamp_indirect", 0) < 10:
            warn("Cycles' sample clamping below its defaults is not applied (the image is not clamped)")
        if not (getattr(cy, "caustics_reflective", True) and getattr(cy, "caustics_refractive", True)):
            warn("Cycles' caustics settings (reflective or refractive off) are not applied: raybundle renders caustics")
        if getattr(cy, "use_fast_gi", False):
            warn("Fast GI approximation is not applied: raybundle renders full global illumination")
        if getattr(cy, "use_camera_cull", False) or getattr(cy, "use_distance_cull", False):
            warn("camera and distance culling is not modeled: culled objects are rendered")
        if getattr(cy, "texture_limit_render", "OFF") != "OFF":
            warn(f"the texture size limit ({cy.texture_limit_render}) is not applied: textures are read at full size")
    if world is not None:
        vis = getattr(world, "cycles_visibility", None)
        off = [k for k in ("camera", "diffuse", "glossy", "transmission", "scatter") if not getattr(vis, k, True)]
        if off:
            warn(f"world {world.name!r}: world ray visibility is not modeled ({', '.join(off)} off): every ray sees it")
        wc = getattr(world, "cycles", None)
        if not getattr(wc, "use_shadows", True):
            warn(f"world {world.name!r}: world shadows off is not modeled: its light is shadowed")
        if getattr(wc, "max_bounces", 1024) < 1024:
            warn(f"world {world.name!r}: its max bounces ({wc.max_bounces}) is not applied")
    off = [label for key, label in (("use_sky", "Environment"), ("use_solid", "Surfaces"))
           if not getattr(view_layer, key, True)]
    if off:
        warn(f"view layer {view_layer.name!r}: the view layer's filter ({', '.join(off)} off) is not modeled")
    if scene.render.use_freestyle and getattr(view_layer, "use_freestyle", False):
        warn("Freestyle lines are not drawn")
    if scene.render.use_multiview:
        warn("multi-view (stereo) is not supported: one view is rendered")


def _object_settings(ob, warn):
    """Warn about object ``ob``'s settings that change Cycles' image and are not modeled: shadow
    terminator offsets other than Blender's defaults (normal 0, geometry 0.1, shading 0)."""
    cy = getattr(ob, "cycles", None)
    found = [(getattr(holder, k, d), d) for holder, k, d in (
        (ob, "shadow_terminator_normal_offset", 0.0), (ob, "shadow_terminator_geometry_offset", 0.1),
        (ob, "shadow_terminator_shading_offset", 0.0), (cy, "shadow_terminator_offset", 0.0),
        (cy, "shadow_terminator_geometry_offset", 0.1))]
    if any(abs(v - d) > 1e-6 for v, d in found):
        warn(f"object {ob.name!r}: shadow terminator offsets are not modeled")


def _warn_large_linked_emitters(sc, tobj, objects, warn):
    """One warning naming the linked emitting meshes too large for the first shot
    (:func:`raybundle.lights.sources.small_emitters`): the bundles carry their light to every
    surface, so their light linking is not applied."""
    from raybundle.lights.sources import small_emitters

    if sc.linking is None or not sc.linking.face_emitter.any():
        return
    emitter = sc.linking.face_emitter[sc.triangle_source]
    linked = (emitter > 0) & sc.materials.is_emitter[sc.triangle_material]
    linked &= ~np.isin(sc.triangle_material, small_emitters(sc))
    names = sorted({objects[o].original for o in np.unique(tobj[sc.triangle_source[linked]])})
    if names:
        warn(f"emitting mesh{'es' if len(names) > 1 else ''} {', '.join(repr(n) for n in names[:3])}: too large for the "
             "first shot, so their light linking is not applied (their light reaches every surface)")


def _ray_visible(ob, warn):
    """False for objects no ray can see; warns about partial visibility."""
    flags = [getattr(ob, k, True) for k in ("visible_camera", "visible_diffuse", "visible_glossy",
                                             "visible_shadow", "visible_transmission")]
    if not any(flags):
        return False
    if not all(flags):
        warn(f"object {ob.name!r}: per-ray-type visibility is not supported; rendered as fully visible")
    if getattr(ob, "is_holdout", False) or getattr(ob, "is_shadow_catcher", False):
        warn(f"object {ob.name!r}: holdout / shadow catcher is not supported; rendered as a normal object")
    return True


def _texture_uvs(me, ob, slots, tri_poly, poly_mat, loops, converter, images, warn):
    """For an object whose materials have albedo textures (``converter.textures``), cut-outs
    (``converter.cutouts``) or normal maps (``converter.normal_maps``): ((T, 3, 2) corner UVs,
    (T,) image index into ``images`` (-1 untextured, -2 the corner colors), (T, 3, 3) corner
    colors of a color attribute, (T,) coverage map index into ``images`` (-1 opaque), (T,)
    normal map index into ``images`` (-1 none), (T,) bool: that map is a bump's), or None.
    ``images`` (key -> (index, bpy Image or :class:`.shaders.EvaluatedImage`, its kind:
    "albedo", "alpha" or "normal", read at the nearest texel)) grows as new images are met."""
    for m in slots:
        converter.convert(m)                  # (cached) fills converter.textures, .cutouts, .normal_maps
    tex = [converter.texture_of(ob, m) for m in slots] or [None]
    cut = [converter.cutouts.get(m.name_full) if m is not None else None for m in slots] or [None]
    nrm = [converter.normal_maps.get(m.name_full) if m is not None else None for m in slots] or [None]
    if not any(tex) and not any(cut) and not any(nrm):
        return None
    slot = np.clip(poly_mat[tri_poly], 0, len(tex) - 1)
    uv = np.zeros((len(loops), 3, 2))
    img = np.full(len(loops), -1, np.int64)
    alpha = np.full(len(loops), -1, np.int64)
    normal = np.full(len(loops), -1, np.int64)
    bump = np.zeros(len(loops), bool)
    colors = np.zeros((len(loops), 3, 3))
    layers = {}

    def read_uv(name, what, sel, k):
        layer = (me.uv_layers.get(name) if name else
                 next((l for l in me.uv_layers if l.active_render), me.uv_layers.active))
        if layer is None:
            warn(f"object {ob.name!r}: material {slots[k].name!r} has {what} but the mesh has no UV "
                 f"map{' ' + repr(name) if name else ''}: {'its mean color is used' if 'image' in what else 'opaque'}")
            return False
        if layer.name not in layers:
            a = np.empty(2 * len(me.loops), np.float32)
            layer.uv.foreach_get("vector", a)
            layers[layer.name] = a.reshape(-1, 2)
        uv[sel] = layers[layer.name][loops[sel]]
        return True

    for k, (got, cover, nmap) in enumerate(zip(tex, cut, nrm)):
        sel = np.nonzero(slot == k)[0]
        if len(sel) == 0:
            continue
        read = None                               # the UV map this slot's faces hold
        if got is not None and got.attribute is not None:
            colors[sel] = _corner_colors(me, got.attribute, ob, slots[k], warn)[loops[sel]]
            img[sel] = -2
        elif got is not None and read_uv(got.uv, f"the image texture {got.image.name!r}", sel, k):
            img[sel] = images.setdefault((got.image.name_full, got.closest),
                                         (len(images), got.image, "albedo", got.closest))[0]
            read = got.uv
        for what, m, label in (("alpha", cover, "cut-out (Alpha)"), ("normal", nmap, "normal or bump map")):
            if m is None:
                continue
            if m.uv is not None:                  # a map: through the UVs read already, or its own
                if read is not None and read != m.uv:
                    warn(f"object {ob.name!r}: material {slots[k].name!r} reads its {label} through another UV map "
                         f"than its albedo or cut-out: the first one's ({read or 'the active one'}) is used for all")
                elif read is None:
                    if not read_uv(m.uv, f"a {label}", sel, k):
                        continue
                    read = m.uv
            index = images.setdefault((what, m.image.name_full), (len(images), m.image, what, False))[0]
            if what == "alpha":
                alpha[sel] = index
            else:
                normal[sel], bump[sel] = index, m.bump
    if np.all(img == -1) and np.all(alpha == -1) and np.all(normal == -1):
        return None
    return uv, img, colors, alpha, normal, bump


def _corner_colors(me, name, ob, mat, warn):
    """(corners, 3) linear RGB of color attribute ``name`` ("" = the active render one) of
    mesh ``me`` per face corner; black, warned, when the mesh does not have it (as Cycles)."""
    ca = me.color_attributes
    attr = ca.get(name) if name else (ca[ca.render_color_index] if len(ca) and ca.render_color_index >= 0 else None)
    if attr is None or attr.domain not in ("POINT", "CORNER"):
        warn(f"object {ob.name!r}: material {mat.name!r} reads the color attribute {name or '(active)'!r}, which "
             "the mesh does not have: black, as in Cycles")
        return np.zeros((len(me.loops), 3))
    vals = np.empty(4 * len(attr.data), np.float32)
    attr.data.foreach_get("color", vals)             # linear for byte and float colors alike
    vals = vals.reshape(-1, 4)[:, :3].astype(float)
    if attr.domain == "CORNER":
        return vals
    return vals[corner_vertices(me)]


def corner_vertices(me):
    """(corners,) int32: the vertex of each face corner of mesh ``me`` (the fast hidden
    ``.corner_vert`` attribute, else the loops)."""
    cv = np.empty(len(me.loops), np.int32)
    attr = me.attributes.get(".corner_vert")
    if attr is not None:
        attr.data.foreach_get("value", cv)
    else:
        me.loops.foreach_get("vertex_index", cv)
    return cv


# -------------------------------------------------------------------- lights
def light_color(ld):
    """(3,) color x 2**exposure (x temperature color when enabled) of a bpy Light."""
    c = np.array(ld.color[:3], float) * 2.0 ** float(getattr(ld, "exposure", 0.0))
    if getattr(ld, "use_temperature", False) and hasattr(ld, "temperature_color"):
        c = c * np.array(ld.temperature_color[:3], float)
    return c


def convert_light(ld, M, warn, nodes=None):
    """(kind, dict) for a bpy Light ``ld`` with world matrix ``M`` (4, 4):
    kind "point" (position, intensity, spot_*, radius), "sun" (direction,
    irradiance, angle) or "area" (center, axis_u, axis_v, normal, shape, radiance), each with
    ``shadow`` (1, or 0 with Cast Shadow off).  Formulas: module docstring.  ``nodes``: a dict
    that keeps each light data-block's :func:`.light_nodes.light_node_factor` (its instances share
    one reading and one profile)."""
    if nodes is None:
        nodes = {}
    if ld.name_full not in nodes:
        nodes[ld.name_full] = light_node_factor(ld, warn)
    got = _convert_light(ld, M, warn, *nodes[ld.name_full])
    if got is not None:
        got[1]["shadow"] = float(bool(getattr(ld, "use_shadow", True)))
    return got


def _convert_light(ld, M, warn, factor, profile):
    color = light_color(ld) * factor
    power = float(ld.energy)
    normalize = bool(getattr(ld, "normalize", True))
    pos = M[:3, 3].copy()
    z = M[:3, 2]
    zn = np.linalg.norm(z)
    down = -z / zn if zn > 0 else np.array([0.0, 0.0, -1.0])
    if power < 0:
        warn(f"light {ld.name!r} has negative power: ignored")
        return None
    if ld.type in ("POINT", "SPOT"):
        r = float(ld.shadow_soft_size)
        intensity = color * power / (4 * math.pi)
        if not normalize and r > 0:
            intensity = intensity * math.pi * r * r
        axes = M[:3, :3].T / np.maximum(np.linalg.norm(M[:3, :3], axis=0), 1e-30)[:, None]
        d = dict(position=pos, intensity=intensity, radius=r, spot_direction=np.zeros(3),
                 spot_cos_half_angle=-1.0, spot_blend=0.0, profile=profile, axes=axes)
        if getattr(ld, "use_soft_falloff", False) and r > 0:
            warn(f"light {ld.name!r}: soft falloff is not modelled (a sphere light is used)")
        if ld.type == "SPOT":
            d.update(spot_direction=down, spot_cos_half_angle=math.cos(float(ld.spot_size) / 2),
                     spot_blend=float(ld.spot_blend))
            sx, sy = np.linalg.norm(M[:3, 0]), np.linalg.norm(M[:3, 1])
            if abs(sx - sy) > 1e-6 * max(sx, sy):
                warn(f"spot light {ld.name!r}: a non-uniformly scaled (elliptic) cone is treated as round")
        return "point", d
    if ld.type == "SUN":
        angle = float(ld.angle)
        irradiance = color * power
        if not normalize and angle > 0:
            irradiance = irradiance * math.pi * math.tan(angle / 2) ** 2
        return "sun", dict(direction=down, irradiance=irradiance, angle=angle)
    if ld.type == "AREA":
        sx = float(ld.size)
        sy = float(ld.size_y) if ld.shape in ("RECTANGLE", "ELLIPSE") else sx
        u, v = M[:3, 0] * sx / 2, M[:3, 1] * sy / 2
        ellipse = ld.shape in ("DISK", "ELLIPSE")
        area = (math.pi if ellipse else 4.0) * np.linalg.norm(u) * np.linalg.norm(v)
        if area <= 0:
            warn(f"area light {ld.name!r} has zero size: ignored")
            return None
        radiance = color * power / (math.pi * (area if normalize else 1.0))
        if float(getattr(ld, "spread", math.pi)) < math.pi - 1e-6:
            warn(f"area light {ld.name!r}: spread is not modelled (a Lambertian emitter is used)")
        return "area", dict(center=pos, axis_u=u, axis_v=v, normal=down, shape=int(ellipse), radiance=radiance)
    warn(f"light {ld.name!r} of type {ld.type} is not supported: ignored")
    return None


# -------------------------------------------------------------------- camera
#: coplanar overlaps smaller than this [m^2] are not warned about
OVERLAP_MIN_AREA = 1e-3


def _warn_overlaps(corners, tobj, objects, warn):
    """One warning per pair of objects whose faces overlap in one plane, facing the same way
    (:func:`raybundle.scene.overlaps.coplanar_overlaps`): Cycles renders such z-fighting
    darker, raybundle as one surface."""
    from raybundle.scene.overlaps import coplanar_overlaps

    found = coplanar_overlaps(corners, tobj, OVERLAP_MIN_AREA)
    for a, b, area in found[:3]:
        warn(f"objects {objects[a].name!r} and {objects[b].name!r} overlap in one plane over {area:.2g} m^2 "
             "(z-fighting): Cycles renders the overlap darker, each face shadowing the other; raybundle lights it "
             "as one surface")
    if len(found) > 3:
        warn(f"{len(found) - 3} more pairs of objects overlap in one plane (z-fighting)")


#: a transmissive object is a set of panes when this share of its area lies in planes that face a
#: parallel plane of its own, nearer than :data:`PANE_THICKNESS` times their size
FLAT_GLASS = 0.95
PANE_THICKNESS = 0.1


def _pane_share(n, a, corners):
    """The share of the area ``a`` (N,) of triangles (normals ``n``, corners (N, 3, 3)) that lies in
    planes facing a parallel plane of theirs across a thickness below :data:`PANE_THICKNESS` times
    the plane's size (the two faces of a pane, whose bends cancel)."""
    key_n = np.round(n * 1e4).astype(np.int64)
    offset = np.einsum("ij,ij->i", n, corners[:, 0])
    planes, inv = np.unique(np.column_stack([key_n, np.round(offset * 1e4).astype(np.int64)]), axis=0,
                            return_inverse=True)
    inv = inv.reshape(-1)
    area = np.bincount(inv, a)
    paired = np.zeros(len(planes), bool)
    for i, (nx, ny, nz, off) in enumerate(planes):
        other = np.nonzero((planes[:, 0] == -nx) & (planes[:, 1] == -ny) & (planes[:, 2] == -nz))[0]
        gap = np.abs(planes[other, 3] + off) * 1e-4
        paired[i] = bool(np.any(gap < PANE_THICKNESS * np.sqrt(area[i])))
    return float(area[paired].sum() / max(area.sum(), 1e-300))


def _warn_curved_glass(sc, tobj, objects, warn):
    """One warning naming the objects whose transmissive faces are not panes (:func:`_pane_share`
    below :data:`FLAT_GLASS`): light passes them unbent (:mod:`raybundle.scene.transmission`), so
    their caustic is spread as a soft shadow."""
    glass = np.nonzero(sc.materials.transmits[sc.triangle_material])[0]
    if len(glass) == 0:
        return
    owner = tobj[sc.triangle_source[glass]]
    curved = [objects[o].original for o in np.unique(owner)
              if _pane_share(sc.triangle_normal[glass[owner == o]], sc.triangle_area[glass[owner == o]],
                             sc.triangle_corners[glass[owner == o]]) < FLAT_GLASS]
    if curved:
        warn(f"glass that is not a pane of parallel faces ({', '.join(repr(c) for c in curved[:3])}"
             f"{' ...' if len(curved) > 3 else ''}) lets light through unbent: its caustics are spread as a soft "
             "shadow (the eye sees it refract)")


def render_size(render):
    """(W, H) pixels after the resolution percentage."""
    s = render.resolution_percentage / 100.0
    return max(1, int(render.resolution_x * s)), max(1, int(render.resolution_y * s))


def border_rect(render, size):
    """The render border as (x0, y0, w, h) pixels from the bottom-left, None for the full frame
    (Blender truncates ``border * size``)."""
    w, h = size
    if not render.use_border:
        return None
    x0, x1 = int(render.border_min_x * w), int(render.border_max_x * w)
    y0, y1 = int(render.border_min_y * h), int(render.border_max_y * h)
    if (x0, y0, x1, y1) == (0, 0, w, h):
        return None
    if x1 <= x0 or y1 <= y0:
        from raybundle.scene.model import SceneError

        raise SceneError("the render border is empty: widen it or turn it off")
    return x0, y0, x1 - x0, y1 - y0


def export_camera(cam_ob, render, size=None, border=None, warn=print):
    """A :class:`raybundle.scene.camera.Camera` for camera object ``cam_ob`` (evaluated) and
    the render settings; ``border`` (x0, y0, w, h) crops it to the border's pixels.  The pixel
    filter is Cycles' (Film > Pixel Filter; a box is one pixel wide, as Cycles reads it)."""
    from dataclasses import replace

    from raybundle.scene.camera import Camera
    from raybundle.scene.model import SceneError

    if cam_ob is None:
        raise SceneError("the scene has no camera: add one and make it the active camera")
    cd = cam_ob.data
    if cam_ob.type != "CAMERA":
        raise SceneError(f"the active camera {cam_ob.name!r} is not a camera object")
    if cd.type == "PANO":
        raise SceneError(f"camera {cam_ob.name!r} is panoramic: only perspective and orthographic cameras "
                         "are supported")
    w, h = size or render_size(render)
    M = np.array(cam_ob.matrix_world, float)
    cam = Camera.from_blender(cd.lens, cd.sensor_width, cd.sensor_height, cd.sensor_fit, cd.shift_x, cd.shift_y,
                              (w, h), M, pixel_aspect=(render.pixel_aspect_x, render.pixel_aspect_y),
                              ortho_scale=cd.ortho_scale if cd.type == "ORTHO" else None,
                              clip_start=cd.clip_start)
    if getattr(cd.dof, "use_dof", False):
        warn(f"camera {cam_ob.name!r}: depth of field is not supported (a pinhole is used)")
    cycles = getattr(render.id_data, "cycles", None)
    if cycles is not None:
        kind = str(cycles.pixel_filter_type)
        cam = replace(cam, pixel_filter=kind, filter_width=1.0 if kind == "BOX" else float(cycles.filter_width))
        if float(getattr(cycles, "film_exposure", 1.0)) != 1.0:
            warn(f"film exposure {float(cycles.film_exposure):g} is not applied (the image is as at exposure 1)")
    if border is not None:
        x0, y0, bw, bh = border
        cam = replace(cam, width=bw, height=bh, cx=cam.cx - x0, cy=cam.cy - (h - (y0 + bh)))
    return cam


# -------------------------------------------------------------------- export
def export_scene(depsgraph, camera_object=None, use_border=True, name=None, require_camera=True,
                 defer_world=False):
    """Export the evaluated ``depsgraph`` (its scene and view layer) for rendering.

    A world Blender must render (:mod:`.world`) starts rendering first, in a process of its
    own.  With ``defer_world`` the export does not wait for it: the scene gets a stand-in world
    (:meth:`raybundle.scene.world.World.stand_in_for_render`) and the result's
    :meth:`ExportResult.attach_world` waits for the render and gives the world, so the patch
    layout runs meanwhile (the render then takes one CPU thread, the layout the other).

    ``camera_object`` overrides the scene camera (e.g. ``RenderEngine.camera_override``);
    with ``require_camera`` False (bakes) a scene without a camera exports with
    ``scene.camera = None``.
    Raises :class:`raybundle.scene.model.SceneError` (a ValueError) with a one-line reason
    when there is nothing to render: no mesh, no light, no camera.
    Returns :class:`ExportResult`.
    """
    t0 = time.perf_counter()
    warn = _Warnings()
    scene = depsgraph.scene
    render = scene.render
    size = render_size(render)
    border = border_rect(render, size) if use_border else None
    cam_ob = camera_object if camera_object is not None else scene.camera
    if cam_ob is not None:
        cam_ob = cam_ob.evaluated_get(depsgraph)
    camera = export_camera(cam_ob, render, size, border, warn) if cam_ob is not None or require_camera else None
    world = getattr(depsgraph.view_layer, "world_override", None) or scene.world
    _unmodeled_settings(scene, depsgraph.view_layer, world, warn)
    pending = start_world_export(world, warn, camera_view(cam_ob, render, size, camera, border))
    try:
        result = _export_geometry(depsgraph, scene, warn, cam_ob, camera, size, border, name,
                                  pending.now if defer_world else pending.finish(), t0)
    except BaseException:
        pending.cancel()
        raise
    if defer_world:
        result.world_render = pending
    return result


def _export_geometry(depsgraph, scene, warn, cam_ob, camera, size, border, name, world, t0):
    """:func:`export_scene`'s objects, lights and materials, with the camera and world made;
    Blender bakes the node graphs on the materials' inputs meanwhile (:mod:`.node_graphs`)."""
    override = getattr(depsgraph.view_layer, "material_override", None)
    graphs = start_graph_bake(*_used_materials(depsgraph, override))
    try:
        return _export_objects(depsgraph, scene, warn, cam_ob, camera, size, border, name, world, t0,
                               MaterialConverter(warn, graphs), override)
    finally:
        graphs.cancel()


def _used_materials(depsgraph, override):
    """``(materials, users)``: the materials of the geometry ``depsgraph`` renders (``override``
    alone when set), and material name -> the (original) objects that use it."""
    found, users = {}, {}
    for inst in depsgraph.object_instances:
        ob = inst.object
        if ob.type in GEOMETRY_TYPES:
            mats = [s.material for s in ob.material_slots] or list(getattr(ob.data, "materials", []))
            for m in [override] if override is not None else mats:
                if m is not None:
                    found.setdefault(m.name_full, m)
                    users.setdefault(m.name_full, {}).setdefault(ob.original.name_full, ob.original)
    return list(found.values()), {k: list(v.values()) for k, v in users.items()}


def _export_objects(depsgraph, scene, warn, cam_ob, camera, size, border, name, world, t0, converter, override):
    """:func:`_export_geometry` with the material ``converter`` made."""
    from raybundle.scene.build import build_scene
    from raybundle.scene.materials import MaterialTable
    from raybundle.scene.model import AreaLights, PointLights, SceneError, SunLights
    from raybundle.scene.shading import ShadingNormals

    render = scene.render
    viewport = depsgraph.mode == "VIEWPORT"
    mat_index, mat_specs = {}, []

    def material_id(mat):
        key = None if mat is None else mat.name_full
        if key not in mat_index:
            mat_index[key] = len(mat_specs)
            mat_specs.append(converter.convert(mat))
        return mat_index[key]

    cache = {}
    verts, tris, tmats, tobj, tpoly, tloops, tnorm, temit = [], [], [], [], [], [], [], []
    # albedo textures and cut-outs: corner UVs, image per triangle, corner colors, coverage map per triangle
    tuv, timg, tcol, talpha, tnrm, tbump, images = [], [], [], [], [], [], {}
    objects = []
    lights = {"point": [], "sun": [], "area": []}
    link_sets = LinkSets()
    light_nodes = {}                        # light data-block -> its node tree's reading
    portals = []
    n_vert = n_tri = 0
    for inst in depsgraph.object_instances:
        ob = inst.object
        kind = ob.type
        if kind in UNMODELED_TYPES and inst.show_self and not (viewport and ob.original.hide_render):
            warn(f"object {ob.original.name!r}: {UNMODELED_TYPES[kind]} are not rendered")
        if kind != "LIGHT" and kind not in GEOMETRY_TYPES:
            continue
        M = np.array(inst.matrix_world, float)            # copy now: the iterator reuses items
        if viewport and ob.original.hide_render:
            continue
        if kind == "LIGHT":
            rays = [getattr(ob, f"visible_{k}", True) for k in ("diffuse", "glossy", "transmission")]
            if not (rays[0] or rays[1]):
                continue
            if not all(rays):
                off = ", ".join(k for k, on in zip(("diffuse", "glossy", "transmission"), rays) if not on)
                warn(f"light {ob.original.name!r}: ray visibility ({off} off) is not supported; "
                     "it lights every surface as if all were on")
            if getattr(getattr(ob.data, "cycles", None), "is_portal", False):
                portals.append(ob.original.name)
                continue
            got = convert_light(ob.data, M, warn, light_nodes)
            bounces = getattr(getattr(ob.data, "cycles", None), "max_bounces", 1024)
            if bounces < 1024:
                warn(f"light {ob.original.name!r}: its max bounces ({bounces}) is not applied: raybundle renders every "
                     "bounce of its light")
            if got is not None:
                got[1]["link"] = link_sets.set_of(ob.original)
                lights[got[0]].append(got[1])
            continue
        if not inst.is_instance:
            _unmodeled_features(ob.original, warn)
            _object_settings(ob.original, warn)
        if not inst.show_self or not _ray_visible(ob, warn):
            continue
        me, temp = (ob.data, False) if kind == "MESH" else (None, True)
        if temp:
            try:
                me = ob.to_mesh()
            except RuntimeError:
                me = None
            if me is None:
                continue
        try:
            key = me.as_pointer()
            arrays = cache.get(key) if not temp else None
            if arrays is None:
                arrays = _mesh_arrays(me)
                if not temp:
                    cache[key] = arrays
            pos, tri, loops, tp, mi, cn = arrays
            slots = [s.material for s in ob.material_slots] if len(ob.material_slots) else list(me.materials)
            if override is not None:
                slots = [override] * max(1, len(slots))
            left_out = [converter.left_out(m) for m in slots]
            if any(left_out):                     # faces of a volume without a surface
                keep = ~np.array(left_out)[np.clip(mi[tp], 0, len(slots) - 1)]
                tri, loops, tp = tri[keep], loops[keep], tp[keep]
            textured = _texture_uvs(me, ob, slots, tp, mi, loops, converter, images, warn)
            info = ObjectInfo(ob.name, ob.original.name, me.name, bool(inst.is_instance),
                              inst.parent.name if inst.is_instance and inst.parent else None,
                              n_tri, len(tri), len(me.polygons), len(me.loops), M)
        finally:
            if temp:
                ob.to_mesh_clear()
        if len(tri) == 0:
            continue
        ids = np.array([material_id(m) for m in slots] or [material_id(None)], np.int64)
        tmats.append(ids[np.clip(mi[tp], 0, len(ids) - 1)])
        verts.append(pos @ M[:3, :3].T.astype(np.float64) + M[:3, 3])
        tris.append(tri.astype(np.int64) + n_vert)
        tobj.append(np.full(len(tri), len(objects), np.int32))
        temit.append(link_sets.set_of(ob.original))          # an emitting mesh's own link set
        tpoly.append(tp)
        tloops.append(loops)
        tnorm.append(None if cn is None else world_normals(cn[loops], M))
        # untextured objects hold None: their zeros are made only if some object is textured
        tuv.append((len(tri), textured[0]) if textured else (len(tri), None))
        timg.append(textured[1] if textured else None)
        tcol.append(textured[2] if textured else None)
        talpha.append(textured[3] if textured else None)
        tnrm.append(textured[4] if textured else None)
        tbump.append(textured[5] if textured else None)
        objects.append(info)
        n_vert += len(pos)
        n_tri += len(tri)

    if portals:
        warn(f"light portal{'s' if len(portals) > 1 else ''} {', '.join(repr(p) for p in portals[:3])}"
             f"{' ...' if len(portals) > 3 else ''}: a portal guides Cycles' sampling of the world and emits "
             "nothing; left out (bundles reach the world through the openings without it)")
    if n_tri == 0:
        raise SceneError("nothing to render: the scene has no visible mesh objects")
    if render.use_motion_blur:
        warn("motion blur is not supported: the scene is rendered at the current frame")
    if render.film_transparent:
        warn("transparent film is not supported: the background is the world's color, alpha is 1")

    v = np.concatenate(verts)
    t = np.concatenate(tris)
    m = np.concatenate(tmats)
    mats = MaterialTable.from_list(mat_specs)

    def group(cls, rows):
        if not rows:
            return cls()
        profiles = [r.pop("profile") for r in rows if "profile" in r]
        if profiles:          # photometric profiles: an index into their list (one per profile), -1 for none
            index = {}
            for r, p in zip(rows, profiles):
                r["profile"] = -1 if p is None else index.setdefault(id(p), (len(index), p))[0]
            kept = [p for _, p in sorted(index.values(), key=lambda x: x[0])]
            return cls(**{k: np.array([r[k] for r in rows]) for k in rows[0]}, profiles=kept)
        return cls(**{k: np.array([r[k] for r in rows]) for k in rows[0]})

    texture = None
    if any(x is not None and np.any(x != -1) for x in timg + talpha + tnrm):
        def faces(per_object):
            return np.concatenate([np.full(n, -1, np.int64) if x is None else x for (n, _), x in zip(tuv, per_object)])

        face_image, face_alpha, face_normal = faces(timg), faces(talpha), faces(tnrm)
        face_bump = np.concatenate([np.zeros(n, bool) if b is None else b for (n, _), b in zip(tuv, tbump)])
        tcol = [np.zeros((n, 3, 3)) if c is None else c for (n, _), c in zip(tuv, tcol)]
        tuv = [np.zeros((n, 3, 2)) if u is None else u for n, u in tuv]
        from raybundle.scene.textures import SurfaceTexture

        # albedo maps are the image over its mean (the material holds the mean; a byte sRGB image's
        # texels encoded, as Cycles keeps them), coverage and normal maps as they are
        ordered = sorted(images.values(), key=lambda x: x[0])
        maps = [converter.albedo_map(im) if kind == "albedo" else (np.asarray(converter.image_pixels(im), np.float32),
                                                                   None) for _, im, kind, _ in ordered]
        texture = SurfaceTexture([m for m, _ in maps], face_image, v[t], np.concatenate(tuv), np.concatenate(tcol),
                                 face_alpha, face_normal, face_bump, encoded=[e for _, e in maps],
                                 closest=[closest for *_, closest in ordered])
    with _warnings.catch_warnings(record=True) as caught:
        _warnings.simplefilter("always")
        shading = None
        if all(x is not None for x in tnorm):
            shading = ShadingNormals.of_faces(v[t], np.concatenate(tnorm))
        sc = build_scene(v, t, m, mats, point_lights=group(PointLights, lights["point"]),
                         sun_lights=group(SunLights, lights["sun"]), area_lights=group(AreaLights, lights["area"]),
                         world=world, camera=camera, two_sided=True,
                         triangle_solid=np.zeros(len(t), bool),    # two-sided surfaces are never solids
                         name=name or scene.name, texture=texture, shading=shading,
                         linking=link_sets.linking([(o.original, o.instancer) for o in objects], np.concatenate(tobj),
                                                   np.array(temit, np.int64)))
    for w in caught:
        warn(str(w.message))
    _warn_large_linked_emitters(sc, np.concatenate(tobj), objects, warn)
    _warn_overlaps(v[t], np.concatenate(tobj), objects, warn)
    _warn_curved_glass(sc, np.concatenate(tobj), objects, warn)
    far = float(np.sqrt(((v - camera.position) ** 2).sum(axis=1).max())) if camera is not None else 0.0
    if cam_ob is not None and far > cam_ob.data.clip_end:
        warn(f"camera {cam_ob.name!r}: geometry beyond the clip end ({cam_ob.data.clip_end:g} m) is rendered "
             "(clip end is not modelled)")
    counts = {"objects": len(objects), "triangles": int(len(sc.triangles)), "vertices": int(len(v)),
              "materials": len(mats), "point_lights": len(lights["point"]), "sun_lights": len(lights["sun"]),
              "area_lights": len(lights["area"])}
    return ExportResult(sc, warn, objects, np.concatenate(tobj), np.concatenate(tpoly),
                        np.concatenate(tloops), list(mats.names), size, border,
                        time.perf_counter() - t0, counts)
