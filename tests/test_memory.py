"""Memory that grows with the scene, not with a step's convenience: arrays gathered where read,
freed memory given back between a run's steps."""
import numpy as np

from raybundle.app import pipeline
from raybundle.imaging.settings import RenderSettings
from raybundle.scene import builtin as scenes
from raybundle.util.arrays import GatheredRows
from raybundle.util.memory import release_freed


def test_gathered_rows_read_as_the_array_they_stand_for():
    """Any key, whole-array steps and operators give the numbers of ``values[index]``; with
    ``flip_from`` the rows from there on come out negated."""
    rng = np.random.default_rng(1)
    v = rng.random((7, 3))
    t = rng.integers(0, 7, (5, 3))
    g, a = GatheredRows(v, t), v[t]
    for key in (2, [4, 0], (slice(None), 1), ([1, 3], [2, 0]), (3, 2, 1), (a[:, 0, 0] > 0.5,), (Ellipsis, 0)):
        np.testing.assert_array_equal(g[key], a[key])
    assert g.shape == a.shape and len(g) == 5 and g.ndim == 3
    for got, want in ((np.asarray(g), a), (g.mean(axis=1), a.mean(axis=1)), (g.min(axis=1), a.min(axis=1)),
                      (g > 0.5, a > 0.5), (1 - g, 1 - a), (-g, -a), (np.roll(g, 1, axis=1), np.roll(a, 1, axis=1))):
        np.testing.assert_array_equal(got, want)
    n = GatheredRows(v, np.array([0, 3, 1, 1, 6]), flip_from=3)
    b = v[[0, 3, 1, 1, 6]] * np.array([1, 1, 1, -1, -1.0])[:, None]
    for key in ([4, 0], slice(1, None), (slice(None), 2), 3, (b[:, 0] > 0,)):
        np.testing.assert_array_equal(n[key], b[key])
    np.testing.assert_array_equal(np.asarray(n), b)


def test_a_running_scene_holds_no_corners_or_side_normals_and_32_bit_welded_ids():
    """Through set-up, iterations and an image pass, a laid-out scene keeps no (T, 3, 3)
    corners and no (TS, 3) side normals (their numbers as the arrays gave them), and its
    welded vertex ids and contact tags take 32 bits."""
    sc = pipeline.prepare(scenes.cornell(resolution=(24, 24)), 600)
    r = pipeline.make_renderer(sc, RenderSettings(seed=0))
    r.step()
    r.image_pass()
    n_t, n_ts = len(sc.triangles), len(sc.tside_triangle)
    held = [k for k, x in vars(sc).items() if isinstance(x, np.ndarray) and x.dtype == float
            and x.shape in ((n_t, 3, 3), (n_ts, 3)) and k not in ("vertices", "triangle_normal")]
    assert held == []
    np.testing.assert_array_equal(np.asarray(sc.triangle_corners), sc.vertices[sc.triangles])
    sign = np.where(np.arange(n_ts) < n_t, 1.0, -1.0)[:, None]
    np.testing.assert_array_equal(np.asarray(sc.tside_normal), sc.triangle_normal[sc.tside_triangle] * sign)
    assert sc.smooth_vertex_ids.dtype == np.int32
    assert sc.triangle_corner_tag is None or sc.triangle_corner_tag.dtype == np.int32
    r.tracer.close()


def test_freed_memory_goes_back_to_the_system():
    """Small arrays freed between others still held stay resident until :func:`release_freed`
    returns their pages (glibc; elsewhere it says it could not)."""
    def resident():
        with open("/proc/self/statm") as f:
            return int(f.read().split()[1]) * 4096

    if not release_freed():
        return
    parts = [np.ones(4096) for _ in range(6000)]          # 32 KB each: in the heap, 192 MB
    kept = parts[::10]                                   # the freed nine tenths lie between them
    del parts
    before = resident()
    assert release_freed()
    assert before - resident() > 100 * 2 ** 20
    del kept


def test_the_bundles_sky_guide_keeps_rows_for_the_sides_the_sky_reached():
    """A room lit through a deep window: the bundles' sky sums by guide cell take a row for each
    side a line from the sky reached (a room's inner sides mostly see none straight), not
    (sides, cells)."""
    from test_clusters import room_with_a_deep_window
    from test_world import sky_and_ground

    from raybundle.scene.build import attach_world
    from raybundle.scene.world import World

    sc = pipeline.prepare(attach_world(room_with_a_deep_window(), World(sky_and_ground())), 400)
    r = pipeline.make_renderer(sc, RenderSettings(seed=0))
    for _ in range(4):
        r.step()
    guide = r.solver.world_guide
    reached = np.nonzero(guide.row >= 0)[0]
    assert 0 < guide.used == len(reached) < sc.n_sides and len(guide.sums) <= 1.5 * guide.used
    assert (guide.sums[guide.row[reached]].sum(axis=1) > 0).all()
    r.tracer.close()


