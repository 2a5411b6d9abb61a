"""The compiled lamp arithmetic (:mod:`raybundle.lights.compiled_lights`) against the NumPy
paths it replaces: the same arithmetic, so the same values up to the last bits of their sums."""
import numpy as np
import pytest

from raybundle.lights.direct import DirectLighting, may_light
from raybundle.lights.polygon import clipped_edge_irradiance, light_polygon_irradiance
from raybundle.lights.sources import ShapeLight
from raybundle.util import compiled

from test_compiled_bsdf import _numpy
from test_lights import lamp_scene


def _unit(v):
    return v / np.linalg.norm(v, axis=1, keepdims=True)


def _lamps():
    """A tilted rectangle, a tilted ellipse and a large rectangle close to the points."""
    rng = np.random.default_rng(3)
    out = []
    for ellipse, scale in ((False, 0.6), (True, 0.4), (False, 3.0)):
        n = _unit(rng.normal(size=(1, 3)))[0]
        u = np.cross(n, [0.3, 0.5, 0.8])
        u = scale * u / np.linalg.norm(u)
        v = 0.7 * scale * np.cross(n, u) / np.linalg.norm(u)
        area = (np.pi if ellipse else 4.0) * np.linalg.norm(u) * np.linalg.norm(v)
        out.append(ShapeLight(rng.normal(size=3) * 0.5, u, v, n, ellipse, area, np.array([3.0, 2.0, 1.0])))
    return out


@pytest.fixture
def points():
    rng = np.random.default_rng(11)
    return rng.normal(size=(5000, 3)) * 1.5, _unit(rng.normal(size=(5000, 3))), rng.random((5000, 3))


def test_compiled_area_light_samples_reach_and_estimates_match_numpy(points, monkeypatch):
    """Samples (by area and by solid angle), where each lamp may light a point, its selection
    estimate and its analytic irradiance (Lambert's outline sum, clipped at the horizon)."""
    p, nrm, u = points
    assert compiled.ENABLED
    for lamp in _lamps():
        calls = [lambda: lamp.sample(p, u), lambda: may_light(lamp, p, nrm),
                 lambda: lamp.selection_estimate(p, nrm), lambda: light_polygon_irradiance(lamp, p, nrm)]
        for call in calls[:3] + ([] if lamp.ellipse else calls[3:]):
            got, want = call(), _numpy(monkeypatch, call)
            for g, w in zip(*(x if isinstance(x, tuple) else (x,) for x in (got, want))):
                assert g.shape == w.shape and np.any(w != 0)
                if g.dtype == bool:
                    assert np.array_equal(g, w)
                else:
                    assert np.allclose(g, w, rtol=1e-9, atol=1e-12), np.abs(g - w).max()


def test_compiled_outline_sum_matches_numpy_for_a_concave_outline(points, monkeypatch):
    """An L-shaped outline in the plane z = 0.4: points above it, below it and cut by it."""
    p, nrm, _ = points
    ring = np.array([[0, 0], [2, 0], [2, 1], [1, 1], [1, 2], [0, 2]], float) * 0.5
    ring = np.c_[ring, np.full(len(ring), 0.4)]
    edges = np.stack([ring, np.roll(ring, -1, axis=0)], axis=1)
    got = clipped_edge_irradiance(p, nrm, edges, np.array([0.0, 0.0, 1.0]))
    want = _numpy(monkeypatch, lambda: clipped_edge_irradiance(p, nrm, edges, np.array([0.0, 0.0, 1.0])))
    assert np.count_nonzero(want) > 1000
    assert np.allclose(got, want, rtol=1e-9, atol=1e-12), np.abs(got - want).max()


def test_compiled_shadow_rays_match_numpy(monkeypatch):
    """A lamp over a box's floor (lamp_scene): the shadowed and unshadowed estimates, directions
    and cosines of one sample per point, with the same shadow rays' outcomes."""
    sc = lamp_scene()
    rng = np.random.default_rng(5)
    p = np.c_[rng.uniform(0.05, 0.95, (4000, 2)), np.zeros(4000)]
    nrm = np.tile([0.0, 0.0, 1.0], (4000, 1))
    u = rng.random((4000, 3))

    def run():
        from raybundle.tracing.visibility import RayTracer
        direct = DirectLighting(sc, RayTracer(sc, threads=1))
        light = direct.light_list()[0]
        return direct.light_samples_at(p, nrm, light, u, unshadowed=True)

    got, want = run(), _numpy(monkeypatch, run)
    for g, w in zip(got, want):
        assert np.allclose(g, w, rtol=1e-9, atol=1e-12), np.abs(g - w).max()
    assert np.any(got[0] > 0)


