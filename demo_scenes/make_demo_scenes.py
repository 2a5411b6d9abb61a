"""Build the demo ``.blend`` files with the ``bpy`` module.

Usage::

    make demo-scenes      # the files in the repository: saved by Blender 4.2 (.venv-oldest), which
                          # every supported Blender opens (4.2 cannot read what 5.0 writes)
    .venv/bin/python demo_scenes/make_demo_scenes.py [--out DIR] [--only cornell_box ...]

Writes:

* ``cornell_box.blend``: the core's Cornell box data (:mod:`raybundle.scene.builtin`) as a
  Blender scene: Diffuse BSDF walls and blocks, an Emission lamp (radiance =
  color x strength = the core's ``CORNELL_LIGHT``), two-sided as Blender is.
  Unlike the core's built-in scene, the ceiling is one full quad (no opening
  above the lamp, which hangs 0.5 mm under it) and the blocks have 5 faces (no
  bottom), as a modeller would make it.  One object per wall / block, named
  ``floor``, ``ceiling``, ``back``, ``red``, ``green``, ``light``, ``short_block``,
  ``tall_block``.  Black world, the Cornell camera (35 mm lens, 25 mm sensor).
* ``cornell_glossy.blend``: the same with the floor Mix(Diffuse white, Glossy GGX
  white roughness 0.3, 0.5) and the tall block Glossy GGX (0.8, roughness 0.2).
* ``cornell_bake.blend``: ``cornell_box.blend`` with every face cut 16 x 16 into its
  own 17 x 17 vertices (4,624 in all) and a lightmap UV map per object (a tile per
  face): press Bake in the Ray Bundle GI panel.
* ``cornell_subdivided.blend``: ``cornell_box.blend`` with every mesh subdivided as Edit Mode's
  Subdivide does it (15 cuts: each quad a 16 x 16 grid), so the vertices along a block's
  creases are shared by faces of different normals, and a point-domain bake averages those
  faces' corners there: the bake bench's harder file.
* ``sierpinski.blend``: a level-4 Sierpinski tetrahedron (1024 triangles) on a floor
  under a sky-colored world and a sun (in the style of the thesis' Figure 1).
* ``room.blend``: a small room with Principled BSDF materials (wooden floor, painted
  walls, a metal sphere, a plastic cube), a window with a sun shining through it
  and an area light under the ceiling.

Every file has the ``RAYBUNDLE`` engine selected (when the add-on is available)
and Cycles settings that match the raybundle estimator (box filter 1 px, no
clamping, no glossy filter), so the same file renders with either engine.
"""
from __future__ import annotations

import argparse
import math
import os
import sys

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, os.path.join(ROOT, "tools"))
from cycles_reference import _bpy, cycles_settings, new_with_nodes, reset  # noqa: E402  (bpy set-up shared with the references)


def ensure_addon():
    """Register the add-on from this checkout if it is not registered yet (for ``RAYBUNDLE``)."""
    bpy = _bpy()
    if hasattr(bpy.types.Scene, "raybundle"):
        return True
    try:
        if ROOT not in sys.path:
            sys.path.insert(0, ROOT)
        import raybundle_addon

        raybundle_addon.register()
        return True
    except Exception as e:  # the scenes still build; they open with Blender's default engine
        print(f"make_demo_scenes: the add-on is not available ({e}); files keep the default engine")
        return False


# ------------------------------------------------------------------ materials
def _new_material(name):
    bpy = _bpy()
    mat = new_with_nodes(bpy.data.materials, name)
    nt = mat.node_tree
    nt.nodes.clear()
    out = nt.nodes.new("ShaderNodeOutputMaterial")
    return mat, nt, out


def diffuse_material(name, color):
    mat, nt, out = _new_material(name)
    n = nt.nodes.new("ShaderNodeBsdfDiffuse")
    n.inputs["Color"].default_value = (*color, 1.0)
    n.inputs["Roughness"].default_value = 0.0
    nt.links.new(n.outputs[0], out.inputs["Surface"])
    mat.diffuse_color = (*color, 1.0)
    return mat


