"""The caustic first shot (raybundle.lights.caustics) against a brute-force one-bounce integral.

A sun lights a glossy floor (GGX, roughness 0.3) whose mirror lobe falls on a diffuse wall
standing on the floor's edge.  Per wall patch, the incoming radiance that the floor's
glossy reflection of the sun brings, ``E_i = integral L_r(y(w), -w) cos dw``, is estimated
by brute force from the wall (cosine-sampled rays, L_r from the floor's BRDF and the sun)
and by the caustic shot (lobe-sampled rays from the floor).  Tolerance: 4.5 times the
combined standard error, each from 10 independent batches (fixed seeds).
"""
import numpy as np

from raybundle.app import pipeline
from raybundle.imaging.settings import RenderSettings
from raybundle.methods.stochastic_iteration import StochasticIterationSolver
from raybundle.patches.layout import subdivide
from raybundle.scene.build import build_scene
from raybundle.scene.camera import Camera
from raybundle.scene.materials import MaterialTable
from raybundle.scene.model import SunLights
from raybundle.tracing.sampling import frames_from_normals, points_on_triangles

SUN = np.array([0.6, 0.0, -0.8])            # travel direction: down and towards +x


def floor_and_wall():
    v = np.array([[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0],          # floor, facing +z
                  [1, -1, 0], [1, 1, 0], [1, 1, 2], [1, -1, 2]], float)    # wall x = 1, facing -x
    t = [[0, 1, 2], [0, 2, 3], [4, 6, 5], [4, 7, 6]]
    mats = MaterialTable.from_list([dict(name="glossy", glossy=(0.8, 0.8, 0.8), roughness=0.3, glossy_weight=1.0),
                                    dict(name="wall", diffuse=(0.5, 0.5, 0.5))])
    cam = Camera.look_at((-3, 0, 1.5), (0.5, 0, 0.5), (0, 0, 1), 35, 36, (16, 16))
    sc = build_scene(v, t, [0, 0, 1, 1], mats, sun_lights=SunLights([SUN], [[1.0, 1.0, 1.0]], [0.0]), camera=cam)
    return subdivide(sc, patches=40)


def brute_force_wall(sc, tracer, sides, rng, per_side=4000, batches=10):
    """(batches, len(sides)) estimates of each wall side's E_i by cosine-weighted rays."""
    mats = sc.materials
    out = np.zeros((batches, len(sides)))
    for k, side in enumerate(sides):
        ts = np.nonzero(sc.tside_side == side)[0]
        area = sc.triangle_area[sc.tside_triangle[ts]]
        for b in range(batches):
            pick = ts[rng.choice(len(ts), per_side, p=area / area.sum())]
            u = rng.random((per_side, 4))
            x = points_on_triangles(sc.triangle_corners[sc.tside_triangle[pick]], u[:, 0], u[:, 1])
            n = sc.tside_normal[pick]
            t, bt = frames_from_normals(n)
            r, phi = np.sqrt(u[:, 2]), 2 * np.pi * u[:, 3]
            w = (r * np.cos(phi))[:, None] * t + (r * np.sin(phi))[:, None] * bt + np.sqrt(1 - u[:, 2])[:, None] * n
            tri, _, _, _ = tracer.first_hit(x + n * tracer.eps, w)
            floor = (tri >= 0) & (sc.triangle_material[np.maximum(tri, 0)] == 0)
            up = np.array([0.0, 0.0, 1.0])
            e_sun = -SUN @ up                                   # irradiance on the floor [W/m^2]
            f = mats.brdf(np.zeros(floor.sum(), int), np.broadcast_to(up, (floor.sum(), 3)),
                          np.broadcast_to(SUN, (floor.sum(), 3)), -w[floor], diffuse=False)[:, 0]
            out[b, k] = np.pi * (e_sun * f).sum() / per_side      # pdf cos/pi: E = pi mean(L)
    return out


