"""Blender shader node trees -> the core's material parameters (no rendering here).

The core's material (:class:`raybundle.scene.materials.MaterialTable`) is one
Lambert + GGX mix with emission, optionally with the Principled BSDF's layered
model.  A material's node tree is read from its Cycles output node:

* **Diffuse BSDF**: diffuse color (Oren-Nayar roughness is ignored, warned).
* **Glossy / Anisotropic BSDF**: a GGX lobe with tint and roughness (anisotropy
  ignored, warned; Beckmann and Ashikhmin-Shirley are approximated by GGX, warned;
  Multiscatter GGX maps to the core's energy compensation where it has it).
* **Mix Shader** and **Add Shader** of these: flattened into one Lambert + GGX mix.
  With ``D`` the summed diffuse albedo and ``G`` the summed glossy tint (each
  closure weighted by its mix factors), the core's weight is
  ``g = max(G) / (max(G) + max(D))`` and ``kd = D / (1 - g)``, ``ks = G / g``,
  so ``(1 - g) kd = D`` and ``g ks = G`` exactly; glossy roughness is the
  tint-weighted mean of the lobes' roughness.  A sum above 1 (an Add Shader of
  two reflective closures) creates energy: it is clipped, with a warning.
* **Emission**: radiance = Color x Strength [W m^-2 sr^-1], from both sides.
* **Principled BSDF**: :func:`.closures.principled_to_material` (the one place that maps it).
* An **Image Texture** on a Diffuse BSDF's Color or a Principled BSDF's Base Color,
  looked up through a UV map (the Vector input unlinked, or from a UV Map node or
  Texture Coordinate's UV; through vector nodes from one, Blender bakes it, below), is an albedo texture (:attr:`MaterialConverter.textures`,
  :mod:`raybundle.scene.textures`): the material holds the image's mean linear color, each
  patch its mean over the patch, and images and bakes its detail.  A **Color Attribute**
  node there is the albedo per point the same way (the material white, times the
  attribute's color interpolated over each face).  On any other
  color input an image texture is its mean color (warned); an **RGB** / **Value** node
  gives its value.
* A Principled BSDF's **Alpha** below 1, a constant or a node graph Blender bakes (an image's
  alpha through a UV map), is a cut-out (:attr:`MaterialConverter.cutouts`, the coverage of
  :mod:`raybundle.scene.textures`): light passes where it is cut out.  So is a **Mix Shader**
  of a Transparent BSDF and another shader: its factor is the other's coverage (the
  Transparent BSDF's color is not modeled, warned).
* Any input driven by other nodes is evaluated by Blender where the graph is a function of a
  UV map, or of the point of an object whose UV map covers it once (:mod:`.node_graphs`): an
  albedo texture on an albedo input (the object's own for a graph baked on each object), its
  mean elsewhere.
* A **Glass**, **Refraction** or **Transparent BSDF**, or a Principled BSDF's **Transmission
  Weight** (tinted by its Base Color, the rest of it opaque), is a dielectric interface over
  its share of the surface (:mod:`raybundle.scene.transmission`): its weight, IOR (1 for
  Transparent), roughness, refraction and reflection tints (none reflected by a Refraction
  BSDF, which takes no Fresnel loss either).
* A **Translucent BSDF**: its color (times its mix weight) is the light one side lets through
  to the other, diffusely (``translucent``).
* Anything else (Subsurface, Holdout, groups...) makes the
  whole material fall back to its viewport color (``Material.diffuse_color``) as a
  Diffuse BSDF, with one warning naming the material.  A material without nodes
  is its viewport color (as Cycles does).  No material at all: grey 0.8.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from raybundle.scene.materials import color_text
from raybundle.scene.textures import half_precision, modulation_map

from .closures import Closures, clip_colors, flatten, luminance, principled_to_material
from .images import byte_mean, image_bytes, linear_pixels, srgb_bytes
from .node_links import follow_reroutes, uv_source, uv_through

#: the diffuse color of faces without a material (Blender's default surface)
DEFAULT_GREY = 0.8
#: glass rougher than this with Multiscatter GGX is warned about: single scattering loses some of its light
MULTISCATTER_GLASS = 0.1


class Unsupported(Exception):
    """A node the core cannot model; the material falls back to its viewport color."""


@dataclass(frozen=True)
class EvaluatedImage:
    """Stands for the image Blender baked of a node graph (:mod:`.node_graphs`) where an
    :class:`AlbedoTexture` names an image; its pixels are the converter's."""

    name_full: str

    @property
    def name(self):
        return self.name_full


