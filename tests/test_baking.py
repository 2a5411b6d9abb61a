"""Bakes of the solution at surface points (raybundle.imaging.baking) against closed forms, and
the point location against a brute-force search.

Statistical tolerances: fixed seeds; the furnace bounds are about 4.5 times the bias and
twice the spread measured with two seeds (the furnace has no model error: its radiance
is constant, so everything measured is noise).
"""
import numpy as np
import pytest

from raybundle.app import pipeline
from raybundle.imaging.baking import _locate_by_search, baked_radiance, locate_points
from raybundle.imaging.settings import RenderSettings
from raybundle.scene import builtin as scenes
from raybundle.scene.build import build_scene
from raybundle.scene.camera import Camera
from raybundle.scene.materials import MaterialTable
from raybundle.scene.model import PointLights


def random_face_points(scene, n, rng):
    """``n`` points on the input faces of ``scene``: face ids, barycentrics; the first
    3 x faces are the corners themselves (the hard case: on edges and vertices)."""
    faces = scene.triangle_source
    corner_face = np.repeat(faces, 3)
    corner_bary = np.tile(np.eye(3), (len(faces), 1))
    u = rng.random((n, 2))
    flip = u.sum(axis=1) > 1
    u[flip] = 1 - u[flip]
    bary = np.concatenate([corner_bary, np.stack([1 - u[:, 0] - u[:, 1], u[:, 0], u[:, 1]], axis=1)])
    return np.concatenate([corner_face, rng.choice(faces, n)]), bary


def plane_under_point_light(patches=200):
    """A 2 x 2 m plane (albedo 0.6) 1.5 m under a 100 W/sr white point light; nothing else:
    L(x) = 0.6 / pi * I cos / r^2 exactly (no indirect light)."""
    v = np.array([[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]], float)
    t = np.array([[0, 1, 2], [0, 2, 3]])
    mats = MaterialTable.from_list([dict(name="plane", diffuse=(0.6, 0.6, 0.6))])
    light = PointLights([[0.3, -0.2, 1.5]], [[100.0, 100.0, 100.0]])
    cam = Camera.look_at((0, -3, 2), (0, 0, 0), (0, 0, 1), 35, 36, (8, 8))
    coarse = build_scene(v, t, [0, 0], mats, point_lights=light, camera=cam)
    return coarse, pipeline.make_renderer(pipeline.prepare(coarse, patches=patches), RenderSettings(seed=3))


def test_point_light_bake_matches_closed_form_at_corners_edges_and_inside():
    coarse, r = plane_under_point_light()
    for _ in range(20):
        r.solver.step()
    face, bary = random_face_points(coarse, 2000, np.random.default_rng(1))
    pts = locate_points(coarse, r.scene, r.tracer, face, bary)
    assert pts.found.all()
    assert np.all(r.scene.triangle_source[pts.triangle] == face)
    L = baked_radiance(r.solver, pts)
    d = np.array([0.3, -0.2, 1.5]) - pts.point
    r2 = (d * d).sum(axis=1)
    exact = 0.6 / np.pi * 100.0 * d[:, 2] / np.sqrt(r2) / r2
    # the points are pulled 1e-4 of the way to the face centroid: a relative change < 1e-3
    assert np.allclose(L, exact[:, None], rtol=1e-3), np.abs(L / exact[:, None] - 1).max()
    r.tracer.close()


