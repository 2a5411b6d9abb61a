"""Multiple importance sampling of mesh lights seen in glossy lobes.

The densities the power heuristic needs are checked against the samplers that use them
(the lobe's against ``sample_glossy``'s histogram and its weights, the mesh light's against
the irradiance ``sample`` returns), and the image estimate with MIS against the one with
light samples alone: the same mean (batch-means standard errors, fixed seeds), a fraction of
the variance on the highlight.
"""
import numpy as np
import pytest

from raybundle.app import pipeline
from raybundle.imaging.settings import RenderSettings
from raybundle.lights.sources import MeshLight
from raybundle.methods.stochastic_iteration import StochasticIterationSolver
from raybundle.patches.layout import subdivide
from raybundle.scene.build import build_scene
from raybundle.scene.camera import Camera
from raybundle.scene.materials import MaterialTable
from raybundle.scene.principled import principled_material

MATS = MaterialTable.from_list([
    dict(name="ggx", glossy=(0.9, 0.8, 0.7), roughness=0.4, glossy_weight=1.0),
    dict(name="mix", diffuse=(0.5, 0.5, 0.5), glossy=(0.8, 0.8, 0.8), roughness=0.25, glossy_weight=0.5),
    principled_material((0.6, 0.3, 0.2), roughness=0.35, name="principled"),
])


def test_glossy_pdf_is_the_density_of_sample_glossy():
    """Per material: the histogram of 400k drawn directions over 8 x 8 (cos theta, phi)
    cells against the pdf integrated over each cell (within 5 binomial standard errors
    plus 0.1% of the samples), and ``weight == f_glossy cos / pdf`` sample by sample."""
    rng = np.random.default_rng(4)
    n_s = 400_000
    normal = np.tile([0.0, 0.0, 1.0], (n_s, 1))
    w_out = np.array([np.sin(0.7), 0.0, np.cos(0.7)])
    for m in range(len(MATS)):
        mat = np.full(n_s, m)
        w_i, weight = MATS.sample_glossy(mat, normal, w_out, rng.random((n_s, 2)))
        up = w_i[:, 2] > 0
        pdf = MATS.glossy_pdf(mat[up], normal[up], w_i[up], np.broadcast_to(w_out, (up.sum(), 3)))
        f = MATS.brdf(mat[up], normal[up], -w_i[up], np.broadcast_to(w_out, (up.sum(), 3)), diffuse=False)
        live = weight[up].max(axis=1) > 0
        assert np.allclose(weight[up][live], f[live] * w_i[up][live, 2:3] / pdf[live, None], rtol=1e-6)
        # histogram over z = cos theta in [0, 1] (8 bins) and phi (8 bins) against the integral of pdf
        k, sub = 8, 48
        zb = np.minimum((w_i[up, 2] * k).astype(int), k - 1)
        pb = np.minimum(((np.arctan2(w_i[up, 1], w_i[up, 0]) % (2 * np.pi)) / (2 * np.pi) * k).astype(int), k - 1)
        observed = np.bincount(zb * k + pb, minlength=k * k)
        z = (np.arange(k * sub) + 0.5) / (k * sub)
        phi = (np.arange(k * sub) + 0.5) / (k * sub) * 2 * np.pi
        zz, pp = np.meshgrid(z, phi, indexing="ij")
        s = np.sqrt(1 - zz * zz)
        d = np.stack([s * np.cos(pp), s * np.sin(pp), zz], axis=-1).reshape(-1, 3)
        q = MATS.glossy_pdf(np.full(len(d), m), np.tile([0.0, 0.0, 1.0], (len(d), 1)), d,
                            np.broadcast_to(w_out, d.shape))
        cell = (1.0 / (k * sub)) * (2 * np.pi / (k * sub))            # dz dphi = solid angle
        expected = n_s * (q * cell).reshape(k, sub, k, sub).sum(axis=(1, 3)).ravel()
        assert np.all(np.abs(observed - expected) < 5 * np.sqrt(expected + 1) + 1e-3 * n_s), m


def lamp_over_plane(roughness=0.08, lamp="mesh"):
    """A glossy plane (2 x 2 m) and a small one-sided lamp (0.3 x 0.3 m, facing down) 1 m
    above it, seen by a camera in the lamp's mirror direction; black world.  ``lamp``: an
    emitting quad ("mesh") or a Blender area light ("area", not geometry)."""
    from raybundle.scene.model import AreaLights

    v = np.array([[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0],
                  [-0.15, -0.15, 1], [0.15, -0.15, 1], [0.15, 0.15, 1], [-0.15, 0.15, 1]], float)
    t = [[0, 1, 2], [0, 2, 3], [4, 6, 5], [4, 7, 6]]
    mats = MaterialTable.from_list([dict(name="plane", glossy=(0.9, 0.9, 0.9), roughness=roughness, glossy_weight=1.0),
                                    dict(name="lamp", emission=(5.0, 5.0, 5.0))])
    cam = Camera.look_at((-2.0, 0, 1.0), (-0.5, 0, 0), (0, 0, 1), 40, 36, (32, 32))
    if lamp == "area":
        area = AreaLights(center=[[0, 0, 1]], axis_u=[[0.15, 0, 0]], axis_v=[[0, 0.15, 0]], normal=[[0, 0, -1]],
                          shape=[0], radiance=[[5.0, 5.0, 5.0]])
        return subdivide(build_scene(v[:4], t[:2], [0, 0], mats, camera=cam, area_lights=area), patches=16)
    return subdivide(build_scene(v, t, [0, 0, 1, 1], mats, camera=cam), patches=16)