def test_the_final_images_vertex_values_take_single_precision():
    """The vertex values an image reads at its hits (the final gather's, the image's own
    reconstruction and the caustic shot's averages) are kept in 32 bits: 12 bytes a vertex
    each, where they took 24 (a furnished room's final image held three or four arrays of
    its ~1M welded vertices at once); they are the double projection's values, rounded."""
    from raybundle.imaging.gather import FinalGather

    sc = pipeline.prepare(scenes.load_scene("cornell-glossy"), 300)
    r = pipeline.make_renderer(sc, RenderSettings(seed=0))
    for _ in range(3):
        r.step()
    solver = r.solver
    e = solver.image_incoming(caustic=True, world=True)
    final = FinalGather(solver, image_values=(e, None))
    exact = solver.reconstruction.smooth_and_sharp(e, None)
    for vert in (final.vert, final.image_vert) + ((final.vert_caustic,) if final.vert_caustic is not None else ()):
        assert vert.dtype == np.float32 and vert.nbytes == 12 * solver.reconstruction.n_vertices
    np.testing.assert_allclose(final.image_vert, exact, rtol=1e-6, atol=1e-6 * exact.max())
    r.tracer.close()


def test_the_final_images_projection_makes_its_32_bit_values_in_one_array():
    """The final image's vertex values (three sets of 3 columns, two with a sharp part, in one
    projection: :meth:`~raybundle.patches.reconstruction.LinearReconstruction.smooth_and_sharp_many`)
    are made in one (V, 9) float32 array whose columns the sets are, the cluster fits summing into
    it: on a tessellated sphere in a room (cluster fits on 18,657 vertices, a few projected ones),
    the call peaks at 53 bytes a vertex (the sharp part's average added a column at a time; 98
    with its whole 64-bit (V, 3)), where a 64-bit (V, 9) result and a 32-bit copy of each set took
    158.  The values are the 64-bit projection's, rounded."""
    import tracemalloc

    from test_clusters import furnace_with_sphere

    sc = pipeline.prepare(furnace_with_sphere(96, 192), patches=400)
    s = pipeline.make_solver(sc, RenderSettings(seed=1))
    s.tracer.close()
    rec = s.reconstruction
    assert rec._fit is not None and len(rec._p_vertices)
    rng = np.random.default_rng(7)
    a, b, c, sharp = rng.normal(1.0, 1.0, (4, sc.n_sides, 3))
    pairs = [(a, np.abs(sharp)), (b, np.abs(sharp)), (c, None)]
    rec.smooth_and_sharp_many(pairs, np.float32)                      # kernels compiled, caches made
    tracemalloc.start()
    try:
        start = tracemalloc.get_traced_memory()[0]
        got = rec.smooth_and_sharp_many(pairs, np.float32)
        peak = tracemalloc.get_traced_memory()[1] - start
    finally:
        tracemalloc.stop()
    assert peak < 64 * rec.n_vertices, peak / rec.n_vertices
    assert all(x.dtype == np.float32 and x.base is got[0].base for x in got)
    for x, y in zip(got, rec.smooth_and_sharp_many(pairs)):
        np.testing.assert_allclose(x, y, rtol=1e-6, atol=1e-6 * y.max())


def test_the_cluster_fits_set_up_peaks_under_72_bytes_a_triangle_side():
    """The reconstruction's set-up on a finely tessellated sphere in a room (160k triangle sides,
    read through cluster fits) peaks 67 bytes a triangle side above what it keeps: the (vertex,
    side) keys of its corners and their sort's scratch, with the sides' ids in 32 bits and no
    inverse made for the distinct keys (a first-of-each pass needs none), where it peaked at 79."""
    import tracemalloc

    from test_clusters import furnace_with_sphere

    from raybundle.patches.clusters import make_patches
    from raybundle.patches.reconstruction import LinearReconstruction

    sc = make_patches(furnace_with_sphere(200, 400), patches=400)
    area = sc.triangle_area[sc.tside_triangle]
    LinearReconstruction(sc, area)                                   # kernels compiled
    tracemalloc.start()
    try:
        rec = LinearReconstruction(sc, area)
        kept, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert rec._fit is not None
    assert peak - kept < 72 * len(sc.tside_side), (peak - kept) / len(sc.tside_side)


