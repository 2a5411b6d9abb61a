"""First shot and per-pixel direct light against closed forms."""
import numpy as np
import pytest

from raybundle.lights.reflected_direct import reflected_radiance
from raybundle.app import pipeline
from raybundle.lights.direct import DirectLighting
from raybundle.lights.first_shot import PatchFirstShot
from raybundle.patches.clusters import make_patches
from raybundle.patches.layout import subdivide
from raybundle.scene import builtin as scenes
from raybundle.scene.build import build_scene
from raybundle.scene.materials import MaterialTable
from raybundle.scene.model import PointLights
from raybundle.tracing.visibility import RayTracer
from test_lit_splits import lamp_close_over, tiled_floor

LAMP = MaterialTable.from_list([dict(name="floor", diffuse=(0.5, 0.5, 0.5)), dict(name="lamp", emission=(1, 2, 3))])


def corner_form_factor(a, b, h):
    """Differential area to a parallel a x b rectangle at height h, over one corner."""
    A, B = a / h, b / h
    return (A / np.sqrt(1 + A * A) * np.arctan(B / np.sqrt(1 + A * A))
            + B / np.sqrt(1 + B * B) * np.arctan(A / np.sqrt(1 + B * B))) / (2 * np.pi)


def rect_irradiance(x, y, x0, x1, y0, y1, h, le):
    """Irradiance at (x, y, 0) from a Lambertian rectangle [x0,x1]x[y0,y1] at height h facing down."""
    g = lambda a, b: np.sign(a) * np.sign(b) * corner_form_factor(abs(a), abs(b), h)
    ff = g(x1 - x, y1 - y) - g(x0 - x, y1 - y) - g(x1 - x, y0 - y) + g(x0 - x, y0 - y)
    return np.pi * ff * np.asarray(le)


def lamp_scene(point=False):
    s, h = 0.4, 0.5
    v = np.array([[-2, -2, 0], [2, -2, 0], [2, 2, 0], [-2, 2, 0],
                  [-s / 2, -s / 2, h], [-s / 2, s / 2, h], [s / 2, s / 2, h], [s / 2, -s / 2, h]], float)
    t = np.array([[0, 1, 2], [0, 2, 3], [4, 5, 6], [4, 6, 7]])
    lights = PointLights(np.array([[0.3, -0.2, 0.8]]), np.array([[2.0, 1.0, 0.5]])) if point else None
    return build_scene(v, t, [0, 0, 1, 1], LAMP, point_lights=lights)


@pytest.mark.parametrize("x,y", [(0.0, 0.0), (0.5, 0.1), (-1.2, 0.7)])
def test_direct_light_of_area_light_matches_form_factor(x, y, rng):
    sc = lamp_scene()
    tr = RayTracer(sc)
    dl = DirectLighting(sc, tr)
    n = 100_000
    p = np.tile([x, y, 0.0], (n, 1))
    up = np.tile([0, 0, 1.0], (n, 1))
    out = reflected_radiance(dl, p, up, np.zeros(n, int), up, rng)
    exact = 0.5 / np.pi * rect_irradiance(x, y, -0.2, 0.2, -0.2, 0.2, 0.5, [1, 2, 3])
    se = out.std(axis=0) / np.sqrt(n)
    assert np.all(np.abs(out.mean(axis=0) - exact) < 4.5 * se + 1e-12), (out.mean(axis=0), exact, se)
    tr.close()


def test_point_light_direct_is_inverse_square(rng):
    sc = lamp_scene(point=True)
    tr = RayTracer(sc)
    dl = DirectLighting(sc, tr)
    dl.area_lights = []            # isolate the point light
    pts = np.array([[0.0, 0.0, 0.0], [1.0, 1.0, 0.0]])
    up = np.tile([0, 0, 1.0], (2, 1))
    out = reflected_radiance(dl, pts, up, np.zeros(2, int), up, rng)
    lp, intensity = np.array([0.3, -0.2, 0.8]), np.array([2.0, 1.0, 0.5])
    v = lp - pts
    r2 = (v * v).sum(axis=1)
    exact = 0.5 / np.pi * intensity[None] * (v[:, 2] / np.sqrt(r2) / r2)[:, None]
    # the first point lies under the lamp quad (z = 0.5), which shadows it
    assert np.allclose(out[1], exact[1], rtol=1e-9)
    assert np.all(out[0] == 0)
    tr.close()


def test_first_shot_conserves_the_lights_power():
    """In a closed room the block's emitted power pi Le A all lands on the room's patches.

    This catches shadow rays that wrongly hit the light itself (a regression: rays shifted
    off the surface met grazing light planes early and lost 5% of the power).
    """
    sc = pipeline.prepare(scenes.furnace(resolution=(8, 8)), patches=300)
    tr = RayTracer(sc)
    dl = DirectLighting(sc, tr)
    assert len(dl.area_lights) == 1            # the block is small: a first-shot light
    block = dl.area_lights[0]
    reps = []
    for seed in range(6):
        fs = PatchFirstShot(dl, np.random.default_rng(seed), initial_samples=200)
        reps.append((fs.E[:, 0, :] * sc.patch_area[:, None]).sum(axis=0))
    reps = np.array(reps)
    exact = np.pi * block.radiance * block.area
    se = reps.std(axis=0, ddof=1) / np.sqrt(len(reps))
    assert np.all(np.abs(reps.mean(axis=0) - exact) < 4.5 * se + 1e-9 * exact), (reps.mean(axis=0), exact, se)
    assert np.all(se < 0.01 * exact)
    tr.close()


def test_patch_first_shot_matches_closed_form_under_lamp():
    sc = subdivide(lamp_scene(), max_edge=0.05)
    tr = RayTracer(sc)
    dl = DirectLighting(sc, tr)
    fs = PatchFirstShot(dl, np.random.default_rng(0), initial_samples=100)
    floor = np.nonzero(sc.patch_material == 0)[0]
    c = sc.patch_centroid[floor]
    sel = floor[np.linalg.norm(c[:, :2], axis=1) < 0.3]
    # patch average vs. centroid value: irradiance is smooth at 5 cm, 2nd-order error < 1%
    exact = np.array([rect_irradiance(*sc.patch_centroid[i, :2], -0.2, 0.2, -0.2, 0.2, 0.5, [1, 2, 3]) for i in sel])
    rel = fs.E[sel, 0, :] / exact - 1
    assert abs(rel.mean()) < 0.01 and np.abs(rel).max() < 0.05     # measured at 100 samples: 2.4% at most
    # the mean travel direction points down from the lamp
    assert np.all(fs.direction[sel, 0, 2] < -0.7)
    tr.close()