def test_caustic_shot_matches_brute_force_one_bounce():
    sc = floor_and_wall()
    r = pipeline.make_renderer(sc, RenderSettings(seed=2))
    s = r.solver
    cs = s.caustic
    assert cs is not None and len(cs.tsides) > 0
    wall = np.nonzero((s.patch_material == 1) & (s.normal[:, 0] < -0.9))[0]
    batches, per_batch = 10, 40_000
    est = []
    start, n_start = cs._sum.copy(), cs.samples                 # the set-up's samples
    for _ in range(batches):
        before, n0 = cs._sum.copy(), cs.samples
        cs.refine(per_batch)
        est.append((cs._sum - before)[wall, 0] / (cs.samples - n0))
    est = np.array(est)
    ref = brute_force_wall(sc, r.tracer, wall, np.random.default_rng(7))
    m_c, m_b = est.mean(axis=0), ref.mean(axis=0)
    se = np.sqrt(est.var(axis=0, ddof=1) / batches + ref.var(axis=0, ddof=1) / batches)
    lit = m_b > 0.05 * m_b.max()
    assert lit.sum() >= 3                                  # the lobe lands on several wall patches
    assert np.all(np.abs(m_c - m_b) < 4.5 * se + 1e-3 * m_b.max()), np.c_[m_c, m_b, se]
    assert np.all(se[lit] < 0.05 * m_b[lit])               # and the check has power
    # the running estimate the solver uses is the mean of all samples, the set-up's too
    assert n_start == s.caustic_refine
    assert np.allclose(cs.E[wall, 0], (start[wall, 0] + per_batch * est.sum(axis=0)) / (n_start + batches * per_batch),
                       rtol=1e-9)
    r.tracer.close()


def test_the_caustic_shot_is_lit_before_the_first_transfer(monkeypatch):
    """The caustic shot takes one refinement's samples at set-up, as the first shot takes its
    initial ones: the warm-up's transfers carry its light on, so the iterate holds it from the
    first iteration.  From zero samples the iterates took it up like albedo^n after the warm-up,
    and a short run was dark (bathroom2 of the interior bench at 8 iterations: x0.966 -> x0.976
    of the reference, four seeds).  Read before any transfer (no warm-up)."""
    monkeypatch.setattr(StochasticIterationSolver, "MAX_WARM_UP", 0)
    s = pipeline.make_solver(floor_and_wall(), RenderSettings(seed=1))
    wall = np.nonzero((s.patch_material == 1) & (s.normal[:, 0] < -0.9))[0]
    assert s.caustic.samples == s.caustic_refine > 0 and s.stats.iterations == 0
    e1 = s.first_shot.E[wall].sum(axis=1)[:, 0]
    assert np.all(s.sharp_incoming(wall)[:, 0] >= e1) and (s.caustic.E[wall, 0] > 0).sum() >= 3
    s.tracer.close()


def test_caustic_light_is_not_sent_twice(monkeypatch):
    """With the caustic shot, glossy sides no longer send the first shot's glossy
    reflection through the bundles; without it (caustics off) they do.  (Read before any
    transfer, no warm-up either, so the iterate adds nothing.)"""
    monkeypatch.setattr(StochasticIterationSolver, "MAX_WARM_UP", 0)
    sc = floor_and_wall()
    on = pipeline.make_renderer(sc, RenderSettings(seed=1)).solver
    off = pipeline.make_renderer(sc, RenderSettings(seed=1, caustics=False)).solver
    assert off.caustic is None
    floor = np.nonzero(on.patch_material == 0)[0]
    mirror = np.broadcast_to(SUN * [1, 1, -1], (len(floor), 3))
    sent_on = on.radiance(floor, mirror, first_shot_emission=False, first_shot_glossy=on.caustic is None)
    sent_off = off.radiance(floor, mirror, first_shot_emission=False, first_shot_glossy=off.caustic is None)
    assert np.all(sent_on == 0) and np.all(sent_off > 0)