def test_a_smooth_shaded_bake_takes_its_direct_light_about_the_shading_normal():
    """Cycles' bake shades a smooth-shaded face about its interpolated corner normals, as its
    render does (raybundle.scene.shading): the plane under the point light with corner normals
    bent outwards like a dome's bakes ``0.6 / pi * I max(0, n_s . w) / r^2`` with ``n_s`` the
    shading normal at the point.  About the flat normal (the old bake) the points were a
    median 26% off, up to 240% where the shading normal turns away from the light."""
    from raybundle.scene.shading import ShadingNormals

    v = np.array([[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]], float)
    t = np.array([[0, 1, 2], [0, 2, 3]])
    bent = v[t] * [0.4, 0.4, 0] + [0, 0, 1]
    shading = ShadingNormals(v[t], bent / np.linalg.norm(bent, axis=2, keepdims=True))
    mats = MaterialTable.from_list([dict(name="plane", diffuse=(0.6, 0.6, 0.6))])
    light = PointLights([[0.3, -0.2, 1.5]], [[100.0, 100.0, 100.0]])
    cam = Camera.look_at((0, -3, 2), (0, 0, 0), (0, 0, 1), 35, 36, (8, 8))
    coarse = build_scene(v, t, [0, 0], mats, point_lights=light, camera=cam, shading=shading)
    r = pipeline.make_renderer(pipeline.prepare(coarse, patches=200), RenderSettings(seed=3))
    face, bary = random_face_points(coarse, 2000, np.random.default_rng(1))
    pts = locate_points(coarse, r.scene, r.tracer, face, bary)
    L = baked_radiance(r.solver, pts)[:, 0]
    d = np.array([0.3, -0.2, 1.5]) - pts.point
    r2 = (d * d).sum(axis=1)
    n_s = shading.at(face, pts.point)
    exact = 0.6 / np.pi * 100.0 * np.maximum(0, np.einsum("ij,ij->i", n_s, d)) / np.sqrt(r2) / r2
    flat = 0.6 / np.pi * 100.0 * d[:, 2] / np.sqrt(r2) / r2
    assert np.abs(flat / exact - 1).max() > 0.05                  # the two normals differ enough to tell
    assert np.allclose(L, exact, rtol=2e-3), np.abs(L / exact - 1).max()
    r.tracer.close()


def test_locate_by_rays_equals_brute_force_search():
    """Every point's patch triangle found by the normal ray is the one the exhaustive
    search over its face's triangles finds (same triangle, same barycentrics)."""
    sc_in = scenes.furnace()
    r = pipeline.make_renderer(pipeline.prepare(sc_in, patches=400), RenderSettings(seed=0))
    face, bary = random_face_points(sc_in, 3000, np.random.default_rng(2))
    pts = locate_points(sc_in, r.scene, r.tracer, face, bary)
    assert pts.found.all()
    tri, fb = np.full(len(face), -1, np.int64), np.zeros((len(face), 3))
    _locate_by_search(r.scene, face, pts.point, np.arange(len(face)), tri, fb, chunk=5000)   # several chunks
    same = tri == pts.triangle
    # a point on the shared edge of two patch triangles may go to either: same position then
    on_edge = np.minimum(fb.min(axis=1), pts.bary.min(axis=1)) < 1e-6
    assert np.all(same | on_edge) and same.mean() > 0.99
    back = np.einsum("nk,nkc->nc", pts.bary, r.scene.triangle_corners[pts.triangle])
    assert np.allclose(back, pts.point, atol=1e-9)
    assert np.allclose(fb[same], pts.bary[same], atol=1e-9)
    r.tracer.close()


def test_dropped_faces_and_bad_ids_are_not_found_and_bake_to_zero():
    coarse, r = plane_under_point_light(patches=50)
    pts = locate_points(coarse, r.scene, r.tracer, np.array([0, 7, -1]), np.full((3, 3), 1 / 3))
    assert pts.found.tolist() == [True, False, False]
    L = baked_radiance(r.solver, pts)
    assert L[0].min() > 0 and not L[1:].any()
    r.tracer.close()


def test_refinement_by_lighting_cuts_until_edges_interpolate():
    """raybundle.imaging.baking.refine_by_lighting on the plane under a point light: the sub-triangles
    tile each face exactly (areas add up), and every edge of a triangle that stopped before
    the last level interpolates the closed form at its midpoint within the tolerance."""
    from raybundle.imaging.baking import refine_by_lighting

    coarse, r = plane_under_point_light()
    out = refine_by_lighting(r.solver, coarse, np.arange(len(coarse.triangles)), max_level=4, tolerance=0.05)
    corners = np.einsum("kcj,kjx->kcx", out.bary, coarse.triangle_corners[out.face])
    area = 0.5 * np.linalg.norm(np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]), axis=1)
    assert np.isclose(area.sum(), coarse.triangle_area.sum(), rtol=1e-12)
    level = np.round(np.log(coarse.triangle_area[out.face] / area) / np.log(4)).astype(int)
    assert level.min() < level.max() < 4          # measured: levels 2 and 3; none needed the last

    def exact(p):
        d = np.array([0.3, -0.2, 1.5]) - p
        r2 = (d * d).sum(axis=-1)
        return 0.6 / np.pi * 100.0 * d[..., 2] / np.sqrt(r2) / r2

    done = corners[level < 4]
    ends = 0.5 * (exact(done) + exact(done[:, [1, 2, 0]]))
    miss = np.abs(exact(0.5 * (done + done[:, [1, 2, 0]])) - ends) / (ends + 0.02 * exact(corners).mean())
    assert miss.max() < 0.05 * 1.01, miss.max()
    assert not out.capped
    # a cap on the triangle count stops the cutting before it is passed, and says so
    few = refine_by_lighting(r.solver, coarse, np.arange(len(coarse.triangles)), max_level=4, max_triangles=40)
    assert few.capped and len(few.face) <= 40
    r.tracer.close()