def test_polygon_irradiance_matches_the_rectangle_closed_form_and_clips_at_the_horizon():
    """Lambert's formula (raybundle.lights.polygon.polygon_irradiance) against the closed form of a
    point under a rectangle's corner, and, with the rectangle partly below a tilted
    point's horizon, against dense midpoint quadrature of cos_x cos_l / r^2 (deterministic)."""
    from raybundle.lights.polygon import polygon_irradiance

    a, b, c = 1.3, 0.7, 0.9                   # rectangle [0, a] x [0, b] at height c over the origin
    rect = np.array([[0, 0, c], [a, 0, c], [a, b, c], [0, b, c]], float)
    x, y = a / c, b / c
    f = (x / np.hypot(1, x) * np.arctan(y / np.hypot(1, x)) + y / np.hypot(1, y) * np.arctan(x / np.hypot(1, y))) \
        / (2 * np.pi)
    got = polygon_irradiance(np.zeros((1, 3)), np.array([[0, 0, 1.0]]), rect[None])
    assert np.isclose(got[0], np.pi * f, rtol=1e-12)
    # a normal tilted 70 degrees: part of the rectangle lies below the horizon
    t = np.radians(70)
    normal = np.array([-np.sin(t), 0.0, np.cos(t)])
    p = np.array([0.4, 0.2, 0.0])
    g = (np.arange(1000) + 0.5) / 1000
    u, v = np.meshgrid(g * a, g * b)
    q = np.stack([u.ravel(), v.ravel(), np.full(u.size, c)], axis=1) - p
    r2 = (q * q).sum(axis=1)
    quad = (np.maximum(q @ normal, 0) * c / r2 ** 2).mean() * a * b
    got = polygon_irradiance(p[None], normal[None], rect[None])[0]
    assert 0 < (q @ normal < 0).mean() < 1           # the test really clips
    assert np.isclose(got, quad, rtol=1e-4), (got, quad)
    # wholly below the horizon: nothing; the triangle form (3 corners) and row padding agree
    assert polygon_irradiance(p[None], -np.array([[0, 0, 1.0]]), rect[None])[0] == 0
    two = polygon_irradiance(np.zeros((2, 3)), np.array([[0, 0, 1.0]] * 2), np.stack([rect[[0, 1, 2]], rect[[0, 2, 3]]]))
    assert np.isclose(two.sum(), np.pi * f, rtol=1e-12)


def test_a_concave_outline_with_a_hole_clipped_at_the_horizon_equals_its_clipped_triangles():
    """raybundle.lights.polygon.clipped_edge_irradiance over an L-shaped outline with a square hole
    (cells of a 4 x 4 grid at z = 1, facing down) equals the sum of polygon_irradiance over
    its 26 triangles, each clipped on its own, at random points below it with random
    normals, many of whose horizons cut it (deterministic; agreement to round-off)."""
    from raybundle.lights.polygon import clipped_edge_irradiance, polygon_irradiance

    cells = [(i, j) for i in range(4) for j in range(4) if not (i >= 2 and j >= 2) and (i, j) != (1, 1)]
    triangles, boundary = [], {}
    for i, j in cells:
        q = [(i, j, 4.0), (i, j + 1, 4.0), (i + 1, j + 1, 4.0), (i + 1, j, 4.0)]
        triangles += [[q[0], q[1], q[2]], [q[0], q[2], q[3]]]
        for k in range(4):                      # directed edges; shared ones cancel
            a, b = q[k], q[(k + 1) % 4]
            if (b, a) in boundary:
                del boundary[(b, a)]
            else:
                boundary[(a, b)] = True
    tris = np.array(triangles) / 4.0
    edges = np.array(list(boundary)) / 4.0
    assert len(edges) == 20                     # the L's perimeter, 16 unit edges, and the hole's 4
    rng = np.random.default_rng(0)
    p = rng.normal(size=(3000, 3)) * 0.6 + [0.5, 0.5, 0.3]
    n = rng.normal(size=(3000, 3))
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    p, n = p[p[:, 2] < 1], n[p[:, 2] < 1]
    want = sum(polygon_irradiance(p, n, np.broadcast_to(t, (len(p), 3, 3))) for t in tris)
    got = clipped_edge_irradiance(p, n, edges, [0.0, 0.0, -1.0])
    side = np.einsum("nk,nvk->nv", n, tris.reshape(1, -1, 3) - p[:, None])
    straddle = (side > 0).any(axis=1) & (side < 0).any(axis=1)
    assert straddle.sum() > 500 and (want > 0).sum() > 1000
    assert np.allclose(got, want, rtol=1e-9, atol=1e-12)


def plate_scene():
    """:func:`lamp_scene` with a plate x in [0, 1] half-way up: its shadow on the floor has
    an umbra for x >= 0.2 and a penumbra for -0.2 < x < 0.2 (along y = 0)."""
    s, h = 0.4, 0.5
    v = np.array([[-2, -2, 0], [2, -2, 0], [2, 2, 0], [-2, 2, 0],
                  [-s / 2, -s / 2, h], [-s / 2, s / 2, h], [s / 2, s / 2, h], [s / 2, -s / 2, h],
                  [0, -1, 0.25], [0, 1, 0.25], [1, 1, 0.25], [1, -1, 0.25]], float)
    t = np.array([[0, 1, 2], [0, 2, 3], [4, 5, 6], [4, 6, 7], [8, 9, 10], [8, 10, 11]])
    return build_scene(v, t, [0, 0, 1, 1, 0, 0], LAMP)


def floor_line(x):
    """Points (x, 0, 0) and their upward normals."""
    p = np.stack([x, np.zeros_like(x), np.zeros_like(x)], axis=1)
    return p, np.tile([0, 0, 1.0], (len(p), 1))


def test_control_variate_direct_light_is_exact_where_the_lamp_is_seen_and_unbiased_in_a_penumbra():
    """reflected_radiance(analytic=...) on a floor line from the open floor through the
    plate's penumbra into its umbra, one light sample per estimate.  Where the lamp is
    wholly seen every single estimate is the closed form (the plain estimate spreads,
    so this can fail); in the penumbra the mean of 4,000 estimates per point is within
    4.5 standard errors (from their spread) of a 2,048-ray ratio estimate; in the umbra,
    with the mask off, every estimate is exactly 0.  Fixed seeds."""
    sc = plate_scene()
    tr = RayTracer(sc)
    dl = DirectLighting(sc, tr)
    x = np.linspace(-0.6, 0.6, 61)
    p, up = floor_line(x)
    ref = dl.irradiance(p, up, np.random.default_rng(1), 2048, 2048) * 0.5 / np.pi
    exact = np.array([rect_irradiance(q[0], 0.0, -0.2, 0.2, -0.2, 0.2, 0.5, [1, 2, 3]) for q in p]) * 0.5 / np.pi
    lit, umbra = x < -0.2 - 1e-9, x > 0.2 + 1e-9
    pen = ~lit & ~umbra
    n = 4000
    rep = lambda a: np.repeat(a, n, axis=0)
    mask = rep(~umbra)
    rng = np.random.default_rng(2)
    cv = reflected_radiance(dl, rep(p), rep(up), np.zeros(len(p) * n, int), rep(up), rng,
                               analytic=mask).reshape(len(p), n, 3)
    plain = reflected_radiance(dl, rep(p), rep(up), np.zeros(len(p) * n, int), rep(up), rng).reshape(len(p), n, 3)
    assert np.allclose(cv[lit], exact[lit][:, None], rtol=1e-9, atol=0)
    assert plain[lit].std(axis=1).min() > 1e-4 * exact[lit].max()
    assert np.all(cv[umbra] == 0)
    se = cv[pen].std(axis=1) / np.sqrt(n)
    z = np.abs(cv[pen].mean(axis=1) - ref[pen]) / np.maximum(se, 1e-12)
    assert pen.sum() > 10 and z.max() < 4.5, z.max()
    tr.close()


