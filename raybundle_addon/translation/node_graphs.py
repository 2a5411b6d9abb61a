"""Material inputs driven by node graphs, evaluated by Blender.

A shader's input (Base Color, Roughness, Metallic, Emission Strength, a Mix Shader's factor...)
driven by nodes the converter does not read directly (:func:`.shaders.read_directly`) is
evaluated by Blender, nothing of the graph is reimplemented here.  The graph can be evaluated
when every node in it computes its output from its inputs alone (:data:`PURE`: Math, Vector
Math, Mix, Color Ramp, Hue/Saturation, Brightness/Contrast, Separate/Combine, curves...) or is
an Image Texture read through one UV map: its value is then a function of the UV, which Cycles
bakes (:mod:`.material_bake`, in a process of its own, on a copy of the material) over a unit
square whose UV covers the images once: the graph's exact value at the centres of a grid
:func:`bake_scale` times finer than the largest image, each image read with its own
interpolation.  A non-linear graph of an interpolated image is not the interpolation of the
graph's values at the texels (a checker through a Color Ramp): the finer grid keeps the
difference below the bilinear error of the finer grid where images are small (magnified on
screen), while large images are baked at their own resolution; and no finer than the image
needs for the objects that use the material (:func:`seen_finer`).  A graph without images is a
constant, baked into one texel.

A shader's Normal input (a Normal Map node in tangent space, a Bump node, anything between them
and images read through a UV map) is baked the same way over the unit square, whose frame
(dP/du, dP/dv, N) is the identity there: the normal (x, y, z) as ``(n + 1) / 2``
(:mod:`raybundle.scene.textures` reads it in each face's frame).  A normal graph that reads the
point of the object is not evaluated (it needs the object's own tangent frame).

What the converter does with the baked image (:class:`.shaders.MaterialConverter`): on an
albedo input (a Diffuse BSDF's Color, a Principled BSDF's Base Color) it is an albedo texture
on that UV map, like an image texture linked there directly; on any other input its mean is
the material's value, with a warning when it varies over the surface.

A graph that reads the position on the object (procedural textures, Texture Coordinate's
Generated, Object or Normal, Mapping, Object Info, images through other coordinates:
:data:`POSITIONAL`) is baked on each object that uses the material, through the object's own
UV map where that map lies inside [0, 1] without overlaps (its faces' UV area at most 1), with
a margin of :data:`OBJECT_BAKE_MARGIN` texels around its islands: the albedo texture is then the
object's own, its edges extended.  Its texels follow the object's size in the image
(:func:`object_bake_size`: :data:`TEXELS_PER_PIXEL` for each pixel its bounding box may cover,
between :data:`OBJECT_BAKE_MIN` and :data:`OBJECT_BAKE_SIZE` a side).  Graphs
reading the view or the light (Fresnel, Layer Weight, Light Path, Geometry, Texture
Coordinate's Camera, Window or Reflection), attributes or node groups are not evaluated: the
socket's own value is used, with a warning naming the node.  One process bakes every graph of
a scene; the results are kept on disk (:mod:`.bake_cache`): the same material, object and task
are not baked again.
"""
from __future__ import annotations

import json
import os
from dataclasses import dataclass, field

import numpy as np

from .bake_cache import BakeCache, cache_folder, image_digest, library_digest, task_key
from .blender_process import BlenderProcess, BlenderProcessError, temporary_folder

#: node types whose output is a function of their inputs alone (no position, view, light or attribute)
PURE = frozenset((
    "REROUTE", "MATH", "VECT_MATH", "MIX", "MIX_RGB", "VALTORGB", "HUE_SAT", "BRIGHTCONTRAST", "GAMMA",
    "INVERT", "SEPRGB", "COMBRGB", "SEPARATE_COLOR", "COMBINE_COLOR", "SEPXYZ", "COMBXYZ", "SEPHSV",
    "COMBHSV", "RGB", "VALUE", "CURVE_RGB", "CURVE_FLOAT", "CURVE_VEC", "MAP_RANGE", "CLAMP", "RGBTOBW",
    "BLACKBODY", "WAVELENGTH"))
