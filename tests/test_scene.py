import numpy as np
import pytest

from raybundle.patches.layout import subdivide
from raybundle.scene import builtin as scenes
from raybundle.scene.build import build_scene
from raybundle.scene.materials import MaterialTable
from raybundle.scene.model import PointLights, SceneError
from raybundle.scene.npz import load_npz

LIGHT = MaterialTable.from_list([dict(name="white", diffuse=(0.5, 0.5, 0.5)), dict(name="lamp", emission=(1, 1, 1))])
QUAD_V = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], float)
QUAD_T = np.array([[0, 1, 2], [0, 2, 3]])


def test_cornell_geometry_and_orientation():
    sc = scenes.cornell()
    assert sc.n_patches == 42          # (9 room quads + 2 closed blocks x 6 quads) x 2 triangles
    lo, hi = sc.vertices.min(axis=0), sc.vertices.max(axis=0)
    assert np.allclose(lo, [-0.556, 0, 0], atol=1e-9) and np.allclose(hi, [0, 0.5592, 0.5488], atol=1e-9)
    light = sc.materials.names.index("light")
    assert np.allclose(sc.triangle_normal[sc.triangle_material == light], [0, 0, -1])
    red = sc.materials.names.index("red")
    assert np.all(sc.patch_centroid[sc.patch_material == red][:, 0] < -0.5)   # red on the left (-x)
    # walls face the interior
    inside = np.array([-0.278, 0.28, 0.27])
    walls = np.isin(sc.triangle_material, [1, 2])
    to_in = inside - sc.triangle_corners[walls].mean(axis=1)
    assert np.all(np.einsum("ij,ij->i", sc.triangle_normal[walls], to_in) > 0)


def test_subdivide_preserves_area_and_hits_target():
    sc = scenes.cornell()
    for target in (500, 4000):
        sub = subdivide(sc, patches=target)
        assert abs(sub.triangle_area.sum() - sc.triangle_area.sum()) < 1e-9
        assert 0.7 * target < sub.n_patches < 1.3 * target
        assert np.allclose(sub.patch_normal[sub.triangle_patch], sc.triangle_normal[sub.triangle_source])
    sub = subdivide(sc, max_edge=0.05)
    e = np.linalg.norm(sub.triangle_corners - np.roll(sub.triangle_corners, 1, axis=1), axis=2).max(axis=1)
    reflects = sc.materials.reflects[sub.triangle_material]
    assert e[reflects].max() <= 0.05 + 1e-9
    # the lamp reflects nothing: it stays whole (its two triangles)
    assert (~reflects).sum() == (~sc.materials.reflects[sc.triangle_material]).sum() == 2


def test_npz_round_trip(tmp_path):
    from dataclasses import replace
    sc = subdivide(scenes.furnace(glossy=True), patches=300)
    sc.camera = replace(sc.camera, pixel_filter="GAUSSIAN", filter_width=2.5)
    sc.point_lights = PointLights(np.array([[1.0, 1, 1]]), np.array([[2.0, 2, 2]]))
    path = tmp_path / "s.npz"
    sc.save_npz(path)
    back = load_npz(path)
    assert np.array_equal(back.triangles, sc.triangles) and np.allclose(back.vertices, sc.vertices)
    assert np.array_equal(back.triangle_patch, sc.triangle_patch)
    assert back.materials.names == sc.materials.names
    assert np.allclose(back.materials.emission_albedo_complement, sc.materials.emission_albedo_complement)
    assert np.allclose(back.camera.matrix_world, sc.camera.matrix_world) and back.camera.fx == sc.camera.fx
    assert np.allclose(back.analytic_radiance, sc.analytic_radiance)
    assert np.allclose(back.point_lights.intensity, 2.0)
    assert (back.camera.pixel_filter, back.camera.filter_width) == ("GAUSSIAN", 2.5)


def test_nan_vertices_are_an_error():
    v = QUAD_V.copy()
    v[2, 1] = np.nan
    with pytest.raises(SceneError, match="NaN or infinite"):
        build_scene(v, QUAD_T, [1, 1], LIGHT)


def test_zero_area_triangles_are_dropped_with_a_count():
    t = np.vstack([QUAD_T, [[0, 1, 1]], [[0, 0, 0]]])
    with pytest.warns(UserWarning, match="dropped 2 zero-area"):
        sc = build_scene(QUAD_V, t, [1, 1, 0, 0], LIGHT)
    assert sc.dropped_triangles == 2 and len(sc.triangles) == 2


