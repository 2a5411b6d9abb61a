"""Settings (``scene.raybundle``) and the last run's statistics.

Settings are an ordinary :class:`bpy.types.PropertyGroup` saved with the
``.blend``.  The statistics of the last render are read-only properties whose
getters read :data:`LAST_RUN`, a plain dict the render thread fills in: a
render engine must not write ID properties from its thread, and the values
need not be saved.
"""
from __future__ import annotations

import bpy
from bpy.props import BoolProperty, EnumProperty, FloatProperty, IntProperty, StringProperty

#: scene name -> statistics of that scene's last render (filled by :mod:`.engine`)
LAST_RUN: dict[str, dict] = {}


def _solver_items():
    """One enum item per solver of the core's registry (:data:`raybundle.solvers.SOLVERS`)."""
    from raybundle.solvers import SOLVERS

    return [(name, name.replace("-", " ").capitalize(), ((cls.__doc__ or name).strip().splitlines() or [name])[0])
            for name, cls in SOLVERS.items()]


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