def plain_light_samples(dl, p, up, k):
    """``(mean, standard error)`` (N,) of ``k`` plain samples a point of the first light of ``dl``
    at points ``p`` facing ``up`` (N, 3), red channel (fixed seed)."""
    rng = np.random.default_rng(0)
    plain = dl.light_samples_at(np.repeat(p, k, 0), np.repeat(up, k, 0), dl.sampled_lights()[0],
                                rng.random((len(p) * k, 3)))[0]
    plain = plain[:, 0].reshape(len(p), k)
    return plain.mean(axis=1), plain.std(axis=1) / np.sqrt(k)


def test_bake_direct_light_is_unbiased_where_a_shadow_begins():
    """DirectLighting.irradiance on the floor line where the plate's penumbra begins (V 0.9-1):
    the mean of 200 estimates (16 rays, 256 in a penumbra) per point is within 4.5 standard
    errors of plain light samples (400,000 per point).  Estimating from the rays that decide
    whether a point lies in a penumbra read the points whose 16 rays all passed as wholly lit:
    1-1.9% too bright there, 4 to 21 standard errors (fails on that code).  Fixed seeds."""
    sc = plate_scene()
    tr = RayTracer(sc)
    dl = DirectLighting(sc, tr)
    p, up = floor_line(np.linspace(-0.19, -0.13, 7))
    ref, se_ref = plain_light_samples(dl, p, up, 400_000)
    # 200 estimates a point, in one call (each row its own random shift: independent estimates)
    runs = dl.irradiance(np.repeat(p, 200, 0), np.repeat(up, 200, 0), np.random.default_rng(0), 16, 256)
    runs = runs[:, 0].reshape(len(p), 200).T
    se = np.hypot(runs.std(axis=0) / np.sqrt(len(runs)), se_ref)
    z = (runs.mean(axis=0) - ref) / se
    assert np.all(ref < 0.999 * rect_irradiance(p[:, 0], 0.0, -0.2, 0.2, -0.2, 0.2, 0.5, 1.0))   # all in the penumbra
    assert np.abs(z).max() < 4.5, z
    tr.close()


def test_unclamped_direct_light_is_unbiased_close_to_a_lamp_with_one_ray():
    """DirectLighting.irradiance with one shadow ray a light at points 6 cm under the lamp of
    :func:`lamp_scene`, half-shaded by a 6 cm strip 3 cm under it: there a blocked sample's
    ``e_s`` can exceed the lamp's ``Le I(x)``, so the control variate's estimate is often
    below 0.  Unclamped (what the final gather sums) the mean of 16,000 estimates a point is within
    4.5 standard errors of plain light samples (200,000 a point); clamped at 0 (what the old code's
    final gather summed) it is 17 standard errors above them in the strip's shadow edge (the old
    gather's one-ray hits next to the bathroom bench room's window: 11% high).  Fixed seeds."""
    s, h = 0.4, 0.5
    v = np.array([[-2, -2, 0], [2, -2, 0], [2, 2, 0], [-2, 2, 0],
                  [-s / 2, -s / 2, h], [-s / 2, s / 2, h], [s / 2, s / 2, h], [s / 2, -s / 2, h],
                  [-0.03, -1, 0.47], [0.03, -1, 0.47], [0.03, 1, 0.47], [-0.03, 1, 0.47]], float)
    t = np.array([[0, 1, 2], [0, 2, 3], [4, 5, 6], [4, 6, 7], [8, 9, 10], [8, 10, 11]])
    sc = build_scene(v, t, [0, 0, 1, 1, 0, 0], LAMP)
    tr = RayTracer(sc)
    dl = DirectLighting(sc, tr)
    p = np.stack([np.linspace(-0.12, 0.12, 9), np.zeros(9), np.full(9, 0.44)], axis=1)
    up = np.tile([0, 0, 1.0], (len(p), 1))
    ref, se_ref = plain_light_samples(dl, p, up, 200_000)
    n = 16000
    z = {}
    for clamp in (False, True):
        runs = dl.irradiance(np.repeat(p, n, 0), np.repeat(up, n, 0), np.random.default_rng(1), 1, clamp=clamp)
        runs = runs[:, 0].reshape(len(p), n)
        z[clamp] = (runs.mean(axis=1) - ref) / np.hypot(runs.std(axis=1) / np.sqrt(n), se_ref)
    assert np.abs(z[False]).max() < 4.5, z[False]
    assert z[True].max() > 4.5, z[True]
    tr.close()


def test_bake_direct_light_spends_more_shadow_rays_in_a_penumbra():
    """DirectLighting.irradiance on a floor line across the penumbra of a plate under the
    lamp: the points whose first 16 shadow rays disagree get 256, so their error against a
    2,048-ray answer falls about 4 times (sqrt(256 / 16)), measured 0.28 of the 16-ray
    error; the fully lit points are exact (analytic light, no shadow).  Fixed seeds."""
    sc = plate_scene()
    tr = RayTracer(sc)
    dl = DirectLighting(sc, tr)
    x = np.linspace(-0.6, 0.0, 200)
    p, up = floor_line(x)
    ref = dl.irradiance(p, up, np.random.default_rng(1), 2048, 2048)
    fixed = dl.irradiance(p, up, np.random.default_rng(2), 16, 16)
    adaptive = dl.irradiance(p, up, np.random.default_rng(2), 16, 256)
    pen = (ref[:, 0] > 0) & (ref[:, 0] < 0.999 * ref[:, 0].max())
    open_ = ref[:, 0] > 0.9999 * rect_irradiance(p[:, 0], 0.0, -0.2, 0.2, -0.2, 0.2, 0.5, 1.0)
    assert pen.sum() > 20 and open_.sum() > 20
    lit = [rect_irradiance(q[0], 0.0, -0.2, 0.2, -0.2, 0.2, 0.5, [1, 2, 3]) for q in p[open_]]
    assert np.allclose(adaptive[open_], lit, rtol=1e-9)
    e_fixed = np.sqrt(((fixed - ref)[pen] ** 2).mean())
    e_adaptive = np.sqrt(((adaptive - ref)[pen] ** 2).mean())
    assert e_adaptive < 0.5 * e_fixed, (e_adaptive, e_fixed)
    tr.close()


