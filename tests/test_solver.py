"""The stochastic-iteration solver against analytic answers (furnaces), and its controls.

Tolerances come from the estimator's own variance: the run is cut into B batches of
iterations after a burn-in batch; batch means of a quantity are nearly independent (the
iterates' autocorrelation q^k dies within a batch), so their spread gives the standard
error SE of the overall mean, and the test asserts |mean - exact| < 4.5 SE (a two-sided
false-alarm rate below 1e-5 per check) and that SE itself is small (so the test has power).
"""
import threading

import numpy as np
import pytest

from raybundle.app import pipeline
from raybundle.imaging.settings import RenderSettings
from raybundle.scene import builtin as scenes


def furnace_renderer(glossy, sequence, patches=600, seed=0, res=(24, 24), glossy_gather=True, directions=1,
                     **furnace):
    sc = scenes.furnace(glossy=glossy, resolution=res, **furnace)
    sc = pipeline.prepare(sc, patches=patches)
    return pipeline.make_renderer(sc, RenderSettings(sequence=sequence, seed=seed, resolve_samples=4,
                                                     glossy_gather=glossy_gather, directions_per_step=directions))


def batch_means(renderer, batches, per_batch):
    """Per batch: area-weighted patch radiance towards the normals (B, 3) and the image mean (B, 3)."""
    s, r = renderer.solver, renderer
    area = s.area[:, None] / s.area.sum()
    patch_b, img_b = [], []
    r.image_pass()
    for b in range(batches + 1):
        acc = np.zeros(3)
        snap = (r.pass_sum.copy(), r.passes, r.glossy_sum.copy(), r.glossy_iterations,
                s.mean_incoming * s.averaged, r.emission.sum.copy(), r.emission.count.copy(),
                r.gather_sum.copy(), r.gather_passes, r.pass_samples.copy())
        for _ in range(per_batch):
            s.step()
            if not s.diffuse_only:
                r.accumulate_glossy()
            acc += (s.iterate_radiance(s.normal) * area).sum(axis=0)
            if s.stats.iterations % 8 == 0:
                r.image_pass()
        if b == 0:
            continue      # burn-in: the start-up transient (bias O(1/m)) stays out
        d_direct = (r.pass_sum - snap[0]) / np.maximum(r.pass_samples - snap[9], 1)[:, None]
        d_glossy = (r.glossy_sum - snap[2]) / max(r.glossy_iterations - snap[3], 1)
        e_batch = (s.mean_incoming * s.averaged - snap[4]) / per_batch
        d_emission = (r.emission.sum - snap[5]) / np.maximum(r.emission.count - snap[6], 1)[:, None]
        d_gather = (r.gather_sum - snap[7]) / max(r.gather_passes - snap[8], 1)
        img = d_direct + d_emission + d_glossy + d_gather + r.diffuse_indirect(e_batch)
        hit = r.gbuffer.hit
        patch_b.append(acc / per_batch)
        img_b.append(img[hit].mean(axis=0))
    return np.array(patch_b), np.array(img_b)


#: below this share of the exact value a furnace's mean is not asked to settle: the bundles' own
#: sampling of a side's crossings is unbiased to about 0.03% (measured over 3,200 grids a direction),
#: and under the control variate (PatchSolution.transfer) a closed furnace's SE falls to about
#: 0.005%, under that
FLOOR = 1e-3


def assert_converged(samples, exact, max_se):
    mean = samples.mean(axis=0)
    se = samples.std(axis=0, ddof=1) / np.sqrt(len(samples))
    assert np.all(se < max_se * exact), (se, exact)
    assert np.all(np.abs(mean - exact) < 4.5 * se + FLOOR * exact), (mean, exact, se)
    return mean, se


