"""Bakes against Cycles' bake of the same file where patch values are not to be trusted: the corners
of a block standing on a floor, a concave L-shaped wall (one mesh, its crease vertices shared), and a
lightmap of a floor beside walls and the block; point and corner domains.

The room (2 m) has coarse patches (200) and its one lamp low in a corner, facing the ceiling, so
that every surface near the floor is lit indirectly and the light changes within a patch next to the
edges and contacts.  There, reading patch values is biased by several percent: the lightmap texels
interpolated from the patches, and a vertex gather whose rays, landing by an edge, read the patches
one bounce further (the bake's gather before its second bounce).

Each group of vertices (texels) is compared by its mean over two seeds against Cycles' bake of the
same points (2 x 256 samples), within :data:`TOLERANCE`: the groups' means spread by at most 0.4%
(standard deviation over seeds 1-6), and the coarse solution itself sits up to 3% low next to the
block (the gather reads it; ``docs/method.md``, weak points).  The old estimators missed by 4.6-7%
at the wall's foot, 3.6% at the block's base and 6.6-11.8% in the lightmap.  The lightmap's 64²
texels gather with a window of 5 x 5.  Texels whose footprint reaches under the block are left out
(a texel's indirect light is its centre's, Cycles' its footprint's).
"""
from __future__ import annotations

import bpy
import numpy as np
import pytest
from addon_helpers import add_light, add_object, box, node_material
from addon_helpers import addon  # noqa: F401
from cycles_reference import bake_image, cycles_settings

#: the largest relative difference of a group's mean from Cycles' (module docstring)
TOLERANCE = 0.04
BLOCK = ((-0.2, -0.1, 0.0), (0.4, 0.5, 0.6))
LIGHTMAP = 64
SEEDS = (1, 2)