def test_a_footprints_direct_light_is_the_centres_times_the_share_that_sees_the_light():
    """A lightmap texel stands for its footprint, as Cycles' bake averages a texel: footprints
    0.1 m wide centred across the hard edge (x = 0) of the plate's shadow under a point light of
    radius 0 straight above it.  Each estimate (16 shadow rays, 256 where they disagree) is, within
    4.5 standard errors over 32 runs, the centre's unoccluded light times the share of the footprint
    lit, ``(0.05 - x) / 0.1`` clipped to [0, 1].  Without a footprint a texel is lit or dark as its
    centre is (a stair-stepped edge).  Fixed seeds."""
    from raybundle.tracing.footprint import Footprint

    corners = plate_scene().triangle_corners[[0, 1, 4, 5]]            # the floor and the plate, no lamp
    sc = build_scene(corners.reshape(-1, 3), np.arange(12).reshape(-1, 3), [0] * 4, LAMP,
                     point_lights=PointLights(np.array([[0.0, 0.0, 0.8]]), np.array([[1.0, 1.0, 1.0]])))
    tr = RayTracer(sc)
    dl = DirectLighting(sc, tr)
    x = np.linspace(-0.06, 0.06, 7)
    p, up = floor_line(x)
    light = dl.sampled_lights()[0]
    centre = dl.light_samples_at(p, up, light, np.zeros((len(p), 3)), unshadowed=True)[3][:, 0]
    runs = 32
    k = np.repeat(np.arange(len(p)), runs)
    floor = np.array([[-2, -2, 0], [2, -2, 0], [0, 2, 0]], float)          # a triangle around the footprints
    fp = Footprint(np.tile([0.1, 0, 0.0], (len(k), 1)), np.tile([0, 0.1, 0.0], (len(k), 1)),
                   np.tile(floor, (len(k), 1, 1)))
    est = dl.irradiance(p[k], up[k], np.random.default_rng(3), 16, 256, footprint=fp)[:, 0].reshape(len(p), runs)
    want = centre * np.clip((0.05 - x) / 0.1, 0.0, 1.0)
    z = (est.mean(axis=1) - want) / (est.std(axis=1) / np.sqrt(runs) + 1e-9 * centre)
    assert np.abs(z).max() < 4.5, (est.mean(axis=1) / centre, z)
    bare = dl.irradiance(p, up, np.random.default_rng(3), 16, 256)[:, 0]
    assert np.allclose(bare, np.where(x < 0, centre, 0.0), rtol=1e-9)
    tr.close()


def test_a_lamp_cut_into_a_grid_integrates_by_its_outline_like_the_whole_lamp():
    """A mesh lamp of 2 x 5 x 5 triangles: its plane's outline is merged to 4 edges, and the
    analytic irradiance (outline where the lamp is above the horizon, clipped triangles
    where the horizon cuts it) equals the two-triangle lamp's at random points."""
    from raybundle.lights.polygon import light_polygon_irradiance
    from raybundle.lights.sources import MeshLight

    def lamp_scene(n):
        g = np.linspace(-0.5, 0.5, n + 1)
        v = np.array([[x, y, 1.0] for y in g for x in g])
        q = [(j * (n + 1) + i, j * (n + 1) + i + 1, (j + 1) * (n + 1) + i + 1, (j + 1) * (n + 1) + i)
             for j in range(n) for i in range(n)]
        t = [[a, c, b] for a, b, c, d in q] + [[a, d, c] for a, b, c, d in q]    # facing down
        floor = np.array([[-3, -3, 0], [3, -3, 0], [3, 3, 0], [-3, 3, 0]], float)
        v = np.concatenate([v, floor])
        f0 = len(v) - 4
        t += [[f0, f0 + 1, f0 + 2], [f0, f0 + 2, f0 + 3]]
        mats = MaterialTable.from_list([dict(name="lamp", emission=(5.0, 5.0, 5.0)),
                                        dict(name="floor", diffuse=(0.5, 0.5, 0.5))])
        sc = build_scene(v, t, [0] * (len(t) - 2) + [1, 1], mats)
        tri = np.nonzero(sc.triangle_material == 0)[0]
        return MeshLight(0, tri, np.cumsum(sc.triangle_area[tri]) / sc.triangle_area[tri].sum(),
                         float(sc.triangle_area[tri].sum()), np.full(3, 5.0), np.zeros(len(tri), bool), sc)

    grid, whole = lamp_scene(5), lamp_scene(1)
    planes = grid.planes
    assert len(planes) == 1 and len(planes[0][5]) == 4
    rng = np.random.default_rng(3)
    p = rng.uniform([-1, -1, 0], [1, 1, 0.99], (500, 3))
    n = rng.normal(size=(500, 3)) + [0, 0, 2]
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    a, ok_a = light_polygon_irradiance(grid, p, n)
    b, ok_b = light_polygon_irradiance(whole, p, n)
    assert ok_a.all() and ok_b.all() and np.allclose(a, b, rtol=1e-9, atol=1e-12)
    assert (np.einsum("ij,ij->i", n, [0, 0, 1] - p) < 0.5).any()      # some points see it cut by the horizon
    # sampling it from 2 mm below: unbiased (4.5 SE, fixed seed) and bounded, as for the
    # two-triangle lamp; triangle by triangle (by area) the estimate is heavy-tailed there
    q = np.array([[0.1, -0.05, 0.998]] * 40000)
    nq = np.tile([0.0, 0.0, 1.0], (40000, 1))
    exact = 5.0 * light_polygon_irradiance(grid, q[:1], nq[:1])[0][0]
    for light, max_rel_std in ((grid, 1.0), (whole, 1.0)):    # measured 0.58 (cos_x over a lamp filling the sky)
        y, e = light.sample(q, np.random.default_rng(5).random((40000, 3)))
        v = y - q
        est = e[:, 0] * np.maximum(np.einsum("ij,ij->i", nq, v) / np.linalg.norm(v, axis=1), 0)
        se = est.std() / np.sqrt(len(est))
        assert abs(est.mean() - exact) < 4.5 * se and est.std() / exact < max_rel_std, (est.mean(), exact, est.std())
    y, e = grid._sample_triangles(q, np.random.default_rng(5).random((40000, 3)))
    v = y - q
    est = e[:, 0] * np.maximum(np.einsum("ij,ij->i", nq, v) / np.linalg.norm(v, axis=1), 0)
    assert est.std() / exact > 2      # measured 5.6


@pytest.mark.parametrize("height", [0.002, 0.05, 0.5, 6.0])
def test_a_large_area_light_close_by_is_sampled_by_solid_angle(height):
    """A 6 x 4 m rectangular Blender area light facing down, ``height`` above a point with a
    tilted normal: the light-sample estimate ``e cos_x`` is unbiased against the analytic
    irradiance (4.5 SE, fixed seed) and bounded (relative std below 1.2, measured 0.62, 0.60,
    0.47 and 0.15).  By area alone (the old sampling) it was heavy-tailed close by: relative
    std 27 at 2 mm, 3.8 at 5 cm, and biased in a finite sample at 2 mm (and through the image's control variate, negative fireflies in
    the pixels next to a hall's large panels)."""
    from raybundle.lights.polygon import light_polygon_irradiance
    from raybundle.lights.sources import ShapeLight

    light = ShapeLight(np.array([0.0, 0.0, 1.0]), np.array([3.0, 0, 0]), np.array([0, 2.0, 0]),
                       np.array([0, 0, -1.0]), False, 24.0, np.array([1.0, 2.0, 3.0]))
    n = 100_000
    q = np.tile([2.1, -1.3, 1.0 - height], (n, 1))
    nq = np.tile(np.array([0.3, 0.1, 1.0]) / np.linalg.norm([0.3, 0.1, 1.0]), (n, 1))
    y, e = light.sample(q, np.random.default_rng(7).random((n, 3)))
    assert np.allclose(y[:, 2], 1.0) and (np.abs(y[:, 0]) <= 3 + 1e-9).all() and (np.abs(y[:, 1]) <= 2 + 1e-9).all()
    v = y - q
    est = e * np.maximum(np.einsum("ij,ij->i", nq, v) / np.linalg.norm(v, axis=1), 0.0)[:, None]
    exact = light_polygon_irradiance(light, q[:1], nq[:1])[0][0] * light.radiance
    se = est.std(axis=0) / np.sqrt(n)
    assert np.all(np.abs(est.mean(axis=0) - exact) < 4.5 * se), (est.mean(axis=0), exact, se)
    assert est[:, 0].std() / exact[0] < 1.2, est[:, 0].std() / exact[0]


