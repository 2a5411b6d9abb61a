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
    from raybundle_addon.translation.export import export_scene

    return export_scene(bpy.context.evaluated_depsgraph_get())


def _between(nt, node, source, target):
    """Link ``source`` (an output) -> ``node`` -> ``target`` (an input); returns ``node``."""
    nt.links.new(source, node.inputs[0] if node.type != "VALTORGB" else node.inputs["Fac"])
    nt.links.new(node.outputs[0], target)
    return node


def _against_cycles_by_region(tmp_path, samples, floor):
    """Render the scene with Cycles (two halves of ``samples``) and raybundle (20 iterations) on
    48 x 36 pixels; ``(ours, reference, rel)``: the raybundle image, the reference's 6 x 6
    regions of 8 x 6 pixels and the relative error of those brighter than ``floor`` x the brightest."""
    from addon_helpers import render_cycles, render_raybundle

    a = render_cycles(tmp_path / "a.exr", samples=samples, seed=1)
    b = render_cycles(tmp_path / "b.exr", samples=samples, seed=2)
    ours = render_raybundle(tmp_path / "rb.exr", iterations=20, seed=3)

    def regions(x):
        return x.reshape(6, 6, 6, 8, 3).mean(axis=(1, 3))

    ref = regions(0.5 * (a + b))
    lit = ref.mean(axis=-1) > floor * ref.mean(axis=-1).max()
    return ours, ref, (regions(ours) / np.where(ref > 0, ref, 1) - 1)[lit]


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


def test_a_color_ramp_on_a_noise_texture_is_baked_on_the_object_as_cycles_renders_it(fresh, tmp_path):
    """A Noise Texture (Generated coordinates, the object's own) through a Color Ramp on the
    Diffuse Color: Blender bakes it on the plate itself, through its UV map, as finely as the
    image needs (its 32 x 32 pixels: 128 texels a side, where it was 1,024), its edges extended; the render follows Cycles pixel by pixel.  Another object without a UV map gets the
    mean, with a warning."""
    from addon_helpers import render_cycles, render_raybundle

    plane, _ = textured_plane()
    nt = plane.data.materials[0].node_tree
    noise = nt.nodes.new("ShaderNodeTexNoise")
    noise.inputs["Scale"].default_value = 3.0
    ramp = _between(nt, nt.nodes.new("ShaderNodeValToRGB"), noise.outputs["Fac"],
                    nt.nodes["Diffuse BSDF"].inputs["Color"])
    ramp.color_ramp.elements[0].position, ramp.color_ramp.elements[1].position = 0.35, 0.65
    ramp.color_ramp.elements[0].color = (0.9, 0.4, 0.05, 1)
    ramp.color_ramp.elements[1].color = (0.05, 0.2, 0.8, 1)
    ex = _export()
    assert not any("Color" in w for w in ex.warnings), ex.warnings
    assert ex.scene.texture is not None and ex.scene.texture.images[0].shape == (128, 128, 3)
    assert ex.scene.texture.extend == [True]
    ref = render_cycles(tmp_path / "cy.exr", samples=64, seed=2)
    ours = render_raybundle(tmp_path / "rb.exr", iterations=40, seed=2)
    rel = ours / ref - 1
    # measured: mean 0.07%, 95th percentile 1.7%, largest 10.8% (one pixel on the ramp's steep part,
    # Cycles' noise at 64 samples); with the socket's own grey the pattern was gone
    assert abs(rel.mean()) < 0.01 and np.percentile(np.abs(rel), 95) < 0.04 and np.abs(rel).max() < 0.2, \
        (rel.mean(), np.percentile(np.abs(rel), 95), np.abs(rel).max())
    add_object("no uv", [(3, 0, 0), (4, 0, 0), (4, 1, 0), (3, 1, 0)], [(0, 1, 2, 3)], [plane.data.materials[0]])
    ex = _export()
    assert any("is not baked on every object" in w and "'no uv' has no UV map" in w for w in ex.warnings), \
        ex.warnings


def test_a_graph_baked_on_an_object_is_as_fine_as_the_image_needs(fresh):
    """Texels a side of a graph baked on an object: 16 (four a side) for each pixel its bounding
    box may cover, over the share of the square its UV map covers, between 128 and 1,024; the whole
    image's where the object reaches behind the camera, the most without a camera."""
    from raybundle_addon.translation.node_graphs import object_bake_size

    plane = plane_with_uvs(size=2.0)
    add_light("POINT", location=(0, 0, 1))
    add_camera((0, 0, 3), resolution=(200, 100), ortho_scale=8.0)      # 25 px a metre: 50 x 50 px
    camera = _export().scene.camera
    assert object_bake_size(plane, camera, 1.0) == 208                 # sqrt(16 x 2,500) = 200 -> a multiple of 16
    assert object_bake_size(plane, camera, 0.25) == 400
    plane.location.x = 100.0                                           # out of the image: the fewest
    bpy.context.view_layer.update()
    assert object_bake_size(plane, camera, 1.0) == 128
    plane.location.x = 0.0
    plane.scale = (3.0, 3.0, 1.0)                                      # 150 x 100 px (clipped by the image)
    bpy.context.view_layer.update()
    assert object_bake_size(plane, camera, 1.0) == 496                 # sqrt(16 x 15,000) = 490
    plane.location.z = 3.5                                             # behind the camera
    bpy.context.view_layer.update()
    assert object_bake_size(plane, camera, 1.0) == 576                 # sqrt(16 x 20,000) = 566
    assert object_bake_size(plane, None, 1.0) == 1024


