"""Render a raybundle scene with Blender's Cycles (pip ``bpy``), for references and checks.

Usage::

    python tools/cycles_reference.py cornell --samples 1024 --seed 1 --out out/reference/cornell-256x256-1.exr

Builds the scene in Blender with the node set-up that :mod:`raybundle.scene.materials`
models (Mix Shader(Diffuse BSDF, Glossy BSDF GGX) + one-sided Emission), the
same camera, and renders with settings that match the raybundle estimator: box
pixel filter one pixel wide, no clamping, no glossy filter, caustics on, many
bounces, black world, no denoiser.  This script lives outside ``core/`` because
the core library never imports ``bpy``.
"""
from __future__ import annotations

import argparse
import os
import sys
import time

import numpy as np


def _bpy():
    import bpy

    return bpy


def new_with_nodes(collection, name):
    """A new material or world (``collection``: ``bpy.data.materials`` or ``.worlds``) with its
    node tree: Blender 5 makes the tree itself (``use_nodes`` is deprecated there), 4.2 makes it
    on ``use_nodes = True``."""
    block = collection.new(name)
    if block.node_tree is None:
        block.use_nodes = True
    return block


def reset():
    """An empty scene (factory settings, no world, no objects)."""
    bpy = _bpy()
    bpy.ops.wm.read_factory_settings(use_empty=True)
    return bpy.context.scene


def make_material(name, diffuse, glossy, roughness, glossy_weight, emission):
    """A node material: Add(Mix(Diffuse, Glossy GGX, fac), Emission * (1 - backfacing))."""
    bpy = _bpy()
    mat = new_with_nodes(bpy.data.materials, name)
    nt = mat.node_tree
    nt.nodes.clear()
    out = nt.nodes.new("ShaderNodeOutputMaterial")
    dif = nt.nodes.new("ShaderNodeBsdfDiffuse")
    dif.inputs["Color"].default_value = (*diffuse, 1.0)
    dif.inputs["Roughness"].default_value = 0.0
    glo = nt.nodes.new("ShaderNodeBsdfGlossy")
    glo.distribution = "GGX"
    glo.inputs["Color"].default_value = (*glossy, 1.0)
    glo.inputs["Roughness"].default_value = float(roughness)
    mix = nt.nodes.new("ShaderNodeMixShader")
    mix.inputs["Fac"].default_value = float(glossy_weight)
    nt.links.new(dif.outputs[0], mix.inputs[1])
    nt.links.new(glo.outputs[0], mix.inputs[2])
    surface = mix.outputs[0]
    if any(e > 0 for e in emission):
        em = nt.nodes.new("ShaderNodeEmission")
        em.inputs["Color"].default_value = (*emission, 1.0)
        geo = nt.nodes.new("ShaderNodeNewGeometry")
        inv = nt.nodes.new("ShaderNodeMath")
        inv.operation = "SUBTRACT"
        inv.inputs[0].default_value = 1.0
        nt.links.new(geo.outputs["Backfacing"], inv.inputs[1])
        nt.links.new(inv.outputs[0], em.inputs["Strength"])      # one-sided emitter
        add = nt.nodes.new("ShaderNodeAddShader")
        nt.links.new(surface, add.inputs[0])
        nt.links.new(em.outputs[0], add.inputs[1])
        surface = add.outputs[0]
    nt.links.new(surface, out.inputs["Surface"])
    return mat


def add_scene_mesh(scene):
    """The raybundle scene's triangles as one Blender mesh with a material slot per material."""
    bpy = _bpy()
    me = bpy.data.meshes.new("raybundle")
    me.from_pydata(scene.vertices.tolist(), [], scene.triangles.tolist())
    mt = scene.materials
    for k, name in enumerate(mt.names):
        me.materials.append(make_material(name, mt.diffuse[k], mt.glossy[k], mt.roughness[k],
                                          mt.glossy_weight[k], mt.emission[k]))
    me.polygons.foreach_set("material_index", scene.triangle_material.astype(np.int32))
    me.update()
    ob = bpy.data.objects.new("raybundle", me)
    bpy.context.scene.collection.objects.link(ob)
    return ob