def test_an_area_lamps_analytic_irradiance_is_its_clipped_rectangles():
    """A rectangular area lamp's unoccluded ``I(x)``, taken by its outline (Lambert's sum over
    its corners where the point sees it whole), is that of its rectangle clipped to the point's
    horizon (:func:`~raybundle.lights.polygon.polygon_irradiance`) at 20,000 random points and
    normals, half of them with the horizon through the lamp; 0 behind it."""
    from raybundle.lights.polygon import light_polygon_irradiance, polygon_irradiance
    from raybundle.lights.sources import ShapeLight

    rng = np.random.default_rng(4)
    lamp = ShapeLight(np.array([0.2, -0.1, 2.0]), np.array([1.5, 0.3, 0]), np.array([-0.2, 1.0, 0]),
                      np.array([0, 0, -1.0]), False, 4 * np.hypot(1.5, 0.3) * np.hypot(0.2, 1.0), np.ones(3))
    x = rng.uniform(-3, 3, (20_000, 3))
    nx = rng.normal(size=(20_000, 3))
    nx /= np.linalg.norm(nx, axis=1)[:, None]
    corners = np.array([lamp.center + a * lamp.axis_u + b * lamp.axis_v for a, b in ((-1, -1), (1, -1), (1, 1), (-1, 1))])
    got, ok = light_polygon_irradiance(lamp, x, nx)
    want = np.where(x[:, 2] < 2.0, polygon_irradiance(x, nx, np.broadcast_to(corners, (len(x), 4, 3))), 0.0)
    cut = np.any(np.einsum("nck,nk->nc", corners[None] - x[:, None], nx) < 0, axis=1) & (x[:, 2] < 2.0)
    assert ok.all() and 0.3 < cut.mean() and np.allclose(got, want, rtol=1e-9, atol=1e-12)


def test_an_area_lamps_selection_estimate_bounds_its_unoccluded_irradiance():
    """Lamp selection's estimate for a rectangular area lamp is an upper bound of its exact
    unoccluded irradiance (:func:`light_polygon_irradiance`): 200 random rectangles, 2,000
    random points and normals each (measured: at most 0.99993 of it), and within 10% of it
    5 to 10 sizes away facing the lamp.  A point whose tangent plane cuts the lamp through its
    centre is lit by the half above; the guess at the centre gave it 0, so the lamp was taken
    there with probability 1/16 and weighted 16: fireflies on the hall's stair block."""
    from raybundle.lights.polygon import light_polygon_irradiance
    from raybundle.lights.sources import ShapeLight

    rng = np.random.default_rng(1)
    worst = 0.0
    for _ in range(200):
        u, v = rng.normal(size=3), rng.normal(size=3)
        v = np.cross(u, v)
        u, v = u * rng.uniform(0.05, 3) / np.linalg.norm(u), v * rng.uniform(0.05, 3) / np.linalg.norm(v)
        n = np.cross(u, v) / np.linalg.norm(np.cross(u, v))
        lamp = ShapeLight(rng.normal(size=3), u, v, n, False, 4 * np.linalg.norm(u) * np.linalg.norm(v),
                          np.array([1.0, 2.0, 3.0]))
        x = lamp.center + rng.normal(size=(2000, 3)) * rng.uniform(0.1, 5)
        nx = rng.normal(size=(2000, 3))
        nx /= np.linalg.norm(nx, axis=1)[:, None]
        exact, ok = light_polygon_irradiance(lamp, x, nx)
        bound = lamp.selection_estimate(x, nx)
        lit = ok & (exact > 1e-12)
        worst = max(worst, float(np.max(exact[lit] * 2.0 / bound[lit])))
        far = lamp.center + n * rng.uniform(5, 10) * (np.linalg.norm(u) + np.linalg.norm(v))
        e_far, _ = light_polygon_irradiance(lamp, far[None], -n[None])
        assert lamp.selection_estimate(far[None], -n[None])[0] < 1.1 * 2.0 * e_far[0]
    assert worst <= 1.0 + 1e-9, worst
    lamp = ShapeLight(np.zeros(3), np.array([0.5, 0, 0]), np.array([0, 0.5, 0]), np.array([0, 0, -1.0]), False, 1.0,
                      np.ones(3))
    x, nx = np.array([[0.0, 0.0, -1.0]]), np.array([[1.0, 0.0, 0.0]])
    exact, _ = light_polygon_irradiance(lamp, x, nx)
    assert exact[0] > 0.01 and lamp.selection_estimate(x, nx)[0] >= exact[0]


def test_a_lamp_giving_little_light_at_a_point_costs_few_shadow_rays_there():
    """Lamps chosen by their contribution: beside the area lamp of :func:`lamp_scene`, a weak
    point lamp gives a few percent of the light on a floor line and is taken there by chance
    (probability P < 1, weighted 1 / P).  Such a lamp takes no penumbra samples where it is
    taken by chance: the old code took 8 for each (the interior bench's hall spent a fifth of
    its image passes' light samples on 9 lamps inside their fittings giving 0.07% of its
    light).  The estimates stay unbiased: per point, the means of 20,000 estimates agree with
    those of every lamp always taken within 4.5 standard errors."""
    from raybundle.lights.direct import light_bits

    sc = lamp_scene()
    sc.point_lights = PointLights(np.array([[1.5, 0.0, 0.4]]), np.array([[0.08, 0.08, 0.08]]))
    tr = RayTracer(sc)
    dl = DirectLighting(sc, tr)
    assert len(dl.light_list()) == 2
    b = light_bits(2)[1]                                    # the point lamp's bit
    n = 20_000
    p, up = floor_line(np.linspace(-1.0, -0.4, 4))
    P, U, m = np.repeat(p, n, axis=0), np.repeat(up, n, axis=0), np.zeros(len(p) * n, int)
    bits = np.full(len(P), b, np.uint64)

    def estimate(**kw):
        rays = dl.rays
        out = reflected_radiance(dl, P, U, m, U, np.random.default_rng(3), **kw)
        return out.reshape(len(p), n, 3), dl.rays - rays

    always, _ = estimate()
    chosen, r_chosen = estimate(select=np.random.default_rng(4).random(len(P)))
    pen, r_pen = estimate(select=np.random.default_rng(4).random(len(P)),
                          penumbra=(bits, 8, np.random.default_rng(5).random((len(P), 3)), None))
    taken_point = r_chosen - len(P)                         # the area lamp takes one ray at every point
    assert 0.15 * len(P) < taken_point < 0.9 * len(P)        # taken by chance here
    assert r_pen == r_chosen                                 # and then without penumbra samples
    for got in (chosen, pen):
        se = np.sqrt(got.var(axis=1) / n + always.var(axis=1) / n)
        z = np.abs(got.mean(axis=1) - always.mean(axis=1)) / np.maximum(se, 1e-12)
        assert z.max() < 4.5, z.max()
    tr.close()


