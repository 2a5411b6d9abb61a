"""The caustic first shot (raybundle.caustics) against a brute-force one-bounce integral.

A sun lights a glossy floor (GGX, roughness 0.3) whose mirror lobe falls on a diffuse wall
standing on the floor's edge.  Per wall patch, the incoming radiance that the floor's
glossy reflection of the sun brings, ``E_i = integral L_r(y(w), -w) cos dw``, is estimated
by brute force from the wall (cosine-sampled rays, L_r from the floor's BRDF and the sun)
and by the caustic shot (lobe-sampled rays from the floor).  Tolerance: 4.5 times the
combined standard error, each from 10 independent batches (fixed seeds).
"""
import numpy as np

from raybundle import pipeline
from raybundle.camera import Camera
from raybundle.imaging import RenderSettings
from raybundle.materials import MaterialTable
from raybundle.sampling import frames_from_normals, points_on_triangles
from raybundle.scene import SunLights, build_scene, subdivide

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
    # the running estimate the solver uses is the mean of all samples
    assert np.allclose(cs.E[wall, 0], est.mean(axis=0), rtol=1e-9)
    r.tracer.close()


def test_caustic_light_is_not_sent_twice():
    """With the caustic shot, glossy sides no longer send the first shot's glossy
    reflection through the bundles; without it (caustics off) they do."""
    sc = floor_and_wall()
    on = pipeline.make_renderer(sc, RenderSettings(seed=1)).solver
    off = pipeline.make_renderer(sc, RenderSettings(seed=1, caustics=False)).solver
    assert off.caustic is None
    floor = np.nonzero(on.patch_material == 0)[0]
    mirror = np.broadcast_to(SUN * [1, 1, -1], (len(floor), 3))
    sent_on = on.radiance(floor, mirror, first_shot_emission=False, first_shot_glossy=on.caustic is None)
    sent_off = off.radiance(floor, mirror, first_shot_emission=False, first_shot_glossy=off.caustic is None)
    assert np.all(sent_on == 0) and np.all(sent_off > 0)
