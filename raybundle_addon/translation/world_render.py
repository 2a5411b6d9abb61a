"""Render a World into an equirectangular image with Cycles (run in a process of its own).

Usage (by :func:`raybundle_addon.translation.world.render_world`, never imported by the add-on)::

    python world_render.py LIBRARY.blend WORLD_NAME OUT.exr WIDTH SAMPLES THREADS [VIEW.json]
    blender -b --factory-startup --python world_render.py -- LIBRARY.blend WORLD_NAME OUT.exr WIDTH SAMPLES THREADS [VIEW.json]

Loads the world ``WORLD_NAME`` from ``LIBRARY.blend`` into an empty scene and renders it
through a panoramic equirectangular camera at rotation (90, 0, -90) degrees (the layout of
:mod:`raybundle.scene.world`: the image's centre looks along +X, its top row at the zenith),
``WIDTH`` x ``WIDTH / 2`` pixels, box filter one pixel wide (each pixel the mean radiance of
its cell), no denoising, Standard view, on ``THREADS`` CPU threads (0: all) at the lowest
priority (nice 19: below the node-graph bakes, :mod:`.material_bake`, which the export waits for,
while the world is read only after the patch layout), into a 32-bit
float EXR.  Only the world is in the
scene, so every camera ray sees it directly: Blender evaluates whatever its node tree holds.

With ``VIEW.json`` it then renders the world once more through the scene's camera as the
JSON describes it (``matrix`` 16 floats row by row, ``type``, ``lens``, ``sensor_width``,
``sensor_height``, ``sensor_fit``, ``shift_x``, ``shift_y``, ``ortho_scale``, ``size`` [w, h],
``pixel_aspect`` [x, y], ``samples``) into its ``out`` EXR: the world each pixel of the render
sees, with the same box filter one pixel wide (each pixel its mean over its area, as
raybundle's own pixels are).
"""
import json
import math
import os
import sys


def main(argv):
    if hasattr(os, "nice"):         # below the caller and the graph bakes (on Windows: Popen's flag)
        os.nice(19)
    import bpy

    library, name, out, width, samples, threads = argv[0], argv[1], argv[2], int(argv[3]), int(argv[4]), int(argv[5])
    bpy.ops.wm.read_factory_settings(use_empty=True)
    with bpy.data.libraries.load(library, link=False) as (src, dst):
        if name not in src.worlds:
            raise SystemExit(f"world {name!r} not found in {library}")
        dst.worlds = [name]
    sc = bpy.context.scene
    sc.world = dst.worlds[0]
    cam = bpy.data.cameras.new("equirectangular")
    cam.type = "PANO"
    if hasattr(cam, "panorama_type"):
        cam.panorama_type = "EQUIRECTANGULAR"
    else:                                             # Blender before 4.0 kept it in cycles settings
        cam.cycles.panorama_type = "EQUIRECTANGULAR"
    ob = bpy.data.objects.new("equirectangular", cam)
    ob.rotation_euler = (math.pi / 2, 0.0, -math.pi / 2)
    sc.collection.objects.link(ob)
    sc.camera = ob
    r = sc.render
    r.engine = "CYCLES"
    r.resolution_x, r.resolution_y, r.resolution_percentage = width, max(1, width // 2), 100
    r.filter_size = 1.0
    r.film_transparent = False
    if threads > 0:
        r.threads_mode, r.threads = "FIXED", threads
    c = sc.cycles
    c.device = "CPU"
    c.samples = samples
    c.use_adaptive_sampling = False
    c.use_denoising = False
    c.pixel_filter_type = "BOX"
    c.seed = 0
    c.sample_clamp_direct = c.sample_clamp_indirect = 0.0
    sc.view_settings.view_transform = "Standard"
    sc.view_settings.look = "None"
    sc.view_settings.exposure = 0.0
    sc.view_settings.gamma = 1.0
    s = r.image_settings
    s.file_format = "OPEN_EXR"
    s.color_depth = "32"
    s.exr_codec = "ZIP"
    r.filepath = out
    bpy.ops.render.render(write_still=True)
    if len(argv) > 6:
        with open(argv[6]) as f:
            view = json.load(f)
        data = bpy.data.cameras.new("view")
        data.type = view["type"]
        for key in ("lens", "sensor_width", "sensor_height", "sensor_fit", "shift_x", "shift_y", "ortho_scale"):
            setattr(data, key, view[key])
        data.clip_start, data.clip_end = 1e-6, 1e30
        cam = bpy.data.objects.new("view", data)
        m = view["matrix"]
        from mathutils import Matrix
        cam.matrix_world = Matrix([m[0:4], m[4:8], m[8:12], m[12:16]])
        sc.collection.objects.link(cam)
        sc.camera = cam
        r.resolution_x, r.resolution_y = view["size"]
        r.pixel_aspect_x, r.pixel_aspect_y = view["pixel_aspect"]
        c.samples = int(view["samples"])
        r.filepath = view["out"]
        bpy.ops.render.render(write_still=True)


if __name__ == "__main__":
    args = sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else sys.argv[1:]
    main(args)
