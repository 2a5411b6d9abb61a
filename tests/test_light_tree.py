"""The light tree (:mod:`raybundle.lights.light_tree`): its choices against the probabilities
it reports, its importance bound against the light that really arrives, and the direct light
it estimates against each lamp sampled on its own (the same mean; less variance per shadow ray
than lamps chosen uniformly)."""
import numpy as np
import pytest

from raybundle.app import pipeline
from raybundle.imaging.settings import RenderSettings
from raybundle.lights.direct import DirectLighting
from raybundle.lights.light_tree import LightTree, cone_union
from raybundle.scene.build import build_scene
from raybundle.scene.camera import Camera
from raybundle.scene.materials import MaterialTable
from raybundle.scene.model import AreaLights, PointLights


def uv_sphere(center, radius, n_u=16, n_v=8):
    """Vertices and outward triangles of a UV sphere."""
    th = np.linspace(0, np.pi, n_v + 1)
    ph = np.linspace(0, 2 * np.pi, n_u + 1)[:-1]
    v = [(0, 0, 1)] + [(np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)) for t in th[1:-1] for p in ph] + \
        [(0, 0, -1)]
    v = np.asarray(center) + radius * np.asarray(v, float)
    ring = lambda i, j: 1 + i * n_u + (j % n_u)          # noqa: E731
    t = [(0, ring(0, j), ring(0, j + 1)) for j in range(n_u)]
    for i in range(n_v - 2):
        for j in range(n_u):
            t += [(ring(i, j), ring(i + 1, j), ring(i + 1, j + 1)), (ring(i, j), ring(i + 1, j + 1), ring(i, j + 1))]
    last = len(v) - 1
    t += [(last, ring(n_v - 2, j + 1), ring(n_v - 2, j)) for j in range(n_u)]
    return v, np.asarray(t)


def many_lamps(n_points=120, seed=0, res=(24, 16)):
    """A 6 x 6 m floor and a 6 x 3 m wall (diffuse 0.5), a glowing sphere (both sides emit, as in
    Blender), two small one-sided emitting quads facing down, one area light, and ``n_points``
    point and spot lights of intensities spread over three decades, at random above the floor."""
    rng = np.random.default_rng(seed)
    v = [(-3, -3, 0), (3, -3, 0), (3, 3, 0), (-3, 3, 0), (-3, 3, 0), (3, 3, 0), (3, 3, 3), (-3, 3, 3)]
    t = [(0, 1, 2), (0, 2, 3), (4, 5, 6), (4, 6, 7)]
    m = [0, 0, 0, 0]
    sv, st = uv_sphere((1.0, 1.0, 1.2), 0.3)
    t += (st + len(v)).tolist()
    m += [1] * len(st)
    v += sv.tolist()
    for cx in (-1.5, 0.5):
        q = len(v)
        v += [(cx, -1, 2), (cx + 0.2, -1, 2), (cx + 0.2, -0.8, 2), (cx, -0.8, 2)]
        t += [(q, q + 2, q + 1), (q, q + 3, q + 2)]
        m += [2, 2]
    mats = MaterialTable.from_list([dict(name="floor", diffuse=(0.5, 0.5, 0.5)),
                                    dict(name="sphere", emission=(20.0, 18.0, 15.0)),
                                    dict(name="panel", emission=(40.0, 40.0, 40.0))])
    pos = np.column_stack([rng.uniform(-2.8, 2.8, n_points), rng.uniform(-2.8, 2.5, n_points),
                           rng.uniform(0.3, 2.8, n_points)])
    inten = 10 ** rng.uniform(-1, 2, n_points)[:, None] * np.array([1.0, 0.9, 0.8])
    spot = np.zeros((n_points, 3))
    spot[::4] = (0, 0, -1)                                    # every fourth a spot pointing down
    cos_half = np.where(np.any(spot != 0, axis=1), np.cos(0.5), -1.0)
    lights = PointLights(position=pos, intensity=inten, spot_direction=spot, spot_cos_half_angle=cos_half,
                         spot_blend=np.full(n_points, 0.2), radius=np.where(np.arange(n_points) % 3 == 0, 0.05, 0.0))
    area = AreaLights(center=[[-2, 2, 2.5]], axis_u=[[0.3, 0, 0]], axis_v=[[0, 0.2, 0]], normal=[[0, 0, -1]],
                      shape=[0], radiance=[[30.0, 30.0, 30.0]])
    two = np.zeros(len(t), bool)
    two[4:4 + len(st)] = True
    cam = Camera.look_at((0, -5.5, 3.0), (0, 0.5, 0.6), (0, 0, 1), 60, 36, res)
    return build_scene(v, t, m, mats, point_lights=lights, area_lights=area, camera=cam, two_sided=two)


