"""Materials as Blender defines them: node graphs on a material's inputs evaluated by Blender.

Against Cycles on the same file, pixel by pixel, and against the values Blender computes.
"""
from __future__ import annotations

import numpy as np
import pytest
from addon_helpers import (  # noqa: F401
    add_camera,
    add_light,
    add_object,
    addon,
    bpy,
    fresh,
    node_material,
    plane_with_uvs,
    textured_plane,
)


def _export():
    from raybundle_addon.export import export_scene

    return export_scene(bpy.context.evaluated_depsgraph_get())


def _between(nt, node, source, target):
    """Link ``source`` (an output) -> ``node`` -> ``target`` (an input); returns ``node``."""
    nt.links.new(source, node.inputs[0] if node.type != "VALTORGB" else node.inputs["Fac"])
    nt.links.new(node.outputs[0], target)
    return node


def test_a_color_ramp_on_an_image_drives_the_albedo_as_in_cycles(fresh, tmp_path):
    """Image -> Math (power 2) -> Color Ramp (orange to blue) -> Diffuse Color: Blender bakes the
    graph over the image's texels; the render follows Cycles pixel by pixel.  The converter
    alone would use the socket's own color (uniform white-grey)."""
    from addon_helpers import render_cycles, render_raybundle

    plane, _ = textured_plane()
    nt = plane.data.materials[0].node_tree
    tex, diffuse = nt.nodes["Image Texture"], nt.nodes["Diffuse BSDF"]
    ramp = nt.nodes.new("ShaderNodeValToRGB")
    ramp.color_ramp.elements[0].color = (0.9, 0.4, 0.05, 1)
    ramp.color_ramp.elements[1].color = (0.05, 0.2, 0.8, 1)
    power = nt.nodes.new("ShaderNodeMath")
    power.operation, power.inputs[1].default_value = "POWER", 2.0
    nt.links.new(tex.outputs["Color"], power.inputs[0])
    _between(nt, ramp, power.outputs[0], diffuse.inputs["Color"])
    ex = _export()
    assert not any("Color" in w for w in ex.warnings), ex.warnings
    assert ex.scene.texture is not None and len(ex.scene.texture.images) == 1
    ref = render_cycles(tmp_path / "cy.exr", samples=64, seed=2)
    ours = render_raybundle(tmp_path / "rb.exr", iterations=40, seed=2)
    rel = ours / ref - 1
    # measured: mean 0.01%, 95th percentile 1.2%, largest 3.7% (Cycles' noise at 64 samples);
    # the socket's own color: -70 .. +400% per channel
    assert abs(rel.mean()) < 0.01 and np.percentile(np.abs(rel), 95) < 0.04 and np.abs(rel).max() < 0.1, \
        (rel.mean(), np.percentile(np.abs(rel), 95), np.abs(rel).max())
    assert np.corrcoef(ours[..., 2].ravel(), ref[..., 2].ravel())[0, 1] > 0.99