def test_repeated_triangles_are_dropped_and_back_to_back_pairs_become_two_sided():
    """Triangles with another's corners: a same-facing copy (corners in any rotation, or at a
    separate but equal vertex) is dropped; a reversed one-sided copy of the same material
    makes the first two-sided; a reversed copy of another material stays; any copy of a
    two-sided triangle is dropped; triangles sharing only an edge stay.  With patches given,
    nothing becomes two-sided."""
    v = np.vstack([QUAD_V, QUAD_V[:1]])                  # vertex 4 repeats vertex 0's position
    t = np.array([[0, 1, 2], [1, 2, 0], [4, 1, 2], [0, 2, 1],      # copies of the first: 2 dropped, 1 merged
                  [0, 2, 3], [0, 3, 2],                             # reversed copy, another material: stays
                  [1, 3, 2]])                                       # shares an edge only
    m = [1, 1, 1, 1, 1, 0, 0]
    with pytest.warns(UserWarning, match="dropped 3 triangles that repeat.*1 one-sided triangles with a reversed"):
        sc = build_scene(v, t, m, LIGHT)
    assert len(sc.triangles) == 4 and sc.dropped_triangles == 3
    assert sc.triangle_two_sided.tolist() == [True, False, False, False]
    assert sc.triangle_source.tolist() == [0, 4, 5, 6]
    with pytest.warns(UserWarning, match="dropped 2 triangles"):
        sc = build_scene(v, t[:4], m[:4], LIGHT, triangle_patch=[0, 0, 0, 1])
    assert len(sc.triangles) == 2 and not sc.triangle_two_sided.any()
    with pytest.warns(UserWarning, match="dropped 3 triangles"):
        sc = build_scene(v, t[:4], m[:4], LIGHT, two_sided=True)
    assert len(sc.triangles) == 1 and sc.triangle_two_sided.all()


@pytest.mark.parametrize("kwargs,msg", [
    (dict(triangles=np.zeros((0, 3), int), triangle_material=[]), "empty"),
    (dict(triangle_material=[0, 0]), "no lights"),
    (dict(triangle_material=[0, 5]), "material ids"),
    (dict(triangles=np.array([[0, 1, 9], [0, 2, 3]])), "vertex indices"),
])
def test_bad_scenes_give_clear_errors(kwargs, msg):
    args = dict(vertices=QUAD_V, triangles=QUAD_T, triangle_material=[1, 1], materials=LIGHT)
    args.update(kwargs)
    with pytest.raises(SceneError, match=msg):
        build_scene(**args)


def test_albedo_above_one_is_an_error():
    bad = MaterialTable.from_list([dict(name="hot", diffuse=(1.1, 0.5, 0.5), emission=(1, 1, 1))])
    with pytest.raises(SceneError, match="albedo > 1"):
        build_scene(QUAD_V, QUAD_T, [0, 0], bad)


def test_point_light_alone_is_a_light():
    sc = build_scene(QUAD_V, QUAD_T, [0, 0], LIGHT,
                     point_lights=PointLights(np.array([[0.5, 0.5, 1.0]]), np.array([[1.0, 1, 1]])))
    assert sc.n_patches == 2


def test_patches_must_be_of_one_material_and_face_one_way():
    v = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [0, 0, 1]], float)
    two = MaterialTable.from_list([dict(name="a", diffuse=(0.5,) * 3, emission=(1,) * 3), dict(name="b", diffuse=(0.2,) * 3)])
    with pytest.raises(SceneError, match="mixes materials"):
        build_scene(v, QUAD_T, [0, 1], two, triangle_patch=[0, 0])
    with pytest.raises(SceneError, match="60 degrees"):          # a sheet folded flat back on itself
        build_scene(v, [[0, 1, 2], [0, 3, 2]], [0, 0], two, triangle_patch=[0, 0])
    # a curved patch (a cluster, 90 degrees folded: 45 degrees from its mean normal) is allowed
    assert build_scene(v, [[0, 1, 2], [0, 4, 1]], [0, 0], two, triangle_patch=[0, 0]).n_patches == 1
    with pytest.raises(SceneError, match="entries for 2 triangles"):
        build_scene(v, QUAD_T, [0, 0], two, triangle_patch=[0, 0, 1])
    with pytest.raises(SceneError, match="point lights"):
        build_scene(v, QUAD_T, [0, 0], two, point_lights=PointLights(np.zeros((2, 3)), np.ones((1, 3))))


def grid_triangles(x0, x1, y0, y1, step=0.1, down=False):
    """(K, 3, 3) triangles covering the rectangle at z = 0 in squares ``step`` wide, facing +z
    (or -z)."""
    xs, ys = np.linspace(x0, x1, round((x1 - x0) / step) + 1), np.linspace(y0, y1, round((y1 - y0) / step) + 1)
    gx, gy = np.meshgrid(xs, ys, indexing="ij")
    p = np.stack([gx, gy, np.zeros_like(gx)], axis=-1)
    a, b, c, d = p[:-1, :-1], p[1:, :-1], p[1:, 1:], p[:-1, 1:]
    tri = np.concatenate([np.stack([a, b, c], axis=2).reshape(-1, 3, 3), np.stack([a, c, d], axis=2).reshape(-1, 3, 3)])
    return tri[:, ::-1] if down else tri