def _direct(scene, light_tree="on"):
    from raybundle.tracing.visibility import RayTracer

    return DirectLighting(scene, RayTracer(scene), light_tree=light_tree)


def _points(n, seed):
    """Random points on the floor (normal +z) and the wall (normal -y)."""
    rng = np.random.default_rng(seed)
    floor = np.column_stack([rng.uniform(-2.9, 2.9, n), rng.uniform(-2.9, 2.9, n), np.zeros(n)])
    wall = np.column_stack([rng.uniform(-2.9, 2.9, n), np.full(n, 3.0), rng.uniform(0.05, 2.9, n)])
    nrm = np.r_[np.tile([0.0, 0.0, 1.0], (n, 1)), np.tile([0.0, -1.0, 0.0], (n, 1))]
    return np.r_[floor, wall], nrm


def test_the_tree_draws_each_emitter_with_the_probability_it_reports():
    """At three points: 300k draws binned by emitter against ``pdf`` (within 5 binomial standard
    errors plus 0.05% of the draws), each draw's probability equal to ``pdf`` of what it drew, the
    probabilities summing to 1; the emitters are the sphere's and the quads' triangles, the
    point and spot lights and the area light."""
    d = _direct(many_lamps())
    tree = d.tree
    assert tree.n_emitters == 224 + 4 + 1 + 120
    pts, nrm = _points(2, seed=1)
    rng = np.random.default_rng(2)
    n = 300_000
    for x, nx in zip(pts[[0, 1, 3]], nrm[[0, 1, 3]]):
        em, p, _ = tree.sample(np.tile(x, (n, 1)), np.tile(nx, (n, 1)), rng.random(n))
        pdf = tree.pdf(np.arange(tree.n_emitters), np.tile(x, (tree.n_emitters, 1)), np.tile(nx, (tree.n_emitters, 1)))
        assert pdf.sum() == pytest.approx(1.0, abs=1e-9)
        np.testing.assert_allclose(p, pdf[em], rtol=1e-12)
        count = np.bincount(em, minlength=tree.n_emitters)
        assert np.all(np.abs(count - n * pdf) < 5 * np.sqrt(n * pdf + 1) + 5e-4 * n)


def test_an_emitter_the_tree_never_draws_gives_the_point_nothing():
    """The importance is a bound: wherever the tree gives an emitter probability 0 (below the
    point's horizon, a one-sided quad or the area light seen from behind), 16 samples of that emitter alone give no light there; and the tree does draw
    some emitters everywhere."""
    d = _direct(many_lamps())
    tree = d.tree
    pts, nrm = _points(200, seed=3)
    lights = d.light_list()
    rng = np.random.default_rng(4)
    zero = 0
    for x, nx in zip(pts, nrm):
        pdf = tree.pdf(np.arange(tree.n_emitters), np.tile(x, (tree.n_emitters, 1)), np.tile(nx, (tree.n_emitters, 1)))
        assert pdf.sum() > 0
        for em in np.nonzero(pdf == 0)[0]:
            zero += 1
            light = lights[tree.light[em]]
            x16, n16 = np.tile(x, (16, 1)), np.tile(nx, (16, 1))
            if hasattr(light, "sample_triangle"):
                y, e = light.sample_triangle(x16, np.full(16, tree.k[em]), rng.random(16), rng.random(16))
            else:
                y, e = light.sample(x16, rng.random((16, 3)))
            cos_x = np.einsum("ij,ij->i", n16, y - x16)
            assert np.all((e.max(axis=1) == 0) | (cos_x <= 1e-12)), (em, type(light).__name__)
    assert zero > 100                     # the test met such emitters