def test_caustic_splats_match_brute_force_per_pixel():
    """The caustic light-traced into the pixels (imaging.caustic_splats.CausticSplats.splat) against a
    brute-force integral at the pixels' own points: per wall pixel (all of it wall), jittered
    primary rays find points x, and ``kd / pi E_c(x)`` with ``E_c(x) = integral over the
    floor of L_r(y -> x) cos_x cos_y / r^2 dA_y`` (nothing stands between floor and wall), L_r
    the floor's glossy reflection of the sun, by a 128 x 128 midpoint rule.  Pixel by pixel,
    so a side average (what the patches hold) would fail where the lobe's spot falls off
    across a patch.  Tolerance: 4.5 combined standard errors from 10 and 4 batches."""
    sc = floor_and_wall()
    r = pipeline.make_renderer(sc, RenderSettings(seed=3))
    assert r.caustic_splats is not None
    cam, tracer, mats = r.camera, r.tracer, sc.materials
    n_pix = cam.width * cam.height
    batches = 10
    splat = []
    for _ in range(batches):
        r.caustic_splats.sum[:] = 0.0
        r.caustic_splats.samples = 0
        r.caustic_splats.splat(100_000)
        splat.append(r.caustic_splats.sum[:, 0] / r.caustic_splats.samples)
    splat = np.array(splat)
    rng = np.random.default_rng(11)
    g = (np.arange(128) + 0.5) / 128 * 2 - 1
    fy, fx = np.meshgrid(g, g, indexing="ij")
    floor = np.stack([fx.ravel(), fy.ravel(), np.zeros(fx.size)], axis=1)       # cell area (2/128)^2
    up = np.array([0.0, 0.0, 1.0])
    per_pixel = 8
    pix = np.repeat(np.arange(n_pix), per_pixel)
    brute_batches = 4
    brute, inside = np.zeros((brute_batches, n_pix)), np.ones(n_pix, bool)
    for b in range(brute_batches):
        py, px = np.divmod(pix, cam.width)
        org, d = cam.rays(px + rng.random(len(pix)), py + rng.random(len(pix)))
        tri, t, _, _ = tracer.first_hit(org, d)
        wall = (tri >= 0) & (sc.triangle_material[np.maximum(tri, 0)] == 1)
        inside &= np.bincount(pix, wall, minlength=n_pix) == per_pixel
        e_c = np.zeros(len(pix))
        on = np.nonzero(wall)[0]
        for lo in range(0, len(on), 32):
            i = on[lo:lo + 32]
            v = ((org[i] + t[i, None] * d[i])[:, None, :] - floor[None]).reshape(-1, 3)      # floor -> x
            dist = np.linalg.norm(v, axis=1)
            w_out = v / dist[:, None]
            f = mats.brdf(np.zeros(len(v), int), np.broadcast_to(up, v.shape), np.broadcast_to(SUN, v.shape),
                          w_out, diffuse=False)[:, 0]
            e = (-SUN @ up) * f * w_out[:, 0] * w_out[:, 2] / dist ** 2 * (2 / 128) ** 2
            e_c[i] = e.reshape(len(i), -1).sum(axis=1)
        brute[b] = 0.5 / np.pi * np.bincount(pix, e_c, minlength=n_pix) / per_pixel
    m_s, m_b = splat.mean(axis=0), brute.mean(axis=0)
    se = np.sqrt(splat.var(axis=0, ddof=1) / batches + brute.var(axis=0, ddof=1) / brute_batches)
    lit = inside & (m_b > 0.2 * m_b[inside].max())
    assert lit.sum() >= 8, lit.sum()
    assert np.all(np.abs(m_s - m_b)[inside] < 4.5 * se[inside] + 1e-3 * m_b.max()), np.c_[m_s, m_b, se][inside]
    assert np.all(se[lit] < 0.05 * m_b[lit])                # the check has power
    assert m_b[lit].max() > 1.5 * m_b[lit].min()            # and the spot varies across the pixels
    r.tracer.close()