def _lamp_floor(n=6000, blocker="diffuse"):
    """A glossy floor under a mesh lamp, two area lamps and a point lamp, a ``blocker``
    (diffuse or glass) casting penumbrae, and ``n`` points on the floor with their normals, eye
    directions and which of them ask for the glossy lobe's MIS share."""
    from raybundle.scene.build import build_scene
    from raybundle.scene.materials import MaterialTable
    from raybundle.scene.model import AreaLights, PointLights

    block = dict(name="blocker", diffuse=(0.2, 0.2, 0.2))
    if blocker == "glass":
        block.update(transmission=1.0, transmission_ior=1.5)
    mats = MaterialTable.from_list([
        dict(name="floor", diffuse=(0.5, 0.4, 0.3), glossy=(0.8, 0.8, 0.8), glossy_weight=0.3, roughness=0.2),
        dict(name="lamp", emission=(4.0, 4.0, 4.0)), block])
    v = np.array([[-3, -3, 0], [3, -3, 0], [3, 3, 0], [-3, 3, 0], [-0.2, -0.2, 2], [-0.2, 0.2, 2], [0.2, 0.2, 2],
                  [0.2, -0.2, 2], [-0.5, -0.5, 0.6], [0.5, -0.5, 0.6], [0.5, 0.5, 0.6], [-0.5, 0.5, 0.6]], float)
    t = [[0, 1, 2], [0, 2, 3], [4, 5, 6], [4, 6, 7], [8, 9, 10], [8, 10, 11]]
    area = AreaLights([[1.0, 0.5, 1.5], [-1.0, 0.0, 1.2]], [[0.3, 0, 0], [0.2, 0, 0]], [[0, 0.2, 0], [0, 0.3, 0]],
                      [[0, 0, -1], [0.3, 0, -0.954]], [0, 1], [[8.0, 6.0, 4.0], [3.0, 5.0, 7.0]])
    sc = build_scene(v, t, [0, 0, 1, 1, 2, 2], mats, area_lights=area,
                     point_lights=PointLights(np.array([[0.5, -1.0, 1.0]]), np.array([[3.0, 3.0, 3.0]])))
    rng = np.random.default_rng(9)
    p = np.c_[rng.uniform(-2.0, 2.0, (n, 2)), np.zeros(n)]
    up = np.tile([0.0, 0.0, 1.0], (n, 1))
    eye = _unit(np.c_[rng.normal(size=(n, 2)) * 0.5, np.ones(n)])
    return sc, p, up, eye, rng.random(n) < 0.5


@pytest.mark.parametrize("tree", ["off", "on"])
def test_compiled_lamp_samples_give_the_numpy_paths_estimate(tree, monkeypatch):
    """:func:`reflected_radiance` on a glossy floor under a mesh lamp, two area lamps (one
    an ellipse) and a point lamp, a blocker casting penumbrae: with the control variate, penumbra samples on
    Kronecker sequences, lamps chosen by their contribution (or the light tree), the glossy
    lobe's MIS share and its part apart, the same estimates and shadow flags on both paths."""
    from raybundle.lights.reflected_direct import reflected_radiance
    from raybundle.tracing.visibility import RayTracer

    sc, p, up, eye, mis = _lamp_floor()
    n = len(p)

    def run():
        tr = RayTracer(sc, threads=1)
        dl = DirectLighting(sc, tr, light_tree=tree)
        flags, lobe = np.zeros((n, 2), np.uint64), np.zeros((n, 3))
        out = reflected_radiance(dl, p, up, np.zeros(n, int), eye, None, 2, mis=mis, shadow_flags=flags,
                                 analytic=np.ones(n, bool), glossy_part=lobe,
                                 penumbra=(np.full(n, np.uint64(3)), 2, np.random.default_rng(4).random((n, 3)),
                                           np.zeros(n, np.int64)),
                                 select=np.random.default_rng(5).random(n))
        tr.close()
        return out, lobe, flags

    got, want = run(), _numpy(monkeypatch, run)
    for g, w in zip(got, want):
        assert np.any(w != 0)
        assert np.allclose(g, w, rtol=1e-9, atol=1e-12), np.abs(g - w).max()
    assert np.any(got[2][:, 0] & got[2][:, 1])              # some penumbrae



