"""Patches as clusters of triangles (:mod:`raybundle.patches.clusters`): the layout, and the
solution on curved clusters against the furnace's exact answer.

Statistical checks follow ``test_solver``: batch means after a burn-in batch, |mean -
exact| < 4.5 SE and SE itself small."""
from dataclasses import replace

import numpy as np
import pytest
from test_solver import assert_converged

from raybundle.app import pipeline
from raybundle.imaging.settings import RenderSettings
from raybundle.patches.clusters import NORMAL_CELLS, make_patches, normal_cells, tessellate
from raybundle.patches.layout import crowding, subdivide
from raybundle.patches.reconstruction import LinearReconstruction
from raybundle.scene import builtin as scenes
from raybundle.scene.build import build_scene
from raybundle.scene.materials import MaterialTable
from raybundle.tracing.visibility import RayTracer


def uv_sphere(centre, radius, rings, segments):
    """A closed, outward-facing UV sphere: (vertices (V, 3), triangles (T, 3))."""
    theta = np.linspace(0, np.pi, rings + 1)[1:-1]
    phi = np.linspace(0, 2 * np.pi, segments, endpoint=False)
    ring = np.stack([np.sin(theta)[:, None] * np.cos(phi), np.sin(theta)[:, None] * np.sin(phi),
                     np.cos(theta)[:, None] + 0 * phi], axis=2).reshape(-1, 3)
    v = np.vstack([[0, 0, 1], ring, [0, 0, -1]]) * radius + centre
    tris = []
    idx = lambda r, s: 1 + r * segments + s % segments        # noqa: E731
    for s in range(segments):
        tris.append([0, idx(0, s), idx(0, s + 1)])
        tris.append([len(v) - 1, idx(rings - 2, s + 1), idx(rings - 2, s)])
        for r in range(rings - 2):
            tris += [[idx(r, s), idx(r + 1, s), idx(r + 1, s + 1)], [idx(r, s), idx(r + 1, s + 1), idx(r, s + 1)]]
    return v, np.array(tris)


def furnace_with_sphere(rings=24, segments=48):
    """The diffuse furnace's room with a floating tessellated sphere instead of the block:
    every surface emits Le with albedo a, so L = Le / (1 - a) everywhere."""
    room = scenes.furnace()
    walls = np.nonzero(room.triangle_material == 0)[0]
    sv, st = uv_sphere(np.array([1.0, 1.0, 0.7]), 0.45, rings, segments)
    v = np.vstack([room.vertices, sv])
    t = np.vstack([room.triangles[walls], st + len(room.vertices)])
    m = np.concatenate([np.zeros(len(walls), int), np.ones(len(st), int)])
    return build_scene(v, t, m, room.materials, camera=room.camera, analytic_radiance=room.analytic_radiance)


def test_without_small_triangles_the_layout_is_subdivides():
    sc = scenes.cornell()
    for target in (300, 4000):
        assert np.array_equal(make_patches(sc, patches=target).triangle_patch,
                              subdivide(sc, patches=target).triangle_patch)


def test_tessellated_box_is_grouped_to_the_target():
    sc = scenes.cornell()
    fine = tessellate(sc, 20000)
    assert len(fine.triangles) > 19000 and np.array_equal(fine.triangle_source, np.arange(len(fine.triangles)))
    assert np.isclose(fine.triangle_area.sum(), sc.triangle_area.sum(), rtol=1e-12)
    for target in (500, 2000):
        p = make_patches(fine, patches=target)
        assert 0.85 * target < p.n_patches < 1.15 * target, p.n_patches
        assert np.isclose(p.triangle_area.sum(), sc.triangle_area.sum(), rtol=1e-12)
        first = np.zeros(p.n_patches, np.int64)
        first[p.triangle_patch[::-1]] = np.arange(len(p.triangles))[::-1]
        assert np.all(p.triangle_material == p.triangle_material[first[p.triangle_patch]])
        # walls of a box: every cluster lies on one wall (the measured red wall's two triangles
        # are 0.3 degrees apart: one cluster may hold both)
        assert np.all(np.einsum("ij,ij->i", p.triangle_normal, p.patch_normal[p.triangle_patch]) > np.cos(0.01))


@pytest.mark.parametrize("target", [1400, 1800])
def test_a_floor_of_equal_triangles_is_laid_out_to_the_target(target):
    """A floor subdivided 32 x 32 (2,048 equal triangles, as Blender's Subdivide makes them): its
    count jumps at once from about 1,000 (the triangles grouped in cells a quad wide) to 8,192
    (each cut into four); a target between gets about its count (grouped in finer cells).  The
    layout before gave about 1,000 or 8,192 patches, whatever the target between."""
    n = 32
    x = np.linspace(0.0, 1.0, n + 1)
    v = np.stack(np.meshgrid(x, x, indexing="ij"), axis=-1).reshape(-1, 2)
    v = np.hstack([v, np.zeros((len(v), 1))])
    i = (np.arange(n)[:, None] * (n + 1) + np.arange(n)[None, :]).reshape(-1)
    t = np.vstack([np.stack([i, i + n + 1, i + n + 2], 1), np.stack([i, i + n + 2, i + 1], 1)])
    p = make_patches(scene_of([(v, t)]), patches=target)
    assert 0.85 * target < p.n_patches < 1.15 * target, p.n_patches