@dataclass(frozen=True)
class Coverage:
    """A material's cut-out (a Principled BSDF's Alpha below 1, a Mix with a Transparent BSDF):
    the coverage map ``image``
    (an :class:`EvaluatedImage`) read through UV map ``uv`` ("" the active render one; None for
    a constant coverage, which needs no UV map)."""

    image: object
    uv: str | None = None


@dataclass(frozen=True)
class NormalMap:
    """A material's normal or bump map: ``image`` (an :class:`EvaluatedImage`) holds the normal
    its nodes give over a unit square (x, y, z in the frame dP/du, dP/dv, N of one metre per UV
    unit), read through UV map ``uv`` ("" the active render one); ``bump``: a Bump node's, whose
    slope scales with the surface's metres per UV unit (:mod:`raybundle.scene.textures`)."""

    image: object
    uv: str = ""
    bump: bool = False


@dataclass(frozen=True)
class AlbedoTexture:
    """What drives a material's diffuse albedo point by point: an image through a UV map
    (``uv`` the map's name, "" for the active render UV map) or a color attribute
    (``attribute`` its name, "" for the active render one); ``closest``: the Image Texture node
    reads the nearest texel (Closest interpolation), else it interpolates linearly; ``extend``: beyond
    the image's edges its edge texels are read (Extend extension, a graph baked on one object), else
    it repeats."""

    image: object = None
    uv: str = ""
    attribute: str | None = None
    closest: bool = False
    extend: bool = False

    @property
    def key(self):
        return (("attribute", self.attribute) if self.attribute is not None else
                (self.image.name_full, self.uv, self.closest, self.extend))