def glowing_sphere_over_floor(n_u=48, n_v=24):
    """A UV sphere of radius 0.3 m centred 1 m above a floor, emitting on both sides (as Blender's
    meshes do), radiance (1, 2, 3)."""
    from test_light_tree import uv_sphere

    sv, st = uv_sphere((0.0, 0.0, 1.0), 0.3, n_u, n_v)
    v = np.r_[np.array([[-3, -3, 0], [3, -3, 0], [3, 3, 0], [-3, 3, 0]], float), sv]
    t = np.r_[np.array([[0, 1, 2], [0, 2, 3]]), st + 4]
    two = np.r_[np.zeros(2, bool), np.ones(len(st), bool)]
    return build_scene(v, t, [0, 0] + [1] * len(st), LAMP, two_sided=two)


def test_a_glowing_sphere_is_sampled_by_its_bounding_cone():
    """A sphere of 2,256 emitting triangles, both sides: from the floor its samples are directions
    in the cone of its bounding sphere, traced to its triangles.  Their density equals ``pdf``'s
    (``Le cos / e``) and the irradiance agrees with sampling its triangles by area (within 4.5
    standard errors, 4,000 samples at each of 20 points) and with the closed form of an ideal
    sphere, ``pi Le (R / d)^2 cos``, on average to the facets' 1% (measured 0.5% low); per sample its variance is a small
    fraction of the area sampling's (half of whose samples fall on the far side, hidden by the
    front)."""
    sc = glowing_sphere_over_floor()
    d = DirectLighting(sc, RayTracer(sc))
    light = d.area_lights[0]
    assert light._cone is not None and light.planes is None
    rng = np.random.default_rng(3)
    n, ratio = 4000, []
    for x in np.linspace(-2.0, 2.0, 20):
        p = np.tile([x, 0.3 * x, 0.0], (n, 1))
        nrm = np.tile([0.0, 0.0, 1.0], (n, 1))
        y, e = light.sample(p, rng.random((n, 3)))
        ok = e[:, 0] > 0
        assert ok.mean() > 0.99                                # hardly a ray through the facets' gaps
        k = np.full(n, 0)           # any triangle: outside the sphere the density is the cone's
        np.testing.assert_allclose(light.pdf(p[ok], k[ok], y[ok]), light.radiance[0] / e[ok, 0], rtol=1e-9)
        cone = d.light_samples_at(p, nrm, light, rng.random((n, 3)))[0][:, 2]
        # by area: the far side's samples are hidden by the front, the shadow rays decide it
        area_e = d.shadowed(p, nrm, *light._sample_triangles(p, rng.random((n, 3))))[0][:, 2]
        se = np.sqrt(cone.var() / n + area_e.var() / n)
        assert abs(cone.mean() - area_e.mean()) < 4.5 * se, (x, cone.mean(), area_e.mean(), se)
        dist = np.linalg.norm(np.array([0.0, 0.0, 1.0]) - p[0])
        exact = np.pi * 3.0 * (0.3 / dist) ** 2 * (1.0 / dist)
        ratio.append(cone.mean() / exact)
        assert cone.var() < 0.05 * area_e.var()
    assert np.mean(ratio) == pytest.approx(1.0, abs=0.01) and np.ptp(ratio) < 0.03, ratio


@pytest.mark.parametrize("tree", ["off", "on"])
def test_a_lamp_with_cast_shadow_off_lights_through_a_blocker(tree):
    """Lamps with ``shadow`` 0 (Blender's Cast Shadow off) light a floor under a blocking plane as
    if the plane were not there: per pixel and per light sample (:meth:`light_samples_at`, which
    the bakes, the first shot and the caustic shot take), each lamp on its own and through the
    light tree, with the same samples (the estimates are equal); a lamp that casts shadows beside
    them is still blocked."""
    rng = np.random.default_rng(3)
    n = 6
    pos = np.column_stack([rng.uniform(-1, 1, n), rng.uniform(-1, 1, n), rng.uniform(2.0, 3.0, n)])
    floor = [(-3, -3, 0), (3, -3, 0), (3, 3, 0), (-3, 3, 0)]
    lid = [(-2, -2, 1), (2, -2, 1), (2, 2, 1), (-2, 2, 1)]
    mats = MaterialTable.from_list([dict(name="floor", diffuse=(0.5, 0.5, 0.5))])

    def scene(blocker, shadow):
        v = floor + (lid if blocker else [])
        t = [[0, 1, 2], [0, 2, 3]] + ([[4, 5, 6], [4, 6, 7]] if blocker else [])
        return build_scene(np.array(v, float), t, [0] * len(t), mats, two_sided=True,
                           point_lights=PointLights(pos, np.full((n, 3), 20.0), radius=np.full(n, 0.2),
                                                    shadow=shadow))

    pts = np.column_stack([rng.uniform(-1.5, 1.5, (500, 2)), np.zeros(500)])
    up = np.tile([0, 0, 1.0], (500, 1))
    got = {}
    for key, sc in (("open", scene(False, np.zeros(n))), ("shadowless", scene(True, np.zeros(n))),
                    ("one casts", scene(True, np.eye(n)[0]))):
        tr = RayTracer(sc)
        dl = DirectLighting(sc, tr, light_tree=tree)
        got[key] = (reflected_radiance(dl, pts, up, np.zeros(500, int), up, np.random.default_rng(5)),
                    dl.irradiance(pts, up, np.random.default_rng(6), samples_per_light=2))
        tr.close()
    for a, b in zip(got["open"], got["shadowless"]):
        assert np.allclose(a, b), np.abs(a - b).max()
    for a, b in zip(got["one casts"], got["open"]):            # the first lamp's sixth is blocked
        assert a.mean() < 0.95 * b.mean()


