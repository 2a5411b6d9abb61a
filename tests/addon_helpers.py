"""Shared set-up of the add-on tests (the real ``bpy`` module, no mocks).

Importing this module points ``BLENDER_USER_RESOURCES`` at a temporary folder
(before ``bpy`` is imported, so nothing touches the user's Blender config),
imports ``bpy``, and puts the repository, ``demo_scenes/`` and ``tools/`` on ``sys.path``.
"""
from __future__ import annotations

import os
import sys
import tempfile

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
if "bpy" not in sys.modules:
    os.environ["BLENDER_USER_RESOURCES"] = tempfile.mkdtemp(prefix="rb-blender-user-")
for p in (ROOT, os.path.join(ROOT, "demo_scenes"), os.path.join(ROOT, "tools")):
    if p not in sys.path:
        sys.path.insert(0, p)

import bpy  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402
from cycles_reference import cycles_settings, exr_output, new_with_nodes  # noqa: E402

#: the headless command line as the README's set-up installs it (the repository's
#: pyproject.toml), beside this Python
BLENDER_CLI = os.path.join(os.path.dirname(sys.executable), "raybundle-blender")


def blender_cli_command(*args):
    """``raybundle-blender ARGS`` (the installed command: the tests run it from temporary folders)."""
    if not os.path.isfile(BLENDER_CLI):
        pytest.fail(f"{BLENDER_CLI} is not installed: `pip install -e .` in the repository (make test does)")
    return [BLENDER_CLI, *map(str, args)]


def ensure_registered():
    import raybundle_addon

    if not hasattr(bpy.types.Scene, "raybundle"):
        raybundle_addon.register()
    return raybundle_addon


@pytest.fixture(scope="module")
def addon():
    """The add-on registered from source for the module (unregistered afterwards)."""
    mod = ensure_registered()
    yield mod
    if hasattr(bpy.types.Scene, "raybundle"):
        mod.unregister()


@pytest.fixture
def fresh(addon):
    """An empty scene (factory settings, no world, no objects); returns bpy.context.scene."""
    bpy.ops.wm.read_factory_settings(use_empty=True)
    return bpy.context.scene


# ------------------------------------------------------------------ building
def node_material(name, kind="diffuse", color=(0.8, 0.8, 0.8), strength=1.0, roughness=0.5, ior=1.5):
    """A material with one shader node ``kind`` (diffuse, glossy, emission, principled,
    translucent, glass, refraction, transparent) to the output."""
    from make_demo_scenes import _new_material

    mat, nt, out = _new_material(name)
    node = nt.nodes.new({"diffuse": "ShaderNodeBsdfDiffuse", "glossy": "ShaderNodeBsdfGlossy",
                         "emission": "ShaderNodeEmission", "principled": "ShaderNodeBsdfPrincipled",
                         "translucent": "ShaderNodeBsdfTranslucent", "glass": "ShaderNodeBsdfGlass",
                         "refraction": "ShaderNodeBsdfRefraction", "transparent": "ShaderNodeBsdfTransparent"}[kind])
    if kind in ("glass", "refraction"):
        node.inputs["Roughness"].default_value = roughness
        node.inputs["IOR"].default_value = ior
    if kind == "principled":
        node.inputs["Base Color"].default_value = (*color, 1.0)
        node.inputs["Roughness"].default_value = roughness
    else:
        node.inputs["Color"].default_value = (*color, 1.0)
    if kind == "emission":
        node.inputs["Strength"].default_value = strength
    if kind == "glossy":
        node.distribution = "GGX"
        node.inputs["Roughness"].default_value = roughness
    if kind == "diffuse":
        node.inputs["Roughness"].default_value = 0.0
    nt.links.new(node.outputs[0], out.inputs["Surface"])
    return mat


def furnace_material(le, albedo):
    """Add(Emission white x ``le``, Diffuse ``albedo``): a closed room of it glows at Le / (1 - a)."""
    mat = new_with_nodes(bpy.data.materials, "furnace")
    nt = mat.node_tree
    nt.nodes.clear()
    out = nt.nodes.new("ShaderNodeOutputMaterial")
    e, d, add = (nt.nodes.new(t) for t in ("ShaderNodeEmission", "ShaderNodeBsdfDiffuse", "ShaderNodeAddShader"))
    e.inputs["Color"].default_value = (1, 1, 1, 1)
    e.inputs["Strength"].default_value = le
    d.inputs["Color"].default_value = (*albedo, 1)
    nt.links.new(e.outputs[0], add.inputs[0])
    nt.links.new(d.outputs[0], add.inputs[1])
    nt.links.new(add.outputs[0], out.inputs["Surface"])
    return mat