def test_textures_survive_the_npz_round_trip(tmp_path):
    """A textured scene written to .npz and read back keeps its maps and faces, and renders
    the same image (same seed and iterations); corner colors (a color attribute) too."""
    from raybundle.scene.npz import load_npz
    from raybundle.scene.textures import SurfaceTexture

    coarse, _, tex = textured_plane(patches=100, res=8)
    coarse.save_npz(tmp_path / "textured.npz")
    back = load_npz(tmp_path / "textured.npz").texture
    assert back is not None and len(back.images) == 1 and np.array_equal(back.images[0], tex.images[0])
    for name in ("face_image", "face_corners", "face_uv"):
        assert np.array_equal(getattr(back, name), getattr(tex, name))
    assert back.face_color is None
    images = [pipeline.make_renderer(pipeline.prepare(sc, patches=100), RenderSettings(seed=3)).run(iterations=4).image
              for sc in (coarse, load_npz(tmp_path / "textured.npz"))]
    assert np.array_equal(images[0], images[1])
    colors = SurfaceTexture([], [-2, -1], tex.face_corners, tex.face_uv, np.random.default_rng(0).random((2, 3, 3)))
    again = SurfaceTexture.from_arrays(colors.to_arrays())
    assert again.images == [] and np.array_equal(again.face_color, colors.face_color)
    assert np.array_equal(again.face_image, [-2, -1])


@pytest.mark.parametrize("gather", [0, 64])
def test_furnace_bake_is_le_over_one_minus_albedo(gather, seed=0):
    """Points on every face of the furnace (corners included) bake to Le / (1 - a), with
    the indirect light interpolated from the patches or gathered by 64 rays per point."""
    sc_in = scenes.furnace()
    r = pipeline.make_renderer(pipeline.prepare(sc_in, patches=400), RenderSettings(seed=seed))
    for _ in range(150):
        r.solver.step()
    face, bary = random_face_points(sc_in, 4000, np.random.default_rng(3))
    L = baked_radiance(r.solver, locate_points(sc_in, r.scene, r.tracer, face, bary), light_samples=16,
                       gather_rays=gather)
    exact = sc_in.analytic_radiance
    rel = L / exact - 1
    # measured (seeds 0, 1; 150 iterations x 16 directions; the block is a first-shot light,
    # its 12 triangles integrated analytically, 16 shadow rays per point): channel means within
    # 0.2% of exact; spread of the point values (std) 0.41-0.58%, largest 3.1% interpolated,
    # 0.24-0.28% and 1.7% gathered (with plain light sampling: 0.84% and 8.3%, under the
    # block where only its bottom face lights)
    assert np.all(np.abs(rel.mean(axis=0)) < 0.012), rel.mean(axis=0)
    assert rel.std() < 0.011 and np.abs(rel).max() < 0.07
    r.tracer.close()