# batch sizes: few iterations, with the SE still well under max_se (the largest channel's SE / exact
# of the image: 0.14, 0.14, 0.12 and 0.05% for the diffuse ones, under the transfer's control variate;
# 0.93, 1.26, 1.45 and 0.46% at 3 times as many iterations without it; 0.44 and 0.23% for the
# glossy ones in 2026-11; 8 a batch in the last would leave batches without an image pass)
@pytest.mark.parametrize("glossy,sequence,batches,per_batch,directions", [
    (False, "prng", 12, 24, 1), (False, "stratified", 12, 30, 1), (False, "pi-powers", 10, 60, 1),
    (False, "stratified", 12, 20, 8), (True, "pi-powers", 10, 20, 1), (True, "stratified", 12, 16, 8)],
    ids=["prng-diffuse", "stratified-diffuse", "pi-powers-diffuse", "stratified-8-diffuse", "pi-powers-glossy",
         "stratified-8-glossy"])
def test_furnace_converges_to_analytic(glossy, sequence, batches, per_batch, directions):
    """Every sequence, and 8 directions per step (diffuse lobe: their mean; glossy lobe: one
    drawn per side), converges to Le / (1 - a); the glossy lobe with one sequence per
    directions count (the sequence's own part is the diffuse runs')."""
    r = furnace_renderer(glossy, sequence, directions=directions)
    exact = r.scene.analytic_radiance
    patch, img = batch_means(r, batches, per_batch)
    assert_converged(patch, exact, max_se=0.02)
    assert_converged(img, exact, max_se=0.02)
    r.tracer.close()


def test_a_furnace_s_iterates_hold_still_under_the_control_variate():
    """In a closed furnace every side receives the same radiance from every direction, so the
    noise of an iterate's E is all in the cosines of its few directions and the grid's
    aliasing: what the control variate of :meth:`PatchSolution.transfer` takes out.  The
    iterate's light over the whole furnace (its area-weighted mean: noise at the scale of walls,
    which the running average keeps longest) spread by 2.3% from one step to the next before,
    at the default 16 directions a step; now by about 0.2%."""
    r = furnace_renderer(False, "stratified", directions=16)
    s, exact = r.solver, np.pi * r.scene.analytic_radiance
    for _ in range(20):
        s.step()
    means = []
    for _ in range(20):
        s.step()
        means.append(np.average(s.incoming / exact, axis=0, weights=s.area).mean())
    assert np.std(means) < 0.006, np.std(means)
    r.tracer.close()


def test_glossy_furnace_with_its_lobes_sent_from_the_iterate(monkeypatch):
    """With every glossy lobe sent from the iterate, ``E_j f_g(t_j, s_j)`` (thesis 3.3; the
    solver does so for weak rough lobes, :meth:`sharp_lobes`), the glossy furnace converges to
    its exact radiance too, and its iterations trace no gather rays (SE 0.5% of the exact)."""
    from raybundle.methods.stochastic_iteration import StochasticIterationSolver

    monkeypatch.setattr(StochasticIterationSolver, "ITERATE_LOBE_PEAK", 1e9)
    r = furnace_renderer(True, "stratified", directions=8)
    s = r.solver
    assert len(s.glossy_patches) and not s.traced_lobe.any()
    gathered = []
    gather = s._gather
    s._gather = lambda points, normals, w: (gathered.append(len(points)), gather(points, normals, w))[1]
    patch, img = batch_means(r, 12, 16)
    assert sum(gathered) == 0
    assert_converged(patch, r.scene.analytic_radiance, max_se=0.02)
    assert_converged(img, r.scene.analytic_radiance, max_se=0.02)
    r.tracer.close()


def test_glossy_furnace_with_its_weak_lobes_gathered_by_chance(monkeypatch):
    """A traced lobe that is a small share of what its side reflects is gathered along a
    direction only with chance share / GATHER_SHARE, weighted by the inverse: unbiased (the
    glossy furnace converges to its exact radiance, SE < 2%) at a fraction of the gather rays.
    Here every lobe takes its chance (GATHER_SHARE 4, a quarter or less)."""
    from raybundle.methods.stochastic_iteration import StochasticIterationSolver

    monkeypatch.setattr(StochasticIterationSolver, "GATHER_SHARE", 4.0)
    r = furnace_renderer(True, "stratified", directions=8)
    s = r.solver
    traced = s.gather_chance[s.traced_lobe]
    assert len(traced) and traced.max() <= 0.25
    gathered = []
    gather = s._gather
    s._gather = lambda points, normals, w: (gathered.append(len(points)), gather(points, normals, w))[1]
    patch, img = batch_means(r, 12, 16)
    # (only the sides a bundle line leaves from are gathered, and no ray below a lobe's horizon)
    per_direction = sum(gathered) / s.stats.directions / s.glossy_send_rays
    assert 0.2 * traced.sum() < per_direction < 1.05 * traced.sum(), (per_direction, traced.sum(), len(traced))
    assert_converged(patch, r.scene.analytic_radiance, max_se=0.02)
    assert_converged(img, r.scene.analytic_radiance, max_se=0.02)
    r.tracer.close()