#: node types whose output depends on the point of the object (baked on the object itself)
POSITIONAL = frozenset((
    "TEX_NOISE", "TEX_VORONOI", "TEX_WAVE", "TEX_MAGIC", "TEX_GRADIENT", "TEX_CHECKER", "TEX_BRICK",
    "TEX_MUSGRAVE", "TEX_WHITE_NOISE", "TEX_GABOR", "TEX_COORD", "MAPPING", "OBJECT_INFO", "VECTOR_ROTATE",
    "UVMAP"))
#: Texture Coordinate outputs that depend on the view: not baked
VIEW_COORDINATES = frozenset(("Camera", "Window", "Reflection"))
#: texels a side of a graph baked on an object: at most, at least, and per pixel it may cover
OBJECT_BAKE_SIZE, OBJECT_BAKE_MIN, TEXELS_PER_PIXEL = 1024, 128, 16
#: texels the bake extends an object's UV islands by (bilinear lookups at their edges read them)
OBJECT_BAKE_MARGIN = 2
#: shader nodes whose color and value inputs the converter reads
READ_SHADERS = frozenset(("BSDF_DIFFUSE", "BSDF_GLOSSY", "BSDF_ANISOTROPIC", "EMISSION", "MIX_SHADER",
                          "BSDF_PRINCIPLED"))
#: texels a graph's bake aims at: images smaller than this are baked on a grid up to
#: :data:`MAX_BAKE_SCALE` times finer in each axis
BAKE_TEXELS = 1_000_000
MAX_BAKE_SCALE = 8
#: ... and an image read through a tiling Mapping as many times finer again as it repeats, up to
#: this many texels a side
MAX_BAKE_SIDE = 4096
#: seconds before the bake is given up
BAKE_TIMEOUT = 300.0

@dataclass
class GraphInput:
    """An input socket whose graph Blender bakes: ``material`` (its ``name_full``), ``node``
    (name) and ``socket`` (identifier); ``images``: Image Texture node name -> bpy Image;
    ``uv``: the UV map they are read through ("" the active render one); ``size`` (W, H)."""

    material: str
    node: str
    socket: str
    images: dict = field(default_factory=dict)
    uv: str = ""
    size: tuple = (1, 1)
    #: baked on each object that uses the material (the graph reads the point of the object)
    per_object: bool = False
    #: how many times finer than its images' texels (and their tiling) ``size`` is in each axis
    finer: int = 1

    @property
    def key(self):
        return (self.material, self.node, self.socket)


def socket_key(mat, sock):
    """The key of ``sock`` (an input of a node of material ``mat``) among the baked graphs."""
    return (mat.name_full, sock.node.name, sock.identifier)


