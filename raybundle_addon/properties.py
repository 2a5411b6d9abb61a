"""Settings (``scene.raybundle``) and the last run's statistics.

Settings are an ordinary :class:`bpy.types.PropertyGroup` saved with the
``.blend``.  The statistics of the last render are read-only properties whose
getters read :data:`LAST_RUN`, a plain dict the render thread fills in: a
render engine must not write ID properties from its thread, and the values
need not be saved.
"""
from __future__ import annotations

from dataclasses import dataclass

import bpy
from bpy.props import BoolProperty, EnumProperty, FloatProperty, IntProperty, StringProperty

from raybundle.app.plan import DEFAULT_TIME_LIMIT
from raybundle.patches.clusters import DEFAULT_PATCHES

#: scene name -> statistics of that scene's last render (filled by :mod:`.engine`)
LAST_RUN: dict[str, dict] = {}
#: scene name -> statistics of that scene's last bake (filled by :mod:`.bake`)
LAST_BAKE: dict[str, dict] = {}


def _solver_items():
    """One enum item per solver of the core's registry (:data:`raybundle.methods.registry.SOLVERS`), and auto."""
    from raybundle.methods.registry import SOLVERS

    return [(name, name.replace("-", " ").capitalize(), ((cls.__doc__ or name).strip().splitlines() or [name])[0])
            for name, cls in SOLVERS.items()] + [
        ("auto", "Auto", "Chosen from what the scene holds (raybundle.app.auto): the bundle iteration unless glossy "
         "lobes carry most of the reflection, then path tracing; bakes take the bundle iteration")]


#: the panel's settings a render takes, property -> :class:`raybundle.app.plan.RunOptions` field
#: (the budget, Budget with Time Limit or Iterations, is :func:`run_options`' own)
RUN_PROPERTIES = {"method": "method", "seed": "seed", "patches": "patches",
                  "bundle_resolution": "bundle_resolution", "first_shot": "first_shot"}


def run_options(scene, view_layer=None):
    """``scene.raybundle`` as the core's :class:`raybundle.app.plan.RunOptions`
    (:data:`RUN_PROPERTIES`, and the Budget: the Time Limit or the Iterations), with the
    scene's Cycles Light Paths limits and ``view_layer``'s component passes."""
    from raybundle.app.plan import RunOptions

    rb = getattr(scene, "raybundle", None)
    depth = dict(transmission_depth=light_path_limit(scene, "transmission_bounces"),
                 glossy_depth=light_path_limit(scene, "glossy_bounces"), components=wants_components(view_layer))
    if rb is None:
        return RunOptions(**depth)
    values = {field: getattr(rb, prop) for prop, field in RUN_PROPERTIES.items()}
    if rb.budget == "ITERATIONS":
        values["iterations"] = int(rb.iterations)
    else:
        values["time_limit"] = float(rb.time_limit)
    return RunOptions(**values, **depth)


def wants_components(view_layer):
    """Whether ``view_layer`` (or None) asks for the component passes."""
    settings = getattr(view_layer, "raybundle", None)
    return bool(settings is not None and settings.use_pass_components)


def light_path_limit(scene, bounces):
    """``scene``'s Cycles Light Paths limit ``bounces`` ("transmission_bounces": the refractions
    on glass an eye path takes; "glossy_bounces": its reflections there, total internal ones
    too) within the Total, as Cycles applies it (the default file's 12 and 4, a converted
    file's 64: the hall's balustrade seen at its edge guides the eye about 24 times), or None
    where the scene has no Cycles settings (the core's defaults)."""
    cycles = getattr(scene, "cycles", None)
    if cycles is None or not hasattr(cycles, bounces):
        return None
    return int(min(getattr(cycles, bounces), cycles.max_bounces))


def _stat(key, default):
    def get(self):
        value = LAST_RUN.get(self.id_data.name, {}).get(key, default)
        return type(default)(value)
    return get


@dataclass
class BakeSettings:
    """Plain copy of the bake settings of ``scene.raybundle`` (see :mod:`.properties`)."""

    color_attribute: bool = True
    domain: str = "POINT"
    lightmaps: bool = False
    lightmap_size: int = 1024
    lightmap_margin: int = 16
    camera: bool = False
    directory: str = "//raybundle_bake/"
    light_samples: int = 32
    single_user: bool = False
    #: rays per vertex or corner of the final gather: -1 automatic (what the time left buys, in the
    #: budget), 0 none (the patches interpolated), else that many
    gather_rays: int = -1
    subdivide: bool = False
    subdivide_levels: int = 3

    @classmethod
    def from_scene(cls, scene):
        """The bake settings of ``scene.raybundle`` (:data:`BAKE_PROPERTIES`; Gather Rays -1 where
        Automatic is on)."""
        rb = getattr(scene, "raybundle", None)
        if rb is None:
            return cls()
        out = cls(**{field: getattr(rb, prop) for prop, field in BAKE_PROPERTIES.items()})
        if rb.bake_gather_auto:
            out.gather_rays = -1
        return out

    def validate(self):
        if not (self.color_attribute or self.lightmaps or self.camera):
            raise ValueError("nothing to bake: turn on Color Attribute, Lightmaps or Camera View")
        if self.domain not in ("POINT", "CORNER"):
            raise ValueError(f"unknown color attribute domain {self.domain!r}: POINT or CORNER")
        if self.lightmaps and not 1 <= self.lightmap_size <= 16384:
            raise ValueError("the lightmap size must lie in [1, 16384]")
        if self.light_samples < 1:
            raise ValueError("light samples must be at least 1")
        if self.gather_rays < -1:
            raise ValueError("gather rays must be -1 (automatic), 0 (off) or more")
        if self.subdivide and not 1 <= self.subdivide_levels <= 6:
            raise ValueError("subdivision levels must lie in [1, 6]")