def glossy_material(name, color, roughness, diffuse=None, fac=1.0):
    """Glossy BSDF (GGX), or Mix(Diffuse ``diffuse``, Glossy, ``fac``) when ``diffuse`` is given."""
    mat, nt, out = _new_material(name)
    g = nt.nodes.new("ShaderNodeBsdfGlossy")
    g.distribution = "GGX"
    g.inputs["Color"].default_value = (*color, 1.0)
    g.inputs["Roughness"].default_value = roughness
    if diffuse is None:
        nt.links.new(g.outputs[0], out.inputs["Surface"])
    else:
        d = nt.nodes.new("ShaderNodeBsdfDiffuse")
        d.inputs["Color"].default_value = (*diffuse, 1.0)
        d.inputs["Roughness"].default_value = 0.0
        mix = nt.nodes.new("ShaderNodeMixShader")
        mix.inputs["Fac"].default_value = fac
        nt.links.new(d.outputs[0], mix.inputs[1])
        nt.links.new(g.outputs[0], mix.inputs[2])
        nt.links.new(mix.outputs[0], out.inputs["Surface"])
    mat.diffuse_color = (*color, 1.0)
    return mat


def emission_material(name, radiance):
    """Emission with Color x Strength = ``radiance`` [W m^-2 sr^-1] (both sides, as Blender emits)."""
    mat, nt, out = _new_material(name)
    strength = float(max(radiance))
    e = nt.nodes.new("ShaderNodeEmission")
    e.inputs["Color"].default_value = (*(np.asarray(radiance) / strength), 1.0)
    e.inputs["Strength"].default_value = strength
    nt.links.new(e.outputs[0], out.inputs["Surface"])
    return mat


def principled_material(name, base, roughness=0.5, metallic=0.0):
    mat, nt, out = _new_material(name)
    p = nt.nodes.new("ShaderNodeBsdfPrincipled")
    p.inputs["Base Color"].default_value = (*base, 1.0)
    p.inputs["Roughness"].default_value = roughness
    p.inputs["Metallic"].default_value = metallic
    nt.links.new(p.outputs[0], out.inputs["Surface"])
    mat.diffuse_color = (*base, 1.0)
    return mat


def world(color, strength, name="World"):
    bpy = _bpy()
    w = new_with_nodes(bpy.data.worlds, name)
    bg = w.node_tree.nodes["Background"]
    bg.inputs["Color"].default_value = (*color, 1.0)
    bg.inputs["Strength"].default_value = strength
    w.color = color
    bpy.context.scene.world = w
    return w


# ------------------------------------------------------------------- geometry
def add_mesh(name, verts, faces, material=None, materials=None, material_index=None):
    bpy = _bpy()
    me = bpy.data.meshes.new(name)
    me.from_pydata([tuple(map(float, v)) for v in verts], [], [tuple(map(int, f)) for f in faces])
    for m in (materials or ([material] if material is not None else [])):
        me.materials.append(m)
    if material_index is not None:
        me.polygons.foreach_set("material_index", np.asarray(material_index, np.int32))
    me.update()
    ob = bpy.data.objects.new(name, me)
    bpy.context.scene.collection.objects.link(ob)
    return ob


def quads_mesh(name, quads, material):
    """An object from quads (each (4, 3) in metres)."""
    verts = np.concatenate([np.asarray(q, float) for q in quads])
    faces = [tuple(range(4 * k, 4 * k + 4)) for k in range(len(quads))]
    return add_mesh(name, verts, faces, material)


def add_camera(matrix_world, lens, sensor_width, resolution, sensor_fit="AUTO", name="Camera"):
    bpy = _bpy()
    from mathutils import Matrix

    cd = bpy.data.cameras.new(name)
    cd.lens, cd.sensor_width, cd.sensor_fit = lens, sensor_width, sensor_fit
    ob = bpy.data.objects.new(name, cd)
    ob.matrix_world = Matrix(np.asarray(matrix_world, float).tolist())
    sc = bpy.context.scene
    sc.collection.objects.link(ob)
    sc.camera = ob
    sc.render.resolution_x, sc.render.resolution_y = resolution
    sc.render.resolution_percentage = 100
    return ob


def look_at_matrix(position, target, up=(0, 0, 1)):
    p = np.asarray(position, float)
    back = p - np.asarray(target, float)
    back /= np.linalg.norm(back)
    right = np.cross(up, back)
    right /= np.linalg.norm(right)
    m = np.eye(4)
    m[:3, 0], m[:3, 1], m[:3, 2], m[:3, 3] = right, np.cross(back, right), back, p
    return m