def add_object(name, verts, faces, materials=(), location=(0, 0, 0)):
    me = bpy.data.meshes.new(name)
    me.from_pydata([tuple(map(float, v)) for v in verts], [], [tuple(f) for f in faces])
    for m in materials:
        me.materials.append(m)
    me.update()
    ob = bpy.data.objects.new(name, me)
    ob.location = location
    bpy.context.scene.collection.objects.link(ob)
    return ob


def add_light(kind, location=(0, 0, 0), rotation=(0, 0, 0), **props):
    ld = bpy.data.lights.new(kind.lower(), kind)
    for k, v in props.items():
        setattr(ld, k, v)
    ob = bpy.data.objects.new(kind.lower(), ld)
    ob.location, ob.rotation_euler = location, rotation
    bpy.context.scene.collection.objects.link(ob)
    return ob


def add_camera(location, rotation=(0, 0, 0), resolution=(32, 32), lens=50.0, ortho_scale=None):
    cd = bpy.data.cameras.new("cam")
    cd.lens = lens
    if ortho_scale:
        cd.type, cd.ortho_scale = "ORTHO", ortho_scale
    ob = bpy.data.objects.new("cam", cd)
    ob.location, ob.rotation_euler = location, rotation
    sc = bpy.context.scene
    sc.collection.objects.link(ob)
    sc.camera = ob
    sc.render.resolution_x, sc.render.resolution_y = resolution
    sc.render.resolution_percentage = 100
    return ob


def set_world(color, strength):
    w = new_with_nodes(bpy.data.worlds, "world")
    bg = w.node_tree.nodes["Background"]
    bg.inputs["Color"].default_value = (*color, 1.0)
    bg.inputs["Strength"].default_value = strength
    bpy.context.scene.world = w
    return w


def box(lo, hi):
    """Vertices and quads of an axis-aligned box."""
    x0, y0, z0 = lo
    x1, y1, z1 = hi
    v = [(x0, y0, z0), (x1, y0, z0), (x1, y1, z0), (x0, y1, z0), (x0, y0, z1), (x1, y0, z1), (x1, y1, z1),
         (x0, y1, z1)]
    return v, [(0, 3, 2, 1), (4, 5, 6, 7), (0, 1, 5, 4), (1, 2, 6, 5), (2, 3, 7, 6), (3, 0, 4, 7)]


# ----------------------------------------------------------------- rendering
def render_raybundle(path, time_limit=None, iterations=None, seed=0, patches=None):
    """Render the current scene with RAYBUNDLE to a 32-bit EXR via write_still; returns (H, W, 3)."""
    from raybundle.util.io import read_exr

    sc = bpy.context.scene
    sc.render.engine = "RAYBUNDLE"
    rb = sc.raybundle
    rb.seed = seed
    if iterations:
        rb.iterations = iterations
    else:
        rb.iterations, rb.time_limit = 0, time_limit or 5.0
    if patches is not None:
        rb.patches = patches
    exr_output(path)
    bpy.ops.render.render(write_still=True)
    return read_exr(path)


def render_cycles(path, samples=64, seed=0, pixel_filter=("BOX", 1.0)):
    """Render the current scene with Cycles (CPU, no denoising/clamping, the pixel filter
    ``(type, width)``, by default a box 1 px, no glossy filter, Standard view) to an EXR;
    returns (H, W, 3).  The scene keeps the filter."""
    from raybundle.util.io import read_exr

    cycles_settings(samples, seed, world_strength=None)          # keeps the scene's world
    bpy.context.scene.cycles.pixel_filter_type, bpy.context.scene.cycles.filter_width = pixel_filter
    exr_output(path)
    bpy.ops.render.render(write_still=True)
    return read_exr(path)