#: the panel's bake settings, property -> :class:`BakeSettings` field
BAKE_PROPERTIES = {"bake_color_attribute": "color_attribute", "bake_domain": "domain", "bake_lightmaps": "lightmaps",
                   "lightmap_size": "lightmap_size", "lightmap_margin": "lightmap_margin", "bake_camera": "camera",
                   "bake_directory": "directory", "bake_light_samples": "light_samples",
                   "bake_single_user": "single_user", "bake_gather_rays": "gather_rays",
                   "bake_subdivide": "subdivide", "bake_subdivide_levels": "subdivide_levels"}


#: Gather Rays' default before it could be automatic: a file saved with it reads as automatic
LEGACY_GATHER_RAYS = 1024
#: the automatic gather's share of a timed bake's iteration time (the run loop's final share)
GATHER_SHARE = 1.0
#: rays per point of the automatic gather in a bake of given iterations
FIXED_GATHER_RAYS = 1024


def _get_gather_auto(self):
    """Automatic gather's value: as set; in a file saved before it existed, on where Gather Rays
    still held the old default (:data:`LEGACY_GATHER_RAYS`)."""
    if "bake_gather_auto_choice" in self:
        return bool(self["bake_gather_auto_choice"])
    return self.get("bake_gather_rays", LEGACY_GATHER_RAYS) == LEGACY_GATHER_RAYS


def _set_gather_auto(self, value):
    self["bake_gather_auto_choice"] = bool(value)


def _get_budget(self):
    """Budget's value: as set; in a file saved before Budget existed, Iterations where its
    count was above 0 (then 0 meant "none: the Time Limit"), else Time Limit."""
    if "budget_choice" in self:
        return self["budget_choice"]
    return 1 if self.iterations > 0 else 0


def _set_budget(self, value):
    self["budget_choice"] = value


