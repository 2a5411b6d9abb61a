"""Stress scenes for the set-up: what real rooms bring, each alone in a plain room, built with ``bpy``.

Usage (the bpy module is in the project's venv)::

    .venv/bin/python tools/stress_scenes.py --out out/bench-scale/stress [--only objects-1000 ...]

Every scene is a 6 x 4 x 3 m room (floor, ceiling and walls in a white Principled BSDF, a
1 x 1 m area lamp under the ceiling, a 24 mm camera in a corner, 320 x 180 px) holding:

* ``objects-1000``: 1,000 small boxes, each its own object and mesh, in 10 materials;
* ``node-materials-20``: 20 node-graph materials on 5 UV spheres each: 10 read an image
  through a UV map past Mapping and Vector Math, 5 a Noise Texture over the UV map, 5 a
  Noise Texture over Generated coordinates (baked per object);
* ``planes-10000``: 10,000 loose 5 cm tiles (floor and a wall), each touching its neighbours;
* ``chandelier``: 240 glass drops (linked duplicates of one icosphere) in rings under the lamp;
* ``glossy-clusters``: 40 clusters of 25 small metal spheres of four roughnesses;
* ``transmission-chain``: 10 glass panes in a row between the camera and the back wall;
* ``triangles-1M``, ``triangles-4M``: a displaced grid of 1M and 4M triangles on the floor.

Files are written as ``<name>.blend`` (and the image the materials read, ``stress-checker.png``)
with the RAYBUNDLE engine selected and Cycles set as the references are.
"""
from __future__ import annotations

import argparse
import math
import os
import sys

import numpy as np

_TOOLS = os.path.dirname(os.path.abspath(__file__))
_ROOT = os.path.dirname(_TOOLS)
sys.path[:0] = [_TOOLS, os.path.join(_ROOT, "demo_scenes")]

W, D, H = 6.0, 4.0, 3.0


def _bpy():
    import bpy

    return bpy


def mesh(name, verts, faces, materials=(), material_index=None, link=True):
    """An object of a new mesh from arrays: ``verts`` (V, 3), ``faces`` (F, k) of one polygon size,
    built with ``foreach_set`` (fast for millions of faces); a UV map from the vertices' x, y."""
    bpy = _bpy()
    verts, faces = np.asarray(verts, np.float32), np.asarray(faces, np.int32)
    me = bpy.data.meshes.new(name)
    me.vertices.add(len(verts))
    me.vertices.foreach_set("co", verts.ravel())
    me.loops.add(faces.size)
    me.loops.foreach_set("vertex_index", faces.ravel())
    me.polygons.add(len(faces))
    me.polygons.foreach_set("loop_start", np.arange(0, faces.size, faces.shape[1], dtype=np.int32))
    uv = me.uv_layers.new(name="UVMap")
    uv.data.foreach_set("uv", verts[faces.ravel(), :2].ravel())
    for m in materials:
        me.materials.append(m)
    if material_index is not None:
        me.polygons.foreach_set("material_index", np.asarray(material_index, np.int32))
    me.update(calc_edges=True)
    ob = bpy.data.objects.new(name, me)
    if link:
        bpy.context.scene.collection.objects.link(ob)
    return ob


def instance(name, me, location, scale=1.0):
    """A linked duplicate of mesh ``me``."""
    bpy = _bpy()
    ob = bpy.data.objects.new(name, me)
    ob.location = tuple(map(float, location))
    ob.scale = (scale,) * 3
    bpy.context.scene.collection.objects.link(ob)
    return ob


def box(lo, hi):
    """(verts (8, 3), quads (6, 4)) of an axis-aligned box, faces outward."""
    from make_demo_scenes import _box_faces

    v, f = _box_faces(lo, hi)
    return np.array(v, float), np.array(f)


def ico_mesh(name, subdivisions, radius=1.0):
    import bmesh

    bpy = _bpy()
    me = bpy.data.meshes.new(name)
    bm = bmesh.new()
    bmesh.ops.create_icosphere(bm, subdivisions=subdivisions, radius=radius)
    bm.to_mesh(me)
    bm.free()
    me.uv_layers.new(name="UVMap")
    return me


def uv_sphere_mesh(name, segments, rings, radius=1.0):
    import bmesh

    bpy = _bpy()
    me = bpy.data.meshes.new(name)
    bm = bmesh.new()
    bm.loops.layers.uv.new("UVMap")
    bmesh.ops.create_uvsphere(bm, u_segments=segments, v_segments=rings, radius=radius, calc_uvs=True)
    bm.to_mesh(me)
    bm.free()
    return me


def glass_material(name, ior=1.5):
    from make_demo_scenes import _new_material

    mat, nt, out = _new_material(name)
    g = nt.nodes.new("ShaderNodeBsdfGlass")
    g.inputs["IOR"].default_value = ior
    g.inputs["Roughness"].default_value = 0.0
    nt.links.new(g.outputs[0], out.inputs["Surface"])
    return mat