class MaterialConverter:
    """Converts Blender materials to :meth:`MaterialTable.from_list` specs.

    ``warn(message)`` collects warnings; each material is converted once (cache), ahead of its
    use by :meth:`convert_ahead` too.
    """

    def __init__(self, warn, graphs=None):
        self.warn = warn
        #: the node graphs Blender evaluated (:class:`.node_graphs.GraphBake`), or None
        self.graphs = graphs
        self._material = None
        self._cache = {}
        self._held = {}                 # material name -> the warnings of a conversion made ahead
        self._image_pixels, self._image_bytes = {}, {}       # the latter: byte sRGB images' bytes
        #: material name -> its :class:`AlbedoTexture`
        self.textures = {}
        #: material name -> its :class:`Coverage` (cut-out materials only)
        self.cutouts = {}
        #: material name -> its :class:`NormalMap` (materials with a normal or bump map only)
        self.normal_maps = {}
        #: names of the materials with a volume and no surface shader: their faces are left out
        self.volume_only = set()
        #: (object name, material name) -> the :class:`AlbedoTexture` Blender baked on that object
        self.object_textures = {}
        self._normalizer = {}           # image name -> the material's mean albedo its map divides by
        self._albedo = []               # albedo textures met while converting one material
        self._cutout = []               # coverages met while converting one material
        self._normal = []               # normal maps met while converting one material

    # ------------------------------------------------------------ materials
    def convert(self, mat):
        """The spec dict of ``mat`` (a bpy Material or None); its warnings are told now, the
        first time it is asked for."""
        key = None if mat is None else mat.name_full
        if key not in self._cache:
            self._cache[key] = self._convert(mat)
        for message in self._held.pop(key, ()):
            self.warn(message)
        return self._cache[key]

    def convert_ahead(self, mat):
        """Convert ``mat`` (a bpy Material) before it is needed, keeping its warnings until
        :meth:`convert` asks for it (a material no exported object uses warns of nothing)."""
        if mat.name_full in self._cache:
            return
        warn, held = self.warn, []
        self.warn = held.append
        try:
            self._cache[mat.name_full] = self._convert(mat)
        finally:
            self.warn = warn
        self._held[mat.name_full] = held

    def _convert(self, mat):
        if mat is None:
            return dict(name="(no material)", diffuse=(DEFAULT_GREY,) * 3)
        name = mat.name_full
        nt = mat.node_tree
        if nt is None:
            return self._viewport(mat)
        out = nt.get_output_node("CYCLES") or nt.get_output_node("ALL")
        if out is not None and not out.inputs["Surface"].is_linked and out.inputs["Volume"].is_linked:
            self.warn(f"material {name!r}: volumes are not modeled: its faces, which have no surface shader, are left "
                      "out (Cycles renders the volume inside them)")
            self.volume_only.add(name)
            return dict(name=name)
        if out is not None:
            for socket in ("Volume", "Displacement"):
                if socket in out.inputs and out.inputs[socket].is_linked:
                    self.warn(f"material {name!r}: its {socket.lower()} is not modeled: the surface alone is "
                              "rendered")
        if out is None or not out.inputs["Surface"].is_linked:
            self.warn(f"material {name!r} has no surface shader connected to its output: rendered black")
            return dict(name=name)
        notes = []
        self._albedo, self._cutout, self._normal = [], [], []
        self._material = mat
        try:
            acc = Closures()
            self._closure(out.inputs["Surface"], 1.0, acc, notes, 0)
        except Unsupported as e:
            self.warn(f"material {name!r}: {e}; using its viewport color")
            return self._viewport(mat)
        if self._cutout:
            self.cutouts[name] = self._cutout[0]
            if len(self._cutout) > 1:
                notes.append("several Principled BSDFs with an Alpha: the first one's is used")
        if self._normal:
            self.normal_maps[name] = self._normal[0]
            if len(self._normal) > 1:
                notes.append("several shaders with a normal or bump map: the first one's is used for all")
        found = list(dict.fromkeys(t.key for t in self._albedo))
        if len(found) == 1:
            self.textures[name] = self._albedo[0]
        elif len(found) > 1:
            notes.append(f"{len(found)} different textures or color attributes on its albedo: images are replaced "
                         "by their mean color, attributes by white")
        if not getattr(getattr(mat, "cycles", None), "use_bump_map_correction", True):
            notes.append("Bump Map Correction off is not modeled: its glossy and glass lobes keep normals whose "
                         "mirror direction clears the surface")
        for n in dict.fromkeys(notes):        # once each, in order
            self.warn(f"material {name!r}: {n}")
        return flatten(name, acc, self.warn)

    def left_out(self, mat):
        """Whether the faces of material ``mat`` (a bpy Material or None) are left out: a volume
        without a surface shader, which Cycles renders as a medium with no surface."""
        self.convert(mat)
        return mat is not None and mat.name_full in self.volume_only

    def _viewport(self, mat):
        return clip_colors(dict(name=mat.name_full, diffuse=tuple(mat.diffuse_color[:3])), mat.name_full, self.warn)

    # ------------------------------------------------------------- closures
    def _closure(self, socket, weight, acc, notes, depth):
        """Add what shader ``socket`` (an input) delivers, times ``weight``, into ``acc``."""
        if depth > 64:
            raise Unsupported("the shader graph is too deep (a cycle?)")
        if not socket.is_linked or weight == 0.0:
            return
        link = socket.links[0]
        if getattr(link, "is_muted", False) or not getattr(link, "is_valid", True):
            return
        node = follow_reroutes(link.from_node)
        if node is None or getattr(node, "mute", False):
            return
        t = node.type
        if t == "BSDF_DIFFUSE":
            acc.diffuse += weight * self.color(node.inputs["Color"], notes)
            if "Roughness" in node.inputs and self.value(node.inputs["Roughness"], notes) > 0:
                notes.append("Diffuse BSDF roughness (Oren-Nayar) is ignored (Lambert)")
            self._normal_map(node, notes)
        elif t in ("BSDF_GLOSSY", "BSDF_ANISOTROPIC"):
            self._glossy(node, weight, acc, notes)
        elif t == "BSDF_TRANSLUCENT":
            acc.translucent += weight * np.clip(self.color(node.inputs["Color"], notes), 0.0, 1.0)
            self._normal_map(node, notes)
        elif t in ("BSDF_GLASS", "BSDF_REFRACTION", "BSDF_TRANSPARENT"):
            self._interface(node, weight, acc, notes)
        elif t == "EMISSION":
            acc.emission += weight * self.color(node.inputs["Color"], notes) * max(
                self.value(node.inputs["Strength"], notes), 0.0)
        elif t == "MIX_SHADER" and _transparent_input(node) is not None:
            # Mix(Fac, Transparent, X): X where covered, a fraction Fac (1 - Fac with the
            # Transparent second) of the light; the rest passes on: a cut-out of X
            clear = _transparent_input(node)
            color = self.color(follow_reroutes(node.inputs[clear].links[0].from_node).inputs["Color"], notes)
            if np.any(np.abs(color - 1.0) > 1e-6):
                notes.append(f"a Transparent BSDF's color {color_text(color)} is not modeled: it passes all light")
            self._coverage(node.inputs[0], weight, notes, invert=clear == 2)
            self._closure(node.inputs[3 - clear], weight, acc, notes, depth + 1)
        elif t == "MIX_SHADER":
            fac = float(np.clip(self.value(node.inputs[0], notes), 0.0, 1.0))
            self._closure(node.inputs[1], weight * (1.0 - fac), acc, notes, depth + 1)
            self._closure(node.inputs[2], weight * fac, acc, notes, depth + 1)
        elif t == "ADD_SHADER":
            self._closure(node.inputs[0], weight, acc, notes, depth + 1)
            self._closure(node.inputs[1], weight, acc, notes, depth + 1)
        elif t == "BSDF_PRINCIPLED":
            self._principled(node, weight, acc, notes)
        else:
            label = node.bl_label if hasattr(node, "bl_label") else t
            raise Unsupported(f"the {label} node ({node.name!r}) is not supported")

    def _glossy(self, node, weight, acc, notes):
        """A Glossy or Anisotropic BSDF ``node`` times ``weight`` into ``acc``: a GGX lobe."""
        color = weight * self.color(node.inputs["Color"], notes)
        r = float(np.clip(self.value(node.inputs["Roughness"], notes), 0.0, 1.0))
        acc.glossy += color
        acc.rough_sum += luminance(color) * r
        acc.glossy_lum += luminance(color)
        dist = getattr(node, "distribution", "GGX")
        acc.multi_ggx.append(dist == "MULTI_GGX")
        if dist not in ("GGX", "MULTI_GGX"):
            notes.append(f"Glossy BSDF distribution {dist} is approximated by GGX")
        if "Anisotropy" in node.inputs and abs(self.value(node.inputs["Anisotropy"], notes)) > 1e-6:
            notes.append("anisotropy is ignored (isotropic GGX)")
        self._normal_map(node, notes)

    def _principled(self, node, weight, acc, notes):
        """A Principled BSDF ``node`` times ``weight`` into ``acc``: its cut-out, its glass
        (Transmission Weight of the non-metallic part) and the rest as the core's model."""
        alpha = node.inputs.get("Alpha")
        if alpha is not None:
            self._coverage(alpha, weight, notes)
        inputs = {s.name: (self.color(s, notes) if s.type == "RGBA" else self.value(s, notes))
                  for s in node.inputs if s.type in ("RGBA", "VALUE") and s.name != "Alpha"}
        # Cycles: metallic, then Transmission Weight of the rest is glass tinted by the base color
        glass = (1.0 - float(np.clip(inputs.get("Metallic", 0.0), 0.0, 1.0))) * float(
            np.clip(inputs.pop("Transmission Weight", 0.0), 0.0, 1.0))
        if glass > 0:
            self._glass(weight * glass, np.clip(inputs.get("Base Color", (0.8,) * 3), 0.0, 1.0)[:3],
                        np.clip(inputs.get("Specular Tint", (1.0,) * 3), 0.0, 1.0)[:3],
                        float(inputs.get("IOR", 1.5)), 1, float(inputs.get("Roughness", 0.5)), acc, notes,
                        getattr(node, "distribution", "MULTI_GGX"))
        spec = principled_to_material(inputs, getattr(node, "distribution", "MULTI_GGX"),
                                      notes.append)
        simple = principled_to_material(inputs, getattr(node, "distribution", "MULTI_GGX"),
                                        lambda m: None, layered=False)
        if glass < 1.0 - 1e-6:
            acc.principled.append((weight * (1.0 - glass), spec, simple))
        else:                             # all glass: only its emission is left of the rest
            acc.emission += weight * np.asarray(spec.get("emission", (0.0, 0.0, 0.0)), float)
        self._normal_map(node, notes)

    def _interface(self, node, weight, acc, notes):
        """A Glass, Refraction or Transparent BSDF ``node`` times ``weight`` into ``acc``: a
        smooth dielectric interface (:mod:`raybundle.scene.transmission`)."""
        color = np.clip(self.color(node.inputs["Color"], notes), 0.0, 1.0)
        if node.type == "BSDF_TRANSPARENT":
            self._glass(weight, color, np.zeros(3), 1.0, 1, 0.0, acc, notes)
            return
        ior = self.value(node.inputs["IOR"], notes)
        rough = self.value(node.inputs["Roughness"], notes) if "Roughness" in node.inputs else 0.0
        glass = node.type == "BSDF_GLASS"
        self._glass(weight, color, color if glass else np.zeros(3), ior, int(glass), rough, acc, notes,
                    getattr(node, "distribution", "GGX"))
        self._normal_map(node, notes)

    def _glass(self, weight, color, reflection, ior, fresnel, roughness, acc, notes, distribution="GGX"):
        if roughness > MULTISCATTER_GLASS and distribution == "MULTI_GGX":
            notes.append(f"rough glass (roughness {roughness:.3g}): its Multiscatter GGX is approximated by single "
                         "scattering (a little darker)")
        if ior <= 0:
            notes.append(f"an IOR of {ior:g} is not physical: 1 is used (no bending)")
            ior = 1.0
        acc.transmission.append((weight, np.asarray(color, float), np.asarray(reflection, float), ior, fresnel,
                                 float(np.clip(roughness, 0.0, 1.0))))

    def _coverage(self, sock, weight, notes, invert=False):
        """Record the cut-out given by input ``sock`` (a Principled BSDF's ``Alpha``, a Mix
        Shader's ``Fac`` with a Transparent BSDF; ``invert``: the coverage is 1 - its value): a
        constant, or the map Blender baked of its node graph (:mod:`.node_graphs`); nothing
        where the coverage is 1."""
        node = follow_reroutes(sock.links[0].from_node) if sock.is_linked else None
        uv, px = None, None
        if node is None:
            value = float(sock.default_value)
        elif node.type == "VALUE":
            value = float(node.outputs[0].default_value)
        else:
            got = "it was not evaluated" if self.graphs is None else self.graphs.get(self._material, sock)
            if isinstance(got, str):
                notes.append(f"{sock.name!r} is driven by a {node.bl_label} node ({got}): the surface is opaque")
                return
            px = np.clip(np.asarray(got, np.float32)[..., :1], 0.0, 1.0)
            if invert:
                px = 1.0 - px
            value = float(px.max()) if float(px.max() - px.min()) <= 1e-6 else None
            uv = None if value is not None else self.graphs.uv(self._material, sock)
        if value is not None:
            value = float(np.clip(1.0 - value if invert and px is None else value, 0.0, 1.0))
            if value >= 1.0 - 1e-6:
                return
            px = np.full((1, 1, 1), value, np.float32)
        if abs(weight - 1.0) > 1e-9:
            notes.append(f"the cut-out of {sock.node.name!r}, mixed with other shaders, cuts out the whole material")
        self._cutout.append(Coverage(self._evaluated(sock, np.repeat(px, 3, axis=2)), uv))

    def _normal_map(self, node, notes):
        """Record the normal or bump map on shader ``node``'s Normal input: the normal its nodes
        give, baked by Blender over a unit square (:mod:`.node_graphs`); nothing where it is
        the surface's own everywhere."""
        sock = node.inputs.get("Normal")
        if sock is None or not sock.is_linked:
            return
        got = "it was not evaluated" if self.graphs is None else self.graphs.get(self._material, sock)
        if isinstance(got, (str, dict)):
            why = got if isinstance(got, str) else "it was baked on each object"
            notes.append(f"the normal / bump map of {node.name!r} is not modeled ({why}): the surface's own normal "
                         "is used")
            return
        n = 2.0 * np.asarray(got, np.float32)[..., :3] - 1.0
        if np.allclose(n, (0.0, 0.0, 1.0), atol=1e-4):
            return
        src = follow_reroutes(sock.links[0].from_node)
        self._normal.append(NormalMap(self._evaluated(sock, n), self.graphs.uv(self._material, sock),
                                      src is not None and src.type == "BUMP"))

    # --------------------------------------------------------------- inputs
    def color(self, sock, notes):
        """(3,) linear RGB of a color (or float) input socket."""
        if sock.type == "VALUE":
            return np.full(3, self.value(sock, notes))
        if sock.is_linked:
            node = follow_reroutes(sock.links[0].from_node)
            if node is not None and node.type == "RGB":
                return np.array(node.outputs[0].default_value[:3], float)
            if node is not None and not read_directly(sock, node):       # Blender evaluates the graph
                got = self._graph(sock, node, notes)
                if got is not None:
                    return got
            elif node is not None and node.type in ("TEX_IMAGE", "TEX_ENVIRONMENT"):
                mean = self.image_mean(node.image)
                if mean is not None:
                    uv = uv_source(node) if node.type == "TEX_IMAGE" else None
                    albedo = _is_albedo(sock)
                    if albedo and uv is not None:
                        self._albedo.append(AlbedoTexture(node.image, uv, closest=node.interpolation == "Closest",
                                                          extend=node.extension == "EXTEND"))
                        if node.extension not in ("REPEAT", "EXTEND"):
                            notes.append(f"image texture {node.image.name!r}: {node.extension.lower()} extension "
                                         "is treated as repeat")
                        if node.interpolation not in ("Linear", "Closest"):
                            notes.append(f"image texture {node.image.name!r}: {node.interpolation} interpolation is "
                                         "treated as Linear")
                        return mean
                    why = ("its texture coordinates are not a UV map" if albedo else
                           "only textures on a Diffuse Color or Base Color are modelled")
                    notes.append(f"image texture {node.image.name!r} on {sock.name!r} is replaced by its mean color "
                                 f"{color_text(mean)} ({why})")
                    return mean
                notes.append(f"image texture on {sock.name!r} has no image data: using the socket's value")
            elif node is not None and node.type == "VERTEX_COLOR":
                # the attribute's color is the albedo itself: white here, times the color per point
                self._albedo.append(AlbedoTexture(attribute=node.layer_name))
                return np.ones(3)
        return np.array(sock.default_value[:3], float)

    def value(self, sock, notes):
        if sock.type == "RGBA":
            return float(luminance(self.color(sock, notes)))
        if sock.is_linked:
            node = follow_reroutes(sock.links[0].from_node)
            if node is not None and node.type == "VALUE":
                return float(node.outputs[0].default_value)
            if node is not None:
                got = self._graph(sock, node, notes)
                if got is not None:
                    return float(got[0])
        return float(sock.default_value)

    def _graph(self, sock, node, notes):
        """(3,) the value of the node graph driving ``sock`` (from ``node``) as Blender baked it
        (:mod:`.node_graphs`): on an albedo input an albedo texture (its mean returned), elsewhere
        its mean (noted when it varies); None (noted) when Blender did not evaluate it."""
        got = "it was not evaluated" if self.graphs is None else self.graphs.get(self._material, sock)
        if isinstance(got, str):
            notes.append(f"{sock.name!r} is driven by a {node.bl_label} node ({got}): using the socket's own value")
            return None
        if isinstance(got, dict):
            return self._object_graph(sock, node, got, notes)
        mean = got.reshape(-1, 3).astype(float).mean(axis=0)
        lo, hi = got.reshape(-1, 3).min(axis=0), got.reshape(-1, 3).max(axis=0)
        if np.all(hi - lo <= 1e-6):
            return mean
        if sock.type == "RGBA" and _is_albedo(sock):
            self._albedo.append(AlbedoTexture(self._evaluated(sock, got), self.graphs.uv(self._material, sock)))
            return mean
        if sock.type == "RGBA":
            notes.append(f"{sock.name!r} varies over the surface with its node graph: its mean color "
                         f"{color_text(mean)} is used")
        else:
            notes.append(f"{sock.name!r} varies over the surface with its node graph ({lo[0]:.3g} to {hi[0]:.3g}): "
                         f"its mean {mean[0]:.3g} is used")
        return mean

    def _object_graph(self, sock, node, got, notes):
        """:meth:`_graph` of a graph Blender baked on each object (``got``: object name -> its
        map or a reason): the material holds the objects' mean; on an albedo input each object
        gets its own albedo texture (its map over that mean)."""
        baked = {k: np.asarray(v, np.float32) for k, v in got.items() if v is not None and not isinstance(v, str)}
        for why in dict.fromkeys(v for v in got.values() if isinstance(v, str)):
            notes.append(f"{sock.name!r} ({node.bl_label} node) is not baked on every object: {why}; the mean of "
                         "the others is used there")
        if not baked:
            notes.append(f"{sock.name!r} is driven by a {node.bl_label} node that was baked on no object: using "
                         "the socket's own value")
            return None
        mean = np.mean([v.reshape(-1, 3).astype(float).mean(axis=0) for v in baked.values()], axis=0)
        if sock.type == "RGBA" and _is_albedo(sock):
            for obj, px in baked.items():
                image = self._evaluated(sock, px, obj)
                self._normalizer[image.name_full] = mean
                self.object_textures[(obj, self._material.name_full)] = AlbedoTexture(
                    image, self.graphs.uv(self._material, sock, obj), extend=True)
        elif sock.type == "RGBA":
            notes.append(f"{sock.name!r} varies over the surface with its node graph: its mean color "
                         f"{color_text(mean)} is used")
        else:
            notes.append(f"{sock.name!r} varies over the surface with its node graph: its mean {mean[0]:.3g} is used")
        return mean

    def _evaluated(self, sock, pixels, obj=None):
        """The :class:`EvaluatedImage` of ``pixels`` (H, W, 3) Blender baked for input ``sock`` of
        the material being converted (on object ``obj``), its pixels kept for :meth:`image_pixels`."""
        where = f"{obj}: " if obj is not None else ""
        image = EvaluatedImage(f"{self._material.name_full}: {where}{sock.node.name}.{sock.name}")
        self._image_pixels[image.name_full] = np.asarray(pixels, np.float32)
        return image

    def texture_of(self, ob, mat):
        """The :class:`AlbedoTexture` of material ``mat`` on object ``ob`` (an object's own bake
        first, then the material's), or None."""
        if mat is None:
            return None
        own = self.object_textures.get((getattr(ob, "original", ob).name_full, mat.name_full))
        return own if own is not None else self.textures.get(mat.name_full)

    def modulation(self, image):
        """(H, W, 3) the albedo map of ``image``, its pixels over the material's mean albedo (the image's
        own mean, or the objects' for a graph baked on each), in half precision where that holds it."""
        px = self.image_pixels(image)
        mean = self._normalizer.get(image.name_full)
        if mean is None:
            return half_precision(modulation_map(px)[0])
        return half_precision(np.where(mean > 0, px / np.where(mean > 0, mean, 1.0), 1.0).astype(np.float32))

    def albedo_map(self, image):
        """``(texels (H, W, 3), encoded, byte values)`` of ``image``'s albedo map
        (:class:`raybundle.scene.textures.SurfaceTexture`): a byte image in the sRGB color space as
        Cycles keeps it, its bytes with the encoded value of each, and ``encoded`` the inverse of
        its linear mean (the lookup decodes after interpolating, as Cycles does); any other its
        :meth:`modulation` and None, None."""
        if self._normalizer.get(image.name_full) is None and srgb_bytes(image):
            got = self._bytes(image)
            if got is not None:
                mean = self.image_mean(image)
                return got[0], np.where(mean > 0, 1.0 / np.where(mean > 0, mean, 1.0), 1.0), got[1]
        return self.modulation(image), None, None

    def image_pixels(self, image):
        """(H, W, 3) linear RGB of ``image`` (row 0 at the bottom), or None without pixel data."""
        if image is None:
            return None
        key = image.name_full
        if key not in self._image_pixels:
            self._image_pixels[key] = linear_pixels(image)
        return self._image_pixels[key]

    def image_mean(self, image):
        """(3,) mean linear color of ``image``, or None without pixel data (a byte sRGB image's
        from its bytes, :func:`.images.byte_mean`, without decoding every texel)."""
        if image is not None and image.name_full not in self._image_pixels and srgb_bytes(image):
            got = self._bytes(image)
            return None if got is None else byte_mean(*got)
        px = self.image_pixels(image)
        return None if px is None else px.reshape(-1, 3).mean(axis=0)

    def _bytes(self, image):
        """:func:`.images.image_bytes` of a byte sRGB ``image``, read from Blender once."""
        if image.name_full not in self._image_bytes:
            self._image_bytes[image.name_full] = image_bytes(image)
        return self._image_bytes[image.name_full]