@pytest.mark.parametrize("glossy", [True, False], ids=["glossy", "diffuse"])
def test_a_sphere_is_grouped_within_one_normal_cell_per_cluster(glossy):
    """A glossy lobe is evaluated about its cluster's normal in the iteration: a glossy sphere's
    clusters lie within one cell of the cube map (15 degrees).  A diffuse one's small clusters
    (under a quarter of a patch) merge by the cube face (55 degrees), but the cells' count holds.
    The glossy sphere's cells and grid cells outnumber the target at the coarsest patch size
    the layout takes (:func:`~raybundle.patches.clusters.surface_size`): about twice the count."""
    v, t = uv_sphere(np.zeros(3), 1.0, 64, 128)
    spec = dict(name="white", diffuse=(0.5, 0.5, 0.5), emission=(1, 1, 1))
    if glossy:
        spec.update(glossy=(0.3,) * 3, glossy_weight=0.5, roughness=0.3)
    sc = build_scene(v, t, np.zeros(len(t), int), MaterialTable.from_list([spec]))
    p = make_patches(sc, patches=300)
    assert 200 < p.n_patches < (700 if glossy else 400) and len(p.triangles) == len(t), p.n_patches
    cells = (normal_cells(p.triangle_normal),) if glossy else (normal_cells(p.triangle_normal, 1),)
    for cell in cells:
        per_patch = np.zeros(p.n_patches, np.int64)
        per_patch[p.triangle_patch] = cell
        assert np.all(cell == per_patch[p.triangle_patch])
    # a cell of the cube map spans at most ~15 degrees from its middle, a face ~55
    cos = np.einsum("ij,ij->i", p.triangle_normal, p.patch_normal[p.triangle_patch])
    assert cos.min() > np.cos(np.radians(20 if glossy else 60)), np.degrees(np.arccos(cos.min()))
    assert NORMAL_CELLS == 5


def test_a_shelf_over_a_floor_is_not_its_patch():
    """Parallel surfaces closer than a patch but more than half a patch apart keep their own clusters."""
    floor = tessellate(build_scene([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], [[0, 1, 2], [0, 2, 3]], [0, 0],
                                   MaterialTable.from_list([dict(name="w", diffuse=(0.5,) * 3, emission=(1,) * 3)])),
                       4000)
    shelf_v = floor.vertices + [0, 0, 0.08]
    v = np.vstack([floor.vertices, shelf_v])
    t = np.vstack([floor.triangles, floor.triangles + len(floor.vertices)])
    sc = build_scene(v, t, np.zeros(len(t), int), floor.materials)
    p = make_patches(sc, patches=400)                 # patch size ~ sqrt(2 m^2 / 400) = 0.07 m
    z = p.triangle_corners[:, :, 2].mean(axis=1)
    for patch in range(p.n_patches):
        zs = z[p.triangle_patch == patch]
        assert np.ptp(zs) < 1e-9


def quad(x0, x1, y0, y1, z, up=True):
    """Two triangles of a horizontal rectangle facing up (or down)."""
    v = [[x0, y0, z], [x1, y0, z], [x1, y1, z], [x0, y1, z]]
    return v, ([[0, 1, 2], [0, 2, 3]] if up else [[0, 2, 1], [0, 3, 2]])


def scene_of(parts, detail=None):
    """One scene of ``parts`` [(vertices, triangles)], one diffuse material, and ``detail``
    (vertices, triangles) too: triangles much smaller than a patch, so that the layout groups."""
    v, t = [], []
    for pv, pt in parts + ([detail] if detail is not None else []):
        t.append(np.asarray(pt) + sum(len(x) for x in v))
        v.append(np.asarray(pv, float))
    t = np.vstack(t)
    return build_scene(np.vstack(v), t, np.zeros(len(t), int),
                       MaterialTable.from_list([dict(name="w", diffuse=(0.5,) * 3, emission=(1,) * 3)]))