def lightmap_blocks(x, block=4):
    """(H / block, W / block, 3) means of ``block`` x ``block`` texels."""
    h, w = x.shape[:2]
    return x.reshape(h // block, block, w // block, block, 3).mean(axis=(1, 3))


def object_id_image(export, camera=None):
    """(H, W) int: the exported object seen through each pixel centre (-1 = nothing),
    traced with the core's tracer on the exported (unsubdivided) scene."""
    from raybundle.tracing.visibility import RayTracer

    sc = export.scene
    cam = camera or sc.camera
    py, px = np.divmod(np.arange(cam.width * cam.height), cam.width)
    org, d = cam.rays(px + 0.5, py + 0.5)
    tr = RayTracer(sc)
    try:
        tri = tr.first_hit(org, d)[0]
    finally:
        tr.close()
    src = sc.triangle_source[np.maximum(tri, 0)]
    obj = np.where(tri >= 0, export.triangle_object[src], -1)
    return obj.reshape(cam.height, cam.width)


def erode(mask, r=1):
    """Pixels of ``mask`` whose (2r+1)^2 neighbourhood lies inside it (drop edge pixels)."""
    out = mask.copy()
    h, w = mask.shape
    p = np.pad(mask, r, constant_values=False)
    for dy in range(-r, r + 1):
        for dx in range(-r, r + 1):
            out &= p[r + dy:r + dy + h, r + dx:r + dx + w]
    return out


def plane_with_uvs(size=2.0):
    """A white-ish (0.6) plane of ``size`` m at z = 0 with UVs = (x, y) / size + 0.5, 4 x 4 quads."""
    n = 4
    xs = np.linspace(-size / 2, size / 2, n + 1)
    v = [(x, y, 0.0) for y in xs for x in xs]
    f = [(j * (n + 1) + i, j * (n + 1) + i + 1, (j + 1) * (n + 1) + i + 1, (j + 1) * (n + 1) + i)
         for j in range(n) for i in range(n)]
    ob = add_object("plane", v, f, [node_material("white", color=(0.6, 0.6, 0.6))])
    me = ob.data
    uv = me.uv_layers.new(name="UVMap")
    co = np.array([me.vertices[lp.vertex_index].co[:2] for lp in me.loops])
    uv.uv.foreach_set("vector", (co / size + 0.5).astype(np.float32).ravel())
    return ob


def textured_plane():
    """``plane_with_uvs`` with a Diffuse BSDF whose Color is an 8 x 8 float image texture
    (a checker of 0.15 and 0.75 with a brighter corner texel), under a point light, seen by
    an ortho camera from above (32 x 32 pixels over the plane)."""
    plane = plane_with_uvs()
    img = bpy.data.images.new("checker", 8, 8, float_buffer=True)
    px = np.where((np.add.outer(np.arange(8), np.arange(8)) % 2)[..., None], 0.15, 0.75) * np.ones(3)
    px[0, 0] = 0.95
    rgba = np.concatenate([px, np.ones((8, 8, 1))], axis=2).astype(np.float32)
    img.pixels.foreach_set(rgba.ravel())
    mat = plane.data.materials[0]
    nt = mat.node_tree
    tex = nt.nodes.new("ShaderNodeTexImage")
    tex.image = img
    nt.links.new(tex.outputs["Color"], nt.nodes["Diffuse BSDF"].inputs["Color"])
    add_light("POINT", location=(0.3, -0.2, 1.5), energy=1000.0, shadow_soft_size=0.0)
    add_camera((0, 0, 3), resolution=(32, 32), ortho_scale=2.0)
    return plane, px


def regions_agree(ours, theirs, grid=8, sigmas=4.5, floor=0.002):
    """Compare two renders of one file, each given by two seeds ``(A, B)`` (H, W, 3): the
    ``grid`` x ``grid`` regions' means of ``(A + B) / 2``, channel by channel, each within
    ``sigmas`` standard errors of the difference, the standard error of each side's region mean
    ``sqrt(mean((A - B)^2) / (4 n))`` over the region's n pixels, plus ``floor`` times the region's
    mean (where both sides are almost free of noise, a lamp's direct light on an open floor, a
    difference of float rounding and sub-pixel patterns is not a wrong image).  Returns
    ``(ok, z)``: whether every region agrees and the regions' (grid, grid, 3) differences in
    units of that tolerance over ``sigmas``."""
    def region(x):
        h, w = x.shape[:2]
        return x[:h - h % grid, :w - w % grid].reshape(grid, h // grid, grid, w // grid, 3)

    diff = np.zeros((grid, grid, 3))
    var = np.zeros((grid, grid, 3))
    for (a, b), sign in ((ours, 1.0), (theirs, -1.0)):
        ra, rb = region(a), region(b)
        n = ra.shape[1] * ra.shape[3]
        diff += sign * 0.5 * (ra + rb).mean(axis=(1, 3))
        var += ((ra - rb) ** 2).mean(axis=(1, 3)) / (4 * n)
    mean = 0.5 * (region(theirs[0]) + region(theirs[1])).mean(axis=(1, 3))
    z = sigmas * diff / np.maximum(sigmas * np.sqrt(var) + floor * np.abs(mean), 1e-30)
    return bool(np.all(np.abs(z) <= sigmas)), z


def assert_like_cycles(ours, theirs):
    """Two seeds of ours and of Cycles' render of one file (``(A, B)`` each): the image means
    within 3% and :func:`regions_agree` (the 8 x 8 regions within 4.5 standard errors)."""
    ratio = float(np.mean(ours) / np.mean(theirs))
    ok, z = regions_agree(ours, theirs)
    print(f"mean x{ratio:.4f}, regions |z| max {np.abs(z).max():.2f}")
    assert ratio == pytest.approx(1.0, abs=0.03), ratio
    assert ok, np.round(np.abs(z).max(axis=-1), 1)