def test_a_byte_images_values_decode_through_a_table_to_the_transfer_functions_numbers():
    """A byte sRGB image's 256 values decode through a table to the very numbers of the transfer
    function applied texel by texel."""
    from raybundle.scene.textures import srgb_to_linear
    from raybundle_addon.translation.images import decode_srgb_bytes

    rgb = np.random.default_rng(1).permutation(np.arange(256 * 3) % 256).reshape(16, 16, 3).astype(np.float32) / 255
    got = decode_srgb_bytes(rgb)
    assert got.dtype == np.float32 and np.array_equal(got, srgb_to_linear(rgb).astype(np.float32))


def test_a_byte_images_pixels_are_read_once_and_its_mean_is_its_decoded_texels(fresh, monkeypatch):
    """A byte sRGB image on a Base Color is read from Blender once per export (its mean for the
    material and its bytes for the texture alike; reading it twice cost a room of seven photos a
    second), and its mean is that of its texels decoded one by one.  A texture without color
    attributes keeps no corner colors (nine floats a face, all zero)."""
    from raybundle.scene.textures import srgb_to_linear
    from raybundle_addon.translation import images
    from raybundle_addon.translation.shaders import MaterialConverter

    plane = plane_with_uvs(size=4.0)
    img = bpy.data.images.new("photo", 40, 24)                   # bytes, sRGB
    px = np.random.default_rng(2).random((24, 40, 4)).astype(np.float32)
    img.pixels.foreach_set(px.ravel())
    nt = plane.data.materials[0].node_tree
    tex = nt.nodes.new("ShaderNodeTexImage")
    tex.image = img
    nt.links.new(tex.outputs["Color"], nt.nodes["Diffuse BSDF"].inputs["Color"])
    add_light("SUN", rotation=(0.3, 0.2, 0), energy=3.0, angle=0.0)
    add_camera((0, 0, 5), resolution=(16, 16), ortho_scale=4.0)
    reads = []
    real = images._pixels
    monkeypatch.setattr(images, "_pixels", lambda image: reads.append(image.name) or real(image))
    tex = _export().scene.texture
    assert tex.images[0].dtype == np.uint8 and tex.face_color is None
    assert reads == ["photo"]
    held = np.asarray(img.pixels[:], np.float32).reshape(24, 40, 4)[..., :3]
    want = srgb_to_linear(held).astype(float).reshape(-1, 3)          # each texel's value as Blender holds it
    np.testing.assert_allclose(MaterialConverter(print).image_mean(img), want.mean(axis=0), rtol=1e-12)


def test_the_export_unloads_the_image_files_it_loaded_and_keeps_those_loaded_before(fresh, tmp_path):
    """Two photos on two planes' Base Color, saved as files: the one Blender had not loaded is
    unloaded again once the export has read its pixels (its copy in Blender stayed for the whole
    render: a room's photographs, tens of megabytes), the one already loaded (shown in an image
    editor, say) stays loaded; both textures are the files' pixels."""
    from raybundle_addon.translation.images import image_bytes

    rng = np.random.default_rng(4)
    files = {}
    for name in ("unloaded", "shown"):
        im = bpy.data.images.new(name, 20, 12)
        im.pixels.foreach_set(rng.random((12, 20, 4)).astype(np.float32).ravel())
        im.filepath_raw, im.file_format = str(tmp_path / f"{name}.png"), "PNG"
        im.save()
        bpy.data.images.remove(im)
        files[name] = bpy.data.images.load(str(tmp_path / f"{name}.png"))
    for k, (name, im) in enumerate(files.items()):
        plane = plane_with_uvs(size=1.0)
        plane.location.x = 1.5 * k
        plane.data.materials[0] = plane.data.materials[0].copy()
        nt = plane.data.materials[0].node_tree
        tex = nt.nodes.new("ShaderNodeTexImage")
        tex.image = im
        nt.links.new(tex.outputs["Color"], nt.nodes["Diffuse BSDF"].inputs["Color"])
    assert files["shown"].pixels[0] >= 0.0                       # loaded, as an editor showing it would
    assert not files["unloaded"].has_data and files["shown"].has_data
    add_light("SUN", rotation=(0.3, 0.2, 0), energy=3.0, angle=0.0)
    add_camera((0.75, 0, 5), resolution=(16, 16), ortho_scale=4.0)
    tex = _export().scene.texture
    assert not files["unloaded"].has_data and files["shown"].has_data
    held = [image_bytes(files[name])[0] for name in files]          # read again from the files
    assert all(any(np.array_equal(g, h) for g in tex.images) for h in held)