class RAYBUNDLE_PG_settings(bpy.types.PropertyGroup):
    budget: EnumProperty(
        name="Budget", description="What ends the run", get=_get_budget, set=_set_budget,
        items=[("TIME", "Time Limit", "The whole run's seconds, set-up included", 0),
               ("ITERATIONS", "Iterations", "A fixed number of iterations: with a fixed seed, reproducible bit for bit",
                1)])
    time_limit: FloatProperty(
        name="Time Limit", description="Seconds of the whole run, from its start to the image (Budget: Time Limit)",
        default=DEFAULT_TIME_LIMIT, min=0.0, soft_max=3600.0, subtype="TIME_ABSOLUTE", unit="TIME_ABSOLUTE")
    iterations: IntProperty(
        name="Iterations", description="Number of iterations (Budget: Iterations). "
        "A fixed count with a fixed seed is reproducible bit for bit",
        default=0, min=0)
    seed: IntProperty(name="Seed", description="Random seed of the directions and samples", default=0, min=0)
    patches: IntProperty(
        name="Patches", description="Target number of patches (finite elements): faces larger than a patch are "
        "cut, triangles much smaller grouped; 0 = one patch per triangle",
        default=DEFAULT_PATCHES, min=0, soft_max=200000)
    bundle_resolution: IntProperty(
        name="Bundle Resolution", description="Rays per side of each bundle grid; 0 = automatic",
        default=0, min=0, max=4096)
    first_shot: BoolProperty(
        name="First Shot", description="Shoot the power of lights and small emitters first with shadow rays "
        "(sharp direct light); off = everything through the iteration", default=True)
    method: EnumProperty(name="Method", description="Solver of the rendering equation", items=_solver_items())

    # bake (raybundle.bake); glossy lobes are view-dependent: a bake holds the diffuse part and emission
    bake_color_attribute: BoolProperty(
        name="Color Attribute", default=BakeSettings.color_attribute,
        description="Write the view-independent radiance (diffuse light and emission; glossy reflections "
        "depend on the viewer and are left out) into a FLOAT_COLOR attribute 'RayBundle' of every mesh, "
        "set active for viewport shading. The geometry itself is not changed")
    bake_domain: EnumProperty(
        name="Domain", default=BakeSettings.domain,
        items=[("POINT", "Vertex", "One value per vertex (smooth; a vertex on a crease averages its faces)"),
               ("CORNER", "Face Corner", "One value per face corner (each face keeps its own light: hard edges "
                "between faces)")],
        description="Domain of the color attribute")
    bake_subdivide: BoolProperty(
        name="Into a Subdivided Copy", default=BakeSettings.subdivide,
        description="Bake the color attribute into a new object '<name>.RayBundle' (hidden from renders) whose "
        "triangles are cut into 4, again and again, where the light's linear interpolation along an edge misses "
        "its midpoint by more than 5%: finer where shadows and corners need it. The original is not changed")
    bake_subdivide_levels: IntProperty(
        name="Max Subdivisions", default=BakeSettings.subdivide_levels, min=1, max=6,
        description="How many times a triangle may be cut into 4 (each level at most 4 times the triangles)")
    bake_lightmaps: BoolProperty(
        name="Lightmaps", default=BakeSettings.lightmaps,
        description="For each selected mesh with a UV map: an image filled texel by texel with the "
        "view-independent radiance (glossy reflections are left out), saved as EXR and kept as an Image")
    lightmap_size: IntProperty(name="Lightmap Size", description="Width and height of each lightmap in texels",
                               default=BakeSettings.lightmap_size, min=16, max=16384)
    lightmap_margin: IntProperty(
        name="Margin", description="Texels filled around each UV island (seams, bilinear and mip-map lookups)",
        default=BakeSettings.lightmap_margin, min=0, max=256)
    bake_camera: BoolProperty(
        name="Camera View", default=BakeSettings.camera,
        description="Also write the active camera's view (with glossy reflections) as an EXR and an Image")
    bake_directory: StringProperty(
        name="Output", subtype="DIR_PATH", default=BakeSettings.directory,
        description="Folder of the lightmap and camera EXRs ('//' = next to the .blend file)")
    bake_light_samples: IntProperty(
        name="Light Samples", default=BakeSettings.light_samples, min=1, max=4096,
        description="Shadow rays per light per vertex or corner for the direct light, 16 times as many where "
        "they find a penumbra (lightmap texels: a quarter, and 4 times as many in a penumbra); polygonal "
        "lights are integrated exactly and the rays only find their shadows")
    bake_gather_auto: BoolProperty(
        name="Automatic Gather", get=_get_gather_auto, set=_set_gather_auto,
        description="Color attributes: gather the indirect light of every vertex or corner with as many rays "
        f"as the Time Limit leaves (it keeps {GATHER_SHARE / (1 + GATHER_SHARE):.0%} of the time after set-up "
        f"for the gather); with Iterations, {FIXED_GATHER_RAYS:,} rays. Off: the Gather Rays below")
    bake_gather_rays: IntProperty(
        name="Gather Rays", default=LEGACY_GATHER_RAYS, min=0, max=65536,
        description="Color attributes, Automatic Gather off: rays per vertex or corner that gather the indirect "
        "light from the solution (right next to corners and contacts, where patch values cannot follow the "
        "light); 0 = interpolate the patches (faster). Lightmaps always interpolate")
    bake_single_user: BoolProperty(
        name="Make Single User", default=BakeSettings.single_user,
        description="Objects sharing one mesh get their own copy of it, each baked with its own light; "
        "off = they keep sharing it and it holds the first object's light")

    # read-only statistics of the last render (see LAST_RUN)
    last_status: StringProperty(name="Status", get=_stat("status", ""))
    last_iterations: IntProperty(name="Iterations", get=_stat("iterations", 0))
    last_seconds: FloatProperty(name="Seconds", get=_stat("seconds", 0.0), precision=1)
    last_rays: FloatProperty(name="Rays (millions)", get=_stat("mrays", 0.0), precision=1)
    last_patches: IntProperty(name="Patches", get=_stat("patches", 0))
    last_triangles: IntProperty(name="Triangles", get=_stat("triangles", 0))
    last_first_image: FloatProperty(name="First Image (s)", get=_stat("first_image_seconds", 0.0), precision=2)
    last_warnings: IntProperty(name="Warnings", get=_stat("n_warnings", 0))


class RAYBUNDLE_PG_view_layer(bpy.types.PropertyGroup):
    use_pass_components: BoolProperty(
        name="Light Components", default=False,
        description="Render passes of the image's parts as Ray Bundle GI estimates them, which sum to Combined: "
        "RB Emission (emitters and the world seen), RB Lamps and RB World (their direct light on the diffuse "
        "lobe, per pixel), RB Glossy, RB Diffuse Indirect (from the patches), RB Caustics, and RB Glass (the share "
        "of a pixel's samples seen through glass or a mirror). A pass costs a second BRDF evaluation per light sample")


classes = (RAYBUNDLE_PG_settings, RAYBUNDLE_PG_view_layer)


def register():
    for c in classes:
        bpy.utils.register_class(c)
    bpy.types.Scene.raybundle = bpy.props.PointerProperty(type=RAYBUNDLE_PG_settings)
    bpy.types.ViewLayer.raybundle = bpy.props.PointerProperty(type=RAYBUNDLE_PG_view_layer)


def unregister():
    del bpy.types.ViewLayer.raybundle
    del bpy.types.Scene.raybundle
    for c in reversed(classes):
        bpy.utils.unregister_class(c)