def test_texel_points_cover_each_texel_once_and_reproduce_its_centre():
    from raybundle.imaging.lightmap import texel_points

    # the unit square as two triangles, plus a degenerate triangle (covers nothing)
    uv = np.array([[[0, 0], [1, 0], [1, 1]], [[0, 0], [1, 1], [0, 1]], [[0.2, 0.2], [0.2, 0.2], [0.3, 0.3]]], float)
    tx = texel_points(uv, 37, 23, chunk=100)          # several chunks
    assert len(tx.texel) == 37 * 23 and len(np.unique(tx.texel)) == 37 * 23 and tx.overlap == 0
    centre = np.stack([(tx.texel % 37 + 0.5) / 37, (tx.texel // 37 + 0.5) / 23], axis=1)
    back = np.einsum("nk,nkc->nc", tx.bary, uv[tx.triangle])
    assert np.allclose(back, centre, atol=1e-12) and np.all(tx.triangle < 2)
    # a triangle over half the square: the texels whose centres lie below the diagonal
    half = texel_points(uv[:1], 16, 16)
    x, y = half.texel % 16, half.texel // 16
    assert len(half.texel) == 16 * 17 // 2 and np.all(y <= x)
    # overlapping islands are counted
    assert texel_points(np.concatenate([uv[:1], uv[:1]]), 16, 16).overlap == 16 * 15 // 2   # off the diagonal


def test_dilate_grows_the_margin_by_neighbour_means():
    from raybundle.imaging.lightmap import dilate

    img = np.zeros((9, 9, 1))
    ok = np.zeros((9, 9), bool)
    img[4, 4], ok[4, 4] = 2.0, True
    img[4, 5], ok[4, 5] = 4.0, True
    out, grown = dilate(img, ok, 2)
    assert grown.sum() == 6 * 5 and not grown[0].any()      # two rings around a 1 x 2 block
    assert out[3, 3, 0] == 2.0 and out[3, 6, 0] == 4.0 and out[3, 4, 0] == 3.0
    assert out[4, 4, 0] == 2.0                               # filled texels keep their values


def textured_plane(patches=400, res=32):
    """``plane_under_point_light`` with a 4 x 4 checker texture (texels 0.4 and 1.6 of the
    mean) on the plane's albedo through UVs (x, y) / 2 + 0.5, seen by an ortho camera
    from above (res x res pixels over the plane)."""
    from raybundle.scene.textures import SurfaceTexture, modulation_map

    v = np.array([[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]], float)
    t = np.array([[0, 1, 2], [0, 2, 3]])
    checker = np.where((np.add.outer(np.arange(4), np.arange(4)) % 2)[..., None], 0.4, 1.6) * np.ones(3)
    mod, mean = modulation_map(checker * 0.5)
    tex = SurfaceTexture([mod], [0, 0], v[t], (v[t][..., :2] + 1) / 2)
    mats = MaterialTable.from_list([dict(name="plane", diffuse=(0.6 * mean).tolist())])
    light = PointLights([[0.3, -0.2, 1.5]], [[100.0, 100.0, 100.0]])
    m = np.eye(4)
    m[:3, 3] = (0, 0, 3)
    cam = Camera.from_blender(50, 36, 36, "AUTO", 0, 0, (res, res), m, ortho_scale=2.0)
    coarse = build_scene(v, t, [0, 0], mats, point_lights=light, camera=cam, texture=tex)
    return coarse, pipeline.make_renderer(pipeline.prepare(coarse, patches=patches), RenderSettings(seed=3)), tex


def test_texture_detail_stays_sharp_in_bakes_and_images_and_patches_hold_its_mean():
    coarse, r, tex = textured_plane()
    # patch albedo: the mean of the texture over each patch; over the plane, the texture's mean
    kd = r.solver.kd_over_pi * np.pi
    plane_mean = (kd * r.solver.area[:, None]).sum(axis=0) / r.solver.area.sum()
    assert np.allclose(plane_mean, 0.6 * 0.5, rtol=0.01), plane_mean
    assert kd.max() / kd.min() > 2     # patches in dark and bright texels differ (4x, blurred by bilinear lookups)
    # bakes at points: closed form x the texel's albedo, exactly
    face, bary = random_face_points(coarse, 3000, np.random.default_rng(4))
    pts = locate_points(coarse, r.scene, r.tracer, face, bary)
    L = baked_radiance(r.solver, pts)
    d = np.array([0.3, -0.2, 1.5]) - pts.point
    r2 = (d * d).sum(axis=1)
    albedo = 0.6 * 0.5 * tex.at(face, pts.point)
    exact = albedo / np.pi * 100.0 * (d[:, 2] / np.sqrt(r2) / r2)[:, None]
    assert np.allclose(L, exact, rtol=1e-3)
    # the camera image: each pixel the box-filtered closed form x albedo (computed here by 8 x 8
    # sub-samples); 60 iterations of image passes, jitter noise only (deterministic: seed 3)
    img = r.run(iterations=60).image
    n = 32
    s = (np.arange(8) + 0.5) / 8
    sub = (np.arange(n)[:, None] + s[None, :]).ravel() / n * 2 - 1     # sub-sample x (or y) [m]
    x, y = np.meshgrid(sub, -sub)                                        # image rows go down = -y
    p = np.stack([x.ravel(), y.ravel(), np.zeros(x.size)], axis=1)
    dd = np.array([0.3, -0.2, 1.5]) - p
    rr = (dd * dd).sum(axis=1)
    face_of = np.where(p[:, 1] <= p[:, 0], 0, 1)                        # triangle 0: below the diagonal y = x
    ref = (0.6 * 0.5 / np.pi * 100.0 * (dd[:, 2] / np.sqrt(rr) / rr))[:, None] * tex.at(face_of, p)
    ref = ref.reshape(n, 8, n, 8, 3).mean(axis=(1, 3))
    rel = img / ref - 1
    # measured: mean 1e-5, 95th percentile of |rel| 0.4%, largest 1.1% (patch-mean albedo: +-50% at texel edges)
    assert np.abs(rel.mean()) < 0.005 and np.percentile(np.abs(rel), 95) < 0.02 and np.abs(rel).max() < 0.05
    r.tracer.close()


def test_a_patch_over_many_texels_reads_its_mean_from_the_maps_pyramid():
    """The mean of a map over a triangle covering thousands of texels (a 64 x 64 noise map tiled
    8 times) is the map's mean within 0.3%, read on a coarser level of its pyramid with at most
    MAX_SAMPLES points; a coverage map gives each triangle its mean coverage the same way."""
    from raybundle.scene.textures import MAX_SAMPLES, SurfaceTexture

    noise = np.random.default_rng(2).random((64, 64, 3)).astype(np.float32) + 0.5
    v = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], float)
    t = np.array([[0, 1, 2], [0, 2, 3]])
    tex = SurfaceTexture([noise, np.repeat(noise[..., :1] - 0.5, 3, axis=2)], [0, 0], v[t], v[t][..., :2] * 8,
                         face_alpha=[1, 1])
    mats = MaterialTable.from_list([dict(diffuse=(0.5, 0.5, 0.5), emission=(1.0, 1.0, 1.0))])
    sc = build_scene(v, t, [0, 0], mats, texture=tex)
    means = tex._triangle_means(sc, tex.face_image, seed=1)
    assert np.allclose(means, noise.reshape(-1, 3).mean(axis=0), rtol=0.003), means
    assert tex.level(0, 3).shape == (8, 8, 3) and np.allclose(tex.level(0, 3).mean(), noise.mean(), rtol=1e-6)
    assert 64 * 64 * 64 / 2 > MAX_SAMPLES                  # each triangle covers more texels than it reads
    cover = tex.triangle_coverage(sc, seed=1)
    assert np.allclose(cover, noise[..., 0].mean() - 0.5, rtol=0.01), cover


def _cornell_gather(iterations=10):
    """A bake gather (raybundle.imaging.bake_gather) of 700 points of the Cornell box's faces."""
    from raybundle.imaging.bake_gather import BakeGather

    coarse = scenes.load_scene("cornell")
    r = pipeline.make_renderer(pipeline.prepare(coarse), RenderSettings(seed=4))
    for _ in range(iterations):
        r.solver.step()
    face, bary = random_face_points(coarse, 700 - 3 * len(coarse.triangles), np.random.default_rng(2))
    pts = locate_points(coarse, r.scene, r.tracer, face, bary)
    return r, pts, lambda: BakeGather(r.solver, pts, seed=9)


def test_a_bake_gather_gives_the_same_values_however_its_slices_fall():
    """Gathered in one call or a block at a time (a modal operator's ticks), the points take the
    same values: each block has its own random stream.  Points not found keep zero."""
    r, pts, make = _cornell_gather()
    whole, sliced = make(), make()
    whole.start(48)
    assert whole.advance() is False and whole.gathered == pts.found.sum()
    sliced.start(48)
    steps = 0
    while sliced.advance(0.0):
        steps += 1
    assert steps >= 2 and np.array_equal(whole.indirect, sliced.indirect)
    assert not np.array_equal(whole.indirect, make().indirect)      # gathered, not the interpolation
    r.tracer.close()


def test_a_bake_gather_past_its_deadline_leaves_the_rest_interpolated():
    """With its deadline passed, the gather does its first block (its cost is not known before)
    and leaves every other point the values interpolated from the patches; the time a budget
    buys is what its probe measures: none in no time, the most rays in an hour."""
    import time

    r, pts, make = _cornell_gather()
    g = make()
    interpolated = g.indirect.copy()
    g.start(48, deadline=time.perf_counter() - 1.0)
    assert g.advance() is False
    first = g.todo[:g.gathered]
    assert 0 < g.gathered < len(g.todo) and g.interpolated == len(g.todo) - g.gathered
    assert not np.array_equal(g.indirect[first], interpolated[first])
    assert np.array_equal(g.indirect[g.todo[g.gathered:]], interpolated[g.todo[g.gathered:]])
    assert make().automatic_rays(1e-6) == 0 and make().automatic_rays(3600.0) == make().MAX_RAYS
    r.tracer.close()