def test_the_contact_lines_boxes_are_held_once_for_every_axis():
    """The contact lines' search keeps every triangle's box once, per axis and contiguous, and
    its sweeps along the three axes read those (a room's walls, floor and ceiling take all
    three): 197 bytes a triangle at its peak on a room holding a tessellated sphere, where a
    copy of the boxes per axis took 341 (the bathroom's contact cuts peaked on them)."""
    import tracemalloc

    from raybundle.patches.contacts import contact_segments, welded_vertices
    from test_clusters import furnace_with_sphere

    sc = furnace_with_sphere(128, 256)
    walls = np.nonzero(sc.triangle_material == 0)[0]
    welded_vertices(sc)                                        # the scene's caches made
    assert len(contact_segments(sc, walls, 0.01)) == 6
    tracemalloc.start()
    try:
        start = tracemalloc.get_traced_memory()[0]
        contact_segments(sc, walls, 0.01)
        peak = tracemalloc.get_traced_memory()[1] - start
    finally:
        tracemalloc.stop()
    assert peak < 240 * len(sc.triangles), peak / len(sc.triangles)


def test_the_final_gathers_rays_go_32768_at_a_time():
    """The final gather traces its rays in pieces of 32,768 (``chunk_rays``): 400,000 rays from
    100,000 points of a glossy Cornell box peak at 16 MB above the call's start, where pieces of
    65,536 rays peaked at 26 MB and of 262,144 at 85 MB (in the bathroom's own materials, its
    final image's highest point), in the same time."""
    import tracemalloc

    from raybundle.imaging.gather import FinalGather

    sc = pipeline.prepare(scenes.load_scene("cornell-glossy"), 300)
    s = pipeline.make_solver(sc, RenderSettings(seed=0))
    s.step()
    rng = np.random.default_rng(1)
    tside = rng.integers(0, len(sc.tside_side), 100_000)
    bary = rng.dirichlet(np.ones(3), len(tside))
    corners = sc.triangle_corners[sc.tside_triangle[tside]]
    points = np.einsum("nk,nkc->nc", bary, corners)
    final = FinalGather(s)
    final.irradiance(points[:1000], sc.tside_normal[tside[:1000]], 4, rng, at=(tside[:1000], bary[:1000]))
    tracemalloc.start()
    try:
        start = tracemalloc.get_traced_memory()[0]
        final.irradiance(points, sc.tside_normal[tside], 4, rng, at=(tside, bary))
        peak = tracemalloc.get_traced_memory()[1] - start
    finally:
        tracemalloc.stop()
        s.tracer.close()
    assert peak < 20 * 2 ** 20, peak / 2 ** 20


