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

Lights
    :mod:`.lights` (Blender's units, as Cycles converts them), each light's node tree
    :mod:`.light_nodes`, light and shadow linking :mod:`.light_linking`.  A light portal (an area
    light with Portal on) guides Cycles' sampling of the world and emits nothing: it is left out
    (noted once), since bundles reach the world through the openings without it.

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

import time
from dataclasses import dataclass, field

import numpy as np

from .images import loaded_while_read
from .light_linking import LinkSets
from .lights import convert_light
from .mesh_data import mesh_arrays, texture_uvs
from .node_graphs import start_graph_bake
from .scene_builder import SceneBuilder
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
    """Warn about object ``ob``'s settings that change Cycles' image and are not modeled: the
    shadow terminator's normal and shading offsets other than Blender's defaults (0); its
    geometry offset is modeled (:func:`geometry_offset`)."""
    cy = getattr(ob, "cycles", None)
    found = [getattr(holder, k, 0.0) for holder, k in (
        (ob, "shadow_terminator_normal_offset"), (ob, "shadow_terminator_shading_offset"),
        (cy, "shadow_terminator_offset"))]
    if any(abs(v) > 1e-6 for v in found):
        warn(f"object {ob.name!r}: shadow terminator normal and shading offsets are not modeled")


def geometry_offset(ob):
    """Object ``ob``'s Shadow Terminator Geometry Offset, as Cycles reads it: the object's own
    property where Blender has one (5.x; its ``cycles`` group keeps an unused copy), else its
    ``cycles`` group's (4.2)."""
    from raybundle.scene.shading import DEFAULT_GEOMETRY_OFFSET

    if hasattr(ob, "shadow_terminator_geometry_offset"):
        return float(ob.shadow_terminator_geometry_offset)
    return float(getattr(getattr(ob, "cycles", None), "shadow_terminator_geometry_offset", DEFAULT_GEOMETRY_OFFSET))


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
    area = np.bincount(inv.reshape(-1), a)
    # each plane's normal and its opposite as ids of one table; the planes sorted by (normal, offset)
    nid = np.unique(np.vstack([planes[:, :3], -planes[:, :3]]), axis=0, return_inverse=True)[1].reshape(-1)
    own, opposite = nid[:len(planes)], nid[len(planes):]
    off = planes[:, 3]
    lo_off, span = off.min(), int(off.max() - off.min()) + 1
    order = np.lexsort((off, own))
    key = own[order] * span + (off[order] - lo_off)
    # the nearest of the opposite normal's planes to the offset -off (a pane's other face)
    first = np.searchsorted(key, opposite * span, "left")
    last = np.searchsorted(key, opposite * span + span - 1, "right")
    at = np.searchsorted(key, opposite * span + np.clip(-off, lo_off, lo_off + span - 1) - lo_off)
    gap = np.full(len(planes), np.inf)
    for cand in (at - 1, at):
        ok = (cand >= first) & (cand < last)
        c = np.where(ok, cand, 0)
        gap = np.where(ok, np.minimum(gap, np.abs(off[order[c]] + off) * 1e-4), gap)
    paired = gap < PANE_THICKNESS * np.sqrt(area)
    return float(area[paired].sum() / max(area.sum(), 1e-300))


def _warn_curved_glass(sc, tobj, objects, warn):
    """One warning naming the objects whose transmissive faces are not panes (:func:`_pane_share`
    below :data:`FLAT_GLASS`): light passes them unbent (:mod:`raybundle.scene.transmission`), so
    their caustic is spread as a soft shadow."""
    glass = np.nonzero(sc.materials.transmits[sc.triangle_material])[0]
    if len(glass) == 0:
        return
    owner = tobj[sc.triangle_source[glass]]
    glass = glass[np.argsort(owner, kind="stable")]
    owners, start = np.unique(np.sort(owner), return_index=True)
    curved = [objects[o].original for o, g in zip(owners.tolist(), np.split(glass, start[1:]))
              if _pane_share(sc.triangle_normal[g], sc.triangle_area[g], sc.triangle_corners[g]) < FLAT_GLASS]
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
    if defer_world and pending.running:
        result.world_render = pending
    return result


def _export_geometry(depsgraph, scene, warn, cam_ob, camera, size, border, name, world, t0):
    """:func:`export_scene`'s objects, lights and materials, with the camera and world made;
    Blender bakes the node graphs on the materials' inputs meanwhile (:mod:`.node_graphs`)."""
    override = getattr(depsgraph.view_layer, "material_override", None)
    materials, users = _used_materials(depsgraph, override)
    with loaded_while_read():             # the images' pixels are read into the scene's arrays
        graphs = start_graph_bake(materials, users, camera=camera)
        try:
            converter = MaterialConverter(warn, graphs)
            for m in materials:         # while Blender bakes: those that do not wait for it (their images decoded)
                if not graphs.bakes(m):
                    converter.convert_ahead(m)
            return _export_objects(depsgraph, scene, warn, cam_ob, camera, size, border, name, world, t0,
                                   converter, override)
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
    from raybundle.scene.model import SceneError

    viewport = depsgraph.mode == "VIEWPORT"
    build = SceneBuilder(converter)
    link_sets = LinkSets()
    light_nodes, portals, meshes = {}, [], {}     # a light data-block's node tree reading; meshes read
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
            _export_light(ob, M, build, link_sets, light_nodes, portals, warn)
            continue
        if not inst.is_instance:
            _unmodeled_features(ob.original, warn)
            _object_settings(ob.original, warn)
        if inst.show_self and _ray_visible(ob, warn):
            _export_mesh(inst, ob, M, build, link_sets, meshes, override, warn)
    if portals:
        warn(f"light portal{'s' if len(portals) > 1 else ''} {', '.join(repr(p) for p in portals[:3])}"
             f"{' ...' if len(portals) > 3 else ''}: a portal guides Cycles' sampling of the world and emits "
             "nothing; left out (bundles reach the world through the openings without it)")
    if build.n_triangles == 0:
        raise SceneError("nothing to render: the scene has no visible mesh objects")
    if scene.render.use_motion_blur:
        warn("motion blur is not supported: the scene is rendered at the current frame")
    if scene.render.film_transparent:
        warn("transparent film is not supported: the background is the world's color, alpha is 1")
    sc, v, t, mats = build.scene(world, camera, name or scene.name, link_sets, warn)
    tobj, objects = build.triangle_object(), build.objects
    _warn_large_linked_emitters(sc, tobj, objects, warn)
    _warn_overlaps(v[t], tobj, objects, warn)
    _warn_curved_glass(sc, tobj, objects, warn)
    far = float(np.sqrt(((v - camera.position) ** 2).sum(axis=1).max())) if camera is not None else 0.0
    if cam_ob is not None and far > cam_ob.data.clip_end:
        warn(f"camera {cam_ob.name!r}: geometry beyond the clip end ({cam_ob.data.clip_end:g} m) is rendered "
             "(clip end is not modelled)")
    lights = build.lights
    counts = {"objects": len(objects), "triangles": int(len(sc.triangles)), "vertices": int(len(v)),
              "materials": len(mats), "point_lights": len(lights["point"]), "sun_lights": len(lights["sun"]),
              "area_lights": len(lights["area"])}
    return ExportResult(sc, warn, objects, tobj, build.joined("polygons"), build.joined("loops"), list(mats.names),
                        size, border, time.perf_counter() - t0, counts)


def _export_light(ob, M, build, link_sets, light_nodes, portals, warn):
    """Light object ``ob`` (world matrix ``M``) into ``build.lights``, unless no diffuse or glossy
    ray sees it, or it is a portal (its name added to ``portals``)."""
    rays = [getattr(ob, f"visible_{k}", True) for k in ("diffuse", "glossy", "transmission")]
    if not (rays[0] or rays[1]):
        return
    if not all(rays):
        off = ", ".join(k for k, on in zip(("diffuse", "glossy", "transmission"), rays) if not on)
        warn(f"light {ob.original.name!r}: ray visibility ({off} off) is not supported; "
             "it lights every surface as if all were on")
    if getattr(getattr(ob.data, "cycles", None), "is_portal", False):
        portals.append(ob.original.name)
        return
    got = convert_light(ob.data, M, warn, light_nodes)
    bounces = getattr(getattr(ob.data, "cycles", None), "max_bounces", 1024)
    if bounces < 1024:
        warn(f"light {ob.original.name!r}: its max bounces ({bounces}) is not applied: raybundle renders every "
             "bounce of its light")
    if got is not None:
        got[1]["link"] = link_sets.set_of(ob.original)
        build.lights[got[0]].append(got[1])


def _export_mesh(inst, ob, M, build, link_sets, meshes, override, warn):
    """Mesh-like object instance ``inst`` (object ``ob``, world matrix ``M``) into ``build``: its
    evaluated mesh's arrays (read once per mesh data-block, kept in ``meshes``; other types
    through a temporary mesh), without the faces of volume-only materials."""
    me, temp = (ob.data, False) if ob.type == "MESH" else (None, True)
    if temp:
        try:
            me = ob.to_mesh()
        except RuntimeError:
            me = None
        if me is None:
            return
    try:
        key = me.as_pointer()
        arrays = meshes.get(key) if not temp else None
        if arrays is None:
            arrays = mesh_arrays(me)
            if not temp:
                meshes[key] = arrays
        pos, tri, loops, tp, mi, cn = arrays
        slots = [s.material for s in ob.material_slots] if len(ob.material_slots) else list(me.materials)
        if override is not None:
            slots = [override] * max(1, len(slots))
        left_out = [build.converter.left_out(m) for m in slots]
        if any(left_out):                     # faces of a volume without a surface
            keep = ~np.array(left_out)[np.clip(mi[tp], 0, len(slots) - 1)]
            tri, loops, tp = tri[keep], loops[keep], tp[keep]
        textured = texture_uvs(me, ob, slots, tp, mi, loops, build.converter, build.images, warn)
        info = ObjectInfo(ob.name, ob.original.name, me.name, bool(inst.is_instance),
                          inst.parent.name if inst.is_instance and inst.parent else None,
                          build.n_triangles, len(tri), len(me.polygons), len(me.loops), M)
    finally:
        if temp:
            ob.to_mesh_clear()
    if len(tri):
        build.add_object(info, (pos, tri, loops, tp, mi, cn), M, slots, textured, link_sets.set_of(ob.original),
                         geometry_offset(ob.original))