def test_glossy_furnace_image_without_gather():
    """The thesis' own eye estimator E_i f(t_i, w_eye) per iteration (glossy_gather off)."""
    r = furnace_renderer(True, "prng", glossy_gather=False)
    patch, img = batch_means(r, 12, 40)          # SE 0.64% of the exact
    assert r.glossy_iterations > 0 and not r.settings.glossy_gather
    assert_converged(img, r.scene.analytic_radiance, max_se=0.03)
    r.tracer.close()


def test_halton_converges_to_a_wrong_answer():
    """Thesis 1.2: Halton points driving the iteration bias the result where the same furnace
    driven by a PRNG is not biased: 60 patches of albedo (0.6, 0.3, 0.5), 8 batches of 150
    iterations, measured 6.2 SE low in blue against 1.3 SE at most.  (The 6.8 SE this test
    once showed at 300 patches was the first shot's refinement's bias, which every sequence
    had; Halton's there is below 1 SE.)"""
    with pytest.warns(UserWarning, match="Halton"):
        r = furnace_renderer(False, "halton", patches=60, albedo=(0.6, 0.3, 0.5))
    assert_biased(r, per_batch=150)
    r = furnace_renderer(False, "prng", patches=60, albedo=(0.6, 0.3, 0.5))
    with pytest.raises(AssertionError):
        assert_biased(r, per_batch=150)


def assert_biased(renderer, batches=8, per_batch=75):
    """Some channel of the patch mean lies beyond 4.5 SE of the analytic answer."""
    exact = renderer.scene.analytic_radiance
    try:
        patch, _ = batch_means(renderer, batches, per_batch)
    finally:
        renderer.tracer.close()
    mean = patch.mean(axis=0)
    se = patch.std(axis=0, ddof=1) / np.sqrt(len(patch))
    assert np.any(np.abs(mean - exact) > 4.5 * se), (mean, exact, se)


def test_same_seed_same_image_and_different_seed_differs():
    sc = pipeline.prepare(scenes.cornell(glossy=True, resolution=(32, 32)), patches=300)
    imgs = [pipeline.render(sc, RenderSettings(seed=s, resolve_samples=2), iterations=4).image for s in (5, 5, 6)]
    assert np.array_equal(imgs[0], imgs[1])
    assert not np.array_equal(imgs[0], imgs[2])


def test_stop_flag_returns_valid_partial_image():
    sc = pipeline.prepare(scenes.cornell(resolution=(32, 32)), patches=300)
    stop = threading.Event()
    seen = []

    def progress(frac, info):
        seen.append(info["iterations"])
        if info["iterations"] == 7:
            stop.set()

    res = pipeline.render(sc, RenderSettings(resolve_samples=2), iterations=10_000, progress=progress, stop=stop)
    assert res.cancelled and res.stats["iterations"] == 7 and seen[-1] == 7
    assert np.isfinite(res.image).all() and res.image.mean() > 0.01


def test_keyboard_interrupt_returns_valid_partial_image():
    sc = pipeline.prepare(scenes.cornell(resolution=(32, 32)), patches=300)
    calls = {"n": 0}

    def progress(frac, info):
        calls["n"] += 1
        if calls["n"] == 5:
            raise KeyboardInterrupt

    res = pipeline.render(sc, RenderSettings(resolve_samples=2), iterations=10_000, progress=progress)
    assert res.cancelled and res.stats["iterations"] == 5
    assert np.isfinite(res.image).all() and res.image.mean() > 0.01