def render_settings(time_limit=30.0, samples=256):
    """The RAYBUNDLE engine (if registered) and Cycles settings matching raybundle's estimator."""
    bpy = _bpy()
    cycles_settings(samples, world_strength=None)               # keeps the scene's world
    sc = bpy.context.scene
    if hasattr(sc, "raybundle"):
        sc.render.engine = "RAYBUNDLE"
        sc.raybundle.time_limit = time_limit


# --------------------------------------------------------------------- scenes
def build_cornell(glossy=False, resolution=(256, 256)):
    """The Cornell box .blend (module docstring); returns {name: object}."""
    from raybundle.scene import builtin as scenes

    to_m = scenes.cornell_to_blender
    white = diffuse_material("white", scenes.WHITE)
    mats = {"white": white, "red": diffuse_material("red", scenes.RED),
            "green": diffuse_material("green", scenes.GREEN),
            "light": emission_material("light", scenes.CORNELL_LIGHT)}
    floor_mat, tall_mat = white, white
    if glossy:
        floor_mat = glossy_material("floor_mix", (1, 1, 1), 0.3, diffuse=(1, 1, 1), fac=0.5)
        tall_mat = glossy_material("tall_glossy", (0.8, 0.8, 0.8), 0.2)
    q = scenes._CORNELL_QUADS
    obs = {}
    for name, mat in (("floor", floor_mat), ("back", white), ("red", mats["red"]), ("green", mats["green"]),
                      ("light", mats["light"])):
        obs[name] = quads_mesh(name, [to_m(q[name])], mat)
    # one full ceiling quad (the core's built-in box opens it above the lamp)
    ceiling = [[556.0, 548.8, 0], [556.0, 548.8, 559.2], [0, 548.8, 559.2], [0, 548.8, 0]]
    obs["ceiling"] = quads_mesh("ceiling", [to_m(ceiling)], white)
    for name, top, h, mat in (("short_block", scenes._SHORT_TOP, 165.0, white),
                              ("tall_block", scenes._TALL_TOP, 330.0, tall_mat)):
        blk = scenes._block_quads(top, h)
        obs[name] = quads_mesh(name, [to_m(b) for b in blk[:1] + blk[2:]], mat)      # no bottom face
    cam = scenes.cornell_camera(resolution)
    add_camera(cam.matrix_world, 35.0, 25.0, resolution)
    world((0.0, 0.0, 0.0), 0.0, "Black")
    render_settings()
    return obs


def sierpinski_triangles(level, a, b, c, d):
    """Faces (N*4, 3, 3) of a Sierpinski tetrahedron of ``level`` on corners a, b, c, d."""
    tets = [np.array([a, b, c, d], float)]
    for _ in range(level):
        nxt = []
        for t in tets:
            for k in range(4):
                nxt.append(0.5 * (t + t[k]))
        tets = nxt
    faces = []
    for t in tets:
        faces += [t[[0, 1, 2]], t[[0, 3, 1]], t[[1, 3, 2]], t[[2, 3, 0]]]
    return np.array(faces)


def build_sierpinski(level=4, resolution=(320, 240)):
    s = 2.0
    h = s * math.sqrt(2.0 / 3.0)
    r = s / math.sqrt(3.0)
    base = [(r * math.cos(t), r * math.sin(t), 0.0) for t in (0.0, 2 * math.pi / 3, 4 * math.pi / 3)]
    faces = sierpinski_triangles(level, *base, (0.0, 0.0, h))
    verts = faces.reshape(-1, 3)
    add_mesh("sierpinski", verts, np.arange(len(verts)).reshape(-1, 3),
             diffuse_material("gold", (0.8, 0.55, 0.2)))
    add_mesh("floor", [(-6, -6, 0), (6, -6, 0), (6, 6, 0), (-6, 6, 0)], [(0, 1, 2, 3)],
             diffuse_material("floor", (0.6, 0.6, 0.6)))
    bpy = _bpy()
    sun = bpy.data.lights.new("Sun", "SUN")
    sun.energy = 3.0
    sun.angle = math.radians(2.0)
    ob = bpy.data.objects.new("Sun", sun)
    ob.rotation_euler = (math.radians(45), 0.0, math.radians(30))
    bpy.context.scene.collection.objects.link(ob)
    world((0.35, 0.5, 0.8), 0.6, "Sky")
    add_camera(look_at_matrix((4.2, -3.2, 2.4), (0.0, 0.0, 0.6)), 35.0, 36.0, resolution)
    render_settings()