def test_caustic_splat_filter_keeps_to_one_surface():
    """The splats' one-pixel tent (CausticSplats.image) averages only over pixels
    that see the same surface: a caustic that is 1 on every wall pixel and 0 on the floor's
    comes back unchanged (no light leaks across the edge), a lone splat spreads to its
    wall neighbours, and once the splats are many the image is the raw average."""
    sc = floor_and_wall()
    r = pipeline.make_renderer(sc, RenderSettings(seed=3))
    g = r.trace_gbuffer(np.full((len(r.eye.pixel), 2), 0.5))
    wall = g.hit & (g.material == 1)
    assert 0 < wall.sum() < len(wall) - 16
    r.caustic_splats.sum[:] = wall[:, None] * 1.0
    r.caustic_splats.samples = 1
    assert np.array_equal(r.caustic_splats.image(), r.caustic_splats.sum)
    lone = np.nonzero(wall.reshape(r.camera.height, r.camera.width)[1:-1, 1:-1])
    p = (lone[0][len(lone[0]) // 2] + 1) * r.camera.width + lone[1][len(lone[0]) // 2] + 1
    r.caustic_splats.sum[:] = 0.0
    r.caustic_splats.sum[p] = 16.0
    img = r.caustic_splats.image()[:, 0]
    assert 0 < img[p] < 16 and np.count_nonzero(img) > 1 and np.all(wall[img > 0])
    r.caustic_splats.samples = r.caustic_splats.FILTER_SAMPLES * len(r.eye.pixel)
    assert np.array_equal(r.caustic_splats.image(), r.caustic_splats.sum / r.caustic_splats.samples)
    r.tracer.close()


def test_caustic_draws_make_no_copy_of_the_first_shot_per_tside():
    """The caustic shot's draw (:meth:`~raybundle.lights.caustics.CausticShot.sample`) picks its
    tsides by power without a (T, L, 3) copy of the first shot: under 40 bytes per caustic tside
    at its peak for one light (with the copy, 51)."""
    import tracemalloc

    s = pipeline.make_solver(subdivide(floor_and_wall(), patches=40000), RenderSettings(seed=2))
    cs, rng = s.caustic, np.random.default_rng(0)
    cs.sample(100, rng)
    tracemalloc.start()
    try:
        base = tracemalloc.get_traced_memory()[0]
        cs.sample(100, rng)
        peak = tracemalloc.get_traced_memory()[1] - base
    finally:
        tracemalloc.stop()
    assert s.first_shot.n_lights == 1 and len(cs.tsides) > 10_000
    assert peak < 40 * len(cs.tsides), peak / len(cs.tsides)


def test_caustic_splats_hold_one_image_whatever_the_samples():
    """:meth:`~raybundle.imaging.caustic_splats.CausticSplats.splat` in pieces: each piece gives
    its samples' pixels and values, summed into the image in order as the pieces end, not an
    image of its own kept until all have ended.  At 600 x 600 pixels and 16 pieces the draw's
    peak stays under two images (with an image a piece, over sixteen)."""
    import tracemalloc

    from dataclasses import replace

    sc = floor_and_wall()
    sc = replace(sc, camera=Camera.look_at((-3, 0, 1.5), (0.5, 0, 0.5), (0, 0, 1), 35, 36, (600, 600)))
    r = pipeline.make_renderer(sc, RenderSettings(seed=3))
    cs = r.caustic_splats
    cs.splat(1000)
    image = cs.sum.nbytes
    tracemalloc.start()
    try:
        base = tracemalloc.get_traced_memory()[0]
        cs.splat(192_000)                    # 16 pieces (visibility.PIECE_POINTS)
        peak = tracemalloc.get_traced_memory()[1] - base
    finally:
        tracemalloc.stop()
    assert cs.samples == 193_000
    assert peak < 2 * image, peak / image