def add_camera(camera):
    """A Blender camera equal to a :class:`raybundle.scene.camera.Camera` (horizontal sensor fit)."""
    bpy = _bpy()
    from mathutils import Matrix

    cd = bpy.data.cameras.new("cam")
    cd.sensor_fit = "HORIZONTAL"
    cd.sensor_width = 36.0
    cd.lens = camera.fx * 36.0 / camera.width
    cd.shift_x = (camera.width / 2 - camera.cx) / camera.width
    cd.shift_y = (camera.cy - camera.height / 2) / camera.width
    ob = bpy.data.objects.new("cam", cd)
    ob.matrix_world = Matrix(camera.matrix_world.tolist())
    sc = bpy.context.scene
    sc.collection.objects.link(ob)
    sc.camera = ob
    sc.render.resolution_x, sc.render.resolution_y = camera.width, camera.height
    sc.render.resolution_percentage = 100
    return ob


def cycles_settings(samples, seed=0, world_strength=0.0):
    """Cycles as the references use it; ``world_strength`` None keeps the scene's world."""
    bpy = _bpy()
    sc = bpy.context.scene
    sc.render.engine = "CYCLES"
    c = sc.cycles
    c.device = "CPU"
    c.samples = int(samples)
    c.use_adaptive_sampling = False
    c.use_denoising = False
    c.seed = int(seed)
    c.pixel_filter_type = "BOX"
    sc.render.filter_size = 1.0
    c.max_bounces = c.diffuse_bounces = c.glossy_bounces = 64
    c.transparent_max_bounces = 8
    c.sample_clamp_direct = c.sample_clamp_indirect = 0.0
    c.blur_glossy = 0.0
    c.caustics_reflective = True
    c.use_light_tree = True
    sc.view_settings.view_transform = "Standard"
    sc.view_settings.look = "None"
    sc.view_settings.exposure = 0.0
    if world_strength is not None:
        world = new_with_nodes(bpy.data.worlds, "world")
        bg = world.node_tree.nodes["Background"]
        bg.inputs["Color"].default_value = (1.0, 1.0, 1.0, 1.0)
        bg.inputs["Strength"].default_value = float(world_strength)
        sc.world = world
    exr_output(None)


def exr_output(path):
    """The current scene saves 32-bit float EXR (linear radiance) to ``path``
    (None: keep the output path)."""
    sc = _bpy().context.scene
    if hasattr(sc.render.image_settings, "media_type"):    # Blender 5: a single image, not a multilayer one
        sc.render.image_settings.media_type = "IMAGE"
    sc.render.image_settings.file_format = "OPEN_EXR"
    sc.render.image_settings.color_depth = "32"
    sc.render.image_settings.exr_codec = "ZIP"
    if path is not None:
        sc.render.filepath = os.path.abspath(str(path))
        sc.render.use_file_extension = False


def render_to(path):
    """Render the current scene to ``path`` (EXR) and read it back as (H, W, 3) float32."""
    bpy = _bpy()
    from raybundle.util.io import read_exr

    exr_output(path)
    bpy.ops.render.render(write_still=True)
    return read_exr(path)


def plane_under_white_world(material, cos_view, res, samples, path):
    """Render a huge plane with ``material`` under a uniform white world (strength 1),
    seen by an orthographic camera at cos(theta) = ``cos_view``: every pixel's
    radiance is the material's directional albedo a(w_out).  Returns (res*res, 3)."""
    bpy = _bpy()
    me = bpy.data.meshes.new("plane")
    s = 1000.0
    me.from_pydata([(-s, -s, 0), (s, -s, 0), (s, s, 0), (-s, s, 0)], [], [(0, 1, 2, 3)])
    me.materials.append(material)
    ob = bpy.data.objects.new("plane", me)
    bpy.context.scene.collection.objects.link(ob)
    cd = bpy.data.cameras.new("cam")
    cd.type = "ORTHO"
    cd.ortho_scale = 0.05
    cam = bpy.data.objects.new("cam", cd)
    sin = np.sqrt(1 - cos_view ** 2)
    cam.location = (10 * sin, 0, 10 * cos_view)
    cam.rotation_euler = (np.arccos(cos_view), 0, np.pi / 2)     # look at the origin along -location
    bpy.context.scene.collection.objects.link(cam)
    sc = bpy.context.scene
    sc.camera = cam
    sc.render.resolution_x = sc.render.resolution_y = res
    cycles_settings(samples, world_strength=1.0)
    return render_to(str(path)).reshape(-1, 3).astype(float)