def _box_faces(lo, hi):
    x0, y0, z0 = lo
    x1, y1, z1 = hi
    v = [(x0, y0, z0), (x1, y0, z0), (x1, y1, z0), (x0, y1, z0), (x0, y0, z1), (x1, y0, z1), (x1, y1, z1),
         (x0, y1, z1)]
    f = [(0, 3, 2, 1), (4, 5, 6, 7), (0, 1, 5, 4), (1, 2, 6, 5), (2, 3, 7, 6), (3, 0, 4, 7)]
    return v, f


def build_room(resolution=(320, 240)):
    """4 x 5 x 2.6 m room, a 1.6 x 1.2 m window in the +y wall, Principled materials."""
    bpy = _bpy()
    W, D, H = 4.0, 5.0, 2.6
    wall = principled_material("wall paint", (0.8, 0.78, 0.74), roughness=0.9)
    floor = principled_material("wood floor", (0.36, 0.2, 0.09), roughness=0.4)
    ceiling = principled_material("ceiling", (0.85, 0.85, 0.85), roughness=0.9)
    add_mesh("floor", [(0, 0, 0), (W, 0, 0), (W, D, 0), (0, D, 0)], [(0, 1, 2, 3)], floor)
    add_mesh("ceiling", [(0, 0, H), (W, 0, H), (W, D, H), (0, D, H)], [(0, 1, 2, 3)], ceiling)
    walls = [[(0, 0, 0), (0, D, 0), (0, D, H), (0, 0, H)], [(W, 0, 0), (W, D, 0), (W, D, H), (W, 0, H)],
             [(0, 0, 0), (W, 0, 0), (W, 0, H), (0, 0, H)]]
    # the +y wall around a window: x 1.2..2.8, z 0.9..2.1
    x0, x1, z0, z1 = 1.2, 2.8, 0.9, 2.1
    walls += [[(0, D, 0), (x0, D, 0), (x0, D, H), (0, D, H)], [(x1, D, 0), (W, D, 0), (W, D, H), (x1, D, H)],
              [(x0, D, 0), (x1, D, 0), (x1, D, z0), (x0, D, z0)], [(x0, D, z1), (x1, D, z1), (x1, D, H), (x0, D, H)]]
    quads_mesh("walls", [np.array(w, float) for w in walls], wall)
    v, f = _box_faces((2.4, 1.6, 0.0), (3.0, 2.2, 0.6))
    add_mesh("cube", v, f, principled_material("red plastic", (0.7, 0.06, 0.05), roughness=0.3))
    import bmesh

    me = bpy.data.meshes.new("sphere")
    bm = bmesh.new()
    bmesh.ops.create_uvsphere(bm, u_segments=32, v_segments=16, radius=0.45)
    bm.to_mesh(me)
    bm.free()
    me.materials.append(principled_material("metal", (0.9, 0.88, 0.85), roughness=0.25, metallic=1.0))
    sphere = bpy.data.objects.new("sphere", me)
    sphere.location = (1.3, 2.6, 0.45)
    bpy.context.scene.collection.objects.link(sphere)
    sun = bpy.data.lights.new("Sun", "SUN")
    sun.energy = 4.0
    sun.angle = math.radians(1.0)
    sob = bpy.data.objects.new("Sun", sun)
    sob.rotation_euler = (math.radians(-55), 0.0, math.radians(15))     # shines in through the window
    bpy.context.scene.collection.objects.link(sob)
    area = bpy.data.lights.new("Ceiling light", "AREA")
    area.shape = "RECTANGLE"
    area.size, area.size_y = 1.0, 0.6
    area.energy = 40.0
    aob = bpy.data.objects.new("Ceiling light", area)
    aob.location = (W / 2, D / 2, H - 0.02)                           # faces down (-Z)
    bpy.context.scene.collection.objects.link(aob)
    world((0.4, 0.55, 0.85), 0.5, "Sky")
    add_camera(look_at_matrix((0.4, 0.3, 1.6), (2.4, 3.6, 0.8)), 24.0, 36.0, resolution)
    render_settings()