def room():
    """The plain room, its lamp and camera (see the module docstring)."""
    from make_demo_scenes import add_camera, look_at_matrix, principled_material, render_settings, world

    bpy = _bpy()
    white = principled_material("room white", (0.75, 0.74, 0.72), roughness=0.8)
    v, f = box((0, 0, 0), (W, D, H))
    mesh("room", v, f[:, ::-1], [white])                       # faces inward
    lamp = bpy.data.lights.new("lamp", "AREA")
    lamp.size, lamp.energy = 1.0, 300.0
    ob = bpy.data.objects.new("lamp", lamp)
    ob.location = (W / 2, D / 2, H - 0.02)
    bpy.context.scene.collection.objects.link(ob)
    world((0.0, 0.0, 0.0), 0.0)
    add_camera(look_at_matrix((0.3, 0.3, 1.7), (W * 0.6, D * 0.7, 0.6)), 24.0, 36.0, (320, 180))
    render_settings(time_limit=30.0)


def objects_1000():
    from make_demo_scenes import principled_material

    mats = [principled_material(f"plastic {k}", (0.2 + 0.06 * k, 0.5, 0.8 - 0.06 * k), roughness=0.5)
            for k in range(10)]
    rng = np.random.default_rng(1)
    for k in range(1000):
        x, y = 1.0 + 4.0 * (k % 40) / 40, 0.6 + 2.8 * (k // 40) / 25
        s = rng.uniform(0.03, 0.06)
        v, f = box((x, y, 0), (x + s, y + s, rng.uniform(0.05, 0.3)))
        mesh(f"box {k}", v, f, [mats[k % 10]])


def checker_image(path, n=256, tiles=8):
    bpy = _bpy()
    img = bpy.data.images.new("stress-checker", n, n)
    ij = np.indices((n, n)).sum(0) // (n // tiles) % 2
    rgba = np.ones((n, n, 4), np.float32)
    rgba[..., 0] = 0.15 + 0.6 * ij
    rgba[..., 1] = 0.3 + 0.3 * ij
    rgba[..., 2] = 0.7 - 0.5 * ij
    img.pixels.foreach_set(rgba.ravel())
    img.filepath_raw = path
    img.file_format = "PNG"
    img.save()
    return img


def node_materials_20(out_dir):
    from make_demo_scenes import _new_material

    img = checker_image(os.path.join(os.path.abspath(out_dir), "stress-checker.png"))
    sphere = uv_sphere_mesh("sphere", 32, 16, radius=0.15)
    for k in range(20):
        mat, nt, out = _new_material(f"graph {k}")
        p = nt.nodes.new("ShaderNodeBsdfPrincipled")
        p.inputs["Roughness"].default_value = 0.6
        nt.links.new(p.outputs[0], out.inputs["Surface"])
        coords = nt.nodes.new("ShaderNodeTexCoord")
        if k < 10:                                  # an image through a UV past vector nodes
            mapping = nt.nodes.new("ShaderNodeMapping")
            mapping.inputs["Scale"].default_value = (1 + k % 3, 1 + k % 3, 1)
            vmath = nt.nodes.new("ShaderNodeVectorMath")
            vmath.operation = "ADD"
            vmath.inputs[1].default_value = (0.1 * k, 0.0, 0.0)
            tex = nt.nodes.new("ShaderNodeTexImage")
            tex.image = img
            nt.links.new(coords.outputs["UV"], mapping.inputs["Vector"])
            nt.links.new(mapping.outputs["Vector"], vmath.inputs[0])
            nt.links.new(vmath.outputs["Vector"], tex.inputs["Vector"])
            nt.links.new(tex.outputs["Color"], p.inputs["Base Color"])
        else:                                       # a procedural over the UV map, or per object
            noise = nt.nodes.new("ShaderNodeTexNoise")
            noise.inputs["Scale"].default_value = 3.0 + k
            ramp = nt.nodes.new("ShaderNodeValToRGB")
            ramp.color_ramp.elements[0].color = (0.1, 0.2, 0.5, 1)
            ramp.color_ramp.elements[1].color = (0.9, 0.7, 0.3, 1)
            nt.links.new(coords.outputs["UV" if k < 15 else "Generated"], noise.inputs["Vector"])
            nt.links.new(noise.outputs["Fac"], ramp.inputs["Fac"])
            nt.links.new(ramp.outputs["Color"], p.inputs["Base Color"])
        for j in range(5):
            me = sphere.copy()
            me.materials.append(mat)
            instance(f"sphere {k}.{j}", me, (0.8 + 0.22 * k, 0.8 + 0.5 * j, 0.15))


def planes_10000():
    from make_demo_scenes import principled_material

    s = 0.05

    def tiles(nu, nv, corner, du, dv):
        i, j = np.meshgrid(np.arange(nu), np.arange(nv), indexing="ij")
        o = np.asarray(corner) + (i.ravel()[:, None] * du + j.ravel()[:, None] * dv) * s
        v = np.stack([o, o + du * s, o + (du + dv) * s, o + dv * s], 1).reshape(-1, 3)
        return v, np.arange(len(v)).reshape(-1, 4)

    x0, y0 = 0.5, 0.5
    v, f = tiles(100, 60, (x0, y0, 0.001), np.array([1.0, 0, 0]), np.array([0, 1.0, 0]))
    mesh("floor tiles", v, f, [principled_material("tile", (0.6, 0.55, 0.5), roughness=0.4)])
    v, f = tiles(100, 40, (x0, y0 + 3.0, 0.001), np.array([1.0, 0, 0]), np.array([0, 0, 1.0]))
    mesh("wall tiles", v, f[:, ::-1], [principled_material("wall tile", (0.3, 0.5, 0.6), roughness=0.3)])


def chandelier():
    drop = ico_mesh("drop", 2, radius=0.03)
    drop.materials.append(glass_material("crystal"))
    k = 0
    for ring, (r, n) in enumerate(((0.25, 40), (0.4, 60), (0.55, 70), (0.7, 70))):
        for a in np.linspace(0, 2 * math.pi, n, endpoint=False):
            instance(f"drop {k}", drop, (W / 2 + r * math.cos(a), D / 2 + r * math.sin(a), H - 0.5 - 0.1 * ring))
            k += 1


def glossy_clusters():
    from make_demo_scenes import principled_material

    metals = [principled_material(f"metal {k}", (0.9, 0.8, 0.6), roughness=r, metallic=1.0)
              for k, r in enumerate((0.1, 0.2, 0.3, 0.45))]
    spheres = []
    for m in metals:
        me = uv_sphere_mesh(f"ball {m.name}", 16, 8, radius=0.04)
        me.materials.append(m)
        spheres.append(me)
    rng = np.random.default_rng(2)
    for c in range(40):
        centre = np.array([0.6 + 4.8 * (c % 8) / 8, 0.6 + 2.8 * (c // 8) / 5, 0.04])
        for j in range(25):
            p = centre + np.array([0.1 * (j % 5), 0.1 * (j // 5), 0.08 * rng.integers(0, 2)])
            instance(f"ball {c}.{j}", spheres[(c + j) % 4], p)


def transmission_chain():
    glass = glass_material("pane glass")
    for k in range(10):
        y = 1.0 + 0.2 * k
        v, f = box((1.5, y, 0.3), (4.5, y + 0.01, 2.4))
        mesh(f"pane {k}", v, f, [glass])


def displaced_grid(triangles):
    from make_demo_scenes import principled_material

    n = int(round(math.sqrt(triangles / 2))) + 1
    xs, ys = np.linspace(0.5, W - 0.5, n), np.linspace(0.5, D - 0.5, n)
    X, Y = np.meshgrid(xs, ys)
    Z = 0.15 + 0.12 * np.sin(5 * X) * np.cos(7 * Y) + 0.03 * np.sin(41 * X + 29 * Y)
    i, j = np.meshgrid(np.arange(n - 1), np.arange(n - 1))
    a = (j * n + i).ravel()
    quads = np.stack([a, a + 1, a + n + 1, a + n], 1)
    mesh("terrain", np.stack([X.ravel(), Y.ravel(), Z.ravel()], 1), quads,
         [principled_material("terrain", (0.4, 0.45, 0.3), roughness=0.7)])


SCENES = {
    "objects-1000": lambda out: objects_1000(),
    "node-materials-20": node_materials_20,
    "planes-10000": lambda out: planes_10000(),
    "chandelier": lambda out: chandelier(),
    "glossy-clusters": lambda out: glossy_clusters(),
    "transmission-chain": lambda out: transmission_chain(),
    "triangles-1M": lambda out: displaced_grid(1_000_000),
    "triangles-4M": lambda out: displaced_grid(4_000_000),
}


def build(name, out_dir):
    """Write ``<out_dir>/<name>.blend``; returns its path."""
    from cycles_reference import reset
    from make_demo_scenes import ensure_addon, save

    os.makedirs(out_dir, exist_ok=True)
    ensure_addon()
    reset()
    room()
    SCENES[name](out_dir)
    path = os.path.join(out_dir, name + ".blend")
    save(path)
    return path


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--out", default=os.path.join(_ROOT, "out", "bench-scale", "stress"))
    p.add_argument("--only", nargs="*", choices=sorted(SCENES))
    a = p.parse_args(argv)
    for name in a.only or SCENES:
        print(build(name, a.out))
    return 0


if __name__ == "__main__":
    sys.exit(main())