@pytest.mark.parametrize("blocker", ["diffuse", "glass"])
def test_lamp_samples_in_pieces_are_the_same_on_any_threads(blocker):
    """:func:`reflected_radiance` split into pieces
    (:meth:`~raybundle.tracing.visibility.RayTracer.map_pieces`) on two threads and on one:
    the same estimates, shadow flags and ray count, where shadow rays pass glass too (its
    random choices are hashed from the pieces' own query numbers); and without glass, the
    same as one call on all the points."""
    from raybundle.lights.reflected_direct import reflected_radiance
    from raybundle.tracing import visibility
    from raybundle.tracing.visibility import RayTracer

    sc, p, up, eye, mis = _lamp_floor(20000, blocker)
    n = len(p)

    def run(threads, fewest=visibility.PIECE_MIN):
        tr = RayTracer(sc, threads=threads)
        dl = DirectLighting(sc, tr)
        flags, lobe = np.zeros((n, 2), np.uint64), np.zeros((n, 3))
        visibility.PIECE_MIN, before = fewest, visibility.PIECE_MIN
        try:
            out = reflected_radiance(dl, p, up, np.zeros(n, int), eye, np.random.default_rng(5), 2, mis=mis,
                                     shadow_flags=flags, analytic=np.ones(n, bool), glossy_part=lobe,
                                     penumbra=(np.full(n, np.uint64(3)), 2, np.random.default_rng(4).random((n, 3)),
                                               None),
                                     select=np.random.default_rng(6).random(n))
        finally:
            visibility.PIECE_MIN = before
        tr.close()
        return out, lobe, flags, dl.rays

    two, one = run(2), run(1)
    assert n >= visibility.PIECE_MIN                          # two pieces at least
    for g, w in zip(two, one):
        assert np.any(w != 0) and np.array_equal(g, w)
    if blocker == "diffuse":
        for g, w in zip(two, run(2, 10 * n)):                 # one piece
            assert np.array_equal(g, w)

def test_compiled_world_samples_match_numpy(monkeypatch):
    """The world light's samples (:mod:`raybundle.lights.compiled_world`) by brightness alone
    and by three sides' guides (one without sums): the same pixels, directions, densities and
    radiance on both paths."""
    from raybundle.lights.world_light import GUIDE_CELLS, SideSums, WorldLight
    from raybundle.scene.world import World
    from raybundle.tracing.visibility import RayTracer

    from test_world import sky_and_ground, tilted_plate

    img = sky_and_ground()
    img[10:14, 30:40] = 40.0
    sc = tilted_plate(np.pi / 3, World(img))
    tr = RayTracer(sc, threads=1)
    wl = WorldLight(sc.world, tr)
    rng = np.random.default_rng(7)
    sums = rng.random((GUIDE_CELLS, 3)) ** 8
    sums[:, 2] = 0.0
    guide, at = wl.guide_of(sums.T), rng.integers(0, 3, 20000)
    u = rng.random((20000, 3))
    for args in ((u,), (u, guide, at)):
        got, want = wl.sample(*args), _numpy(monkeypatch, lambda: wl.sample(*args))
        for g, w in zip(got, want):
            assert np.allclose(g, w, rtol=1e-12, atol=1e-15), np.abs(g - w).max()
    tr.close()


def test_compiled_compact_light_samples_match_numpy(monkeypatch):
    """A glowing sphere (a compact mesh light, sampled by its bounding cone from outside it and
    triangle by triangle inside it): the same samples and selection estimates on both paths."""
    from raybundle.tracing.visibility import RayTracer

    from test_lights import glowing_sphere_over_floor

    sc = glowing_sphere_over_floor()
    tr = RayTracer(sc, threads=1)
    light = DirectLighting(sc, tr).light_list()[0]
    assert light._cone is not None
    centre, radius, _ = light._cone
    rng = np.random.default_rng(2)
    p = centre + _unit(rng.normal(size=(4000, 3))) * radius * rng.uniform(0.5, 4.0, (4000, 1))
    nrm, u = _unit(rng.normal(size=(4000, 3))), rng.random((4000, 3))
    assert 0 < np.count_nonzero(light._outside(p)) < len(p)
    for call in (lambda: light.sample(p, u), lambda: light.selection_estimate(p, nrm)):
        got, want = call(), _numpy(monkeypatch, call)
        for g, w in zip(*(x if isinstance(x, tuple) else (x,) for x in (got, want))):
            assert np.any(w != 0) and np.allclose(g, w, rtol=1e-9, atol=1e-12), np.abs(g - w).max()
    tr.close()