def test_crowding_under_a_plate_is_its_closed_form():
    """Under an unbounded plate at height d < reach, a share 1 - (d / reach)^2 of cosine-distributed
    rays meets it within reach; nothing above: none."""
    d, reach, rays = 0.1, 0.2, 20_000
    sc = scene_of([quad(-0.25, 0.25, -0.25, 0.25, 0.0), quad(-50, 50, -50, 50, d, up=False)])
    tracer = RayTracer(sc)
    try:
        share = crowding(tracer, sc, [0, 1], reach, rays=rays)
        assert np.all(np.abs(share - (1 - (d / reach) ** 2)) < 4 * np.sqrt(0.75 * 0.25 / rays)), share
        assert np.all(crowding(tracer, sc, [2, 3], reach, rays=rays) == 0)       # the plate sees nothing
    finally:
        tracer.close()


def test_a_floor_under_a_stair_step_gets_finer_patches():
    """A floor patch reaching under a step that floats a little above it averages the lit floor
    with the dark one beneath: the floor's patches under the step are cut to half a patch size,
    those in the open stay a patch wide.  The count stays within 1.6 times the target: the
    patch size is at its coarsest (:func:`~raybundle.patches.clusters.surface_size`), so the
    crowded pieces' cuts add to the count instead of coarsening the rest, and so do the contact
    cuts along the step's outline (its gap is under a quarter of a patch)."""
    floor = quad(0, 8, 0, 8, 0.0)
    step = [quad(3, 5, 3.6, 4.4, 0.15, up=False), quad(3, 5, 3.6, 4.4, 0.25)]
    sv, st = uv_sphere(np.array([7.0, 7.0, 1.0]), 0.3, 12, 24)
    sc = scene_of([floor] + step, detail=(sv, st))
    target = 200
    p = make_patches(sc, patches=target)
    assert 0.8 * target < p.n_patches < 1.6 * target, p.n_patches
    on_floor = np.abs(p.triangle_corners[:, :, 2]).max(axis=1) < 1e-9
    area = np.bincount(p.triangle_patch, p.triangle_area, minlength=p.n_patches)
    centre = np.stack([np.bincount(p.triangle_patch, p.triangle_area * p.triangle_corners[:, :, i].mean(axis=1),
                                   minlength=p.n_patches) for i in range(2)], axis=1) / area[:, None]
    floor_patches = np.unique(p.triangle_patch[on_floor])
    c = centre[floor_patches]
    under = (c[:, 0] > 3.2) & (c[:, 0] < 4.8) & (c[:, 1] > 3.7) & (c[:, 1] < 4.3)
    far = np.hypot(c[:, 0] - 4, c[:, 1] - 4) > 2.5
    assert under.any() and far.any()
    assert area[floor_patches[under]].max() < 0.5 * np.median(area[floor_patches[far]]), \
        (area[floor_patches[under]].max(), np.median(area[floor_patches[far]]))