def test_diffuse_only_scene_takes_the_view_independent_path():
    r = furnace_renderer(False, "prng", patches=200)
    assert r.solver.diffuse_only and len(r.solver.glossy_patches) == 0
    g = furnace_renderer(True, "prng", patches=200)
    assert not g.solver.diffuse_only


@pytest.mark.parametrize("kwargs,msg", [
    (dict(light_samples=0), "light_samples"), (dict(bundle_resolution=-1), "bundle_resolution"),
    (dict(image_share=1.0), "image_share"), (dict(image_share=-0.1), "image_share"), (dict(first_shot="all"), "first_shot"),
    (dict(glossy_send_rays=0), "glossy_send_rays"), (dict(gather_rays=-2), "gather_rays"),
    (dict(gather_share=1.0), "gather_share"),
])
def test_bad_settings_are_rejected_before_work(kwargs, msg):
    sc = pipeline.prepare(scenes.cornell(resolution=(8, 8)), patches=100)
    with pytest.raises(ValueError, match=msg):
        pipeline.make_renderer(sc, RenderSettings(**kwargs))


def test_bad_run_limits_are_rejected():
    r = furnace_renderer(False, "prng", patches=100, res=(8, 8))
    with pytest.raises(ValueError, match="seconds"):
        r.run(time_limit=float("nan"))
    with pytest.raises(ValueError, match="iterations or a time limit"):
        r.run()
    r.tracer.close()


def test_view_independent_patch_radiance_matches_furnace():
    """patch_radiance (what the add-on writes back as color attributes) converges too."""
    r = furnace_renderer(False, "prng", patches=300, res=(8, 8))
    for _ in range(1500):
        r.solver.step()
    L = r.solver.patch_radiance()
    exact = r.scene.analytic_radiance
    mean = (L * r.solver.area[:, None]).sum(axis=0) / r.solver.area.sum()
    # 1500 iterations: the batch-means SE of this mean is ~0.45% (test_furnace_converges_to_analytic)
    assert np.all(np.abs(mean / exact - 1) < 0.02), mean


def test_short_runs_keep_no_start_up_transient():
    """48 iterations (a 30 s run on this machine): the image mean over 3 seeds is within 0.1%
    (or 3 SE of the seeds' spread) of the analytic radiance.  The glossy eye paths of passes
    made before the solver's average restarted read an average still rising from zero: -0.9%."""
    sc = pipeline.prepare(scenes.load_scene("furnace-glossy"), patches=1000)
    means = []
    for seed in (1, 2, 3):
        img = pipeline.render(sc, RenderSettings(seed=seed), iterations=48,
                              camera=sc.camera.with_resolution(16, 16)).image
        means.append(img.reshape(-1, 3).mean(axis=0) / sc.analytic_radiance - 1)
    means = np.array(means)
    se = means.std(axis=0, ddof=1) / np.sqrt(len(means))
    assert np.all(np.abs(means.mean(axis=0)) < np.maximum(1e-3, 3 * se)), (means, se)


