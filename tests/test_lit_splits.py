"""Patches split where the lamps' light changes within them (:mod:`raybundle.patches.lit_splits`,
:func:`raybundle.app.pipeline.prepare`)."""
from dataclasses import replace

import numpy as np

from raybundle.app import pipeline
from raybundle.lights.direct import DirectLighting
from raybundle.patches.clusters import make_patches
from raybundle.patches.lit_splits import LEVELS, MAX_ADDED, split_where_lit_unevenly
from raybundle.scene.build import build_scene
from raybundle.scene.materials import MaterialTable
from raybundle.scene.model import AreaLights, SunLights
from raybundle.tracing.visibility import RayTracer

TARGET = 64


def tiled_floor(n=48, size=2.0, **lights):
    """A floor ``size`` wide of n x n tiles (triangles much smaller than a patch: the layout
    groups them into clusters), facing up, under ``lights``."""
    x = np.linspace(0, size, n + 1)
    gx, gy = np.meshgrid(x, x, indexing="ij")
    v = np.stack([gx.ravel(), gy.ravel(), np.zeros(gx.size)], axis=1)
    i = np.arange(n)[:, None] * (n + 1) + np.arange(n)[None, :]
    t = np.concatenate([np.stack([i, i + n + 1, i + n + 2], -1).reshape(-1, 3),
                        np.stack([i, i + n + 2, i + 1], -1).reshape(-1, 3)])
    mats = MaterialTable.from_list([dict(name="floor", diffuse=(0.6,) * 3)])
    return build_scene(v, t, np.zeros(len(t), int), mats, **lights)


def lamp_close_over(corner=(0.5, 0.5), height=0.05, half=0.15, radiance=20.0):
    """A square area lamp ``2 half`` wide ``height`` over the floor, facing down."""
    return AreaLights([[corner[0], corner[1], height]], [[half, 0, 0]], [[0, half, 0]], [[0, 0, -1]], [0],
                      [[radiance] * 3])


def floor_light(scene):
    """(T,) the lamps' irradiance at the centroid of each triangle (one-sided, facing up)."""
    tracer = RayTracer(scene)
    try:
        d = DirectLighting(scene, tracer)
        return d.irradiance(scene.triangle_corners.mean(axis=1), scene.triangle_normal, np.random.default_rng(1),
                            samples_per_light=2).mean(axis=1)
    finally:
        tracer.close()


def misfit(scene, e):
    """The share of the light that one value per patch misplaces: sum a |E_t - E_patch| / sum a E_t."""
    a, p = scene.triangle_area, scene.triangle_patch
    mean = np.bincount(p, a * e) / np.bincount(p, a)
    return float((a * np.abs(e - mean[p])).sum() / (a * e).sum())


def test_patches_under_a_lamp_close_over_a_floor_are_split_where_its_light_changes():
    """A lamp 5 cm over a tiled floor lights a spot whose edge is sharper than a patch: the
    prepared layout splits the clusters over the spot's edge (at most LEVELS times, adding at
    most MAX_ADDED of the count), so one value per patch misplaces less than half the light it
    did; the clusters far from the lamp, lit evenly, are the layout's own."""
    sc = tiled_floor(area_lights=lamp_close_over())
    laid_out = make_patches(sc, patches=TARGET)
    split = pipeline.prepare(sc, patches=TARGET)
    e = floor_light(split)
    assert misfit(split, e) < 0.5 * misfit(laid_out, e), (misfit(split, e), misfit(laid_out, e))
    assert laid_out.n_patches < split.n_patches <= (1 + MAX_ADDED) * laid_out.n_patches
    area = np.bincount(split.triangle_patch, split.triangle_area)
    assert area.min() >= np.bincount(laid_out.triangle_patch, laid_out.triangle_area).max() / 4 ** (LEVELS + 1)
    # far from the lamp every patch holds the same triangles as before
    far = np.hypot(*(sc.triangle_corners[:, :, :2].mean(axis=1) - 0.5).T) > 1.2
    groups = {tuple(np.nonzero(split.triangle_patch == q)[0]) for q in np.unique(split.triangle_patch[far])}
    before = {tuple(np.nonzero(laid_out.triangle_patch == q)[0]) for q in np.unique(laid_out.triangle_patch[far])}
    assert groups & before and len(groups - before) <= 0.1 * len(groups)


def test_an_evenly_lit_floor_and_a_floor_without_lamps_keep_their_layout():
    """Nothing to split: the light is the same at every tile (a sun straight down, nothing in
    its way), or there is no lamp (the world alone lights the floor)."""
    sun = SunLights(direction=[[0, 0, -1]], irradiance=[[3.0] * 3], angle=[0.0])
    for lights in (dict(sun_lights=sun), dict(environment=(1.0, 1.0, 1.0))):
        sc = tiled_floor(**lights)
        laid_out = make_patches(sc, patches=TARGET)
        assert np.array_equal(pipeline.prepare(sc, patches=TARGET).triangle_patch, laid_out.triangle_patch)


def test_the_split_asks_the_light_at_few_triangles_of_an_even_patch():
    """The light is asked at no more than PROBES_PER_PATCH triangles of each patch that is not
    split, and the split of an unevenly lit patch keeps every triangle in exactly one patch."""
    sc = make_patches(tiled_floor(area_lights=lamp_close_over()), patches=TARGET)
    asked = []

    def light(points, normals):
        asked.append(len(points))
        x, y = points[:, 0], points[:, 1]
        return np.where((x < 0.65) & (y < 0.65), 100.0, 1.0)          # a lit square at one corner

    out, added = split_where_lit_unevenly(sc, light)
    assert added == out.n_patches - sc.n_patches > 0
    assert sum(asked) < len(sc.triangles)
    assert np.array_equal(np.unique(out.triangle_patch), np.arange(out.n_patches))


def same_partition(a, b):
    """Whether the patch ids ``a`` and ``b`` (T,) group the triangles alike (whatever their numbers)."""
    pairs = np.unique(np.stack([a, b], axis=1), axis=0)
    return len(pairs) == len(np.unique(a)) == len(np.unique(b))


def test_the_split_is_the_same_however_the_patches_are_numbered():
    """A lamp 5 cm over a tiled floor, half of it shaded by a plate 2 cm over the floor: the
    probes in the plate's penumbra take a few shadow rays each, whose outcome is random.  With
    the patches numbered otherwise (as a layout that adds a cluster key numbers them) the
    split is the same: each probed point's numbers are its own, not its turn in a stream (which
    made the same layout split otherwise: the Cornell box's regions moved by up to 0.7%)."""
    floor = tiled_floor(n=64, area_lights=lamp_close_over())
    plate = np.array([[0.3, 0.3, 0.02], [0.5, 0.3, 0.02], [0.5, 0.7, 0.02], [0.3, 0.7, 0.02]])
    v = np.vstack([floor.vertices, plate])
    t = np.vstack([floor.triangles, [[0, 2, 1], [0, 3, 2]] + np.int64(len(floor.vertices))])
    sc = build_scene(v, t, np.zeros(len(t), int), floor.materials, area_lights=floor.area_lights)
    laid_out = make_patches(sc, patches=TARGET)
    perm = np.random.default_rng(3).permutation(laid_out.n_patches)
    renumbered = replace(laid_out, triangle_patch=perm[laid_out.triangle_patch])
    a = pipeline.split_lit_unevenly(sc, laid_out)
    b = pipeline.split_lit_unevenly(sc, renumbered)
    assert a.n_patches > laid_out.n_patches
    assert same_partition(a.triangle_patch, b.triangle_patch), (a.n_patches, b.n_patches)