def fanned_wall(slivers=100):
    """A 4 m x 3 m wall (z = 0) fanned out from one corner into long thin triangles, as walls
    are around windows in real models: edges up to 5 m, each a hundredth of the area."""
    far = np.concatenate([np.stack([np.full(slivers // 2 + 1, 4.0), np.linspace(0, 3, slivers // 2 + 1)], 1),
                          np.stack([np.linspace(4, 0, slivers // 2 + 1), np.full(slivers // 2 + 1, 3.0)], 1)[1:]])
    v = np.vstack([[0.0, 0.0, 0.0], np.c_[far, np.zeros(len(far))]])
    t = np.array([[0, i, i + 1] for i in range(1, len(far))])
    mats = MaterialTable.from_list([dict(name="w", diffuse=(0.5,) * 3, emission=(1,) * 3)])
    return build_scene(v, t, np.zeros(len(t), int), mats)


def test_a_wall_fanned_into_slivers_gets_patches_a_patch_wide():
    """Slivers are halved along their length and grouped where the pieces lie: patches as
    wide as they are long, about the target's count.  Grouped whole (by their centroids) they
    made clusters metres long; cut into k^2 similar slivers, thousands of patches a few
    square millimetres each."""
    sc = fanned_wall()
    edge = np.linalg.norm(sc.triangle_corners - np.roll(sc.triangle_corners, 1, axis=1), axis=2).max(axis=1)
    assert edge.max() > 4.9 and (sc.triangle_area / edge ** 2).max() < 0.02
    p = make_patches(sc, patches=400)
    assert 0.7 * 400 < p.n_patches < 1.3 * 400, p.n_patches             # the count of spread slivers is estimated
    assert np.isclose(p.triangle_area.sum(), 12.0, rtol=1e-9)
    area = np.bincount(p.triangle_patch, p.triangle_area)
    c = p.triangle_corners
    centre = np.stack([np.bincount(p.triangle_patch, p.triangle_area * c[:, :, k].mean(axis=1)) for k in range(3)],
                      axis=1) / area[:, None]
    extent = np.zeros(p.n_patches)
    np.maximum.at(extent, p.triangle_patch, np.linalg.norm(c - centre[p.triangle_patch][:, None], axis=2).max(axis=1))
    h = np.sqrt(12.0 / p.n_patches)
    assert extent.max() < 2 * h, extent.max() / h                    # a cell h wide, pieces at most h long
    assert np.median(area) > 0.25 * h * h, np.median(area) / h / h


def test_a_cluster_fit_departs_from_its_value_no_more_than_a_neighbour():
    """A ring of triangles around a disc: their centroids nearly coincide, so the ring's
    least-squares gradient from the disc is the difference over a millimetre.  Unlimited, its
    fit read at the ring's outer corners made values hundreds of times the sides'
    (a real room's image: spots 2,000 times too bright); limited to the largest difference
    to a neighbour, every vertex stays within the sides' range widened by that range."""
    mats = MaterialTable.from_list([dict(name="w", diffuse=(0.5,) * 3, emission=(1,) * 3)])
    plane = tessellate(build_scene([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], [[0, 1, 2], [0, 2, 3]], [0, 0], mats),
                       8000)
    x = plane.triangle_corners.mean(axis=1)
    r = np.linalg.norm(x[:, :2] - [0.501, 0.5], axis=1)
    cell = (np.floor(x[:, 0] / 0.2) * 5 + np.floor(x[:, 1] / 0.2)).astype(np.int64)
    patch = np.where(r < 0.08, 0, np.where(r < 0.3, 1, 2 + cell))
    p = replace(plane, triangle_patch=np.unique(patch, return_inverse=True)[1].reshape(-1))
    rec = LinearReconstruction(p, p.triangle_area[p.tside_triangle])
    assert rec._fit is not None and len(rec._fit.vertices) == rec.n_vertices
    values = np.ones((p.n_sides, 1))
    values[np.unique(p.tside_side[p.triangle_patch[p.tside_triangle] == 0])] = 2.0           # the disc
    out = rec.projected(values)[:, 0]
    assert out.min() >= 0.0 and out.max() <= 3.0 + 1e-9, (out.min(), out.max())


def test_clusters_are_read_through_linear_fits_exact_on_a_linear_function():
    """Side values that are the means of a linear function over 100 clusters of a finely
    meshed plane come back exactly at every vertex; the hat projection on the clusters' own
    fine triangles (what a cluster would get without its fit) is 10% off."""
    mats = MaterialTable.from_list([dict(name="w", diffuse=(0.5,) * 3, emission=(1,) * 3)])
    plane = build_scene([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], [[0, 1, 2], [0, 2, 3]], [0, 0], mats)
    p = make_patches(tessellate(plane, 20000), patches=100)
    rec = LinearReconstruction(p, p.triangle_area[p.tside_triangle])
    f = lambda x: 1 + 2 * x[..., 0] + 3 * x[..., 1]                   # noqa: E731
    values = f(rec._fit.centroid)[:, None]          # a linear function's mean: its value at the centroid
    position = np.zeros((rec.n_vertices, 3))
    position[rec.ids.ravel()] = p.triangle_corners[p.tside_triangle].reshape(-1, 3)
    assert len(rec._fit.vertices) == rec.n_vertices
    assert np.abs(rec.projected(values)[:, 0] - f(position)).max() < 1e-8
    rec._fit = None
    assert np.sqrt(((rec.projected(values)[:, 0] - f(position)) ** 2).mean()) > 0.05


def test_several_value_sets_project_in_one_pass_as_each_alone(monkeypatch):
    """``smooth_and_sharp_many`` (the final gather's vertex values and the image's, in one
    projection) gives each set what ``smooth_and_sharp`` gives it alone, on a scene with both
    cluster fits (a tessellated sphere) and projected sides (the box), values that go below
    zero where the projection clamps them, and a sharp part on one set."""
    sc = pipeline.prepare(furnace_with_sphere(), patches=400)
    r = pipeline.make_renderer(sc, RenderSettings(seed=1))
    r.tracer.close()
    rec = r.solver.reconstruction
    assert rec._fit is not None and len(rec._p_vertices)
    # the conjugate gradients run to convergence (a residual 1e-12 of b's, not 1e-5), so that
    # each set's values are the projection's own, not where its stopping rule left them (alone,
    # a set stops at its own iteration; together, at the last set's)
    solve = type(rec)._solve_mass
    monkeypatch.setattr(type(rec), "_solve_mass", lambda self, b: solve(self, b, iterations=300, tol=1e-24))
    rng = np.random.default_rng(7)
    a, b, sharp = rng.normal(1.0, 1.0, (3, sc.n_sides, 3))
    c = rng.random((sc.n_sides, 1))
    alone = [rec.smooth_and_sharp(a, np.abs(sharp)), rec.smooth_and_sharp(b), rec.smooth_and_sharp(c)]
    together = rec.smooth_and_sharp_many([(a, np.abs(sharp)), (b, None), (c, None)])
    assert [x.shape for x in together] == [x.shape for x in alone]
    assert min(x.min() for x in alone) == 0.0                     # the clamp acts
    for x, y in zip(together, alone):
        np.testing.assert_allclose(x, y, rtol=0, atol=1e-9)


def test_furnace_with_curved_clusters_stays_exact():
    """A tessellated sphere grouped into curved clusters (each triangle's side and cosine
    taken at each bundle line) converges to the furnace's L on the sphere's own sides."""
    sc = pipeline.prepare(furnace_with_sphere(), patches=400)
    sphere = np.unique(sc.triangle_patch[sc.triangle_material == 1])
    cos = np.einsum("ij,ij->i", sc.triangle_normal, sc.patch_normal[sc.triangle_patch])
    assert cos[sc.triangle_material == 1].min() < 0.99          # the clusters are curved
    assert np.bincount(sc.triangle_patch)[sphere].mean() > 4
    r = pipeline.make_renderer(sc, RenderSettings(seed=1, directions_per_step=4))
    s = r.solver
    w = s.area[sphere, None] / s.area[sphere].sum()
    batches = []
    for b in range(13):
        acc = np.zeros(3)
        for _ in range(60):
            s.step()
            acc += (s.iterate_radiance(s.normal)[sphere] * w).sum(axis=0)
        if b:
            batches.append(acc / 60)
    assert_converged(np.array(batches), sc.analytic_radiance, max_se=0.01)
    r.tracer.close()


@pytest.mark.parametrize("target", [600])
def test_tessellated_box_renders_like_the_box(target):
    """Grouped triangles give the image of the same box cut into patches directly: the
    two images' difference is no larger than two seeds' difference of either."""
    settings = dict(resolve_samples=2)
    plain = pipeline.prepare(scenes.cornell(resolution=(32, 32)), patches=target)
    fine = pipeline.prepare(tessellate(scenes.cornell(resolution=(32, 32)), 8000), patches=target)
    imgs = {}
    for name, sc in (("plain", plain), ("fine", fine)):
        for seed in (1, 2):
            imgs[name, seed] = pipeline.render(sc, RenderSettings(seed=seed, **settings), iterations=100).image
    mean = imgs["plain", 1].mean()
    rms = lambda a, b: np.sqrt(((a - b) ** 2).mean()) / mean       # noqa: E731
    noise = max(rms(imgs["plain", 1], imgs["plain", 2]), rms(imgs["fine", 1], imgs["fine", 2]))
    between = rms(0.5 * (imgs["plain", 1] + imgs["plain", 2]), 0.5 * (imgs["fine", 1] + imgs["fine", 2]))
    assert between < noise, (between, noise)


def test_half_a_million_triangles_set_up_in_under_a_kilobyte_each():
    """Issue 8's memory bound, tightened by issue 61's: laying out, tracer, first shot, solver,
    one iteration, an image pass and the image of a 500k-triangle box stay under 650 B per
    triangle of NumPy memory (traced: Embree's BVH aside; the input scene, the export's, aside;
    790 B while the scene held its corners and side normals, its welded ids in 64 bits and the
    cluster fits an array beside the projection's), and the patch count follows the target, not the
    triangles (the lamps' splits, :func:`~raybundle.app.pipeline.prepare`'s last step, add at
    most ``MAX_ADDED`` of it). `make bench-scale` measures the whole command up to 4M triangles."""
    import tracemalloc

    from raybundle.patches.lit_splits import MAX_ADDED

    sc = tessellate(scenes.cornell(resolution=(16, 16)), 500_000)
    assert len(sc.triangles) > 495_000
    tracemalloc.start()
    try:
        base = tracemalloc.get_traced_memory()[0]
        made = make_patches(sc, patches=4000)                  # pipeline.prepare, step by step
        laid = pipeline.split_lit_unevenly(sc, made)
        n_made = made.n_patches
        del made                                               # as prepare drops it
        r = pipeline.make_renderer(laid, RenderSettings(seed=0))
        r.solver.step()
        r.image_pass()
        assert np.isfinite(r.image()).all()
        peak = tracemalloc.get_traced_memory()[1] - base
    finally:
        tracemalloc.stop()
    r.tracer.close()
    assert 3500 < n_made < 4500
    assert n_made <= laid.n_patches <= (1 + MAX_ADDED) * n_made
    assert r.solver.bundle_resolution < 200
    assert peak < 650 * len(sc.triangles), peak / len(sc.triangles)


def room_with_a_deep_window(depth=0.6):
    """A 2 m clay room (two-sided faces) lit only by a constant world through a 0.8 m window
    in a wall ``depth`` thick, every face cut into small triangles (as a modelled room's
    frames and reveals are), the camera inside looking away from the window."""
    from raybundle.scene.builtin import _mesh
    from raybundle.scene.camera import Camera

    def quad(*corners):
        return (np.array(corners, float), 0)

    lo, hi, x0, x1 = 0.6, 1.4, 2.0, 2.0 + depth
    quads = [quad([0, 0, 0], [2, 0, 0], [2, 2, 0], [0, 2, 0]), quad([0, 0, 2], [2, 0, 2], [2, 2, 2], [0, 2, 2]),
             quad([0, 0, 0], [0, 2, 0], [0, 2, 2], [0, 0, 2]), quad([0, 0, 0], [2, 0, 0], [2, 0, 2], [0, 0, 2]),
             quad([0, 2, 0], [2, 2, 0], [2, 2, 2], [0, 2, 2])]
    for x in (x0, x1):          # the wall's two faces, the window cut out
        quads += [quad([x, 0, 0], [x, 2, 0], [x, 2, lo], [x, 0, lo]), quad([x, 0, hi], [x, 2, hi], [x, 2, 2], [x, 0, 2]),
                  quad([x, 0, lo], [x, lo, lo], [x, lo, hi], [x, 0, hi]), quad([x, hi, lo], [x, 2, lo], [x, 2, hi], [x, hi, hi])]
    quads += [quad([x0, lo, lo], [x1, lo, lo], [x1, hi, lo], [x0, hi, lo]),      # the reveal: sill, head, jambs
              quad([x0, lo, hi], [x1, lo, hi], [x1, hi, hi], [x0, hi, hi]),
              quad([x0, lo, lo], [x1, lo, lo], [x1, lo, hi], [x0, lo, hi]),
              quad([x0, hi, lo], [x1, hi, lo], [x1, hi, hi], [x0, hi, hi])]
    quads.append(quad([x0, 0, 2], [x1, 0, 2], [x1, 2, 2], [x0, 2, 2]))
    v, t, m = _mesh(quads)
    camera = Camera.look_at([1.9, 1.0, 1.0], [0.0, 1.0, 0.8], [0, 0, 1], 20, 36, (48, 36))
    clay = MaterialTable.from_list([dict(name="clay", diffuse=(0.8, 0.8, 0.8))])
    sc = build_scene(v, t, m, clay, camera=camera, two_sided=True, environment=np.ones(3))
    return tessellate(sc, 4000)


def test_a_window_reveal_thinner_than_a_patch_lets_no_sky_into_the_room():
    """Patches a metre wide (40) in the room of :func:`room_with_a_deep_window`: clusters that
    averaged the reveal's facets out in the sky with those inside sent the sky's light on into
    the room: +43% against the same room at 400 patches (and that one +11% over the path
    tracer; measured, two seeds).  Kept apart by how much of the world they see
    (:func:`~raybundle.patches.clusters.world_view_classes`), the coarse room is +7.5% (the bias of
    metre-wide patches that remains: a floor patch holding the sky's spot and its shade), and
    the fine one within 4% of the path tracer."""
    sc = room_with_a_deep_window()
    means = {}
    for patches in (40, 400):
        img = pipeline.render(pipeline.prepare(sc, patches=patches), RenderSettings(seed=1), iterations=200).image
        means[patches] = img[..., :3].mean()
    assert abs(means[40] / means[400] - 1) < 0.2, means


def _floor_with_details(details=300):
    """A 4 m x 4 m floor (emitting, so the scene has light) under ``details`` tiny triangles of
    as many materials: each its own cluster, whatever the patch size."""
    v, t = quad(0, 4, 0, 4, 0.0)
    verts, tris = [np.asarray(v, float)], [np.asarray(t)]
    rng = np.random.default_rng(3)
    for k in range(details):
        c = np.array([*rng.uniform(0.5, 3.5, 2), rng.uniform(0.2, 1.0)])
        tris.append(np.array([[0, 1, 2]]) + sum(len(x) for x in verts))
        verts.append(c + np.array([[0, 0, 0], [0.02, 0, 0], [0, 0.02, 0.01]]))
    materials = MaterialTable.from_list([dict(name=f"m{k}", diffuse=(0.5,) * 3, emission=(float(k == 0),) * 3)
                                         for k in range(details + 1)])
    return build_scene(np.vstack(verts), np.vstack(tris), np.array([0, 0, *range(1, details + 1)]), materials)


def test_details_that_outnumber_the_patch_count_leave_the_floor_its_patches():
    """300 tiny triangles of 300 materials make 300 clusters at any patch size, three times
    a target of 100: a size chosen for the count alone made the floor one patch per triangle
    (the interior bench's bathrooms, 7-9 m patches).  The patch size is at most twice the one
    that tiles the reflecting area with the count, so the floor keeps at least a quarter of it."""
    from raybundle.patches.clusters import SURFACE_SHARE

    sc = _floor_with_details()
    p = make_patches(sc, patches=100)
    floor = np.unique(p.triangle_patch[p.triangle_material == 0])
    assert len(floor) >= 100 / SURFACE_SHARE ** 2, len(floor)



def test_details_of_one_material_are_grouped_at_the_size_the_count_allows():
    """2,000 tiny facets of one material over a 4 m x 4 m floor: at the floor's capped patch size
    (:func:`~raybundle.patches.clusters.surface_size`) their clusters (grid cell, cube face, slab)
    alone outnumber a target of 100 several times.  Details are grouped at the size whose count
    comes nearest the target instead, so the layout keeps about the target, and the floor its
    share of it."""
    from raybundle.patches.clusters import SURFACE_SHARE

    v, t = quad(0, 4, 0, 4, 0.0)
    rng = np.random.default_rng(5)
    centre = np.column_stack([rng.uniform(0.5, 3.5, (2000, 2)), rng.uniform(0.2, 1.0, 2000)])
    corners = centre[:, None, :] + rng.normal(0.0, 0.01, (2000, 3, 3))
    detail = (corners.reshape(-1, 3), np.arange(6000).reshape(-1, 3))
    sc = scene_of([(v, t)], detail=detail)
    p = make_patches(sc, patches=100)
    floor = np.unique(p.triangle_patch[np.abs(p.triangle_corners[:, :, 2]).max(axis=1) < 1e-12])
    assert len(floor) >= 100 / SURFACE_SHARE ** 2, len(floor)
    assert p.n_patches < 2.5 * 100, p.n_patches


def test_a_tiled_floor_under_a_low_cabinet_is_not_one_patch_with_the_floor_beside_it():
    """A floor of small tiles with a cabinet on short legs over it (its base 2 cm up, a fifth of
    a patch): the tiles under the base see its underside over most of their hemisphere and
    receive little, those beside it see the room.  A cluster holding both gives the lit ones
    the dark ones' average: the rooms of the interior bench read 2-4% dark where the camera
    looks.  No floor patch mixes tiles under the base with tiles beside it (a tile's centre
    decides).  With gaps counted up to 5% of a patch, not a quarter, 7 of them did."""
    from raybundle.patches.clusters import patch_sizes

    floor = tessellate(scene_of([quad(0, 1, 0, 1, 0.0)]), 8000)
    base = [quad(0.3, 0.7, 0.3, 0.7, 0.02, up=False), quad(0.3, 0.7, 0.3, 0.7, 0.3)]
    sc = scene_of([(floor.vertices, floor.triangles)] + base)
    h = patch_sizes(sc, 100)[0]
    assert 0.08 < h < 0.4          # the base's 2 cm: over a quarter of h's 5%, under a quarter of h
    p = make_patches(sc, patches=100)
    on_floor = np.abs(p.triangle_corners[:, :, 2]).max(axis=1) < 1e-12
    c = p.triangle_corners[on_floor].mean(axis=1)
    under = (c[:, 0] > 0.3) & (c[:, 0] < 0.7) & (c[:, 1] > 0.3) & (c[:, 1] < 0.7)
    patch = p.triangle_patch[on_floor]
    mixed = np.intersect1d(patch[under], patch[~under])
    assert len(mixed) == 0, (len(mixed), h)


def test_the_floor_either_side_of_a_bar_just_over_it_is_not_one_patch():
    """A bar lying 2 mm over a finely meshed floor, across a cell of the grouping's grid: the
    floor under the bar is in a gap and groups apart, and the floor on either side of it is in
    two pieces that share no corner.  One lit through a window and one in the room's shade
    (the interior bench's bathroom, a wall behind a window's frame), one cluster for both gave
    the shaded side the mean of both.  No floor patch holds triangles on both sides of the bar
    (a triangle's centre decides); before the pieces were kept apart, 8 did."""
    from raybundle.patches.clusters import patch_sizes

    floor = tessellate(scene_of([quad(0, 1, 0, 1, 0.0)]), 8000)
    x0, x1, z0, z1 = 0.44, 0.48, 0.002, 0.04
    v = [[x0, 0, z0], [x1, 0, z0], [x1, 1, z0], [x0, 1, z0], [x0, 0, z1], [x1, 0, z1], [x1, 1, z1], [x0, 1, z1]]
    t = [[0, 2, 1], [0, 3, 2], [4, 5, 6], [4, 6, 7], [0, 1, 5], [0, 5, 4], [1, 2, 6], [1, 6, 5], [2, 3, 7],
         [2, 7, 6], [3, 0, 4], [3, 4, 7]]
    sc = scene_of([(floor.vertices, floor.triangles), (v, t)])
    h = patch_sizes(sc, 100)[0]
    assert int(x0 / h) == int(x1 / h)              # the bar lies inside a column of cells
    p = make_patches(sc, patches=100)
    on_floor = np.abs(p.triangle_corners[:, :, 2]).max(axis=1) < 1e-12
    x = p.triangle_corners[on_floor].mean(axis=1)[:, 0]
    patch = p.triangle_patch[on_floor]
    assert len(np.intersect1d(patch[x < x0], patch[x > x1])) == 0


def test_the_reconstruction_keeps_no_per_corner_floats():
    """Memory grows with the scene, not with a pass's convenience: a reconstruction over a
    clustered scene, after one averaged and one projected read, keeps under 64 bytes per tside
    beyond the scene's own arrays (the welded ids are the scene's).  Per-corner float weights
    kept for the reads, (TS, 3) each, and 64-bit corner indices made 121."""
    import tracemalloc

    sc = make_patches(tessellate(scenes.cornell(resolution=(16, 16)), 100_000), patches=500)
    area = sc.triangle_area[sc.tside_triangle]
    for name in ("smooth_vertex_ids", "tside_side", "triangle_corners", "tside_triangle", "tside_normal"):
        getattr(sc, name)
    values = np.ones((sc.n_sides, 3))
    tracemalloc.start()
    try:
        base = tracemalloc.get_traced_memory()[0]
        rec = LinearReconstruction(sc, area)
        rec.averaged(values)
        rec.projected(values)
        kept = tracemalloc.get_traced_memory()[0] - base
    finally:
        tracemalloc.stop()
    assert rec._fit is not None
    assert kept < 64 * len(area), kept / len(area)


def test_welding_peaks_under_130_bytes_a_tside():
    """Memory grows with the scene, not with a pass's convenience: the welding of a clustered
    box of 200k triangles (:attr:`~raybundle.scene.model.PatchScene.smooth_vertex_ids`, its
    normals and areas made first) peaks under 130 bytes a tside.  Positions, corner tags and
    corner classes in 32 bits, normal ids by components, no (K, 3) copies of the normals across
    edges and fresh keys sorted in place; 191 bytes before."""
    import tracemalloc

    sc = make_patches(tessellate(scenes.cornell(resolution=(16, 16)), 200_000), patches=1000)
    for name in ("tside_triangle", "tside_normal", "bounding_sphere"):
        getattr(sc, name)
    tracemalloc.start()
    try:
        base = tracemalloc.get_traced_memory()[0]
        ids = sc.smooth_vertex_ids
        peak = tracemalloc.get_traced_memory()[1] - base
    finally:
        tracemalloc.stop()
    assert sc.triangle_corner_tag is not None and ids.shape == (len(sc.tside_triangle), 3)
    assert peak < 130 * len(sc.tside_triangle), peak / len(sc.tside_triangle)


@pytest.mark.parametrize("d, patches", [(0.03, 200), (0.05, 100)])
def test_a_side_inside_a_solid_is_not_one_patch_with_a_side_facing_the_room(d, patches):
    """A two-sided slab ``d`` thick whose bottom is turned in (its front faces up, into the slab,
    like its top's): the bottom's and the top's small triangles lie in one plane's slab of the
    grid, facing the same way, further apart than a gap (a quarter of a patch) and closer than
    half a patch.  A cluster holding both gives the bottom's inner side, enclosed, the
    irradiance of the top's side in the room, and the light it sends into the slab is lost to
    the room (a window frame's box held 1.4% of a room's reflected power so).  No patch holds
    triangles of both (:func:`enclosure_classes`; the layout before it mixed 144 and 64)."""
    from raybundle.patches.clusters import patch_sizes

    quads = [quad(0, 1, 0, 1, 0.0), quad(0, 1, 0, 1, d)]                 # both facing up: the bottom turned in
    for x0, x1, y0, y1, n in ((0, 0, 0, 1, 0), (1, 1, 0, 1, 1), (0, 1, 0, 0, 2), (0, 1, 1, 1, 3)):
        v = [[x0, y0, 0], [x1, y1, 0], [x1, y1, d], [x0, y0, d]]
        quads.append((v, [[0, 1, 2], [0, 2, 3]] if n in (1, 2) else [[0, 2, 1], [0, 3, 2]]))
    base = scene_of(quads)
    sc = tessellate(replace(base, triangle_two_sided=np.ones(len(base.triangles), bool)), 6000)
    h = patch_sizes(sc, patches)[0]
    assert h / 4 < d < h / 2
    p = make_patches(sc, patches=patches)
    z = p.triangle_corners[:, :, 2].mean(axis=1)
    flat = np.abs(p.triangle_normal[:, 2]) > 0.99
    bottom, top = flat & (z < 0.5 * d), flat & (z > 0.5 * d)
    mixed = np.intersect1d(p.triangle_patch[bottom], p.triangle_patch[top])
    assert len(mixed) == 0, (len(mixed), h)