def test_a_node_driven_roughness_and_color_are_blenders_values(fresh, tmp_path):
    """Principled Roughness <- Math(Value 0.6 x 0.5) and Base Color <- Mix(red, blue, 0.25):
    constant graphs, evaluated by Blender to 0.3 and its mix; a glossy plate under an area
    lamp then renders as in Cycles (the highlight's size is the roughness')."""
    from addon_helpers import render_cycles, render_raybundle

    mat = node_material("plate", "principled", color=(0.8, 0.8, 0.8), roughness=0.5)
    nt = mat.node_tree
    bsdf = nt.nodes["Principled BSDF"]
    bsdf.inputs["Metallic"].default_value = 1.0
    value = nt.nodes.new("ShaderNodeValue")
    value.outputs[0].default_value = 0.6
    half = nt.nodes.new("ShaderNodeMath")
    half.operation, half.inputs[1].default_value = "MULTIPLY", 0.5
    _between(nt, half, value.outputs[0], bsdf.inputs["Roughness"])
    mix = nt.nodes.new("ShaderNodeMix")
    mix.data_type = "RGBA"
    mix.inputs["Factor"].default_value = 0.25
    mix.inputs["A"].default_value = (0.9, 0.1, 0.1, 1)
    mix.inputs["B"].default_value = (0.1, 0.1, 0.9, 1)
    nt.links.new(mix.outputs["Result"], bsdf.inputs["Base Color"])
    s = 1.5
    add_object("plate", [(-s, -s, 0), (s, -s, 0), (s, s, 0), (-s, s, 0)], [(0, 1, 2, 3)], [mat])
    add_light("AREA", location=(0, 0.6, 1.2), rotation=(-0.45, 0, 0), energy=100.0, size=1.0)
    add_camera((0, -2.2, 1.6), rotation=(0.95, 0, 0), resolution=(48, 36), lens=35)
    ex = _export()
    mt = ex.scene.materials
    assert mt.roughness[0] == pytest.approx(0.3, abs=1e-6)
    assert np.allclose(mt.glossy[0], (0.7, 0.1, 0.3), atol=1e-6)           # F0 = base color (metallic)
    assert not any("driven" in w for w in ex.warnings), ex.warnings
    a = render_cycles(tmp_path / "a.exr", samples=256, seed=1)
    b = render_cycles(tmp_path / "b.exr", samples=256, seed=2)
    ours = render_raybundle(tmp_path / "rb.exr", iterations=20, seed=3)

    def regions(x):                         # 6 x 6 regions of 8 x 6 pixels
        return x.reshape(6, 6, 6, 8, 3).mean(axis=(1, 3))

    ref = regions(0.5 * (a + b))
    lit = ref.mean(axis=-1) > 0.05 * ref.mean(axis=-1).max()
    rel = (regions(ours) / np.where(ref > 0, ref, 1) - 1)[lit]
    # measured: 10 lit regions, rms 3.7%, largest 5.5% (the highlight's noise after 20
    # iterations; Cycles' own below 2%); the sockets' own values (roughness 0.5, grey): 50-500%
    assert np.sqrt((rel ** 2).mean()) < 0.08 and np.abs(rel).max() < 0.15, rel
    assert ours.mean() == pytest.approx(ref.mean(), rel=0.04)


def test_graphs_blender_cannot_evaluate_over_a_uv_map_keep_their_warning(fresh):
    """A Noise Texture (Generated coordinates) through a Color Ramp: not a function of a UV map,
    so the socket's own value, with a warning naming the node; an image graph on Roughness
    that varies gives its mean, with a warning; the file is left as it was."""
    plane, _ = textured_plane()
    nt = plane.data.materials[0].node_tree
    noise = nt.nodes.new("ShaderNodeTexNoise")
    ramp = _between(nt, nt.nodes.new("ShaderNodeValToRGB"), noise.outputs["Fac"],
                    nt.nodes["Diffuse BSDF"].inputs["Color"])
    glossy = node_material("glossy", "glossy", roughness=0.5)
    gt = glossy.node_tree
    img = nt.nodes["Image Texture"].image
    tex = gt.nodes.new("ShaderNodeTexImage")
    tex.image = img
    half = gt.nodes.new("ShaderNodeMath")
    half.operation, half.inputs[1].default_value = "MULTIPLY", 0.5
    _between(gt, half, tex.outputs["Color"], gt.nodes["Glossy BSDF"].inputs["Roughness"])
    add_object("g", [(3, 0, 0), (4, 0, 0), (4, 1, 0), (3, 1, 0)], [(0, 1, 2, 3)], [glossy])
    before = {k: len(getattr(bpy.data, k)) for k in ("materials", "images", "meshes", "objects", "scenes")}
    nodes = (len(nt.nodes), len(nt.links), len(gt.nodes), len(gt.links))
    ex = _export()
    assert any("'Color' is driven by a Color Ramp node" in w and "Noise Texture" in w for w in ex.warnings), \
        ex.warnings
    k = list(ex.scene.materials.names).index("glossy")
    # the checker's grey texels (32 of 0.15, 31 of 0.75, one 0.95) times 0.5, their mean
    assert ex.scene.materials.roughness[k] == pytest.approx((32 * 0.075 + 31 * 0.375 + 0.475) / 64, abs=1e-6)
    assert any("'Roughness' varies over the surface" in w for w in ex.warnings), ex.warnings
    assert ramp.outputs[0].is_linked and (len(nt.nodes), len(nt.links), len(gt.nodes), len(gt.links)) == nodes
    assert {k: len(getattr(bpy.data, k)) for k in before} == before