def test_compiled_world_guides_match_numpy(monkeypatch):
    """The sides' guides (:meth:`WorldLight.guide_at`) from the bundles' sums (one side without
    any) and the sums learned from samples (one side without any): the same shares,
    probabilities and cumulative probabilities on both paths, up to the order of their sums."""
    from raybundle.lights.world_light import GUIDE_CELLS, SideSums, WorldLight
    from raybundle.scene.world import World
    from raybundle.tracing.visibility import RayTracer

    from test_world import sky_and_ground, tilted_plate

    sc = tilted_plate(np.pi / 3, World(sky_and_ground()))
    tr = RayTracer(sc, threads=1)
    wl = WorldLight(sc.world, tr)
    rng = np.random.default_rng(3)
    n_s = sc.n_sides
    assert n_s >= 2
    bundle = SideSums(n_s)                        # no sums on side 0
    for c in range(GUIDE_CELLS):
        bundle.add(np.arange(1, n_s), c, rng.random(n_s - 1) ** 6)
    learned = np.arange(1, n_s)
    wl.learn(np.repeat(learned, 50), _unit(rng.normal(size=(50 * len(learned), 3))), rng.random(50 * len(learned)))
    sides = rng.integers(0, n_s, 500)
    for sums in (bundle, None):
        (got, at), (want, at_np) = wl.guide_at(sums, sides), _numpy(monkeypatch, lambda: wl.guide_at(sums, sides))
        assert np.array_equal(at, at_np)
        for g, w in zip(got, want):
            assert np.allclose(g, w, rtol=1e-12, atol=1e-15), np.abs(g - w).max()
    tr.close()


@pytest.mark.parametrize("blocker", ["diffuse", "glass"])
def test_world_samples_in_pieces_are_the_same_on_any_threads(blocker):
    """The world's light (:meth:`WorldLight.irradiance`, with sides' guides, the glossy lobes'
    part and the learned guide) split into pieces on two threads and on one: the same
    estimates, rays and learned sums, where shadow rays pass glass too; and without glass, the
    same as one call on all the points."""
    from raybundle.lights.world_light import GUIDE_CELLS, SideSums, WorldLight
    from raybundle.scene.build import build_scene
    from raybundle.scene.materials import MaterialTable
    from raybundle.scene.world import World
    from raybundle.tracing import visibility
    from raybundle.tracing.visibility import RayTracer

    from test_world import sky_and_ground

    block = dict(name="blocker", diffuse=(0.2, 0.2, 0.2))
    if blocker == "glass":
        block.update(transmission=1.0, transmission_ior=1.5)
    mats = MaterialTable.from_list([dict(name="floor", diffuse=(0.5, 0.4, 0.3), glossy=(0.8, 0.8, 0.8),
                                         glossy_weight=0.3, roughness=0.2), block])
    v = np.array([[-3, -3, 0], [3, -3, 0], [3, 3, 0], [-3, 3, 0], [-1, -1, 0.6], [1, -1, 0.6], [1, 1, 0.6],
                  [-1, 1, 0.6]], float)
    sc = build_scene(v, [[0, 1, 2], [0, 2, 3], [4, 6, 5], [4, 7, 6]], [0, 0, 1, 1], mats, world=World(sky_and_ground()))
    rng = np.random.default_rng(5)
    n = 20000
    p = np.c_[rng.uniform(-2.0, 2.0, (n, 2)), np.zeros(n)]
    up = np.tile([0.0, 0.0, 1.0], (n, 1))
    eye = _unit(np.c_[rng.normal(size=(n, 2)) * 0.5, np.ones(n)])
    sides = rng.integers(0, sc.n_sides, n)
    guide = WorldLight.guide_of(rng.random((sc.n_sides, GUIDE_CELLS)) ** 8)
    glossy = np.nonzero(rng.random(n) < 0.5)[0]
    u = rng.random((n, 2, 3))

    def run(threads, fewest=visibility.PIECE_MIN):
        tr = RayTracer(sc, threads=threads)
        wl = WorldLight(sc.world, tr)
        visibility.PIECE_MIN, before = fewest, visibility.PIECE_MIN
        try:
            e, lobe = wl.irradiance(p, up, u, (guide, sides), learn=sides,
                                    lobe=(sc.materials, glossy, np.zeros(len(glossy), int), eye[glossy]))
        finally:
            visibility.PIECE_MIN = before
        tr.close()
        return e, lobe, wl.rays, *wl.learned_rows()

    two, one = run(2), run(1)
    for g, w in zip(two, one):
        assert np.any(w != 0) and np.array_equal(g, w)
    if blocker == "diffuse":
        for g, w in zip(two, run(2, 10 * n)):
            assert np.array_equal(g, w)
