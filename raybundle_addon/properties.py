"""Settings (``scene.raybundle``) and the last run's statistics.

Settings are an ordinary :class:`bpy.types.PropertyGroup` saved with the
``.blend``.  The statistics of the last render are read-only properties whose
getters read :data:`LAST_RUN`, a plain dict the render thread fills in: a
render engine must not write ID properties from its thread, and the values
need not be saved.
"""
from __future__ import annotations

from dataclasses import fields

import bpy
from bpy.props import BoolProperty, EnumProperty, FloatProperty, IntProperty, StringProperty

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


def run_options(scene, seconds=None, iterations=None):
    """``scene.raybundle`` as the core's :class:`raybundle.app.plan.RunOptions`, field by field
    name; Iterations 0 means the Time Limit rules (both 0 is an error).  ``seconds`` or
    ``iterations`` given (the headless command line's) replace the file's budget."""
    from raybundle.app.plan import RunOptions

    rb = getattr(scene, "raybundle", None)
    depth = dict(transmission_depth=light_path_limit(scene, "transmission_bounces"),
                 glossy_depth=light_path_limit(scene, "glossy_bounces"))
    if rb is None:
        return RunOptions(seconds=seconds, iterations=iterations, **depth)
    names = {f.name for f in fields(RunOptions)} & set(rb.bl_rna.properties.keys())
    values = {name: getattr(rb, name) for name in names}
    values.update(depth)
    if seconds is not None or iterations is not None:
        values.update(seconds=seconds, iterations=iterations)
    elif not values["iterations"]:
        if rb.time_limit == 0:
            raise ValueError("set a time limit (seconds) or an iteration count: both are 0")
        values.update(iterations=None, seconds=float(rb.time_limit))
    return RunOptions(**values)


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


def from_properties(cls, rb, prefix=""):
    """A dataclass ``cls`` filled from the property group ``rb`` by field name: field ``x``
    from ``prefix + x`` or ``x``; fields without a property keep their defaults."""
    props = set(rb.bl_rna.properties.keys())
    values = {}
    for f in fields(cls):
        for name in (prefix + f.name, f.name):
            if name in props:
                values[f.name] = getattr(rb, name)
                break
    return cls(**values)


def _stat(key, default):
    def get(self):
        value = LAST_RUN.get(self.id_data.name, {}).get(key, default)
        return type(default)(value)
    return get


class RAYBUNDLE_PG_settings(bpy.types.PropertyGroup):
    time_limit: FloatProperty(
        name="Time Limit", description="Seconds to iterate (used when Iterations is 0)",
        default=30.0, min=0.0, soft_max=3600.0, subtype="TIME_ABSOLUTE", unit="TIME_ABSOLUTE")
    iterations: IntProperty(
        name="Iterations", description="Number of iterations; 0 = iterate until the time limit. "
        "A fixed count with a fixed seed is reproducible bit for bit",
        default=0, min=0)
    seed: IntProperty(name="Seed", description="Random seed of the directions and samples", default=0, min=0)
    patches: IntProperty(
        name="Patches", description="Target number of patches (finite elements); 0 = one patch per triangle. "
        "Meshes with more triangles keep one patch per triangle",
        default=4000, min=0, soft_max=200000)
    bundle_resolution: IntProperty(
        name="Bundle Resolution", description="Rays per side of each bundle grid; 0 = automatic",
        default=0, min=0, max=4096)
    first_shot: BoolProperty(
        name="First Shot", description="Shoot the power of lights and small emitters first with shadow rays "
        "(sharp direct light); off = everything through the iteration", default=True)
    method: EnumProperty(name="Method", description="Solver of the rendering equation", items=_solver_items())

    # bake (raybundle.bake); glossy lobes are view-dependent: a bake holds the diffuse part and emission
    bake_color_attribute: BoolProperty(
        name="Color Attribute", default=True,
        description="Write the view-independent radiance (diffuse light and emission; glossy reflections "
        "depend on the viewer and are left out) into a FLOAT_COLOR attribute 'RayBundle' of every mesh, "
        "set active for viewport shading. The geometry itself is not changed")
    bake_domain: EnumProperty(
        name="Domain", default="POINT",
        items=[("POINT", "Vertex", "One value per vertex (smooth; a vertex on a crease averages its faces)"),
               ("CORNER", "Face Corner", "One value per face corner (each face keeps its own light: hard edges "
                "between faces)")],
        description="Domain of the color attribute")
    bake_subdivide: BoolProperty(
        name="Into a Subdivided Copy", default=False,
        description="Bake the color attribute into a new object '<name>.RayBundle' (hidden from renders) whose "
        "triangles are cut into 4, again and again, where the light's linear interpolation along an edge misses "
        "its midpoint by more than 5%: finer where shadows and corners need it. The original is not changed")
    bake_subdivide_levels: IntProperty(
        name="Max Subdivisions", default=3, min=1, max=6,
        description="How many times a triangle may be cut into 4 (each level at most 4 times the triangles)")
    bake_lightmaps: BoolProperty(
        name="Lightmaps", default=False,
        description="For each selected mesh with a UV map: an image filled texel by texel with the "
        "view-independent radiance (glossy reflections are left out), saved as EXR and kept as an Image")
    lightmap_size: IntProperty(name="Lightmap Size", description="Width and height of each lightmap in texels",
                               default=1024, min=16, max=16384)
    lightmap_margin: IntProperty(
        name="Margin", description="Texels filled around each UV island (seams, bilinear and mip-map lookups)",
        default=16, min=0, max=256)
    bake_camera: BoolProperty(
        name="Camera View", default=False,
        description="Also write the active camera's view (with glossy reflections) as an EXR and an Image")
    bake_directory: StringProperty(
        name="Output", subtype="DIR_PATH", default="//raybundle_bake/",
        description="Folder of the lightmap and camera EXRs ('//' = next to the .blend file)")
    bake_light_samples: IntProperty(
        name="Light Samples", default=32, min=1, max=4096,
        description="Shadow rays per light per vertex or corner for the direct light, 16 times as many where "
        "they find a penumbra (lightmap texels: a quarter, and 4 times as many in a penumbra); polygonal "
        "lights are integrated exactly and the rays only find their shadows")
    bake_gather_rays: IntProperty(
        name="Gather Rays", default=1024, min=0, max=65536,
        description="Color attributes: rays per vertex or corner that gather the indirect light from the "
        "solution (right next to corners and contacts, where patch values cannot follow the light); "
        "0 = interpolate the patches (faster). Lightmaps always interpolate")
    bake_single_user: BoolProperty(
        name="Make Single User", default=False,
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


classes = (RAYBUNDLE_PG_settings,)


def register():
    for c in classes:
        bpy.utils.register_class(c)
    bpy.types.Scene.raybundle = bpy.props.PointerProperty(type=RAYBUNDLE_PG_settings)


def unregister():
    del bpy.types.Scene.raybundle
    for c in reversed(classes):
        bpy.utils.unregister_class(c)