def test_a_furnace_with_a_cut_out_sheet_inside_stays_exact():
    """The diffuse furnace with a two-sided sheet of the same material inside, cut out to a
    checker of coverage 0.1 and 0.9: the light field is still Le / (1 - a) everywhere (the
    sheet emits and reflects where it is; the eye sees it or the wall behind).  The block is a
    first-shot light, so both the bundles' and the first shot's light reach the sheet.  Without
    the sheet's receiving area scaled by its coverage, its patches came out 2.6-10.6% too dark
    and the image 5.9-17.8%; with the first shot's divided by the scaled area too, 0.14-0.45%
    too bright (about 5 standard errors)."""
    from raybundle.scene.build import build_scene
    from raybundle.scene.textures import SurfaceTexture

    base = scenes.furnace(resolution=(24, 24))
    y, z = np.array([0.2, 1.8]), np.array([0.15, 1.35])
    quad = np.array([(0.5, y[0], z[0]), (0.5, y[1], z[0]), (0.5, y[1], z[1]), (0.5, y[0], z[1])])
    v = np.concatenate([base.vertices, quad])
    k = len(base.vertices)
    sheet = np.array([[k, k + 1, k + 2], [k, k + 2, k + 3], [k, k + 2, k + 1], [k, k + 3, k + 2]])
    t = np.concatenate([base.triangles, sheet])
    m = np.concatenate([base.triangle_material, np.zeros(4, np.int64)])
    uv = np.zeros((len(t), 3, 2))
    uv[-4:] = (v[t[-4:]][..., 1:] - (y[0], z[0])) / (y[1] - y[0], z[1] - z[0])
    checker = np.where(np.add.outer(np.arange(8), np.arange(8)) % 2, 0.1, 0.9)
    alpha = np.full(len(t), -1)
    alpha[-4:] = 0
    tex = SurfaceTexture([np.repeat(checker[..., None], 3, axis=2)], np.full(len(t), -1), v[t], uv,
                         face_alpha=alpha)
    with pytest.warns(UserWarning, match="became two-sided"):
        sc = build_scene(v, t, m, base.materials, camera=base.camera, analytic_radiance=base.analytic_radiance,
                         texture=tex)
    r = pipeline.make_renderer(pipeline.prepare(sc, patches=600), RenderSettings(sequence="stratified", seed=0,
                                                                                resolve_samples=4))
    assert r.tracer.cutouts is not None
    patch, img = batch_means(r, 12, 30)
    assert_converged(patch, sc.analytic_radiance, max_se=0.02)
    assert_converged(img, sc.analytic_radiance, max_se=0.02)
    r.tracer.close()


@pytest.mark.parametrize("seeds", [(1, 2, 3, 4)])
def test_eight_iterations_have_the_right_mean(seeds):
    """The running average starts from a warmed-up iterate: eight iterations of a furnace of albedo
    0.8 have its exact mean radiance (averaged from a zero start, 0.58 of it).  Eight iterations'
    area-weighted mean over 16 seeds: sd 0.031 of the exact value; the mean of four seeds is held
    within 4 of its standard errors."""
    exact = scenes.FURNACE_LE[0] / (1 - 0.8)
    got, solvers = [], []
    for seed in seeds:
        sc = pipeline.prepare(scenes.furnace(albedo=0.8, resolution=(16, 16)), patches=600)
        s = pipeline.make_solver(sc, RenderSettings(seed=seed))
        for _ in range(8):
            s.step()
        got.append(float((s.area @ s.patch_radiance()[:, 0]) / s.area.sum() / exact))
        solvers.append(s)
    assert abs(np.mean(got) - 1.0) < 4 * 0.031 / np.sqrt(len(seeds)), got
    assert all(s.averaged == 8 and s.stats.warm_up == s.warm_up_steps > s.burn_in and s.restart_at == 0
               for s in solvers)


def test_the_warm_up_ends_at_the_energy_balance_s_level():
    """Eight iterations of a furnace (albedo 0.8) each have its exact mean radiance, seed by seed:
    the warm-up's iterate is scaled to the level its shape's energy balance gives
    (:mod:`~raybundle.methods.energy_balance`; a closed furnace catches every ray, so the balance
    is exact) and the first iteration's transfer takes the control variate of that start.  Over
    seeds 1-8 the eight iterations' mean came to sd 0.0015 of the exact value, none more than
    0.3% off; unscaled and without the first control, sd 0.025 (seeds 1-4: 1.5, 1.6, 2.8, 1.4%
    off), which fails this."""
    exact = scenes.FURNACE_LE[0] / (1 - 0.8)
    for seed in (1, 2, 3, 4):
        sc = pipeline.prepare(scenes.furnace(albedo=0.8, resolution=(16, 16)), patches=600)
        s = pipeline.make_solver(sc, RenderSettings(seed=seed))
        assert s.level_scale[0] != 1.0 and np.allclose(s.level_scale, s.level_scale[0])
        for _ in range(8):
            s.step()
        got = float((s.area @ s.patch_radiance()[:, 0]) / s.area.sum() / exact)
        assert abs(got - 1.0) < 4 * 0.0015, (seed, got)