@pytest.mark.parametrize("tree", ["off", "on"])
def test_a_linked_lamp_lights_only_its_receivers_and_only_its_blockers_shadow_it(tree):
    """Light and shadow linking (:mod:`raybundle.scene.linking`): lamps of link set 1 light floor A
    and not floor B, and the plane over A (group 2) does not block them; an unlinked lamp beside
    them (set 0) lights both floors and is blocked.  Per pixel and per light sample, each lamp on
    its own and through the light tree: on A the linked lamps give what they give with no plane
    (the same samples), on B nothing."""
    from raybundle.scene.linking import LightLinking

    rng = np.random.default_rng(4)
    n = 6
    pos = np.column_stack([rng.uniform(-1, 1, n), rng.uniform(-1, 1, n), rng.uniform(2.0, 3.0, n)])
    mats = MaterialTable.from_list([dict(name="floor", diffuse=(0.5, 0.5, 0.5))])
    quads = {"A": [(-3, -3, 0), (0, -3, 0), (0, 3, 0), (-3, 3, 0)], "B": [(0, -3, 0), (3, -3, 0), (3, 3, 0), (0, 3, 0)],
             "plane": [(-2.5, -2, 1), (-0.5, -2, 1), (-0.5, 2, 1), (-2.5, 2, 1)]}
    links = LightLinking([0, 0, 1, 1, 2, 2], [[1, 1, 1], [1, 0, 1]], [[1, 1, 1], [1, 1, 0]])

    def scene(names, link, linking):
        v = np.array([c for k in names for c in quads[k]], float)
        t = [[4 * i, 4 * i + 1, 4 * i + 2] for i in range(len(names))] + \
            [[4 * i, 4 * i + 2, 4 * i + 3] for i in range(len(names))]
        src = [2 * i for i in range(len(names))] + [2 * i + 1 for i in range(len(names))]
        return build_scene(v, t, [0] * len(t), mats, two_sided=True, triangle_source=src, linking=linking,
                           point_lights=PointLights(pos, np.full((n, 3), 20.0), radius=np.full(n, 0.2), link=link))

    on_a = np.column_stack([rng.uniform(-2.4, -0.6, (400, 1)), rng.uniform(-1.9, 1.9, (400, 1)), np.zeros(400)])
    on_b = on_a * [-1, 1, 0]
    up = np.tile([0, 0, 1.0], (400, 1))

    def estimates(sc, points, groups):
        tr = RayTracer(sc)
        dl = DirectLighting(sc, tr, light_tree=tree)
        got = (reflected_radiance(dl, points, up, np.zeros(400, int), up, np.random.default_rng(5), receivers=groups),
               dl.irradiance(points, up, np.random.default_rng(6), samples_per_light=2, receivers=groups))
        tr.close()
        return got

    open_a = estimates(scene(["A", "B"], np.zeros(n), None), on_a, None)
    linked = scene(["A", "B", "plane"], np.ones(n), links)
    for a, b in zip(estimates(linked, on_a, np.zeros(400, int)), open_a):
        assert np.allclose(a, b), np.abs(a - b).max()
    for b in estimates(linked, on_b, np.ones(400, int)):
        assert np.all(b == 0)
    one_unlinked = scene(["A", "B", "plane"], np.r_[0, np.ones(n - 1)], links)
    for a, b in zip(estimates(one_unlinked, on_b, np.ones(400, int)), open_a):
        assert 0 < a.mean() < 0.5 * b.mean()               # the unlinked lamp's sixth reaches B