def test_mesh_light_pdf_matches_its_sampler():
    """``MeshLight.pdf`` of each sampled direction equals ``Le cos / e`` of the sample, near
    the lamp (solid-angle sampling) and far from it (area sampling)."""
    sc = lamp_over_plane()
    r = pipeline.make_renderer(sc, RenderSettings(seed=1))
    light = next(li for li in r.direct.area_lights if isinstance(li, MeshLight))
    rng = np.random.default_rng(2)
    for height in (0.999, 0.95, 0.0):                 # just under the lamp, 5 cm, 1 m
        pts = np.column_stack([rng.uniform(-0.5, 0.5, 2000), rng.uniform(-0.5, 0.5, 2000), np.full(2000, height)])
        y, e = light.sample(pts, rng.random((2000, 3)))
        lit = e[:, 0] > 0
        # which of the lamp's triangles holds y: the one whose barycentrics are all >= 0
        c = sc.triangle_corners[light.triangles]
        k = np.zeros(len(y), int)
        for j in range(len(c)):
            a, b, cc = c[j]
            m = np.stack([b - a, cc - a], axis=1)
            uv = np.linalg.lstsq(m, (y - a).T, rcond=None)[0].T
            k[(uv >= -1e-9).all(axis=1) & (uv.sum(axis=1) <= 1 + 1e-9)] = j
        # sample(): e = Le * (solid angle estimate) = Le / pdf, on a plane facing the light
        expected = light.radiance[0] / e[lit, 0]
        got = light.pdf(pts[lit], k[lit], y[lit])
        assert lit.mean() > 0.9 and np.allclose(got, expected, rtol=1e-6), height


def pass_values(scene, mis, passes, seed):
    """Per-pass pixel estimates (passes, N, 3) of the direct and glossy part of ``scene``, no
    iteration; ``mis``: ``glossy_mis``."""
    r = pipeline.make_renderer(scene, RenderSettings(seed=seed, glossy_mis=mis))
    if scene.world is not None and scene.world.emits:
        assert (r.glossy_paths.world_light is not None) == mis         # world samples only with MIS
    out = []
    for _ in range(passes):
        before, n_before, g_before = r.pass_sum.copy(), r.pass_samples.copy(), r.gather_sum.copy()
        r.image_pass()
        out.append((r.pass_sum - before) / (r.pass_samples - n_before)[:, None] + r.gather_sum - g_before)
    r.tracer.close()
    return np.array(out)