def test_coplanar_overlaps_are_found_between_objects_facing_the_same_way():
    """Two objects' faces in one plane facing the same way over 4 m^2 (a strip of one mesh on
    another's floor) are found, with about their area (4 points per triangle); a box's bottom
    on the floor (facing the other way), a tile that only touches the floor, and one object's
    own faces are not."""
    from raybundle.scene.overlaps import coplanar_overlaps

    parts = [grid_triangles(-2, 2, -2, 2), grid_triangles(1, 2, -2, 2, step=0.25),
             grid_triangles(-1, 0, -1, 0, down=True), grid_triangles(2, 3, -2, 2)]
    corners = np.concatenate(parts)
    obj = np.repeat(np.arange(4), [len(x) for x in parts])
    found = coplanar_overlaps(corners, obj)
    assert [(a, b) for a, b, _ in found] == [(0, 1)]
    assert found[0][2] == pytest.approx(4.0, rel=0.05)
    assert coplanar_overlaps(corners, np.zeros(len(obj), int)) == []


def test_covered_points_are_those_of_an_overlap_and_only_those():
    """The points where Cycles z-fights (raybundle.scene.overlaps.covered_points) in the scene
    of the test above: points of the floor under the strip and of the strip over the floor are
    covered; the floor's points beside the strip, the box bottom's (facing the other way), the
    touching tile's, a point off every triangle and points under a second triangle of their own
    object are not."""
    from raybundle.scene.overlaps import covered_points

    parts = [grid_triangles(-2, 2, -2, 2), grid_triangles(1, 2, -2, 2, step=0.25),
             grid_triangles(-1, 0, -1, 0, down=True), grid_triangles(2, 3, -2, 2),
             grid_triangles(-2, -1, -2, -1)]                        # the floor's own second layer
    corners = np.concatenate(parts)
    obj = np.repeat([0, 1, 2, 3, 0], [len(x) for x in parts])
    rng = np.random.default_rng(0)
    tri = rng.integers(len(corners), size=4000)
    u = rng.random((len(tri), 2))
    u = np.where(u.sum(axis=1, keepdims=True) > 1, 1 - u, u)
    c = corners[tri]
    pts = c[:, 0] + u[:, :1] * (c[:, 1] - c[:, 0]) + u[:, 1:] * (c[:, 2] - c[:, 0])
    got = covered_points(corners, obj, pts, tri)
    part = obj[tri]
    strip_x = (pts[:, 0] > 1) & (pts[:, 0] < 2)
    want = ((part == 0) & strip_x) | (part == 1)
    assert got.sum() > 300
    assert np.array_equal(got, want)
    assert not covered_points(corners, obj, np.zeros((1, 3)), np.array([-1])).any()


def test_coplanar_overlaps_test_points_in_blocks_of_bounded_memory():
    """Memory grows with the scene, not with a pass's convenience: two finely meshed floors
    laid over each other (8,192 triangles each, 64M point-in-triangle tests) are found in
    blocks whose peak stays under 80 MB (blocks of 4M tests peaked over 200 MB)."""
    import tracemalloc

    from raybundle.scene.overlaps import coplanar_overlaps

    parts = [grid_triangles(0, 1, 0, 1, step=1 / 64), grid_triangles(0, 1, 0, 1, step=1 / 64)]
    obj = np.repeat([0, 1], [len(x) for x in parts])
    corners = np.concatenate(parts)
    tracemalloc.start()
    try:
        base = tracemalloc.get_traced_memory()[0]
        found = coplanar_overlaps(corners, obj)
        peak = tracemalloc.get_traced_memory()[1] - base
    finally:
        tracemalloc.stop()
    assert [(a, b) for a, b, _ in found] == [(0, 1)]
    assert peak < 80e6, peak / 1e6


def test_coplanar_overlaps_among_a_thousand_objects_in_one_plane(monkeypatch):
    """A thousand small squares side by side in one plane (boxes' bottoms on a floor), each its
    own object, touch without overlapping: only the square laid over one of them is found, with
    its area.  With the tests sampled (a small ``MAX_TESTS``: 150 of the floor's 3,200
    triangles, a quarter of them under the strip) the 4 m^2 strip is still found with about its
    area: the larger of the two sides' estimates, 4.3 +- 0.37 m^2 over 30 seeds, bounded at three
    standard deviations."""
    from raybundle.scene import overlaps

    parts = [grid_triangles(x, x + 0.05, y, y + 0.05, step=0.05) for x in np.arange(40) * 0.1
             for y in np.arange(25) * 0.1] + [grid_triangles(0, 0.05, 0, 0.05, step=0.025)]
    obj = np.repeat(np.arange(len(parts)), [len(x) for x in parts])
    found = overlaps.coplanar_overlaps(np.concatenate(parts), obj)
    assert [(a, b) for a, b, _ in found] == [(0, 1000)]
    assert found[0][2] == pytest.approx(0.05 ** 2, rel=1e-6)

    monkeypatch.setattr(overlaps, "MAX_TESTS", 2_000_000)
    parts = [grid_triangles(-2, 2, -2, 2), grid_triangles(1, 2, -2, 2, step=0.25)]
    found = overlaps.coplanar_overlaps(np.concatenate(parts), np.repeat([0, 1], [len(x) for x in parts]))
    assert [(a, b) for a, b, _ in found] == [(0, 1)]
    assert 4.0 * 0.9 < found[0][2] < 4.3 + 3 * 0.37