@pytest.mark.parametrize("extension", ["EXTEND", "REPEAT"])
def test_an_image_extended_or_repeated_beyond_its_uv_square_is_as_cycles_renders_it(fresh, tmp_path, extension):
    """A checker whose UVs reach from -0.5 to 1.5 over the plane: with Extend its edge texels
    stretch to the plane's rim, with Repeat it tiles; both as in Cycles (Extend was read as
    Repeat, with a warning)."""
    from addon_helpers import assert_like_cycles, render_cycles, render_raybundle

    plane, _ = textured_plane()
    uv = plane.data.uv_layers["UVMap"].uv
    co = np.empty(2 * len(uv), np.float32)
    uv.foreach_get("vector", co)
    uv.foreach_set("vector", (co - 0.5) * 2 + 0.5)
    plane.data.materials[0].node_tree.nodes["Image Texture"].extension = extension
    # a fifth of a pixel off the quads' diagonals: Cycles darkens a pixel 1.6% where one of its
    # 64 samples falls exactly on the edge between two triangles (ours, the exact value, does not)
    bpy.context.scene.camera.location.x += 0.013
    assert not any("extension" in w for w in _export().warnings)
    bpy.context.scene.cycles.pixel_filter_type = "BOX"
    ours = [render_raybundle(tmp_path / f"rb{s}.exr", iterations=6, seed=s) for s in (1, 2)]
    theirs = [render_cycles(tmp_path / f"cy{s}.exr", samples=32, seed=s) for s in (1, 2)]
    assert_like_cycles(ours, theirs)


def test_a_node_driven_roughness_and_color_are_blenders_values(fresh, tmp_path):
    """Principled Roughness <- Math(Value 0.6 x 0.5) and Base Color <- Mix(red, blue, 0.25):
    constant graphs, evaluated by Blender to 0.3 and its mix; a glossy plate under an area
    lamp then renders as in Cycles (the highlight's size is the roughness')."""
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
    ours, ref, rel = _against_cycles_by_region(tmp_path, 256, 0.05)
    # measured: 10 lit regions, rms 3.7%, largest 5.5% (the highlight's noise after 20
    # iterations; Cycles' own below 2%); the sockets' own values (roughness 0.5, grey): 50-500%
    assert np.sqrt((rel ** 2).mean()) < 0.08 and np.abs(rel).max() < 0.15, rel
    assert ours.mean() == pytest.approx(ref.mean(), rel=0.04)