def test_the_warm_up_leaves_its_share_of_the_start_up_transient():
    """The warm-up ends with the start-up transient below ``WARM_UP_TRANSIENT`` of the solution.
    Two solvers of one furnace (albedo 0.8, exact incoming ``E = pi L``) warm up with the same
    random operators, one from zero and one from the exact iterate: what still tells them apart
    is the transient the warm-up left, about 0.8^n of E (a product of n random operators: seeds
    1, 3, 4 and 7 left 0.75 to 1.05 times 0.8^31).  Stopped at 1%, as it was, it left 0.9%."""
    from raybundle.lights.direct import DirectLighting
    from raybundle.methods.stochastic_iteration import StochasticIterationSolver
    from raybundle.tracing.visibility import RayTracer

    sc = pipeline.prepare(scenes.furnace(albedo=np.full(3, 0.8), resolution=(16, 16)), patches=600)
    tracer = RayTracer(sc)
    exact = np.pi * scenes.FURNACE_LE[0] / (1 - 0.8)
    try:
        warmed = []
        for start in (0.0, exact):
            s = StochasticIterationSolver(sc, tracer, DirectLighting(sc, tracer), RenderSettings(seed=3))
            s.incoming[:] = start
            s.warm_up()
            warmed.append(s)
    finally:
        tracer.close()
    a, b = warmed
    assert a.warm_up_steps == b.stats.warm_up == 31 and a.restart_at == 0
    left = float(a.area @ (b.incoming - a.incoming)[:, 0]) / a.area.sum() / exact
    assert 0 < left < 2 * StochasticIterationSolver.WARM_UP_TRANSIENT, left


def test_the_warm_up_stops_when_asked():
    """A stop during the warm-up ends the set-up with Cancelled, as every set-up step does."""
    sc = pipeline.prepare(scenes.furnace(albedo=0.8, resolution=(16, 16)), patches=600)
    stop, stages = threading.Event(), []

    def stage(text):
        stages.append(text)
        if text.startswith("warming up"):
            stop.set()
    with pytest.raises(pipeline.Cancelled, match="warming up"):
        pipeline.make_solver(sc, RenderSettings(seed=1), stage=stage, stop=stop)
    assert stages[-1].startswith("warming up the iteration (")


def test_a_gather_ray_reads_a_near_mirror_within_the_scene_s_own_light():
    """A gather ray that meets a sharp glossy side along the mirror of the side's iterate direction
    t_j reads at most the brightest radiance any side sends: the lobe is followed by one more ray
    (weight at most its albedo), not read as the iterate's ``E_j f_g(t_j, -w)``, which is there
    about ``E_j / alpha^2`` (a spike the bundles then carry on into the running average)."""
    sc = pipeline.prepare(scenes.cornell(resolution=(32, 32), mirror_roughness=0.03), patches=300)
    s = pipeline.make_solver(sc, RenderSettings(seed=1))
    for _ in range(2):
        s.step()
    sides = s.glossy_patches[s.traced_lobe]
    sides = sides[s.glossy_incoming[sides].max(axis=1) > 0]
    assert len(sides)
    j = sides[np.argmax(s.glossy_incoming[sides].max(axis=1))]
    t, n = s.receive_direction[j], s.normal[j]
    mirror = t - 2 * (t @ n) * n
    x = sc.triangle_corners[sc.tside_triangle[sc.tside_side == j][0]].mean(axis=0)
    rays = 256
    got, sky = s._gather(np.tile(x + 0.05 * mirror, (rays, 1)), np.tile(mirror, (rays, 1)),
                         np.tile(-mirror, (rays, 1)))
    brightest = s.radiance(s._all_patches, s.normal, diffuse_incoming=s.received(), first_shot_emission=False,
                           glossy_as_diffuse=True).max()
    assert not sky.any() and got.max() > 0
    assert got.max() <= brightest, (got.max(), brightest, s.glossy_incoming[j])