def grid_faces(ob, n=16):
    """Replace ``ob``'s quads by n x n grids, each face with its own (n+1)^2 vertices
    (bilinear over the quad), and give it a lightmap UV map: one square tile per face
    on a ceil(sqrt F)^2 atlas, a 1/32 gap between tiles."""
    bpy = _bpy()
    me = ob.data
    co = np.empty(3 * len(me.vertices))
    me.vertices.foreach_get("co", co)
    co = co.reshape(-1, 3)
    polys = [list(p.vertices) for p in me.polygons]
    cols = int(math.ceil(math.sqrt(len(polys))))
    tile, gap = 1.0 / cols, 1.0 / 32
    s, t = np.meshgrid(np.linspace(0, 1, n + 1), np.linspace(0, 1, n + 1))
    s, t = s.ravel(), t.ravel()
    j, i = np.divmod(np.arange(n * n), n)
    cell = j * (n + 1) + i
    quad = np.stack([cell, cell + 1, cell + n + 2, cell + n + 1], axis=1)
    verts, faces, uvs = [], [], []
    for k, p in enumerate(polys):
        q = co[p]
        pts = (((1 - s) * (1 - t))[:, None] * q[0] + (s * (1 - t))[:, None] * q[1] + (s * t)[:, None] * q[2]
               + ((1 - s) * t)[:, None] * q[3])
        faces.append(quad + sum(len(v) for v in verts))
        verts.append(pts)
        ty, tx = divmod(k, cols)
        uv = np.stack([tx + gap / 2 + s * (1 - gap), ty + gap / 2 + t * (1 - gap)], axis=1) * tile
        uvs.append(uv[quad].reshape(-1, 2))
    new = bpy.data.meshes.new(me.name)
    new.from_pydata(np.concatenate(verts).tolist(), [], np.concatenate(faces).tolist())
    for m in me.materials:
        new.materials.append(m)
    layer = new.uv_layers.new(name="Lightmap")
    layer.uv.foreach_set("vector", np.concatenate(uvs).astype(np.float32).ravel())
    new.update()
    ob.data = new
    bpy.data.meshes.remove(me)
    return ob


def build_cornell_bake(n=16):
    """The Cornell box .blend with every face cut n x n into its own (n+1)^2 vertices
    (16 faces, 4,624 vertices at n = 16) and a lightmap UV map per object: the bake
    demo and the bake bench's scene."""
    obs = build_cornell(False)
    for ob in obs.values():
        grid_faces(ob, n)
    return obs


def subdivide_edit_mode(ob, cuts=15):
    """``ob``'s mesh as a modeller makes it in Edit Mode: Merge by Distance (a block's faces share
    their corners), then Subdivide (``bpy.ops.mesh.subdivide``): every edge cut ``cuts`` times and
    each quad filled with a grid, the faces of one mesh sharing the vertices along their common
    edges (bmesh's ``remove_doubles`` and ``subdivide_edges``, the operators' own code, without an
    Edit Mode context)."""
    import bmesh

    bm = bmesh.new()
    bm.from_mesh(ob.data)
    bmesh.ops.remove_doubles(bm, verts=bm.verts[:], dist=1e-6)
    bmesh.ops.subdivide_edges(bm, edges=bm.edges[:], cuts=cuts, use_grid_fill=True)
    bm.to_mesh(ob.data)
    bm.free()
    ob.data.update()
    return ob


def build_cornell_subdivided(cuts=15):
    """The Cornell box .blend with every mesh subdivided in Edit Mode (``cuts`` cuts; module
    docstring): the bake bench's file whose crease vertices are shared by faces of different
    normals."""
    obs = build_cornell(False)
    for ob in obs.values():
        subdivide_edit_mode(ob, cuts)
    return obs


SCENES = {
    "cornell_box": lambda: build_cornell(False),
    "cornell_bake": build_cornell_bake,
    "cornell_subdivided": build_cornell_subdivided,
    "cornell_glossy": lambda: build_cornell(True),
    "sierpinski": build_sierpinski,
    "room": build_room,
}


def save(path):
    bpy = _bpy()
    bpy.ops.wm.save_as_mainfile(filepath=os.path.abspath(path), compress=True)


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--out", default=os.path.join(ROOT, "demo_scenes"))
    p.add_argument("--only", nargs="*", choices=sorted(SCENES), help="build only these")
    a = p.parse_args(argv)
    os.makedirs(a.out, exist_ok=True)
    ensure_addon()
    for name in a.only or SCENES:
        reset()
        SCENES[name]()
        path = os.path.join(a.out, name + ".blend")
        save(path)
        print(f"wrote {path} ({os.path.getsize(path) / 1024:.0f} KB)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