def graph_input(mat, sock):
    """The :class:`GraphInput` of the graph that drives input ``sock`` of material ``mat``, or a
    one-line reason why Blender cannot evaluate it over a UV map."""
    from .node_links import follow_reroutes, uv_source, uv_through

    images, uvs, seen, positional, tiling = {}, set(), set(), False, 1.0
    stack = [sock.links[0]]
    while stack:
        link = stack.pop()
        node = follow_reroutes(link.from_node)
        if node is None or node.name in seen:
            continue
        if node.type == "TEX_COORD" and link.from_socket.name in VIEW_COORDINATES:
            return f"it reads Texture Coordinate's {link.from_socket.name}, which depends on the view"
        seen.add(node.name)
        if node.type == "TEX_IMAGE":
            if node.image is None:
                return f"the Image Texture {node.name!r} has no image"
            images[node.name] = node.image
            uv = uv_source(node)
            through = uv_through(node) if uv is None else None
            if through is not None:         # a tiled or offset UV: still a function of the map
                uv, tiling = through[0], max(tiling, through[1])
            if uv is None or getattr(node, "projection", "FLAT") != "FLAT":
                positional = True           # read through other coordinates: baked on the object
            else:
                uvs.add(uv)
                continue
        elif node.type in POSITIONAL:
            positional = True
        elif node.type == "NORMAL_MAP":
            if node.space != "TANGENT":
                return f"its Normal Map node is in {node.space.lower()} space (only tangent space is modeled)"
            if node.uv_map:                 # "" is the active render map, as an image's own
                uvs.add(node.uv_map)
        elif node.type not in PURE and node.type != "BUMP":       # a Bump: a function of its inputs' slopes
            return f"it reads a {node.bl_label} node, which depends on the view, the light or more than the point"
        stack += [lk for s in node.inputs for lk in s.links
                  if not getattr(lk, "is_muted", False) and getattr(lk, "is_valid", True)]
    if positional and sock.type == "VECTOR":
        return "it reads the point of the object (a procedural bump), which needs the object's own tangent frame"
    if positional:
        return GraphInput(mat.name_full, sock.node.name, sock.identifier, images, "",
                          (OBJECT_BAKE_SIZE, OBJECT_BAKE_SIZE), per_object=True)
    if len(uvs) > 1:
        return "its images are read through different UV maps"
    size = (1, 1)
    for im in images.values():
        w, h = im.size
        if w * h > size[0] * size[1]:
            size = (int(w), int(h))
    k = 1
    if images:
        k = bake_scale(size)
        t = int(np.clip(np.ceil(tiling), 1, max(1, MAX_BAKE_SIDE // max(size[0] * k, size[1] * k))))
        size = (size[0] * k * t, size[1] * k * t)
    return GraphInput(mat.name_full, sock.node.name, sock.identifier, images, uvs.pop() if uvs else "", size,
                      finer=k)


def bake_scale(size):
    """How many times finer than an image of ``size`` (W, H) texels its graph is baked in each
    axis: the largest k <= :data:`MAX_BAKE_SCALE` with k^2 W H <= :data:`BAKE_TEXELS`, at least 1."""
    w, h = size
    return int(np.clip(np.floor(np.sqrt(BAKE_TEXELS / max(w * h, 1))), 1, MAX_BAKE_SCALE))


def linked_inputs(mat):
    """The color and value inputs (sockets) of the shaders of ``mat`` that the converter reads,
    linked to nodes it does not read directly."""
    from .node_links import follow_reroutes
    from .shaders import read_directly

    nt = getattr(mat, "node_tree", None)
    out = None if nt is None else (nt.get_output_node("CYCLES") or nt.get_output_node("ALL"))
    if out is None or not out.inputs["Surface"].is_linked:
        return []
    found, seen, stack = [], set(), [out.inputs["Surface"]]
    while stack:
        sock = stack.pop()
        node = follow_reroutes(sock.links[0].from_node) if sock.is_linked else None
        if node is None or node.name in seen or node.type not in READ_SHADERS:
            continue
        seen.add(node.name)
        for s in node.inputs:
            if not s.is_linked:
                continue
            if s.type == "SHADER":
                stack.append(s)
            elif s.type in ("RGBA", "VALUE"):
                src = follow_reroutes(s.links[0].from_node)
                if src is not None and not read_directly(s, src):
                    found.append(s)
            elif s.type == "VECTOR" and s.name == "Normal":       # a normal or bump map
                found.append(s)
    return found


class GraphBake:
    """The graphs of a scene's materials baked by Blender (:func:`start_graph_bake`);
    :meth:`get` waits for the bake the first time."""

    def __init__(self, inputs, reasons, job=None, results=None, objects=None, uv_of=None, kept=None):
        self._inputs, self._reasons, self._job = inputs, reasons, job
        self._results = results
        #: (bakes read from the disk, each input's cache key, the :class:`.bake_cache.BakeCache`)
        self._kept = kept
        #: per-object inputs' key -> the keys of its objects' bakes (key + object name)
        self._objects = objects or {}
        self._uv_of = uv_of or {}
        #: None, or the one-line reason the bake failed
        self.failed = None

    def get(self, mat, sock):
        """(H, W, 3) float32 linear values of the graph driving ``sock`` over its UV map (row
        0 at the bottom), or a one-line reason why there are none; for a graph baked on each
        object (:attr:`GraphInput.per_object`) a dict object name -> those values or a reason."""
        key = socket_key(mat, sock)
        if key in self._reasons:
            return self._reasons[key]
        if key not in self._inputs:
            return "it was not evaluated"
        if self._results is None:
            self._finish()
        failed = None if self.failed is None else f"Blender could not bake it ({self.failed})"
        if self._inputs[key].per_object:       # a failed bake leaves those read from the disk
            return {k[3]: self._results.get(k, self._reasons.get(k, failed)) for k in self._objects.get(key, [])}
        return self._results.get(key, failed)

    def bakes(self, mat):
        """Whether Blender is still baking graphs and one of them is of material ``mat`` (reading
        it would wait for the bake)."""
        return self._job is not None and any(k[0] == mat.name_full for k in self._inputs)

    def uv(self, mat, sock, obj=None):
        """The UV map the graph of ``sock`` is baked over ("" the active render one); on object
        ``obj`` (name) for a graph baked on each object."""
        key = socket_key(mat, sock)
        return self._uv_of.get(key + (obj,), "") if obj is not None else self._inputs[key].uv

    def _finish(self):
        job, paths = self._job
        try:
            job.wait(list(paths.values()))
            baked = {k: np.load(p) for k, p in paths.items()}
            kept, keys, cache = self._kept
            if cache.folder is not None:
                cache.store({keys[k]: v for k, v in baked.items()})
            self._results = {**kept, **baked}
        except (BlenderProcessError, OSError, ValueError) as e:
            self.failed = str(e)
            self._results = dict(self._kept[0])
        finally:
            job.close()
            self._job = None

    def cancel(self):
        if self._job is not None:
            self._job[0].close()
            self._job = None


def texels_seen(ob, camera, uv_area):
    """Texels of the unit square a graph baked over ``ob``'s UV map needs in ``camera``'s image
    (:class:`~raybundle.scene.camera.Camera`): :data:`TEXELS_PER_PIXEL` for each pixel its bounding
    box may cover (the whole image where the box reaches behind the camera), over ``uv_area``,
    the area of the unit square its UV map covers (more than 1 where it tiles); infinite
    without a camera."""
    if camera is None:
        return np.inf
    m = np.array(ob.matrix_world, float)
    corners = np.array([tuple(c) for c in ob.bound_box], float) @ m[:3, :3].T + m[:3, 3]
    px, py, _, _, density = camera.project(corners)
    if np.any(density <= 0):
        pixels = camera.width * camera.height
    else:
        pixels = ((np.clip(px.max(), 0, camera.width) - np.clip(px.min(), 0, camera.width))
                  * (np.clip(py.max(), 0, camera.height) - np.clip(py.min(), 0, camera.height)))
    return TEXELS_PER_PIXEL * pixels / max(uv_area, 1 / 64)


def object_bake_size(ob, camera, uv_area):
    """Texels a side of a graph baked on object ``ob`` (a bpy Object), as many as
    :func:`texels_seen` (``uv_area``: the share of the unit square its UV map covers), between
    :data:`OBJECT_BAKE_MIN` and :data:`OBJECT_BAKE_SIZE`, the largest without a camera."""
    side = np.sqrt(texels_seen(ob, camera, uv_area))
    return int(np.clip(16 * np.ceil(min(side, OBJECT_BAKE_SIZE) / 16), OBJECT_BAKE_MIN, OBJECT_BAKE_SIZE))


def seen_finer(g, objects, camera):
    """How many times finer than its images' texels (at most ``g.finer``) graph ``g``, baked once
    over the unit square for ``objects`` (those using its material), is baked in ``camera``'s
    image: the grid finer than the images serves non-linear graphs of images magnified on
    screen, and no finer than the objects' :func:`texels_seen` needs."""
    if camera is None or g.finer <= 1 or not objects:
        return g.finer
    need = np.sqrt(sum(texels_seen(ob, camera, uv_map_area(ob, g.uv)) for ob in objects))
    own = max(g.size) / g.finer
    return int(np.clip(np.ceil(need / own), 1, g.finer)) if np.isfinite(need) else g.finer


def uv_map_area(ob, name=""):
    """The area of the unit square object ``ob``'s UV map ``name`` ("" its active render one)
    covers, overlaps and tiles counted (0 without that map)."""
    me = getattr(ob, "data", None)
    layers = getattr(me, "uv_layers", None)
    layer = None if not layers else (layers.get(name) if name else
                                     next((l for l in layers if l.active_render), layers.active))
    return 0.0 if layer is None else _uv_area(me, layer)[1]


def _uv_area(me, layer):
    """``(uv (L, 2), area)``: mesh ``me``'s UVs of ``layer`` per loop and its faces' UV area."""
    uv = np.empty(2 * len(me.loops), np.float32)
    layer.uv.foreach_get("vector", uv)
    uv = uv.reshape(-1, 2).astype(float)
    if len(uv) == 0:
        return uv, 0.0
    start = np.empty(len(me.polygons), np.int64)
    me.polygons.foreach_get("loop_start", start)
    nxt = np.arange(len(uv)) + 1
    ends = np.r_[start[1:], len(uv)]
    nxt[ends - 1] = start                       # each polygon's loop closes on its first corner
    cross = uv[:, 0] * uv[nxt, 1] - uv[nxt, 0] * uv[:, 1]
    return uv, float(np.abs(np.add.reduceat(cross, start)).sum() / 2)


def object_uv(ob):
    """``(name, reason, area)``: the UV map of object ``ob`` a graph is baked through (its active
    render one) and the share of the unit square its faces cover, or None, a one-line reason why
    there is none and 0: the map must lie inside [0, 1] with its faces' UV area at most 1 (no
    overlaps, no tiling)."""
    me = getattr(ob, "data", None)
    layers = getattr(me, "uv_layers", None)
    layer = None if not layers else next((l for l in layers if l.active_render), layers.active)
    if layer is None:
        return None, f"object {ob.name!r} has no UV map to bake it through", 0.0
    uv, area = _uv_area(me, layer)
    if len(uv) == 0:
        return None, f"object {ob.name!r} has no faces", 0.0
    if uv.min() < -1e-6 or uv.max() > 1 + 1e-6 or area > 1 + 1e-3:
        return None, (f"object {ob.name!r}'s UV map {layer.name!r} leaves [0, 1] or overlaps itself (UV area "
                      f"{area:.3g}): its graph needs a map that covers it once"), 0.0
    return layer.name, None, area


def _graph_inputs(materials, users, camera):
    """What :func:`start_graph_bake` bakes: ``(inputs, reasons, originals, objects, uv_of,
    size_of, bake_objects)``, the graph inputs Blender can evaluate by key, why the others cannot
    be (key -> reason), the original of each material, the per-object keys of each graph baked on
    each object (``users``: material name -> its objects), each such key's UV map and texels a
    side (seen by ``camera``, :func:`object_bake_size`), and those objects by name."""
    objects, uv_of, size_of, bake_objects = {}, {}, {}, {}
    inputs, reasons, originals = {}, {}, {}
    for mat in dict.fromkeys(m for m in materials if m is not None):
        for sock in linked_inputs(mat):
            got = graph_input(mat, sock)
            if isinstance(got, str):
                reasons[socket_key(mat, sock)] = got
            else:
                inputs[got.key] = got
                originals[mat.name_full] = getattr(mat, "original", mat)
                if not got.per_object and got.finer > 1:
                    finer = seen_finer(got, users.get(mat.name_full, []), camera)
                    got.size = tuple(side // got.finer * finer for side in got.size)
                if got.per_object:
                    objects[got.key] = []
                    for ob in users.get(mat.name_full, []):
                        where, why, area = object_uv(ob)
                        key = got.key + (ob.name_full,)
                        objects[got.key].append(key)
                        if where is None:
                            reasons[key] = why
                        else:
                            uv_of[key] = where
                            size_of[key] = object_bake_size(ob, camera, area)
                            bake_objects[ob.name_full] = ob
    return inputs, reasons, originals, objects, uv_of, size_of, bake_objects


def start_graph_bake(materials, users=None, threads=0, camera=None):
    """Begin baking the graphs Blender can evaluate on the inputs of ``materials`` (bpy
    Materials, None skipped) in one process on ``threads`` CPU threads (0: all): a
    :class:`GraphBake`.  ``users``: material name -> the objects that use it (their originals),
    for graphs baked on each object, as finely as ``camera`` (the exported
    :class:`~raybundle.scene.camera.Camera`, or None) sees them.  Graphs baked before from the
    same material, object and task are read from the disk (:mod:`.bake_cache`)."""
    inputs, reasons, originals, objects, uv_of, size_of, bake_objects = _graph_inputs(materials, users or {},
                                                                                     camera)
    if not inputs:
        return GraphBake(inputs, reasons, results={})
    folder = temporary_folder("raybundle-graphs-")
    try:
        cache = BakeCache(cache_folder())
        results, tasks, paths, keys = _kept_and_tasks(inputs, reasons, originals, objects, uv_of, size_of,
                                                      bake_objects, folder.name, cache)
        for k in [k for k in inputs if k in reasons]:
            del inputs[k]
        if not tasks:
            folder.cleanup()
            return GraphBake(inputs, reasons, results=results, objects=objects, uv_of=uv_of)
        import bpy

        library = os.path.join(folder.name, "materials.blend")
        bpy.data.libraries.write(library, {originals[t["key"][0]] for t in tasks}
                                 | {bake_objects[t["key"][3]] for t in tasks if len(t["key"]) > 3},
                                 path_remap="ABSOLUTE", fake_user=True)
        with open(os.path.join(folder.name, "job.json"), "w") as f:
            json.dump(dict(tasks=[{k: v for k, v in t.items() if k != "key"} for t in tasks]), f)
        job = BlenderProcess("material_bake.py", [library, os.path.join(folder.name, "job.json"), str(int(threads))],
                             folder, BAKE_TIMEOUT)
    except (RuntimeError, OSError, BlenderProcessError) as e:
        folder.cleanup()
        bake = GraphBake(inputs, reasons, results={}, objects=objects)
        bake.failed = str(e)
        return bake
    return GraphBake(inputs, reasons, job=(job, paths), objects=objects, uv_of=uv_of, kept=(results, keys, cache))


def _kept_and_tasks(inputs, reasons, originals, objects, uv_of, size_of, bake_objects, folder, cache):
    """``(kept, tasks, paths, keys)``: the bakes of :func:`start_graph_bake`'s ``inputs`` read
    from ``cache`` (key -> values), the bake script's tasks for the others (each with its
    ``key``), their output paths and cache keys (key -> each); an image without pixels adds
    its input's reason to ``reasons``."""
    from .images import image_rgba

    kept, tasks, paths, keys, files, digests = {}, [], {}, {}, {}, {}

    def digest(what, make):
        if what not in digests:
            digests[what] = make()
        return digests[what]

    for g in inputs.values():
        mat = originals[g.material]
        images = {node: digest(("image", im.name_full), lambda im=im: image_digest(im))
                  for node, im in g.images.items()} if cache.folder is not None else {}
        task = dict(material=mat.name, node=g.node, socket=g.socket, size=list(g.size), uv_maps=[g.uv])
        pending = []
        for key in objects.get(g.key, []) if g.per_object else [g.key]:
            if key in reasons:
                continue
            own = task if not g.per_object else dict(task, object=bake_objects[key[3]].name, uv_maps=[uv_of[key]],
                                                      size=[size_of[key]] * 2, margin=OBJECT_BAKE_MARGIN)
            got = None
            if cache.folder is not None:                      # no digests where nothing is kept
                ids = (mat,) if not g.per_object else (bake_objects[key[3]],)
                lib = digest(ids, lambda ids=ids: library_digest(ids, os.path.join(folder, "digest.blend")))
                keys[key] = task_key(own, [lib, sorted(images.items(), key=str)])
                got = cache.load(keys[key], own["size"][::-1])
            if got is not None:
                kept[key] = got
            else:
                pending.append((key, own))
        if not pending:
            continue
        task_images = {}
        for node, im in g.images.items():
            if im.name_full not in files:
                px = image_rgba(im)
                if px is None:
                    break
                files[im.name_full] = os.path.join(folder, f"image{len(files)}.npy")
                np.save(files[im.name_full], px)
            task_images[node] = files[im.name_full]
        else:
            for key, own in pending:
                paths[key] = os.path.join(folder, f"bake{len(paths)}.npy")
                tasks.append(dict(own, images=task_images, out=paths[key], key=key))
            continue
        reasons[g.key] = f"the image {im.name!r} has no pixel data"
    return kept, tasks, paths, keys