def grid(name, n, mat):
    """The 2 m floor at z = 0 as ``n`` x ``n`` quads, its UV map the unit square over it."""
    v = [(-1.0 + 2.0 * i / n, -1.0 + 2.0 * j / n, 0.0) for j in range(n + 1) for i in range(n + 1)]
    f = [(j * (n + 1) + i, j * (n + 1) + i + 1, (j + 1) * (n + 1) + i + 1, (j + 1) * (n + 1) + i)
         for j in range(n) for i in range(n)]
    ob = add_object(name, v, f, [mat])
    me = ob.data
    vi = np.array([lp.vertex_index for lp in me.loops])
    uv = np.stack([vi % (n + 1), vi // (n + 1)], axis=1) / n
    me.uv_layers.new(name="UVMap").uv.foreach_set("vector", uv.astype(np.float32).ravel())
    return ob


def room():
    """The scene (module docstring): floor, the L wall (x = -1 and y = -1, 12 x 12 quads each), the
    other walls and the ceiling, the block (its faces cut 6 x 6, creases shared), the lamp."""
    import bmesh

    bpy.ops.wm.read_factory_settings(use_empty=True)
    white = node_material("white", color=(0.7, 0.7, 0.7))
    grid("floor", 16, white)
    n, w = 12, 25
    v = [(-1.0, 1.0 - 2.0 * i / n, 2.0 * j / n) if i <= n else (-1.0 + 2.0 * (i - n) / n, -1.0, 2.0 * j / n)
         for j in range(n + 1) for i in range(w)]
    f = [(j * w + i, (j + 1) * w + i, (j + 1) * w + i + 1, j * w + i + 1) for j in range(n) for i in range(w - 1)]
    add_object("lwall", v, f, [white])
    rv = [(1, -1, 0), (1, 1, 0), (-1, 1, 0), (1, -1, 2), (1, 1, 2), (-1, 1, 2), (-1, -1, 2)]
    add_object("rest", rv, [(0, 3, 4, 1), (1, 4, 5, 2), (3, 6, 5, 4)], [white])
    block = add_object("block", *box(*BLOCK), [white])
    bm = bmesh.new()
    bm.from_mesh(block.data)
    bmesh.ops.subdivide_edges(bm, edges=bm.edges[:], cuts=5, use_grid_fill=True)
    bm.to_mesh(block.data)
    bm.free()
    add_light("AREA", location=(-0.75, -0.75, 0.5), rotation=(np.pi, 0.0, 0.0), energy=15.0, size=0.2)
    return bpy.context.scene


def read(name, objects=("floor", "lwall", "block")):
    out = {}
    for ob in objects:
        a = bpy.data.objects[ob].data.color_attributes[name]
        x = np.empty(4 * len(a.data), np.float32)
        a.data.foreach_get("color", x)
        out[ob] = x.reshape(-1, 4)[:, :3].mean(axis=1)
    return out


def vertex_groups(domain):
    """Name -> (object, bool mask over its vertices or corners) of the compared groups."""
    out = {}
    co = {}
    for name in ("floor", "lwall", "block"):
        me = bpy.data.objects[name].data
        c = np.empty(3 * len(me.vertices))
        me.vertices.foreach_get("co", c)
        co[name] = c.reshape(-1, 3)
    (x0, y0, _), (x1, y1, _) = BLOCK
    f = co["floor"]
    gap = np.maximum(np.maximum(x0 - f[:, 0], f[:, 0] - x1), np.maximum(y0 - f[:, 1], f[:, 1] - y1))
    out["floor by the block"] = ("floor", (gap > 0.01) & (gap < 0.2))
    out["floor by the walls"] = ("floor", (np.minimum(f[:, 0], f[:, 1]) < -0.8) | (np.maximum(f[:, 0], f[:, 1]) > 0.8))
    b, lw = co["block"], co["lwall"]
    out["block's base"] = ("block", (b[:, 2] > 0.01) & (b[:, 2] < 0.15))
    out["L wall's crease"] = ("lwall", (np.hypot(lw[:, 0] + 1, lw[:, 1] + 1) < 0.35) & (lw[:, 2] > 0.2))
    out["L wall's foot"] = ("lwall", lw[:, 2] < 0.2)
    if domain == "CORNER":
        for k, (ob, m) in out.items():
            me = bpy.data.objects[ob].data
            cv = np.empty(len(me.loops), np.int64)
            me.loops.foreach_get("vertex_index", cv)
            out[k] = (ob, m[cv])
    return out


def lightmap_groups():
    """Name -> (LIGHTMAP, LIGHTMAP) bool mask of the compared texels (rows bottom-up)."""
    c = (np.arange(LIGHTMAP) + 0.5) / LIGHTMAP * 2.0 - 1.0
    x, y = np.meshgrid(c, c)
    (x0, y0, _), (x1, y1, _) = BLOCK
    gap = np.maximum(np.maximum(x0 - x, x - x1), np.maximum(y0 - y, y - y1))
    wall = np.minimum.reduce([x + 1, y + 1, 1 - x, 1 - y])
    free = gap > 1.2 / LIGHTMAP                          # the texel's footprint clear of the block
    return {"texels by the walls": free & (wall < 0.25), "texels by the block": free & (gap < 0.25),
            "texels in the open": free & (wall > 0.3) & (gap > 0.3)}


@pytest.fixture(scope="module")
def cycles_room(addon):  # noqa: F811
    """Cycles' bakes of the room per seed: the point and corner attributes and the floor's lightmap."""
    room()
    out = {}
    meshes = [ob for ob in bpy.context.scene.objects if ob.type == "MESH"]
    for seed in SEEDS:
        cycles_settings(256, seed, world_strength=None)
        for domain in ("POINT", "CORNER"):
            for ob in meshes:
                a = ob.data.color_attributes.new("Cycles", "FLOAT_COLOR", domain)
                ob.data.color_attributes.active_color = a
                ob.select_set(True)
            bpy.context.view_layer.objects.active = meshes[0]
            bpy.ops.object.bake(type="COMBINED", target="VERTEX_COLORS")
            out[domain, seed] = read("Cycles")
            for ob in meshes:
                ob.data.color_attributes.remove(ob.data.color_attributes["Cycles"])
        out["lightmap", seed] = bake_image(bpy.data.objects["floor"], LIGHTMAP).mean(axis=-1)
    return out


def bake_ours(seed, domain="POINT", lightmap=False):
    from raybundle_addon.bake import BakeJob

    rb = bpy.context.scene.raybundle
    rb.iterations, rb.time_limit, rb.seed, rb.patches = 300, 0.0, seed, 200
    rb.bake_domain, rb.bake_light_samples = domain, 16
    rb.bake_color_attribute, rb.bake_lightmaps = not lightmap, lightmap
    rb.lightmap_size = LIGHTMAP
    out = BakeJob(bpy.context.evaluated_depsgraph_get(), lightmap_objects=["floor"]).run()
    assert not out.warnings, out.warnings
    if not lightmap:
        return read("RayBundle")
    img = bpy.data.images["floor.lightmap"]
    px = np.empty(LIGHTMAP * LIGHTMAP * 4, np.float32)
    img.pixels.foreach_get(px)
    return px.reshape(LIGHTMAP, LIGHTMAP, 4)[..., :3].mean(axis=-1)


def misses(ours, theirs, groups):
    """Name -> the group's mean over ours / over theirs - 1 (``ours`` and ``theirs``: per seed)."""
    out = {}
    for name, (ob, m) in groups.items():
        mean = [np.mean([run[ob][m].mean() if ob else run[m].mean() for run in side]) for side in (ours, theirs)]
        out[name] = mean[0] / mean[1] - 1.0
    return out


@pytest.mark.parametrize("domain", ["POINT", "CORNER"])
def test_vertices_by_contacts_and_a_concave_edge_bake_as_cycles_does(cycles_room, tmp_path, domain):
    """The block's base, the floor around it and beside the walls, the L wall's crease and foot."""
    room()
    bpy.context.scene.raybundle.bake_directory = str(tmp_path)
    ours = [bake_ours(seed, domain) for seed in SEEDS]
    miss = misses(ours, [cycles_room[domain, seed] for seed in SEEDS], vertex_groups(domain))
    print({k: f"{100 * v:+.2f}%" for k, v in miss.items()})
    assert all(abs(v) <= TOLERANCE for v in miss.values()), miss


def test_a_lightmap_beside_walls_and_a_block_bakes_as_cycles_does(cycles_room, tmp_path):
    """The floor's lightmap by the walls, by the block and in the open."""
    room()
    bpy.context.scene.raybundle.bake_directory = str(tmp_path)
    ours = [bake_ours(seed, lightmap=True) for seed in SEEDS]
    groups = {k: (None, m) for k, m in lightmap_groups().items()}
    miss = misses(ours, [cycles_room["lightmap", seed] for seed in SEEDS], groups)
    print({k: f"{100 * v:+.2f}%" for k, v in miss.items()})
    assert all(abs(v) <= TOLERANCE for v in miss.values()), miss