def test_an_ies_file_is_read_as_cycles_reads_it():
    """:func:`raybundle.scene.ies.parse_ies`: the candela values times the multiplier, ballast and
    photometric factors and 4 pi / 177.83; a type C quadrant mirrored to the full circle; the
    profile's values at its grid's directions (v from straight down, h = atan2(x, y) + pi), 0
    above its last vertical angle, and never above :attr:`Profile.peak`; type A refused with a
    one-line error; the ``.npz`` arrays keep the profiles."""
    from raybundle.scene.ies import CANDELA_TO_STRENGTH, IESError, parse_ies

    head = "IESNA:LM-63-2002\n[TEST] x\nTILT=NONE\n1 1000 2.0 4 3 {kind} 2 0.1 0.1 0.0\n0.5 1.0 100\n"
    text = head.format(kind=1) + "0 30 60 90\n0 45 90\n100 200 300 0\n100 400 500 0\n100 600 700 0\n"
    p = parse_ies(text)
    assert np.allclose(np.degrees(p.h_angles), [0, 45, 90, 135, 180, 225, 270, 315, 360])
    assert np.allclose(p.values[[0, 1, 2]] / CANDELA_TO_STRENGTH,
                       [[100, 200, 300, 0], [100, 400, 500, 0], [100, 600, 700, 0]])
    assert np.allclose(p.values[4], p.values[0]) and np.allclose(p.values[6], p.values[2])

    def direction(h, v):
        h, v = np.radians(h) - np.pi, np.radians(v)
        return np.array([[np.sin(v) * np.sin(h), np.sin(v) * np.cos(h), -np.cos(v)]])

    assert p.at(direction(45, 30))[0] == pytest.approx(400 * CANDELA_TO_STRENGTH)
    assert p.at(direction(90, 60))[0] == pytest.approx(700 * CANDELA_TO_STRENGTH)
    assert p.at(direction(45, 120))[0] == 0.0
    rng = np.random.default_rng(1)
    d = rng.normal(size=(20000, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    assert p.at(d).max() <= p.peak
    with pytest.raises(IESError, match="type 3"):
        parse_ies(head.format(kind=3) + "0 30 60 90\n0 45 90\n" + "1 " * 12)
    lights = PointLights([[0, 0, 1.0]], [[1.0, 1, 1]], profile=[0], profiles=[p])
    back = PointLights.from_arrays(lights.to_arrays())
    assert np.allclose(back.profiles[0].values, p.values) and back.profile[0] == 0


def test_the_first_shot_refines_where_its_samples_spread():
    """A 0.4 m lamp 5 cm above a 4 x 4 m floor of 0.15 m patches (the gap is more than a
    quarter patch: no contact cut follows the lamp's outline): the patches under it take
    nearly all of its power pi Le A, those under its edges each lit on part of their area, so
    their samples are 0 or nearly pi Le.  With 16 samples a side and 64 refinements of 64
    samples, the floor's power over 8 seeds is unbiased (4.5 SE) and spreads less than half as
    much as when the refinements went round robin over the floor's triangles alone (measured:
    0.48% against 1.26% of pi Le A)."""
    s, h = 0.4, 0.05
    v = np.array([[-2, -2, 0], [2, -2, 0], [2, 2, 0], [-2, 2, 0],
                  [-s / 2, -s / 2, h], [-s / 2, s / 2, h], [s / 2, s / 2, h], [s / 2, -s / 2, h]], float)
    sc = subdivide(build_scene(v, np.array([[0, 1, 2], [0, 2, 3], [4, 5, 6], [4, 6, 7]]), [0, 0, 1, 1], LAMP),
                   max_edge=0.15)
    tr = RayTracer(sc)
    dl = DirectLighting(sc, tr)
    floor = sc.patch_material[sc.side_patch] == 0
    exact = np.pi * dl.area_lights[0].radiance[0] * s * s

    def spread(round_robin_only):
        got = []
        for seed in range(8):
            fs = PatchFirstShot(dl, np.random.default_rng(seed), initial_samples=16)
            if round_robin_only:
                fs._targeted = lambda n: np.zeros(0, np.int64)
            for _ in range(64):
                fs.refine(64)
            got.append((fs.E[floor, 0, 0] * fs.receiving_area[floor]).sum())
        return np.mean(got), np.std(got, ddof=1)

    mean, sd = spread(False)
    assert abs(mean - exact) < 4.5 * sd / np.sqrt(8), (mean, exact, sd)
    _, sd_round_robin = spread(True)
    assert sd < 0.5 * sd_round_robin, (sd / exact, sd_round_robin / exact)
    tr.close()


def test_the_first_shots_pilot_draws_a_few_points_a_side_not_one_a_triangle():
    """A floor of 48 x 48 tiles grouped into 64 patches under a lamp: E's initial samples take
    one point on each of a cluster's triangles at least (each triangle's mean is kept), but the
    pilot samples that measure a side's spread are ``pilot_samples`` points a side, uniform over
    its area, so the set-up traces at most one shadow ray more a side per pilot sample (they
    were one more a triangle: as many again as E's)."""
    sc = make_patches(tiled_floor(area_lights=lamp_close_over()), patches=64)
    tr = RayTracer(sc)
    try:
        dl = DirectLighting(sc, tr)
        fs = PatchFirstShot(dl, np.random.default_rng(1), initial_samples=16, pilot_samples=4)
        rows = fs.receiving_tsides
        sides = np.unique(sc.tside_side[rows])
        e_rays = sc.tside_samples(16)[rows].sum()
        assert len(rows) > 20 * len(sides)                      # clusters of many triangles
        assert e_rays <= dl.rays <= e_rays + 4 * len(sides), (dl.rays, e_rays, len(sides))
        assert np.all(fs._side_n[sides] == 4)
        assert np.all(fs.E[sides].sum(axis=(1, 2)) > 0)
    finally:
        tr.close()


def test_the_first_shot_is_unbiased_where_lamps_light_slivers_of_sides():
    """A point lamp 2 m above a floor of 0.5 m sides shines through four 2 cm slits between the
    slats of a blind 1 m up: the sides of one column in four are lit on a stripe of a twelfth of
    their width, which most of their samples miss.  Refined where the samples spread, the
    floor's power over 64 seeds is the exact one (the unoccluded irradiance integrated over the
    stripes) within 4 SE.  Had the refinements gone where E's own samples spread, a side whose
    16 samples all missed its stripe would stay dark while one whose samples hit would be
    pulled down to its mean: measured 5.7% low, 7.7 SE."""
    mats = MaterialTable.from_list([dict(name="floor", diffuse=(0.5, 0.5, 0.5))])
    v, f = [[-2, -2, 0], [2, -2, 0], [2, 2, 0], [-2, 2, 0]], [[0, 1, 2], [0, 2, 3]]
    slit, slits = 0.02, [-0.8, -0.3, 0.2, 0.7]
    edges = [-1.0] + [e for c in slits for e in (c - slit / 2, c + slit / 2)] + [1.0]
    for a, b in zip(edges[::2], edges[1::2]):
        n = len(v)
        v += [[a, -1.5, 1], [b, -1.5, 1], [b, 1.5, 1], [a, 1.5, 1]]
        f += [[n, n + 2, n + 1], [n, n + 3, n + 2]]
    sc = subdivide(build_scene(np.array(v, float), np.array(f), [0] * len(f), mats,
                               point_lights=PointLights(np.array([[0, 0, 2.0]]), np.array([[1.0, 1, 1]]))),
                   max_edge=0.5)
    tr = RayTracer(sc)
    dl = DirectLighting(sc, tr)
    corners = sc.triangle_corners[sc.tside_triangle]
    floor = np.zeros(sc.n_sides, bool)
    floor[sc.tside_side[np.all(corners[..., 2] == 0, axis=1)]] = True
    # the exact power: E = I cos / r^2 = 2 I / r^3 on the stripes |x - 2 c| < slit where the floor
    # sees the lamp through a slit (its line to the lamp crosses the blind at x / 2); over y in
    # [-2, 2] it integrates to 8 I / (a^2 sqrt(a^2 + 4)), a^2 = x^2 + 4, then over x by the midpoint rule
    x0 = 2 * slits[0]
    e, _, _ = dl.light_samples_at(np.array([[x0, 0, 0.0]]), np.array([[0, 0, 1.0]]), dl.sampled_lights()[0],
                                  np.zeros((1, 3)))
    intensity = e[0, 0] * (x0 ** 2 + 4) ** 1.5 / 2
    x = 2 * np.array(slits)[:, None] + slit * ((np.arange(1000) + 0.5) / 500 - 1)
    a2 = x * x + 4
    exact = (8 * intensity / (a2 * np.sqrt(a2 + 4))).sum() * slit / 500
    got = []
    for seed in range(64):
        fs = PatchFirstShot(dl, np.random.default_rng(seed), initial_samples=16)
        for _ in range(32):
            fs.refine(64)
        got.append((fs.E[floor, 0, 0] * fs.receiving_area[floor]).sum())
    se = np.std(got, ddof=1) / np.sqrt(len(got))
    assert abs(np.mean(got) - exact) < 4 * se, (np.mean(got) / exact, se / exact)
    tr.close()


def test_first_shot_keeps_its_sums_for_the_tsides_a_light_faces_only():
    """A two-sided floor under a lamp: its undersides face no light and receive nothing, so the
    first shot keeps no sums for them (what chains pool, ``sums()``; half the memory here), and its
    E still comes out of ``set_sums`` from the pooled sums as it was."""
    v = np.array([[-2, -2, 0], [2, -2, 0], [2, 2, 0], [-2, 2, 0]], float)
    sc = subdivide(build_scene(v, [[0, 1, 2], [0, 2, 3]], [0, 0], LAMP, two_sided=True,
                               point_lights=PointLights(np.array([[0.3, -0.2, 0.8]]), np.array([[2.0, 1.0, 0.5]]))),
                   max_edge=0.1)
    tr = RayTracer(sc)
    fs = PatchFirstShot(DirectLighting(sc, tr), np.random.default_rng(0), initial_samples=4)
    fs.refine(500)
    e_sum, d_sum, count = fs.sums()
    assert len(fs.receiving_tsides) == len(sc.tside_triangle) // 2
    assert len(e_sum) == len(d_sum) == len(count) == len(fs.receiving_tsides)
    E = fs.E.copy()
    fs.set_sums(e_sum, d_sum, count)
    np.testing.assert_allclose(fs.E, E, rtol=1e-12, atol=1e-15)
    tr.close()


def test_first_shot_keeps_direction_sums_for_the_directed_sides_only():
    """The mean travel direction serves glossy sides alone: with ``directed`` the other sides
    keep no direction sums (a clay room none: a third of the first shot's memory), while the
    directed sides' ``direction`` and every side's E are the very numbers of a first shot that
    keeps them all, after refinement and after ``set_sums``."""
    sc = subdivide(lamp_scene(point=True), max_edge=0.1)
    tr = RayTracer(sc)
    floor = sc.patch_material[sc.side_patch] == 0
    directed = floor & (sc.patch_centroid[sc.side_patch][:, 0] > 0)
    shots = []
    for which in (None, directed, np.zeros(sc.n_sides, bool)):
        fs = PatchFirstShot(DirectLighting(sc, tr), np.random.default_rng(3), initial_samples=4, directed=which)
        fs.refine(700)
        shots.append(fs)
    every, some, none = shots
    for fs in (some, none):
        np.testing.assert_array_equal(fs.E, every.E)
    np.testing.assert_array_equal(some.direction[directed], every.direction[directed])
    assert not some.direction[~directed].any() and len(none.sums()[1]) == 0
    assert len(some.sums()[1]) == np.isin(sc.tside_side[some.receiving_tsides], np.nonzero(directed)[0]).sum() > 0
    some.set_sums(*some.sums())
    np.testing.assert_allclose(some.direction[directed], every.direction[directed], rtol=1e-12, atol=1e-15)
    tr.close()