def test_the_cone_union_holds_both_cones():
    """Directions inside either of two random cones lie inside their union, which is no wider
    than pi and, where one holds the other, is that one."""
    rng = np.random.default_rng(5)
    n = 2000
    a = rng.normal(size=(n, 3))
    b = rng.normal(size=(n, 3))
    a /= np.linalg.norm(a, axis=1)[:, None]
    b /= np.linalg.norm(b, axis=1)[:, None]
    ta, tb = rng.uniform(0, 1.5, n) * (rng.random(n) < 0.7), rng.uniform(0, 1.5, n) * (rng.random(n) < 0.7)
    axis, theta = cone_union(a, ta, b, tb)
    assert np.all(theta <= np.pi + 1e-12)
    for ax_c, t_c in ((a, ta), (b, tb)):
        # the cone's edge farthest from the union's axis
        ang = np.arccos(np.clip(np.einsum("ij,ij->i", ax_c, axis), -1, 1))
        assert np.all((ang + t_c <= theta + 1e-6) | (theta == np.pi))
    same = np.arccos(np.clip(np.einsum("ij,ij->i", a, b), -1, 1)) + tb <= ta
    np.testing.assert_allclose(theta[same], ta[same])


def _pass_values(scene, light_tree, passes, seed, tree_class=None):
    """Per-pass direct light (passes, pixels, 3) of ``scene`` and the shadow rays per pass."""
    r = pipeline.make_renderer(pipeline.prepare(scene, patches=8), RenderSettings(seed=seed, light_tree=light_tree,
                                                                                  penumbra_samples=1))
    if tree_class is not None:
        r.direct.tree.__class__ = tree_class
    out = []
    rays = r.direct.rays
    for _ in range(passes):
        before, n_before = r.pass_sum.copy(), r.pass_samples.copy()
        r.image_pass()
        out.append((r.pass_sum - before) / (r.pass_samples - n_before)[:, None])
    rays = (r.direct.rays - rays) / passes
    r.tracer.close()
    return np.array(out), rays


class UniformTree(LightTree):
    """Lamps chosen uniformly: each node's importance its emitter count (for the variance test)."""

    def importance(self, nodes, points, normals):
        if not hasattr(self, "_count"):
            count = (self.emitter >= 0).astype(float)
            for i in np.argsort(-self.depth):
                if self.parent[i] >= 0:
                    count[self.parent[i]] += count[i]
            self._count = count
        return self._count[nodes]