def test_graphs_blender_cannot_evaluate_keep_their_warning_and_the_file_is_unchanged(fresh):
    """A Layer Weight (it depends on the view) through a Color Ramp: the socket's own value, with
    a warning naming the node; an image graph on Roughness that varies gives its mean, with a
    warning; the file is left as it was."""
    plane, _ = textured_plane()
    nt = plane.data.materials[0].node_tree
    weight = nt.nodes.new("ShaderNodeLayerWeight")
    ramp = _between(nt, nt.nodes.new("ShaderNodeValToRGB"), weight.outputs["Facing"],
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
    assert any("'Color' is driven by a Color Ramp node" in w and "Layer Weight" in w for w in ex.warnings), \
        ex.warnings
    k = list(ex.scene.materials.names).index("glossy")
    # the checker's grey texels (32 of 0.15, 31 of 0.75, one 0.95) times 0.5, their mean
    assert ex.scene.materials.roughness[k] == pytest.approx((32 * 0.075 + 31 * 0.375 + 0.475) / 64, abs=1e-6)
    assert any("'Roughness' varies over the surface" in w for w in ex.warnings), ex.warnings
    assert ramp.outputs[0].is_linked and (len(nt.nodes), len(nt.links), len(gt.nodes), len(gt.links)) == nodes
    assert {k: len(getattr(bpy.data, k)) for k in before} == before


def _leaf_plane(alpha, size=1.2, z=0.6):
    """A square of ``size`` m at height ``z`` with UVs over it, a Principled BSDF (green) whose
    Alpha is the alpha channel of an image (``alpha`` (H, W), Closest interpolation)."""
    mat = node_material("leaf", "principled", color=(0.2, 0.6, 0.1), roughness=1.0)
    nt = mat.node_tree
    img = bpy.data.images.new("leaf", alpha.shape[1], alpha.shape[0], alpha=True, float_buffer=True)
    rgba = np.concatenate([np.full(alpha.shape + (3,), 0.5), alpha[..., None]], axis=2).astype(np.float32)
    img.pixels.foreach_set(rgba.ravel())
    tex = nt.nodes.new("ShaderNodeTexImage")
    tex.image, tex.interpolation = img, "Closest"
    nt.links.new(tex.outputs["Alpha"], nt.nodes["Principled BSDF"].inputs["Alpha"])
    h = size / 2
    ob = add_object("leaf", [(-h, -h, z), (h, -h, z), (h, h, z), (-h, h, z)], [(0, 1, 2, 3)], [mat])
    ob.data.uv_layers.new(name="UVMap").uv.foreach_set("vector", np.array([0, 0, 1, 0, 1, 1, 0, 1], np.float32))
    return ob


def test_an_alpha_cut_leaf_lets_light_and_the_eye_through_as_in_cycles(fresh, tmp_path):
    """A leaf plane whose image alpha cuts out a 4 x 4 checker, over a floor under a point lamp,
    seen from above: the floor's checker of light and shadow, the floor seen through the holes
    and the leaf where it is, region by region against Cycles.  Opaque (the old export), the
    shadow under the leaf is whole and the leaf hides the floor."""
    checker = np.add.outer(np.arange(4), np.arange(4)) % 2
    _leaf_plane(checker.astype(float))
    s = 2.0
    add_object("floor", [(-s, -s, 0), (s, -s, 0), (s, s, 0), (-s, s, 0)], [(0, 1, 2, 3)],
               [node_material("floor", color=(0.8, 0.8, 0.8))])
    add_light("POINT", location=(0.2, -0.1, 2.4), energy=400.0, shadow_soft_size=0.0)
    add_camera((0, -1.6, 3.0), rotation=(0.5, 0, 0), resolution=(48, 36), lens=32)
    ex = _export()
    assert ex.scene.texture is not None and ex.scene.texture.has_cutouts
    assert not any("lpha" in w for w in ex.warnings), ex.warnings
    ours, ref, rel = _against_cycles_by_region(tmp_path, 128, 0.02)
    # measured: 36 lit regions, rms 1.2%, largest 6.8%, mean x1.002 (opaque: rms 20%, largest 73%)
    assert np.sqrt((rel ** 2).mean()) < 0.05 and np.abs(rel).max() < 0.12, rel
    assert ours.mean() == pytest.approx(ref.mean(), rel=0.03)


def test_the_headless_command_saves_a_cut_out_scene_with_its_rendered_world(fresh, tmp_path):
    """``--save-npz`` on a file whose world Blender renders (a Gradient Texture) and whose leaf is
    cut out by its image's alpha: the .npz holds the rendered world (it was refused while the
    world was still rendering) and the coverage; the render is finite."""
    import subprocess

    from addon_helpers import blender_cli_command
    from cycles_reference import new_with_nodes

    from raybundle.scene.npz import load_npz

    leaf = _leaf_plane(np.add.outer(np.arange(4), np.arange(4)) % 2 * 1.0)
    leaf.data.materials[0].node_tree.nodes["Image Texture"].image.pack()
    s = 2.0
    add_object("floor", [(-s, -s, 0), (s, -s, 0), (s, s, 0), (-s, s, 0)], [(0, 1, 2, 3)],
               [node_material("floor", color=(0.8, 0.8, 0.8))])
    add_camera((0, -1.6, 3.0), rotation=(0.5, 0, 0), resolution=(24, 18), lens=32)
    world = new_with_nodes(bpy.data.worlds, "gradient")
    nt = world.node_tree
    ramp = nt.nodes.new("ShaderNodeTexGradient")
    nt.links.new(ramp.outputs["Color"], nt.nodes["Background"].inputs["Color"])
    bpy.context.scene.world = world
    blend, out, npz = tmp_path / "leaf.blend", tmp_path / "out.exr", tmp_path / "scene.npz"
    bpy.ops.wm.save_as_mainfile(filepath=str(blend))
    r = subprocess.run(blender_cli_command(blend, "--out", out, "--iterations", 3, "--save-npz", npz),
                       capture_output=True, text=True, cwd=tmp_path, timeout=300)
    assert r.returncode == 0, r.stderr[-2000:]
    sc = load_npz(npz)
    assert not sc.world.is_constant and sc.world.emits
    assert sc.texture is not None and sc.texture.has_cutouts


def test_a_mix_with_a_transparent_bsdf_is_the_same_cut_out_as_an_alpha(fresh, tmp_path):
    """The leaf's cut-out described three ways renders the same image, bit for bit (the same
    seed): the Principled Alpha from the image's alpha; a Mix Shader of a Transparent BSDF (first)
    and the Principled BSDF with the alpha as its factor; the Transparent BSDF second with
    1 - alpha (a Math node) as the factor."""
    from addon_helpers import render_raybundle

    leaf = _leaf_plane((np.add.outer(np.arange(4), np.arange(4)) % 2) * 0.8 + 0.1)
    add_light("POINT", location=(0.2, -0.1, 2.4), energy=400.0, shadow_soft_size=0.0)
    add_camera((0, -1.6, 3.0), rotation=(0.5, 0, 0), resolution=(24, 18), lens=32)
    nt = leaf.data.materials[0].node_tree
    bsdf, tex, out = nt.nodes["Principled BSDF"], nt.nodes["Image Texture"], nt.nodes["Material Output"]
    images = [render_raybundle(tmp_path / "alpha.exr", iterations=4, seed=1)]
    nt.links.remove(bsdf.inputs["Alpha"].links[0])
    clear, mix = nt.nodes.new("ShaderNodeBsdfTransparent"), nt.nodes.new("ShaderNodeMixShader")
    nt.links.new(tex.outputs["Alpha"], mix.inputs[0])
    nt.links.new(clear.outputs[0], mix.inputs[1])
    nt.links.new(bsdf.outputs[0], mix.inputs[2])
    nt.links.new(mix.outputs[0], out.inputs["Surface"])
    ex = _export()
    assert ex.scene.texture.has_cutouts and not any("ransparent" in w for w in ex.warnings), ex.warnings
    images.append(render_raybundle(tmp_path / "mix.exr", iterations=4, seed=1))
    one_minus = nt.nodes.new("ShaderNodeMath")
    one_minus.operation, one_minus.inputs[0].default_value = "SUBTRACT", 1.0
    nt.links.new(tex.outputs["Alpha"], one_minus.inputs[1])
    nt.links.new(one_minus.outputs[0], mix.inputs[0])
    nt.links.new(bsdf.outputs[0], mix.inputs[1])
    nt.links.new(clear.outputs[0], mix.inputs[2])
    images.append(render_raybundle(tmp_path / "inverted.exr", iterations=4, seed=1))
    assert images[0].mean() > 0 and np.array_equal(images[0], images[1]) and np.array_equal(images[0], images[2])


def test_a_lightmap_of_a_node_graph_texture_is_cycles_bake(fresh, tmp_path):
    """The textured plane with a Color Ramp between its image and the Diffuse Color: raybundle's
    lightmap (32 x 32 texels, direct light of the point lamp times the graph's albedo) against
    Cycles' own Combined bake of the same material into the same UV map, in 8 x 8 blocks of
    4 x 4 texels (one texel of the image each)."""
    from addon_helpers import lightmap_blocks
    from cycles_reference import bake_image
    from cycles_reference import cycles_settings

    from raybundle.util.io import read_exr
    from raybundle_addon.bake import BakeJob

    plane, _ = textured_plane()
    nt = plane.data.materials[0].node_tree
    ramp = _between(nt, nt.nodes.new("ShaderNodeValToRGB"), nt.nodes["Image Texture"].outputs["Color"],
                    nt.nodes["Diffuse BSDF"].inputs["Color"])
    ramp.color_ramp.elements[0].color = (0.9, 0.4, 0.05, 1)
    ramp.color_ramp.elements[1].color = (0.05, 0.2, 0.8, 1)
    rb = fresh.raybundle
    rb.iterations, rb.seed, rb.patches, rb.bake_light_samples = 20, 1, 600, 16
    rb.bake_color_attribute, rb.bake_lightmaps, rb.lightmap_size, rb.lightmap_margin = False, True, 32, 2
    rb.bake_directory = str(tmp_path)
    out = BakeJob(bpy.context.evaluated_depsgraph_get(), lightmap_objects=["plane"]).run()
    ours = read_exr(out.lightmaps["plane"])[::-1]              # rows bottom-up, as Image.pixels
    cycles_settings(256, 1, world_strength=None)
    rel = lightmap_blocks(ours) / lightmap_blocks(bake_image(plane, 32)) - 1
    # measured: mean 0.07%, RMS 0.16%, largest 0.41% (the socket's own color: -70 .. +400%)
    assert abs(rel.mean()) < 0.005 and np.sqrt((rel ** 2).mean()) < 0.01 and np.abs(rel).max() < 0.03, rel


def test_a_bake_blender_cannot_finish_falls_back_to_the_sockets_value_with_a_warning(fresh, monkeypatch):
    """When Blender's bake of the graphs fails (here: it cannot finish in the time allowed), the
    export goes on: each graph input keeps its socket's own value, with one warning saying why."""
    from raybundle_addon.translation import node_graphs

    plane, _ = textured_plane()
    nt = plane.data.materials[0].node_tree
    _between(nt, nt.nodes.new("ShaderNodeValToRGB"), nt.nodes["Image Texture"].outputs["Color"],
             nt.nodes["Diffuse BSDF"].inputs["Color"])
    monkeypatch.setattr(node_graphs, "BAKE_TIMEOUT", 0.01)
    monkeypatch.setattr(node_graphs, "cache_folder", lambda: None)         # no bake kept from other tests
    ex = _export()
    assert any("'Color' is driven by a Color Ramp node (Blender could not bake it (it did not finish" in w
               for w in ex.warnings), ex.warnings
    assert ex.scene.texture is None and np.allclose(ex.scene.materials.diffuse[0], 0.6)


def test_graph_bakes_are_kept_on_disk_and_baked_again_when_what_they_read_changes(fresh, tmp_path, monkeypatch):
    """A graph Blender baked is kept on disk, keyed by its material, its images' pixels, the
    object it is baked on and the task: the same scene exported again starts no bake and reads
    the same values; an edited image (a graph over the UV map) and an edited UV map (a graph
    baked on the object) are baked again, the unchanged graph is not; a changed ramp color too."""
    from raybundle_addon.translation import node_graphs
    from raybundle_addon.translation.blender_process import BlenderProcess

    monkeypatch.setattr(node_graphs, "cache_folder", lambda: str(tmp_path))
    starts = []

    class Counted(BlenderProcess):
        def __init__(self, *args):
            starts.append(args)
            super().__init__(*args)

    monkeypatch.setattr(node_graphs, "BlenderProcess", Counted)
    plane, _ = textured_plane()                                 # image -> Color Ramp: over the UV map
    nt = plane.data.materials[0].node_tree
    ramp = _between(nt, nt.nodes.new("ShaderNodeValToRGB"), nt.nodes["Image Texture"].outputs["Color"],
                    nt.nodes["Diffuse BSDF"].inputs["Color"])
    other = plane_with_uvs(size=1.0)                            # noise -> Color Ramp: on the object
    other.location.x = 1.6
    nt2 = other.data.materials[0].node_tree
    _between(nt2, nt2.nodes.new("ShaderNodeValToRGB"), nt2.nodes.new("ShaderNodeTexNoise").outputs["Fac"],
             nt2.nodes["Diffuse BSDF"].inputs["Color"])

    def baked():
        ex = _export()
        assert not any("Color" in w for w in ex.warnings), ex.warnings
        return [im.copy() for im in ex.scene.texture.images], sorted(p.name for p in tmp_path.glob("*.npy")), \
            ex.scene.materials.diffuse_reflectance.copy()

    first, files, _ = baked()
    assert len(starts) == 1 and len(files) == 2 and len(first) == 2
    assert all(im.dtype == np.float16 for im in first)          # float maps kept in half precision
    again, same, _ = baked()
    assert len(starts) == 1 and same == files and all(np.array_equal(a, b) for a, b in zip(first, again))
    img = nt.nodes["Image Texture"].image
    px = np.array(img.pixels[:], np.float32).reshape(-1, 4)
    px[:, :3] = 1 - px[:, :3]
    img.pixels.foreach_set(px.ravel())
    uv = other.data.uv_layers[0].uv
    co = np.empty(2 * len(uv), np.float32)
    uv.foreach_get("vector", co)
    uv.foreach_set("vector", 0.5 * co)
    edited, files2, albedo2 = baked()
    assert len(starts) == 2 and len(files2) == 4 and len(edited) == 2
    assert not any(np.array_equal(a, b) for a, b in zip(first, edited))
    ramp.color_ramp.elements[1].color = (0.05, 0.2, 0.8, 1)
    recolored, files3, albedo3 = baked()
    # one graph baked again: the ramp's, whose colors move its mean albedo (its map over that mean,
    # t c / mean(t c), is the same); the noise graph's map is read from the disk as it was
    assert len(starts) == 3 and len(files3) == 5 and not np.array_equal(albedo2, albedo3)
    assert any(np.array_equal(a, b) for a, b in zip(edited, recolored))


def _shaded_plane(kind):
    """``plane_with_uvs`` (2 m, so a UV unit is 2 m) under a point light, seen from above by an ortho
    camera, its Diffuse BSDF's Normal from a 64 x 1 float image through a Normal Map node
    (``kind`` "normal": the normal tilted by 30 degrees one way on the left half, the other way on
    the right) or a Bump node (``kind`` "bump": the height 0.5 sin(2 pi u) / pi, its slope per UV
    unit cos(2 pi u), per metre half that)."""
    from addon_helpers import plane_with_uvs

    plane = plane_with_uvs()
    u = (np.arange(64) + 0.5) / 64
    if kind == "normal":
        th = np.radians(np.where(u < 0.5, 30.0, -30.0))
        px = (np.stack([np.sin(th), 0 * th, np.cos(th)], axis=1) + 1) / 2
    else:
        px = np.repeat((0.5 * np.sin(2 * np.pi * u) / np.pi)[:, None], 3, axis=1)
    img = bpy.data.images.new(kind, 64, 1, float_buffer=True)
    img.pixels.foreach_set(np.concatenate([px, np.ones((64, 1))], axis=1).astype(np.float32).ravel())
    nt = plane.data.materials[0].node_tree
    tex = nt.nodes.new("ShaderNodeTexImage")
    tex.image = img
    if kind == "normal":
        node = nt.nodes.new("ShaderNodeNormalMap")
        nt.links.new(tex.outputs["Color"], node.inputs["Color"])
    else:
        node = nt.nodes.new("ShaderNodeBump")
        node.inputs["Strength"].default_value, node.inputs["Distance"].default_value = 1.0, 1.0
        nt.links.new(tex.outputs["Color"], node.inputs["Height"])
    nt.links.new(node.outputs["Normal"], nt.nodes["Diffuse BSDF"].inputs["Normal"])
    add_light("POINT", location=(0.3, -0.2, 1.5), energy=1000.0, shadow_soft_size=0.0)
    add_camera((0, 0, 3), resolution=(32, 32), ortho_scale=2.0)
    return plane


@pytest.mark.parametrize("kind", ["normal", "bump"])
def test_normal_and_bump_maps_shade_the_plane_as_in_cycles(fresh, tmp_path, kind):
    """A Normal Map node (tangent space) and a Bump node on a plane's Diffuse BSDF, evaluated by
    Blender over a unit square, shade the eye's view as Cycles does pixel by pixel (the bump's
    slope carried from UV units to metres).  The code before ignored both (with a warning): with
    the plane's own normal the 95th percentile of the pixels' error was 24% (normal map) and 80%
    (bump)."""
    from addon_helpers import render_cycles, render_raybundle

    _shaded_plane(kind)
    ex = _export()
    assert not any("normal" in w.lower() for w in ex.warnings), ex.warnings
    assert ex.scene.texture is not None and ex.scene.texture.has_normal_maps
    assert bool(ex.scene.texture.face_bump.all()) == (kind == "bump")
    ref = render_cycles(tmp_path / "cy.exr", samples=64, seed=2)
    ours = render_raybundle(tmp_path / "rb.exr", iterations=40, seed=2)
    rel = ours.mean(axis=2) / ref.mean(axis=2) - 1
    # measured: mean 0.39 / 0.26%, 95th percentile 1.0 / 0.9%, largest 2.1 / 2.0% (normal map / bump)
    assert abs(rel.mean()) < 0.01 and np.percentile(np.abs(rel), 95) < 0.04, \
        (rel.mean(), np.percentile(np.abs(rel), 95), np.abs(rel).max())


def test_normal_maps_blender_cannot_bake_over_a_unit_square_are_warned_and_left_out(fresh):
    """An object-space Normal Map and a Bump of a Noise Texture: the plane's own normal, one
    warning each naming why."""
    plane = _shaded_plane("normal")
    nt = plane.data.materials[0].node_tree
    nt.nodes["Normal Map"].space = "OBJECT"
    ex = _export()
    assert any("object space" in w and "normal / bump map" in w for w in ex.warnings), ex.warnings
    assert ex.scene.texture is None or not ex.scene.texture.has_normal_maps
    bump = nt.nodes.new("ShaderNodeBump")
    nt.links.new(nt.nodes.new("ShaderNodeTexNoise").outputs["Fac"], bump.inputs["Height"])
    nt.links.new(bump.outputs["Normal"], nt.nodes["Diffuse BSDF"].inputs["Normal"])
    ex = _export()
    assert any("procedural bump" in w for w in ex.warnings), ex.warnings
    assert ex.scene.texture is None or not ex.scene.texture.has_normal_maps


@pytest.mark.parametrize("interpolation", ["Linear", "Closest"])
def test_a_byte_srgb_checker_on_base_color_matches_cycles(fresh, tmp_path, interpolation):
    """An 8 x 8 checker of two saturated colors in a byte sRGB image on a Principled Base Color,
    seen 8 pixels a texel under a sun: the image mean within 3% of Cycles' and its 8 x 8 regions
    within 4.5 standard errors, for Linear and Closest interpolation.  Cycles interpolates such an
    image's encoded values and decodes after (ours decoded first: x1.32 the mean with Linear), and
    Closest reads one texel (ours blended: the weak channel of each color up to x3).  The scene
    keeps the image's bytes (a quarter of the memory of its float values)."""
    from addon_helpers import assert_like_cycles, plane_with_uvs, render_cycles, render_raybundle

    plane = plane_with_uvs(size=4.0)
    img = bpy.data.images.new("checker", 8, 8)                   # bytes, sRGB
    odd = (np.add.outer(np.arange(8), np.arange(8)) % 2).astype(bool)[..., None]
    px = np.where(odd, (0.8, 0.25, 0.1), (0.1, 0.3, 0.7))
    img.pixels.foreach_set(np.concatenate([px, np.ones((8, 8, 1))], axis=2).astype(np.float32).ravel())
    nt = plane.data.materials[0].node_tree
    for n in [n for n in nt.nodes if n.type != "OUTPUT_MATERIAL"]:
        nt.nodes.remove(n)
    shader, tex = nt.nodes.new("ShaderNodeBsdfPrincipled"), nt.nodes.new("ShaderNodeTexImage")
    tex.image, tex.interpolation = img, interpolation
    nt.links.new(tex.outputs["Color"], shader.inputs["Base Color"])
    nt.links.new(shader.outputs[0], nt.nodes["Material Output"].inputs["Surface"])
    add_light("SUN", rotation=(0.3, 0.2, 0), energy=3.0, angle=0.0)
    add_camera((0, 0, 5), resolution=(64, 64), ortho_scale=4.0)
    bpy.context.scene.cycles.pixel_filter_type = "BOX"
    kept = _export().scene.texture.images
    assert [(im.dtype, im.shape) for im in kept] == [(np.uint8, (8, 8, 3))]
    ours = [render_raybundle(tmp_path / f"rb{s}.exr", iterations=6, seed=s) for s in (1, 2)]
    theirs = [render_cycles(tmp_path / f"cy{s}.exr", samples=32, seed=s) for s in (1, 2)]
    assert_like_cycles(ours, theirs)


@pytest.mark.parametrize("coordinates", ["uv map", "texture coordinate"])
def test_an_image_read_through_a_tiling_mapping_is_baked_once_as_cycles_renders_it(fresh, tmp_path, coordinates):
    """UV -> Mapping (scale 2: the checker tiled twice) -> Vector Math (offset) -> Image Texture ->
    Diffuse Color: a function of the UV map, so Blender bakes it once for the material, twice as
    fine as the image for its tiling, however many objects use it (it was baked on each object at
    1,024^2, or, with the image straight on the color, replaced by its mean with a warning); the
    render follows Cycles pixel by pixel.  Seen by an image of 8 x 8 pixels, the bake is only as
    fine as that image needs (it was as fine as for the 32 x 32 one)."""
    from addon_helpers import render_cycles, render_raybundle

    from raybundle_addon.translation.node_graphs import graph_input

    plane, _ = textured_plane()
    mat = plane.data.materials[0]
    nt = mat.node_tree
    tex = nt.nodes["Image Texture"]
    if coordinates == "uv map":
        uv = nt.nodes.new("ShaderNodeUVMap")
        source = uv.outputs["UV"]
    else:
        source = nt.nodes.new("ShaderNodeTexCoord").outputs["UV"]
    mapping = nt.nodes.new("ShaderNodeMapping")
    mapping.inputs["Scale"].default_value = (2.0, 2.0, 1.0)
    offset = nt.nodes.new("ShaderNodeVectorMath")
    offset.operation = "ADD"
    offset.inputs[1].default_value = (0.0625, 0.0, 0.0)
    nt.links.new(source, mapping.inputs["Vector"])
    _between(nt, offset, mapping.outputs["Vector"], tex.inputs["Vector"])
    got = graph_input(mat, nt.nodes["Diffuse BSDF"].inputs["Color"])
    assert not isinstance(got, str) and not got.per_object and got.size == (128, 128), got
    second = add_object("second", [(3, 0, 0), (4, 0, 0), (4, 1, 0), (3, 1, 0)], [(0, 1, 2, 3)], [mat])
    second.data.uv_layers.new(name="UVMap")
    ex = _export()
    assert not any("Color" in w or "mean" in w for w in ex.warnings), ex.warnings
    assert ex.scene.texture is not None and [im.shape for im in ex.scene.texture.images] == [(128, 128, 3)]
    bpy.data.objects.remove(bpy.data.objects["second"])
    ref = render_cycles(tmp_path / "cy.exr", samples=64, seed=2)
    ours = render_raybundle(tmp_path / "rb.exr", iterations=40, seed=2)
    rel = ours / ref - 1
    # as the color ramp's test above: Cycles' noise at 64 samples
    assert abs(rel.mean()) < 0.01 and np.percentile(np.abs(rel), 95) < 0.04 and np.abs(rel).max() < 0.1, \
        (rel.mean(), np.percentile(np.abs(rel), 95), np.abs(rel).max())
    bpy.context.scene.render.resolution_x = bpy.context.scene.render.resolution_y = 8
    assert [im.shape for im in _export().scene.texture.images] == [(32, 32, 3)]      # sqrt(16 x 64) = 32