def test_shading_normals_interpolate_the_corner_normals():
    """At a corner the shading normal is that corner's normal; inside, the normalised
    barycentric mix (raybundle.scene.shading); a flat-shaded scene needs none."""
    from raybundle.scene.shading import ShadingNormals

    corners = np.array([[[0, 0, 0], [1, 0, 0], [0, 1, 0]]], float)
    tilt = np.array([[0.6, 0, 0.8], [0, 0.6, 0.8], [0, 0, 1.0]])
    sn = ShadingNormals.of_faces(corners, tilt[None])
    got = sn.at(np.zeros(4, int), np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1 / 3, 1 / 3, 0]]))
    mix = tilt.mean(axis=0) / np.linalg.norm(tilt.mean(axis=0))
    assert np.allclose(got, [tilt[0], tilt[1], tilt[2], mix], atol=1e-6)
    assert ShadingNormals.of_faces(corners, np.tile([0, 0, 1.0], (1, 3, 1))) is None


def test_the_shadow_terminator_lifts_shadow_rays_clear_of_the_smooth_surface():
    """A facet of the unit sphere with the sphere's normals at its corners: Cycles' lift of a
    shadow ray's origin (raybundle.scene.shading) at points inside it is along their
    interpolated normal and clears the sphere (at least as high as the sphere lies above the
    point along it, at most twice: the corners' envelopes bound the parabola), towards the side
    the light is on; a flat face has none.  With the light ``L`` at cosines ``c_s``, ``c_g`` to
    the shading and flat normals the share of it taken is Cycles': none far from grazing,
    ``1 - c_g / g`` where only the facet grazes, ``2 - (c_g + c_s) / g`` where both do."""
    from raybundle.scene.shading import ShadingNormals, terminator_amount

    def unit(v):
        return v / np.linalg.norm(v, axis=-1, keepdims=True)

    s, c = np.sin(0.4), np.cos(0.4)
    corners = unit(np.array([[s, 0, c], [-s / 2, 0.866 * s, c], [-s / 2, -0.866 * s, c]]))
    facet = unit(np.cross(corners[1] - corners[0], corners[2] - corners[0]))
    facet *= np.sign(facet[2])
    shading = ShadingNormals(np.stack([corners, corners]), np.stack([corners, np.tile(facet, (3, 1))]))
    b = np.random.default_rng(3).dirichlet([2, 2, 2], 500)
    p = b @ corners
    up = np.tile(facet, (len(p), 1))
    lift = shading.terminator_lift(np.zeros(len(p), int), p, up)
    n = unit(b @ corners)
    along = np.einsum("ij,ij->i", lift, n)
    assert np.allclose(lift, along[:, None] * n, atol=1e-12)
    pn = np.einsum("ij,ij->i", p, n)
    height = -pn + np.sqrt(pn ** 2 - (np.einsum("ij,ij->i", p, p) - 1))       # |p + height n| = 1
    assert np.all(along >= height) and np.all(along <= 2 * height), (along / height).min()
    inside = shading.terminator_lift(np.zeros(len(p), int), p, -up)
    assert np.all(np.einsum("ij,ij->i", inside, -up) > 0)
    assert np.allclose(shading.terminator_lift(np.ones(len(p), int), p, up), 0.0, atol=1e-7)
    amount = terminator_amount(np.array([0.1, 0.1, 0.1, 0.1, 0.0]), np.array([0.5, 0.5, 0.05, 0.08, 0.05]),
                               np.array([0.5, 0.05, 0.02, 0.08, 0.02]))
    assert np.allclose(amount, [0.0, 0.5, 1.0, 0.4, 0.0])


def test_connected_components_match_a_graph_search(monkeypatch):
    """The welding's connected components (the compiled union-find, and the NumPy path's hooking
    and pointer jumping) against a breadth-first search, on random graphs from sparse (many
    singletons) to dense, with long chains (a tessellated sphere's corners link in rings); ids
    dense, in the order of each component's smallest node."""
    from collections import deque

    from raybundle.util import compiled
    from raybundle.util.arrays import connected_components
    rng = np.random.default_rng(5)
    cases = [(1, np.zeros((0, 2), np.int64)), (6, np.zeros((0, 2), np.int64)),
             (2000, np.stack([np.arange(1999, 0, -1), np.arange(1998, -1, -1)], axis=1))]   # one chain, reversed
    cases += [(n, rng.integers(0, n, (k, 2))) for n, k in ((50, 20), (500, 400), (3000, 2900), (200, 1000))]
    for n, links in cases:
        nbr = [[] for _ in range(n)]
        for a, b in links.tolist():
            nbr[a].append(b)
            nbr[b].append(a)
        want, c = np.full(n, -1), 0
        for s in range(n):
            if want[s] < 0:
                want[s], todo = c, deque([s])
                while todo:
                    for v in nbr[todo.popleft()]:
                        if want[v] < 0:
                            want[v] = c
                            todo.append(v)
                c += 1
        assert compiled.ENABLED and np.array_equal(connected_components(n, links), want), n
        with monkeypatch.context() as m:
            m.setattr(compiled, "ENABLED", False)
            m.setattr(compiled, "_warned", True)
            assert np.array_equal(connected_components(n, links), want), n