def test_the_tree_keeps_the_mean_and_cuts_the_variance_per_shadow_ray():
    """Direct light of 120 point and spot lights, a glowing sphere, two quads and an area light
    on a floor and wall: the image mean with the tree equals the one with every lamp sampled on
    its own (within 4.5 standard errors of 10 batch means each, fixed seeds); and per shadow ray
    its variance is a fraction of the uniform lamp choice's (measured: ...)."""
    scene = many_lamps()
    passes, batches = 60, 10
    tree, tree_rays = _pass_values(scene, "on", passes, seed=5)
    own, own_rays = _pass_values(scene, "off", passes // 6, seed=6)
    uniform, uni_rays = _pass_values(scene, "on", passes, seed=7, tree_class=UniformTree)
    b_tree = tree.sum(axis=(1, 2)).reshape(batches, -1).mean(axis=1)
    b_own = own.sum(axis=(1, 2)).reshape(batches, -1).mean(axis=1)
    se = np.sqrt(b_tree.var(ddof=1) / batches + b_own.var(ddof=1) / batches)
    assert abs(b_tree.mean() - b_own.mean()) < 4.5 * se, (b_tree.mean(), b_own.mean(), se)
    assert se < 0.02 * b_own.mean()
    var_tree = tree.var(axis=0).sum() * tree_rays
    var_uniform = uniform.var(axis=0).sum() * uni_rays
    print("variance x rays: tree", var_tree, "uniform", var_uniform, "own", own.var(axis=0).sum() * own_rays)
    assert var_tree < 0.25 * var_uniform


TREE_MODE = "on"


def plate_under_five_lamps(roughness=0.12):
    """A glossy plate (GGX, 4 x 4 m) under five one-sided square lamps of sides 0.03 to 0.3 m and
    equal power, 1 m up, seen reflected in it by the camera; black world.  The largest is a
    Blender area light (no geometry), the others emitting quads."""
    v = [(-2, -2, 0), (2, -2, 0), (2, 2, 0), (-2, 2, 0)]
    t = [(0, 1, 2), (0, 2, 3)]
    m = [0, 0]
    mats = [dict(name="plate", glossy=(0.9, 0.9, 0.9), roughness=roughness, glossy_weight=1.0)]
    for i, (x, side) in enumerate(zip((-0.8, -0.4, 0.0, 0.4), (0.03, 0.06, 0.12, 0.2))):
        q, h = len(v), side / 2
        v += [(x - h, -h, 1), (x + h, -h, 1), (x + h, h, 1), (x - h, h, 1)]
        t += [(q, q + 2, q + 1), (q, q + 3, q + 2)]
        m += [i + 1, i + 1]
        mats.append(dict(name=f"lamp{i}", emission=(0.2 / side ** 2,) * 3))
    area = AreaLights(center=[[0.8, 0, 1]], axis_u=[[0.15, 0, 0]], axis_v=[[0, 0.15, 0]], normal=[[0, 0, -1]],
                      shape=[0], radiance=[[0.2 / 0.09] * 3])
    cam = Camera.look_at((0, -3, 0.8), (0, -1.67, 0), (0, 0, 1), 75, 36, (48, 16))
    return build_scene(v, t, m, MaterialTable.from_list(mats), camera=cam, area_lights=area)


def test_the_lobes_rays_and_the_trees_samples_combine_without_bias():
    """A plate reflecting five lamps of one power and very different sizes (four emitting quads
    and an area light), the lamps chosen by the tree: the highlights' mean with the glossy lobe's rays combined by MIS (the tree's choice
    in the light samples' density) equals the one with light samples alone, within 4.5 standard
    errors of 20 batch means each (fixed seeds), and has a fraction of its variance."""
    passes, batches = 320, 20
    runs = []
    for mis, seed in ((True, 5), (False, 6)):
        r = pipeline.make_renderer(pipeline.prepare(plate_under_five_lamps(), patches=8),
                                   RenderSettings(seed=seed, light_tree=TREE_MODE, glossy_mis=mis))
        assert (r.direct.tree is not None) == (TREE_MODE == "on")
        out = []
        for _ in range(passes):
            before, n_before, g_before = r.pass_sum.copy(), r.pass_samples.copy(), r.gather_sum.copy()
            r.image_pass()
            out.append(((r.pass_sum - before) / (r.pass_samples - n_before)[:, None] + r.gather_sum - g_before).sum(axis=1))
        r.tracer.close()
        runs.append(np.array(out))
    mean = 0.5 * (runs[0].mean(axis=0) + runs[1].mean(axis=0))
    hi = np.nonzero(mean > np.percentile(mean, 80))[0]
    b_mis, b_ls = (x[:, hi].reshape(batches, passes // batches, -1).mean(axis=1).sum(axis=1) for x in runs)
    se = np.sqrt(b_mis.var(ddof=1) / batches + b_ls.var(ddof=1) / batches)
    assert se < 0.03 * b_ls.mean()
    assert abs(b_mis.mean() - b_ls.mean()) < 4.5 * se, (b_mis.mean(), b_ls.mean(), se)
    print("variance with MIS / light samples alone:", runs[0][:, hi].var(axis=0).sum() / runs[1][:, hi].var(axis=0).sum())
    assert runs[0][:, hi].var(axis=0).sum() < 0.5 * runs[1][:, hi].var(axis=0).sum()


def test_a_pixel_is_the_mean_of_its_samples_not_of_its_passes():
    """Pixels whose passes disagree most take extra samples (the edges of the small lamps'
    highlights in a near-mirror plate).  A pixel's image is the mean of all its samples: over
    12 passes it is nearer a 160-pass image there than the mean of the passes' estimates (whose
    first passes, of one sample each, weigh as much as the later ones of up to 257), in two seeds;
    and it is what the renderer forms (measured: RMS error 0.28 / 0.25 of the passes' mean's)."""
    scene = pipeline.prepare(plate_under_five_lamps(roughness=0.05), patches=8)

    def run(seed, passes):
        r = pipeline.make_renderer(scene, RenderSettings(seed=seed, light_tree="off"))
        values, counts = [], []
        for _ in range(passes):
            before, n_before = r.pass_sum.copy(), r.pass_samples.copy()
            r.image_pass()
            counts.append(r.pass_samples - n_before)
            values.append((r.pass_sum - before) / counts[-1][:, None])
        r.tracer.close()
        return r, np.array(values).sum(axis=2), np.array(counts)

    ref, _, _ = run(1, 160)
    ref = (ref.pass_sum / ref.pass_samples[:, None]).sum(axis=1)
    for seed in (2, 3):
        r, v, c = run(seed, 12)
        extra = np.nonzero(c.sum(axis=0) > 12)[0]
        assert len(extra) >= 10
        by_samples = (v * c).sum(axis=0) / c.sum(axis=0)
        np.testing.assert_allclose(by_samples, (r.pass_sum / r.pass_samples[:, None]).sum(axis=1), rtol=1e-12)
        by_passes = v.mean(axis=0)
        err_s = np.sqrt(((by_samples - ref)[extra] ** 2).mean())
        err_p = np.sqrt(((by_passes - ref)[extra] ** 2).mean())
        print("RMS error, mean of samples / of passes:", err_s / err_p)
        assert err_s < 0.7 * err_p


def test_the_first_shot_and_a_bake_take_the_lamps_through_the_tree():
    """With a light tree the per-patch first shot and a bake's direct light sample the lamps as
    one light (an emitter chosen at each point), not each lamp on its own: the first shot's
    irradiance summed over the floor and wall, and a bake's at 400 points, agree with the
    per-lamp estimates (within 4.5 standard errors of 8 seeds each; measured x0.995 and x1.009,
    standard errors 3.5% and 0.35% with twice the samples)."""
    from raybundle.lights.first_shot import PatchFirstShot
    from raybundle.patches.layout import subdivide

    scene = subdivide(many_lamps(), patches=32)
    pts, nrm = _points(200, seed=8)
    totals = {}
    for mode in ("on", "off"):
        d = _direct(scene, mode)
        assert (len(d.sampled_lights()) == 1) == (mode == "on")
        first, bake = [], []
        for seed in range(8):
            fs = PatchFirstShot(d, np.random.default_rng(seed), initial_samples=16)
            first.append((fs.E.sum(axis=1).mean(axis=1) * fs.receiving_area).sum())
            bake.append(d.irradiance(pts, nrm, np.random.default_rng(seed), samples_per_light=8).sum())
        d.tracer.close()
        totals[mode] = np.array(first), np.array(bake)
    for k, what in enumerate(("first shot", "bake")):
        a, b = totals["on"][k], totals["off"][k]
        se = np.sqrt(a.var(ddof=1) / len(a) + b.var(ddof=1) / len(b))
        print(what, "with the tree / per lamp:", a.mean() / b.mean(), "standard error", se / b.mean())
        assert abs(a.mean() - b.mean()) < 4.5 * se, (what, a.mean(), b.mean(), se)
        assert se < 0.08 * b.mean()
