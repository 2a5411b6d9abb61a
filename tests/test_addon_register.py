"""The add-on registers and unregisters cleanly, twice in a row, in the real ``bpy`` module."""
import addon_helpers  # noqa: F401  (BLENDER_USER_RESOURCES before bpy)
import bpy
import pytest


def stock_panels_with_engine():
    return sorted(p.__name__ for p in bpy.types.Panel.__subclasses__()
                  if "BLENDER_RENDER" in getattr(p, "COMPAT_ENGINES", ()) and "RAYBUNDLE" in p.COMPAT_ENGINES)


def engines():
    return {getattr(c, "bl_idname", "") for c in bpy.types.RenderEngine.__subclasses__()
            if getattr(c, "is_registered", False)}


def test_register_unregister_twice():
    import raybundle_addon

    if hasattr(bpy.types.Scene, "raybundle"):
        raybundle_addon.unregister()
    assert not stock_panels_with_engine()
    for _ in range(2):
        raybundle_addon.register()
        assert hasattr(bpy.types.Scene, "raybundle")
        assert "RAYBUNDLE" in engines()
        assert len(stock_panels_with_engine()) > 100          # Dimensions, Output, light, camera ... panels
        bpy.ops.wm.read_factory_settings(use_empty=True)
        sc = bpy.context.scene
        sc.render.engine = "RAYBUNDLE"
        assert sc.render.engine == "RAYBUNDLE"
        rb = sc.raybundle
        assert (rb.time_limit, rb.iterations, rb.patches, rb.bundle_resolution, rb.first_shot) == (30.0, 0, 4000, 0,
                                                                                                     True)
        from raybundle.methods.registry import SOLVERS
        assert rb.method in SOLVERS
        assert {i.identifier for i in rb.bl_rna.properties["method"].enum_items} == set(SOLVERS) | {"auto"}
        with pytest.raises((AttributeError, TypeError)):
            rb.last_iterations = 3                             # statistics are read-only
        raybundle_addon.unregister()
        assert not hasattr(bpy.types.Scene, "raybundle")
        assert "RAYBUNDLE" not in engines()
        assert not stock_panels_with_engine()


def test_panel_polls_on_the_engine():
    import raybundle_addon
    from raybundle_addon import ui

    raybundle_addon.register()
    try:
        bpy.ops.wm.read_factory_settings(use_empty=True)
        ctx = bpy.context
        ctx.scene.render.engine = "CYCLES"
        assert not ui.RAYBUNDLE_PT_settings.poll(ctx)
        ctx.scene.render.engine = "RAYBUNDLE"
        assert ui.RAYBUNDLE_PT_settings.poll(ctx)
        assert ui.RAYBUNDLE_PT_settings.bl_context == "render"
    finally:
        raybundle_addon.unregister()