def bake_image(ob, size):
    """Cycles' Combined bake (the scene's Cycles settings) of object ``ob``'s first material into a
    ``size`` x ``size`` image through its active UV map: (size, size, 3), rows bottom-up (as
    ``Image.pixels``).  The image node it bakes through is removed afterwards."""
    bpy = _bpy()
    nt = ob.data.materials[0].node_tree
    target = bpy.data.images.new(f"cycles bake {ob.name}", size, size, float_buffer=True)
    node = nt.nodes.new("ShaderNodeTexImage")
    node.image = target
    nt.nodes.active = node
    for other in bpy.context.scene.objects:
        other.select_set(other is ob)
    bpy.context.view_layer.objects.active = ob
    bpy.ops.object.bake(type="COMBINED", margin=0, use_clear=True, target="IMAGE_TEXTURES")
    px = np.empty(size * size * 4, np.float32)
    target.pixels.foreach_get(px)
    nt.nodes.remove(node)
    return px.reshape(size, size, 4)[..., :3]


def unsupported(scene):
    """Why the scene cannot be built here (this script models triangles, Mix(Diffuse, Glossy)
    materials and one-sided emission, under a black world), or None."""
    mt = scene.materials
    checks = [(len(scene.point_lights) + len(scene.sun_lights) + len(scene.area_lights) > 0, "lights"),
              (scene.world.emits, "a world that emits"),
              (np.any(scene.triangle_two_sided), "two-sided faces"),
              (np.any(mt.emission_albedo_complement > 0), "emission that depends on the albedo"),
              (np.any(mt.has_layer) or np.any(mt.is_layered), "Principled layers"),
              (scene.texture is not None, "image textures")]
    found = [what for bad, what in checks if bad]
    return f"Cycles is built here from triangles and Mix(Diffuse, Glossy) + Emission only: the scene has " \
           f"{', '.join(found)}" if found else None


def curve(name, seconds, out_dir, seed=0, resolution=None):
    """Cycles at 1, 2, 4, ... samples per pixel until a render takes ``seconds``: one JSON line
    per render on stdout (samples, seconds from loading the scene to the EXR written, path)."""
    import json

    from raybundle.scene.builtin import load_scene

    spp, prev = 1, None
    while True:
        t0 = time.perf_counter()
        scene = load_scene(name)
        if resolution:
            scene.camera = scene.camera.with_resolution(*resolution)
        path = os.path.join(out_dir, f"cycles-{spp}.exr")
        render_scene(scene, spp, path, seed)
        dt = time.perf_counter() - t0
        print(json.dumps({"samples": spp, "seconds": round(dt, 3), "path": path}), flush=True)
        # the next render repeats the set-up and doubles the sampling: predicted from the last two
        # (set-up alone dominates the first, so at least two are rendered, and a curve always has a slope)
        if prev is not None and dt + 2 * max(dt - prev, 0.0) > seconds * 1.25:
            return
        spp, prev = spp * 2, dt


def render_scene(scene, samples, out, seed=0):
    reset()
    add_scene_mesh(scene)
    add_camera(scene.camera)
    cycles_settings(samples, seed)
    tmp = out + ".tmp.exr"
    img = render_to(tmp)
    from raybundle.util.io import write_exr

    write_exr(out, img, {"cycles_samples": samples})
    os.unlink(tmp)
    return img


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("scene")
    p.add_argument("--samples", type=int, default=1024)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--out", required=True, help="the EXR (with --curve: a folder)")
    p.add_argument("--resolution", type=int, nargs=2, metavar=("W", "H"))
    p.add_argument("--curve", type=float, metavar="SECONDS",
                   help="render 1, 2, 4, ... samples per pixel until a render takes SECONDS; JSON lines on stdout")
    a = p.parse_args(argv)
    from raybundle.scene.builtin import load_scene

    scene = load_scene(a.scene)
    why = unsupported(scene)
    if why:
        print(f"cycles_reference: {why}", file=sys.stderr)
        return 3
    if a.curve is not None:
        os.makedirs(a.out, exist_ok=True)
        curve(a.scene, a.curve, a.out, a.seed, a.resolution)
        return 0
    if a.resolution:
        scene.camera = scene.camera.with_resolution(*a.resolution)
    t = time.perf_counter()
    render_scene(scene, a.samples, a.out, a.seed)
    print(f"Cycles: {a.scene} at {a.samples} samples/pixel in {time.perf_counter() - t:.1f} s -> {a.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