def test_triangle_areas_and_normals_compiled_are_numpys_bits(monkeypatch):
    """:mod:`raybundle.scene.triangle_geometry`: the kernel's areas and unit normals are the
    NumPy path's bit for bit (random triangles far from the origin, slivers, and a triangle of
    zero area, whose normal is NaN as NumPy's 0 / 0 is), and the unit normal is the cross
    product of the edges over twice the area (a right triangle in the xy plane: +z, area 1/2)."""
    from raybundle.scene import triangle_geometry as tg
    from raybundle.util import compiled
    rng = np.random.default_rng(3)
    v = np.concatenate([rng.normal(size=(600, 3)) * 10.0 + 1e3, [[0, 0, 0], [1, 0, 0], [0, 1, 0], [2, 0, 0]]])
    t = np.concatenate([rng.integers(0, 600, (500, 3)), [[600, 601, 602], [600, 601, 603]]])
    t[:40, 2] = t[:40, 1]                                                # slivers of zero area too
    assert compiled.ENABLED
    area = tg.areas(v, t)
    normal = tg.normals(v, t, area)
    assert area[-2] == 0.5 and np.array_equal(normal[-2], [0.0, 0.0, 1.0]) and area[-1] == 0.0
    assert np.isnan(normal[-1]).all() and np.isnan(normal[:40]).all()
    with monkeypatch.context() as m, np.errstate(invalid="ignore", divide="ignore"):
        m.setattr(compiled, "ENABLED", False)
        m.setattr(compiled, "_warned", True)
        assert np.array_equal(tg.areas(v, t), area)
        assert np.array_equal(tg.normals(v, t, area), normal, equal_nan=True)