def highlight_batches(roughness, passes=320, batches=20, lamp="mesh"):
    """Per-pass sums over the highlight (the brightest 10% of pixels) with and without MIS,
    and their batch means (batches,) each."""
    with_mis = pass_values(lamp_over_plane(roughness, lamp), True, passes, seed=5).sum(axis=2)
    without = pass_values(lamp_over_plane(roughness, lamp), False, passes, seed=6).sum(axis=2)
    mean = 0.5 * (with_mis.mean(axis=0) + without.mean(axis=0))
    hi = np.nonzero(mean > np.percentile(mean, 90))[0]
    assert len(hi) > 20
    y = [x[:, hi] for x in (with_mis, without)]
    return y, [v.reshape(batches, passes // batches, -1).mean(axis=1).sum(axis=1) for v in y]


@pytest.mark.parametrize("lamp", ["mesh", "area"])
def test_mis_keeps_the_mean(lamp):
    """A GGX plane (roughness 0.5) reflecting a lamp (an emitting quad, or an area light the
    lobe's rays meet though it is no geometry): the highlight's mean with MIS equals the
    one with light samples alone within 4.5 standard errors of the difference (20 batch means
    of 16 passes each, fixed seeds), and that standard error is under 1%."""
    _, (b_mis, b_ls) = highlight_batches(0.5, lamp=lamp)
    se = np.sqrt(b_mis.var(ddof=1) / len(b_mis) + b_ls.var(ddof=1) / len(b_ls))
    assert se < 0.01 * b_ls.mean()
    assert abs(b_mis.mean() - b_ls.mean()) < 4.5 * se, (b_mis.mean(), b_ls.mean(), se)


@pytest.mark.parametrize("lamp", ["mesh", "area"])
def test_mis_cuts_the_variance_of_a_sharp_highlight(lamp):
    """Roughness 0.08: light samples alone find the lamp's reflection rarely and with a
    huge BRDF value (per-pass variance over 100 times MIS's when measured); MIS stays within
    the light-sample estimate's standard error and has under a tenth of its variance.  Area
    lights had light samples alone (the full-material hall of the interior bench: single
    pixels 300 times too bright at 60 s)."""
    (y_mis, y_ls), (b_mis, b_ls) = highlight_batches(0.08, lamp=lamp)
    se = np.sqrt(b_mis.var(ddof=1) / len(b_mis) + b_ls.var(ddof=1) / len(b_ls))
    assert abs(b_mis.mean() - b_ls.mean()) < 4.5 * se, (b_mis.mean(), b_ls.mean(), se)
    assert y_mis.var(axis=0).sum() < 0.1 * y_ls.var(axis=0).sum()


@pytest.mark.parametrize("lamp", ["mesh", "area"])
def test_the_lamps_a_glossy_lobe_meets_count_over_the_solvers_restart(lamp, monkeypatch):
    """What the eye's glossy paths take from the lamps (and the world) does not depend on the
    solver's iterations: it counts with the pass, which the restart of the solver's running
    average after its burn-in keeps; only what the paths read from the solver is dropped there.
    Here (a plane with no diffuse lobe under a lamp, black world) that is nothing: the whole
    highlight is in the passes' sum.  The old renderer put it with the solver's part and dropped
    every pass before the restart (the full-material hall of the interior bench: 2/3 of its
    passes at 60 s)."""
    # no warm-up, so the average restarts after burn_in iterations (as a scene whose transient
    # outlasts the warm-up's limit does)
    monkeypatch.setattr(StochasticIterationSolver, "MAX_WARM_UP", 0)
    r = pipeline.make_renderer(lamp_over_plane(0.08, lamp), RenderSettings(seed=3))
    assert r.solver.restart_at == r.solver.burn_in > 0
    r.run(iterations=r.solver.burn_in + 4)
    r.tracer.close()
    assert 0 < r.gather_passes < r.passes
    np.testing.assert_array_equal(r.gather_sum, 0.0)
    assert r.pass_sum.sum() > 0


def plane_under_a_bright_sky_patch(roughness=0.6):
    """A glossy plane (4 x 4 m) under a dim world (0.05) with one small patch of sky 40 times
    as bright (4 x 4 pixels of 64 x 128, about 11 degrees across; too faint to be taken out as a
    sun) in the mirror direction of the camera's view of the plane's middle; no lamps."""
    from raybundle.scene.world import World
    img = np.full((64, 128, 3), 0.05)
    img[18:22, 62:66] = 2.0
    v = np.array([[-2, -2, 0], [2, -2, 0], [2, 2, 0], [-2, 2, 0]], float)
    mats = MaterialTable.from_list([dict(name="plane", glossy=(0.9, 0.9, 0.9), roughness=roughness, glossy_weight=1.0)])
    cam = Camera.look_at((-2.0, 0, 1.0), (-0.5, 0, 0), (0, 0, 1), 40, 36, (24, 24))
    return build_scene(v, [[0, 1, 2], [0, 2, 3]], [0, 0], mats, camera=cam, world=World(img), triangle_patch=[0, 0])


def test_world_samples_share_the_sky_with_the_glossy_lobe():
    """A rough GGX plane (0.6) reflecting a small bright patch of sky: with world samples and
    the lobe's rays combined by MIS the image has the mean of the lobe's rays alone (within 4.5
    standard errors of the difference: 20 batch means of 16 passes, fixed seeds) and a fraction
    of its per-pass variance where the patch is reflected (the lobe's rays find the patch
    rarely).  The lobe shares the diffuse lobe's 4 world samples per pixel, weighted with the
    sample counts: a twelfth of the variance; with one world sample of its own, a quarter."""
    passes, batches = 320, 20
    y_mis, y_lobe = (pass_values(pipeline.prepare(plane_under_a_bright_sky_patch(), patches=1), mis, passes,
                                 seed).sum(axis=2) for mis, seed in ((True, 5), (False, 6)))
    mean = 0.5 * (y_mis.mean(axis=0) + y_lobe.mean(axis=0))
    hi = np.nonzero(mean > np.percentile(mean, 75))[0]
    b_mis, b_lobe = (v[:, hi].reshape(batches, passes // batches, -1).mean(axis=1).sum(axis=1) for v in (y_mis, y_lobe))
    se = np.sqrt(b_mis.var(ddof=1) / batches + b_lobe.var(ddof=1) / batches)
    assert se < 0.02 * b_lobe.mean()
    assert abs(b_mis.mean() - b_lobe.mean()) < 4.5 * se, (b_mis.mean(), b_lobe.mean(), se)
    ratio = y_mis[:, hi].var(axis=0).sum() / y_lobe[:, hi].var(axis=0).sum()
    assert ratio < 0.13, ratio                    # measured 0.079; one sample of its own 0.26; the rays alone 1