def _transparent_input(mix):
    """1 or 2: the input of Mix Shader ``mix`` that a Transparent BSDF drives (the other not), or None."""
    found = [k for k in (1, 2) if mix.inputs[k].is_linked
             and getattr(follow_reroutes(mix.inputs[k].links[0].from_node), "type", None) == "BSDF_TRANSPARENT"]
    return found[0] if len(found) == 1 else None


def read_directly(sock, node):
    """Whether the converter reads input ``sock`` linked to ``node`` without Blender's help
    (:meth:`MaterialConverter.color`, :meth:`MaterialConverter.value`): an RGB or Value node, an
    image texture on a color input (but one read through vector nodes from a UV map, which
    Blender bakes: :func:`.node_links.uv_through`), a color attribute on an albedo input."""
    if sock.type == "VALUE":
        return node.type == "VALUE"
    if node.type == "TEX_IMAGE" and uv_source(node) is None and uv_through(node) is not None:
        return False
    return (node.type in ("RGB", "TEX_IMAGE", "TEX_ENVIRONMENT")
            or node.type == "VERTEX_COLOR" and _is_albedo(sock))


def _is_albedo(sock):
    """A Diffuse BSDF's Color or a Principled BSDF's Base Color input."""
    return sock.name in ("Color", "Base Color") and sock.node.type in ("BSDF_DIFFUSE", "BSDF_PRINCIPLED")


