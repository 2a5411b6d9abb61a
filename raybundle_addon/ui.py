"""Render Properties panels for the ``RAYBUNDLE`` engine, and the stock panels it reuses.

Stock panels (Output, Format, Dimensions, camera, light, material, world...)
show for an engine only when its id is in their ``COMPAT_ENGINES``; the engine
joins every panel that lists ``BLENDER_RENDER`` (as Cycles' add-on does) and
leaves them again on unregister.
"""
from __future__ import annotations

import bpy

ENGINE = "RAYBUNDLE"
_added: list = []          # panels whose COMPAT_ENGINES we extended


class RaybundlePanel:
    bl_space_type = "PROPERTIES"
    bl_region_type = "WINDOW"
    bl_context = "render"
    COMPAT_ENGINES = {ENGINE}

    @classmethod
    def poll(cls, context):
        return context.engine in cls.COMPAT_ENGINES


class RAYBUNDLE_PT_settings(RaybundlePanel, bpy.types.Panel):
    bl_label = "Ray Bundle GI"

    def draw(self, context):
        layout = self.layout
        layout.use_property_split = True
        layout.use_property_decorate = False
        rb = context.scene.raybundle
        col = layout.column()
        col.prop(rb, "budget")
        col.prop(rb, "time_limit" if rb.budget == "TIME" else "iterations")
        col.prop(rb, "seed")
        col = layout.column()
        col.prop(rb, "method")
        col.prop(rb, "patches")
        col.prop(rb, "bundle_resolution")
        col.prop(rb, "first_shot")


class RAYBUNDLE_PT_stats(RaybundlePanel, bpy.types.Panel):
    bl_label = "Last Render"
    bl_parent_id = "RAYBUNDLE_PT_settings"
    bl_options = {"DEFAULT_CLOSED"}

    def draw(self, context):
        from .properties import LAST_RUN

        layout = self.layout
        rb = context.scene.raybundle
        if not rb.last_status:
            layout.label(text="No render yet")
            return
        layout.label(text=rb.last_status, icon="ERROR" if rb.last_status.startswith("error") else "INFO")
        grid = layout.grid_flow(columns=2, even_columns=True)
        for label, value in (("Iterations", f"{rb.last_iterations}"), ("Time", f"{rb.last_seconds:.1f} s"),
                             ("Rays", f"{rb.last_rays:.1f} M"), ("Patches", f"{rb.last_patches}"),
                             ("Triangles", f"{rb.last_triangles}"),
                             ("First image", f"{rb.last_first_image:.2f} s")):
            grid.label(text=label)
            grid.label(text=value)
        last = LAST_RUN.get(context.scene.name, {})
        phases = [p for p in last.get("stats", {}).get("phases", []) if p["seconds"] >= 0.05]
        if phases:
            layout.label(text="Phases")
            grid = layout.grid_flow(columns=2, even_columns=True)
            for p in phases:
                grid.label(text=p["name"].capitalize())
                grid.label(text=f"{p['seconds']:.1f} s")
        for w in last.get("warnings", [])[:6]:
            layout.label(text=w, icon="ERROR")


class RAYBUNDLE_PT_bake(RaybundlePanel, bpy.types.Panel):
    bl_label = "Bake"
    bl_parent_id = "RAYBUNDLE_PT_settings"

    def draw(self, context):
        from .properties import LAST_BAKE

        layout = self.layout
        layout.use_property_split = True
        layout.use_property_decorate = False
        rb = context.scene.raybundle
        col = layout.column(heading="Write")
        col.prop(rb, "bake_color_attribute")
        sub = col.column()
        sub.active = rb.bake_color_attribute
        sub.prop(rb, "bake_domain")
        sub.prop(rb, "bake_gather_auto")
        row = sub.row()
        row.active = not rb.bake_gather_auto
        row.prop(rb, "bake_gather_rays")
        sub.prop(rb, "bake_single_user")
        sub.prop(rb, "bake_subdivide")
        row = sub.row()
        row.active = rb.bake_subdivide
        row.prop(rb, "bake_subdivide_levels")
        col = layout.column()
        col.prop(rb, "bake_lightmaps")
        sub = col.column()
        sub.active = rb.bake_lightmaps
        sub.prop(rb, "lightmap_size")
        sub.prop(rb, "lightmap_margin")
        col.prop(rb, "bake_camera")
        col.prop(rb, "bake_directory")
        col.prop(rb, "bake_light_samples")
        layout.label(text="Glossy reflections are view-dependent: attributes and lightmaps hold diffuse light",
                     icon="INFO")
        layout.operator("raybundle.bake", icon="RENDER_STILL")
        last = LAST_BAKE.get(context.scene.name)
        if last:
            layout.label(text=f"Last bake: {last['status']}",
                         icon="ERROR" if last["status"].startswith("error") else "INFO")
            for w in last.get("warnings", [])[:6]:
                layout.label(text=w, icon="ERROR")


class RAYBUNDLE_PT_passes(RaybundlePanel, bpy.types.Panel):
    bl_label = "Ray Bundle GI Passes"
    bl_context = "view_layer"

    def draw(self, context):
        layout = self.layout
        layout.use_property_split = True
        layout.use_property_decorate = False
        layout.prop(context.view_layer.raybundle, "use_pass_components")


classes = (RAYBUNDLE_PT_settings, RAYBUNDLE_PT_stats, RAYBUNDLE_PT_bake, RAYBUNDLE_PT_passes)


def _stock_panels():
    for cls in bpy.types.Panel.__subclasses__():
        engines = getattr(cls, "COMPAT_ENGINES", None)
        if isinstance(engines, set) and "BLENDER_RENDER" in engines:
            yield cls


def register():
    for c in classes:
        bpy.utils.register_class(c)
    for cls in _stock_panels():
        if ENGINE not in cls.COMPAT_ENGINES:
            cls.COMPAT_ENGINES.add(ENGINE)
            _added.append(cls)


def unregister():
    while _added:
        _added.pop().COMPAT_ENGINES.discard(ENGINE)
    for c in reversed(classes):
        bpy.utils.unregister_class(c)