def test_a_textures_coarser_levels_are_dropped_after_its_means_and_its_faces_take_32_bits():
    """A map's pyramid (its levels of 2 x 2 means) serves the set-up's patch means alone: none
    is held after them (a furnished room held 40 MB of them through its render), and the means
    come out the same when the levels are made again.  The input faces' corners and UVs take 32
    bits (the add-on gives the textures and the shading normals one array of corners; Blender
    keeps UVs in 32 bits), and so do their maps' numbers."""
    from raybundle.scene.build import build_scene
    from raybundle.scene.materials import MaterialTable
    from raybundle.scene.model import PointLights
    from raybundle.scene.textures import SurfaceTexture

    v = np.array([[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]], float)
    t = np.array([[0, 1, 2], [0, 2, 3]])
    checker = np.where((np.add.outer(np.arange(512), np.arange(512)) // 8 % 2)[..., None], 0.4, 1.6) * np.ones(3)
    tex = SurfaceTexture([checker.astype(np.float32)], np.zeros(2, int), v[t], (v[t][..., :2] + 1) / 2)
    scene = build_scene(v, t, np.zeros(2, int), MaterialTable.from_list([dict(name="floor", diffuse=(0.5,) * 3)]),
                        texture=tex, point_lights=PointLights([[0.0, 0.0, 1.0]], [[1.0, 1.0, 1.0]]))
    laid = pipeline.prepare(scene, patches=40)
    means = laid.texture.side_means(laid, seed=0)
    assert laid.texture._pyramids == {}
    assert laid.texture.face_corners.dtype == laid.texture.face_uv.dtype == np.float32
    assert laid.texture.face_image.dtype == laid.texture.face_alpha.dtype == np.int32
    np.testing.assert_array_equal(laid.texture.side_means(laid, seed=0), means)
    assert laid.texture._pyramids == {}


def test_the_vertex_averages_take_no_per_corner_arrays_and_the_glossy_paths_keep_32_bits():
    """A solution's vertex averages (what the glossy eye paths read at their hits) are made
    without (TS, 3) arrays of weights or a 64-bit copy of the corners' ids (a furnished room's
    first average took 60 MB beyond its result), and the glossy eye paths keep them in 32 bits."""
    import tracemalloc

    sc = pipeline.prepare(scenes.load_scene("cornell-glossy"), 4000)
    r = pipeline.make_renderer(sc, RenderSettings(seed=0))
    r.step()
    rec, e = r.solver.reconstruction, r.solver.received()
    tracemalloc.start()
    try:
        out = rec.averaged(e)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    per_corner = 3 * 8 * len(rec.ids)
    # the result, the weights' sums and their guard (V,) each, a column of ones per side
    assert peak < out.nbytes + 2 * 8 * rec.n_vertices + 8 * sc.n_sides + per_corner / 4, (peak, per_corner)
    r.image_pass()
    vert = r.glossy_paths._vert[1]
    assert vert.dtype == np.float32
    np.testing.assert_allclose(vert, rec.averaged(r.solver.received()), rtol=1e-6)
    r.tracer.close()


def test_a_32_bit_vertex_average_keeps_one_64_bit_column_beside_it():
    """An average kept in 32 bits (the caustic shot's at the points the eye sees in a mirror, a
    sharp part added into the final image's projection, the glossy paths') is summed in 64 bits a
    column at a time: its peak is the result, one (V,) float64 and one column of the side values
    (33 bytes a vertex on the glossy Cornell box, 3 columns), where a 64-bit (V, 3), its 32-bit
    copy and the divisor's guard took 57; the same values as the 64-bit average, rounded."""
    import tracemalloc

    sc = pipeline.prepare(scenes.load_scene("cornell-glossy"), 4000)
    r = pipeline.make_renderer(sc, RenderSettings(seed=0))
    r.step()
    rec, e = r.solver.reconstruction, r.solver.received()
    exact = rec.averaged(e)                                   # kernels compiled, caches made
    tracemalloc.start()
    try:
        start = tracemalloc.get_traced_memory()[0]
        out = rec.averaged(e, dtype=np.float32)
        peak = tracemalloc.get_traced_memory()[1] - start
    finally:
        tracemalloc.stop()
    assert out.dtype == np.float32 and out.shape == exact.shape
    assert peak < 20 * rec.n_vertices + 10 * sc.n_sides, peak / rec.n_vertices
    np.testing.assert_array_equal(out, exact.astype(np.float32))
    r.tracer.close()


def test_the_first_shots_sums_per_triangle_side_take_32_bits():
    """The first shot's sums, counts, shares and rows per receiving triangle side, held through
    the render (a furnished room's 70 MB in 64 bits), take 32 bits; its sides' E is summed in 64
    (``test_lights``: E as the pooled sums form it, to 1e-12)."""
    sc = pipeline.prepare(scenes.load_scene("cornell-glossy"), 600)
    r = pipeline.make_renderer(sc, RenderSettings(seed=0))
    r.step()
    fs = r.solver.first_shot
    assert len(fs.receiving_tsides) > 0 and len(fs._d_sum) > 0
    assert {a.dtype for a in (fs._e_sum, fs._d_sum, fs._count, fs._share_in_side)} == {np.dtype(np.float32)}
    assert {a.dtype for a in (fs.receiving_tsides, fs._d_row)} == {np.dtype(np.int32)}
    assert fs.E.dtype == np.float64
    r.tracer.close()


def test_a_float_map_in_half_precision_reads_as_the_float_map_to_its_precision():
    """A float map that half precision holds (finite, below float16's largest) is kept in half the
    memory and reads as the float32 map to 2^-11 of its values, at level 0 (bilinear and closest)
    and on the pyramid's levels (made in float32); one it does not hold stays float32."""
    from raybundle.scene.textures import SurfaceTexture, half_precision

    rng = np.random.default_rng(2)
    im = (rng.random((64, 48, 3)) * 3).astype(np.float32)
    corners = np.array([[[0, 0, 0], [1, 0, 0], [0, 1, 0]]], float)
    uv = np.array([[[0, 0], [1, 0], [0, 1]]], float)
    half = half_precision(im)
    assert half.dtype == np.float16 and half.nbytes == im.nbytes // 2
    at = rng.random((500, 2)) * 2 - 0.5
    for closest in (False, True):
        full = SurfaceTexture([im], [0], corners, uv, closest=[closest])
        small = SurfaceTexture([half], [0], corners, uv, closest=[closest])
        assert small.images[0].dtype == np.float16
        for level in (0, 1, 3):
            want, got = full.lookup(0, at, level), small.lookup(0, at, level)
            assert got.dtype != np.float16
            np.testing.assert_allclose(got, want, rtol=2 ** -11, atol=0)
    assert half_precision(np.array([[[1.0, 7e4, 0.0]]], np.float32)).dtype == np.float32
    assert half_precision(np.array([[[1.0, np.inf, 0.0]]], np.float32)).dtype == np.float32