def test_unique_rows_and_group_ids_match_numpy():
    """The welding's row ids (a mixed-radix key, or dense ranks first where the spans are too
    wide for one, or a lexsort) equal np.unique over rows: ids in lexicographic order, the first
    row of each value."""
    from raybundle.util.arrays import group_ids, unique_rows
    rng = np.random.default_rng(7)
    for span, k in ((3, 3), (2000, 3), (2 ** 40, 3), (2 ** 62, 3), (2 ** 40, 6)):     # the last by lexsort
        a = rng.integers(-span // 2, span // 2, (5000, k), dtype=np.int64)
        a[:2000] = a[rng.integers(0, 3000, 2000)]                  # repeated rows
        _, first, inverse = np.unique(a, axis=0, return_index=True, return_inverse=True)
        got = unique_rows(a)
        assert np.array_equal(got[0], first) and np.array_equal(got[1], inverse.reshape(-1)), span
        assert np.array_equal(group_ids(list(a.T)), inverse.reshape(-1)), span


def test_group_ids_of_wide_columns_make_no_copy_of_them_side_by_side():
    """Memory grows with the scene, not with a pass's convenience: the welding's group ids of
    three columns too wide for one mixed-radix key (a corner's tag, :attr:`~raybundle.scene.model.
    PatchScene.smooth_vertex_ids`) rank the widest first, without an (N, 3) copy of the columns:
    under 56 bytes per row at the peak (with the copy, 81)."""
    import tracemalloc

    from raybundle.util.arrays import group_ids
    rng = np.random.default_rng(0)
    n = 500_000
    cols = [rng.integers(0, 200_000, n), rng.integers(0, 50_000, n), rng.integers(-2 ** 45, 2 ** 12, n)]
    tracemalloc.start()
    try:
        base = tracemalloc.get_traced_memory()[0]
        ids = group_ids(cols)
        peak = tracemalloc.get_traced_memory()[1] - base
    finally:
        tracemalloc.stop()
    assert np.array_equal(ids, np.unique(np.stack(cols, axis=1), axis=0, return_inverse=True)[1].reshape(-1))
    assert peak < 56 * n, peak / n


def test_stable_order_and_unique_ints_match_numpy(monkeypatch):
    """The layout's 1-D sorts (one sort of ``(key - min) * N + index`` where that fits in 62
    bits, a stable sort of the key and its index beyond; compiled radix sorts from
    ``RADIX_MIN`` keys, NumPy's sorts below it and without Numba) give the stable argsort and
    ``np.unique``'s values, first indices and inverse, for keys of any sign, dtype and span,
    empty and single ones too."""
    from raybundle.util import compiled
    from raybundle.util.arrays import RADIX_MIN, stable_order, unique_ints
    assert compiled.ENABLED and 5000 < RADIX_MIN < 40000
    rng = np.random.default_rng(11)
    for numba in (True, False):
        if not numba:
            monkeypatch.setattr(compiled, "ENABLED", False)
            monkeypatch.setattr(compiled, "_warned", True)
        _check_stable_order(rng, stable_order, unique_ints)


def _check_stable_order(rng, stable_order, unique_ints):
    for span, dtype in ((4, np.int64), (1000, np.int32), (2 ** 40, np.int64), (2 ** 50, np.int64),
                        (2 ** 62, np.int64)):
        for n in (0, 1, 7, 5000, 40000):
            key = rng.integers(-span // 2, span // 2, n).astype(dtype)
            if n > 10:
                key[: n // 3] = key[rng.integers(n // 3, n, n // 3)]          # repeated values
            order, value = stable_order(key)
            assert np.array_equal(order, np.argsort(key, kind="stable")) and value.dtype == key.dtype
            assert all(np.array_equal(a, b) for a, b in zip(stable_order(key.astype(np.int64), own=True),
                                                            (order, value)))
            assert np.array_equal(value, np.sort(key))
            want = np.unique(key, return_index=True, return_inverse=True)
            got = unique_ints(key)
            assert all(np.array_equal(g, w.reshape(-1)) for g, w in zip(got, want)), (span, n)


@pytest.mark.parametrize("kind,width", [("BLACKMAN_HARRIS", 1.5), ("GAUSSIAN", 1.0), ("BOX", 2.0)])
def test_sample_positions_follow_the_pixel_filter(kind, width):
    """Cycles' pixel filters (its width conventions: Blackman-Harris reaches ``width`` from the
    centre, a Gaussian 1.5 ``width`` with standard deviation ``width / 4``): the offsets
    :meth:`Camera.subpixel` draws follow :meth:`Camera.filter_weights`' density, a chi-square
    over 40 bins of 200,000 offsets under its 99.9% point (73.4); light splatted at points
    spread evenly over the image lands with total weight 1 on average
    (:meth:`Camera.footprint`); a box one pixel wide is the uniforms themselves, one pixel
    each."""
    from dataclasses import replace
    from raybundle.scene.camera import Camera

    cam = Camera(64, 64, 64.0, 64.0, 32.0, 32.0, np.eye(4), pixel_filter=kind, filter_width=width)
    u = np.random.default_rng(3).random((200_000, 2))
    off = cam.subpixel(u) - 0.5
    half = {"BOX": 0.5, "GAUSSIAN": 1.5}.get(kind, 1.0) * width
    edges = np.linspace(-half, half, 41)
    fine = np.linspace(-half, half, 40 * 200 + 1)
    density = cam.filter_weights(0.5 * (fine[1:] + fine[:-1])) * np.diff(fine)
    expect = len(off) * density.reshape(40, 200).sum(axis=1)
    for axis in (0, 1):
        seen = np.histogram(off[:, axis], edges)[0]
        assert ((seen - expect) ** 2 / expect).sum() < 73.4
    px, py = np.random.default_rng(4).uniform(16, 48, (2, 20_000))
    sample, pixel, weight = cam.footprint(px, py)
    assert abs(weight.sum() / len(px) - 1.0) < 0.01 and np.array_equal(np.unique(sample), np.arange(len(px)))
    box = replace(cam, pixel_filter="BOX", filter_width=1.0)
    assert np.array_equal(box.subpixel(u), u)
    sample, pixel, weight = box.footprint(px, py)
    assert np.array_equal(pixel, np.floor(py).astype(int) * 64 + np.floor(px).astype(int)) and (weight == 1).all()
    with pytest.raises(ValueError, match="pixel filter"):
        replace(cam, pixel_filter="MITCHELL")
    with pytest.raises(ValueError, match="width"):
        replace(cam, filter_width=0.0)


def test_a_world_seen_whole_in_a_pixel_is_the_filters_mean_of_its_view():
    """The world's view (rendered by Blender through the camera at sub-pixels) read in the
    pixels that see only the world: under a Blackman-Harris filter 1.5 px wide, a pixel's value
    is the view's mean weighted by the filter over the sub-pixels it covers: a constant sky
    stays constant, and an edge in the sky is that mean, taken by brute force over the
    view's sub-pixels."""
    from raybundle.scene.camera import Camera
    from raybundle.scene.world import World

    cam = Camera(8, 6, 8.0, 8.0, 4.0, 3.0, np.eye(4), pixel_filter="BLACKMAN_HARRIS", filter_width=1.5)
    view = np.random.default_rng(2).random((24, 32, 3))
    world = World(np.ones((4, 8, 3)), view=view, view_camera=cam.with_resolution(32, 24))
    got = world.view_pixel_means(cam).reshape(6, 8, 3)
    for i, j in ((0, 0), (2, 3), (5, 7), (3, 1)):
        # sub-pixels beyond the image's edge read the view's edge: their weight goes to it
        wy = np.bincount(np.clip(np.arange(-24, 48), 0, 23), cam.filter_weights((np.arange(-24, 48) + 0.5) / 4 - i - 0.5))
        wx = np.bincount(np.clip(np.arange(-32, 64), 0, 31), cam.filter_weights((np.arange(-32, 64) + 0.5) / 4 - j - 0.5))
        want = np.einsum("h,w,hwc->c", wy, wx, view) / (wy.sum() * wx.sum())
        assert np.allclose(got[i, j], want), (i, j)
    flat = World(np.ones((4, 8, 3)), view=np.full((24, 32, 3), 2.0), view_camera=cam.with_resolution(32, 24))
    assert np.allclose(flat.view_pixel_means(cam), 2.0)


def test_an_encoded_map_is_decoded_after_the_lookup_and_kept_by_the_npz_arrays():
    """A map of sRGB-encoded texels (a byte sRGB image, as Cycles keeps it): a lookup midway
    between two texels decodes the interpolated encoded value (not the mean of the decoded ones)
    and scales it; Closest reads the nearest texel; pyramid levels average decoded values; the
    ``.npz`` arrays keep both settings."""
    from raybundle.scene.textures import SurfaceTexture, srgb_to_linear

    enc = np.array([[[0.8, 0.8, 0.8], [0.1, 0.1, 0.1]]], np.float32)           # 1 x 2 texels
    scale = np.array([2.0, 2.0, 2.0])
    corners, uv = np.zeros((1, 3, 3)), np.zeros((1, 3, 2))
    tex = SurfaceTexture([enc, enc], [0], corners, uv, encoded=[scale, None], closest=[False, True])
    mid = np.array([[0.5, 0.5]])                          # halfway between the texel centres 0.25, 0.75
    assert np.allclose(tex.lookup(0, mid), 2.0 * srgb_to_linear(0.45))
    assert np.allclose(tex.lookup(1, np.array([[0.3, 0.5]])), 0.8)
    assert np.allclose(tex.level(0, 1), 2.0 * 0.5 * (srgb_to_linear(0.8) + srgb_to_linear(0.1)))
    back = SurfaceTexture.from_arrays(tex.to_arrays())
    assert np.allclose(back.encoded[0], scale) and back.encoded[1] is None and back.closest == [False, True]


def test_a_map_of_bytes_reads_the_very_values_of_its_float_twin():
    """A byte image's map kept as its bytes (uint8, a quarter of the memory) with the value each
    byte stands for: every lookup (bilinear, Closest, extended, on pyramid levels), a face's
    modulation and the ``.npz`` arrays read the very float32 values of the same map kept as
    floats (its pyramid decodes the 256 values, not each texel: the same floats)."""
    from raybundle.scene.textures import SurfaceTexture

    rng = np.random.default_rng(3)
    k = rng.integers(0, 256, (5, 7, 3)).astype(np.uint8)
    values = (np.arange(256, dtype=np.float32) / np.float32(255))
    values[rng.integers(0, 256, 40)] += np.float32(1e-6)                   # as an image holds them
    corners = np.array([[[0, 0, 0], [1, 0, 0], [0, 1, 0]]], float)
    uv = np.array([[[-0.3, 0.1], [1.4, 0.2], [0.2, 1.1]]])
    scale = np.array([1.5, 2.0, 2.5])
    for extend, closest in ((False, False), (True, False), (False, True)):
        as_bytes = SurfaceTexture([k], [0], corners, uv, encoded=[scale], closest=[closest], extend=[extend],
                                  byte_values=[values])
        as_floats = SurfaceTexture([values[k]], [0], corners, uv, encoded=[scale], closest=[closest], extend=[extend])
        assert as_bytes.images[0].dtype == np.uint8 and as_bytes.images[0].nbytes == k.size
        at = rng.random((500, 2)) * 1.6 - 0.3
        for level in (0, 1, 2):
            assert np.array_equal(as_bytes.lookup(0, at, level), as_floats.lookup(0, at, level))
        points = np.concatenate([rng.random((50, 2)) * 0.5, np.zeros((50, 1))], axis=1)
        assert np.array_equal(as_bytes.at(np.zeros(50, int), points), as_floats.at(np.zeros(50, int), points))
        back = SurfaceTexture.from_arrays(as_bytes.to_arrays())
        assert np.array_equal(back.images[0], values[k]) and np.array_equal(back.lookup(0, at), as_floats.lookup(0, at))


def test_an_extended_map_reads_its_edge_texels_beyond_its_edges():
    """Extend (Blender's Extension, and graphs baked on one object): beyond the outer texel
    centres a lookup reads the edge texel, where Repeat blends it with the opposite edge; inside,
    both interpolate alike; the ``.npz`` arrays keep the setting."""
    from raybundle.scene.textures import SurfaceTexture

    im = np.array([[[1.0] * 3, [2.0] * 3, [3.0] * 3, [4.0] * 3]], np.float32)      # 1 x 4 texels
    corners, uv = np.zeros((1, 3, 3)), np.zeros((1, 3, 2))
    tex = SurfaceTexture([im, im], [0], corners, uv, extend=[False, True])
    edge = np.array([[0.01, 0.5], [0.99, 0.5], [-0.2, 0.5], [1.3, 0.5]])
    assert np.allclose(tex.lookup(1, edge)[:, 0], [1, 4, 1, 4])
    assert np.allclose(tex.lookup(0, edge[:2])[:, 0], [2.38, 2.62])                 # 1 and 4 blended
    inside = np.array([[0.3, 0.5], [0.6, 0.5]])
    assert np.allclose(tex.lookup(0, inside), tex.lookup(1, inside))
    assert np.allclose(tex.level(1, 2)[..., 0], [2.5]) and np.allclose(tex.level(1, 1)[..., 0], [1.5, 3.5])
    assert SurfaceTexture.from_arrays(tex.to_arrays()).extend == [False, True]


def test_a_patch_of_many_small_triangles_takes_an_unbiased_mean_albedo():
    """A 2 x 2 m floor meshed into 20,000 triangles under an 8 x 8 checker (modulation 0.4 and
    1.6) grouped into about 40 patches: each patch's mean albedo, from its triangles' share of
    the patch's points (one point each for these), is unbiased: over 8 seeds it matches a dense
    mean over the patch (64 points a triangle) within 4 standard errors, and over the floor 1."""
    from raybundle.app import pipeline
    from raybundle.scene.build import build_scene
    from raybundle.scene.materials import MaterialTable
    from raybundle.scene.model import PointLights
    from raybundle.scene.textures import SurfaceTexture
    from raybundle.tracing.sampling import uniform_triangle

    n = 100
    xs = np.linspace(-1, 1, n + 1)
    gx, gy = np.meshgrid(xs, xs, indexing="ij")
    p = np.stack([gx, gy, np.zeros_like(gx)], axis=-1)
    a, b, c, d = p[:-1, :-1], p[1:, :-1], p[1:, 1:], p[:-1, 1:]
    tri = np.concatenate([np.stack([a, b, c], axis=2).reshape(-1, 3, 3), np.stack([a, c, d], axis=2).reshape(-1, 3, 3)])
    v, t = tri.reshape(-1, 3), np.arange(3 * len(tri)).reshape(-1, 3)
    checker = np.where((np.add.outer(np.arange(8), np.arange(8)) % 2)[..., None], 0.4, 1.6) * np.ones(3)
    tex = SurfaceTexture([checker.astype(np.float32)], np.zeros(len(tri), int), tri, (tri[..., :2] + 1) / 2)
    mats = MaterialTable.from_list([dict(name="floor", diffuse=(0.5, 0.5, 0.5))])
    scene = build_scene(v, t, np.zeros(len(tri), int), mats, texture=tex,
                        point_lights=PointLights([[0.0, 0.0, 1.0]], [[1.0, 1.0, 1.0]]))
    laid = pipeline.prepare(scene, patches=40)
    runs = np.array([laid.texture.side_means(laid, seed=s)[:, 0] for s in range(8)])
    rng = np.random.default_rng(5)
    u = rng.random((len(laid.triangles), 64, 2))
    w = uniform_triangle(u[..., 0].ravel(), u[..., 1].ravel()).reshape(len(laid.triangles), 64, 3)
    pts = np.einsum("tnk,tkc->tnc", w, laid.triangle_corners)
    dense = tex.at(np.repeat(laid.triangle_source, 64), pts.reshape(-1, 3))[:, 0].reshape(-1, 64).mean(axis=1)
    side, area = laid.tside_side, laid.triangle_area[laid.tside_triangle]
    want = np.bincount(side, area * dense[laid.tside_triangle], minlength=laid.n_sides) / np.maximum(
        np.bincount(side, area, minlength=laid.n_sides), 1e-300)
    assert np.bincount(laid.triangle_patch).mean() > 100             # patches of many triangles
    live = np.unique(side)
    # the mean of 8 seeds against the dense mean, within 4 standard errors of the seeds' spread
    # (and the dense mean's own: 64 points a triangle, a patch of at least 300 triangles)
    err = np.abs(runs[:, live].mean(axis=0) - want[live])
    se = np.hypot(runs[:, live].std(axis=0, ddof=1) / np.sqrt(8), 0.6 / np.sqrt(64 * 300))
    assert np.all(err < 4 * se), np.max(err / se)
    got = runs[0]
    assert np.sum(got[side] * area) / area.sum() == pytest.approx(1.0, abs=0.01)

