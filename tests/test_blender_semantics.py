"""Blender's semantics in the core: two-sided surfaces and emitters, the world as a
constant environment, spot, sun and area lights, against closed forms.

Statistical checks use fixed seeds; tolerances are 4.5 standard errors of the
estimator, measured from the samples themselves (or from two seeds of the same
render), as the rest of the suite does.
"""
import numpy as np
import pytest

from raybundle.lights.reflected_direct import reflected_radiance
from raybundle.app import pipeline
from raybundle.app.metrics import image_error, light_source_mask
from raybundle.imaging.settings import RenderSettings
from raybundle.lights.direct import DirectLighting
from raybundle.scene import builtin as scenes
from raybundle.scene.build import build_scene
from raybundle.scene.materials import MaterialTable
from raybundle.scene.model import AreaLights, PointLights, SunLights
from raybundle.scene.npz import load_npz
from raybundle.tracing.visibility import RayTracer

FLOOR = MaterialTable.from_list([dict(name="floor", diffuse=(0.5, 0.5, 0.5))])


def blender_cornell(flip=(), full_ceiling=True, materials=None, environment=None, one_sided_lamp=False):
    """The Cornell box as a .blend has it: two-sided, 5-face blocks, and (``full_ceiling``)
    no opening above the lamp, which hangs 0.5 mm under the ceiling."""
    from raybundle.scene.builtin import _CORNELL_QUADS, _block_quads, _mesh, cornell_camera, cornell_to_blender

    quads = [(np.array(q, float), {"green": 2, "red": 1, "light": 3}.get(k, 0)) for k, q in _CORNELL_QUADS.items()
             if not (full_ceiling and k.startswith("ceiling"))]
    if full_ceiling:
        quads.append((np.array([[556.0, 548.8, 0], [556.0, 548.8, 559.2], [0, 548.8, 559.2], [0, 548.8, 0]]), 0))
    for top, h in ((scenes._SHORT_TOP, 165.0), (scenes._TALL_TOP, 330.0)):
        quads += [(q, 0) for q in _block_quads(top, h)[:1] + _block_quads(top, h)[2:]]   # no bottom face
    v, t, m = _mesh(quads)
    t[list(flip)] = t[list(flip)][:, ::-1]
    mats = materials or MaterialTable.from_list(
        [dict(name="white", diffuse=scenes.WHITE), dict(name="red", diffuse=scenes.RED),
         dict(name="green", diffuse=scenes.GREEN), dict(name="light", emission=scenes.CORNELL_LIGHT)])
    two = ~(m == 3) if one_sided_lamp else True
    return build_scene(cornell_to_blender(v), t, m, mats, camera=cornell_camera((48, 48)), two_sided=two,
                       environment=environment)


def render(sc, seed, iterations, patches=1200):
    return pipeline.render(pipeline.prepare(sc, patches=patches), RenderSettings(seed=seed),
                           iterations=iterations).image


def test_environment_furnace_is_exact_on_an_open_two_sided_scene():
    """Every surface emits Le on both sides with albedo a, under a world of radiance
    Le / (1 - a): the radiance is Le / (1 - a) everywhere, on every side, in the
    background too, whatever the (open, non-convex) geometry or normal directions."""
    le, a = 0.3, np.array([0.2, 0.5, 0.7])
    mats = MaterialTable.from_list([dict(name=f"m{k}", diffuse=a, emission=(le,) * 3) for k in range(4)])
    exact = le / (1 - a)
    sc = blender_cornell(flip=range(0, 32, 3), materials=mats, environment=exact)
    imgs = [render(sc, seed, 250) for seed in (1, 2)]
    img = 0.5 * (imgs[0] + imgs[1])
    # noise from the two independent renders: se of the mean over pixels
    se = np.abs(imgs[0] - imgs[1]).reshape(-1, 3).mean(axis=0) / 2
    mean = img.reshape(-1, 3).mean(axis=0)
    assert np.all(np.abs(mean - exact) < 4.5 * se + 0.005 * exact), (mean, exact, se)
    assert np.all(np.abs(img.reshape(-1, 3) / exact - 1).max(axis=0) < 0.25)


def test_flipped_normals_render_the_same():
    """A two-sided scene whose faces are turned around renders like the original:
    the flipped render is as close to the original as a second seed of the original."""
    base = blender_cornell()
    flipped = blender_cornell(flip=range(0, 32, 2))
    a, b, c = render(base, 1, 150), render(flipped, 1, 150), render(base, 2, 150)
    mask = light_source_mask(base)
    same_scene = image_error(c, a, exclude=mask)["raw"]
    assert image_error(b, a, exclude=mask)["raw"] < 1.5 * same_scene + 0.005, same_scene


def test_two_sided_lamp_lights_the_ceiling_above_it(rng):
    """The lamp 0.5 mm under a full ceiling emits from its upper side too: the direct
    irradiance on the ceiling above it and in the rim just outside it equals the
    closed-form form factor of the lamp rectangle (parallel, 0.5 mm away), and the
    estimate is not heavy-tailed there (its standard error stays small); a one-sided
    lamp does not light the ceiling at all."""
    from test_lights import rect_irradiance

    le = np.array(scenes.CORNELL_LIGHT)
    # the lamp spans Cornell x 213..343 mm, z 227..332 mm -> Blender x -0.343..-0.213, y 0.227..0.332
    pts = np.array([[-0.28, 0.28], [-0.212, 0.28], [-0.210, 0.28], [-0.28, 0.226], [-0.28, 0.220]])
    exact = np.array([rect_irradiance(x, y, -0.343, -0.213, 0.227, 0.332, 0.0005, le) for x, y in pts])
    for one_sided in (False, True):
        sc = blender_cornell(one_sided_lamp=one_sided)
        tr = RayTracer(sc)
        dl = DirectLighting(sc, tr)
        n = 20000
        p = np.repeat(np.column_stack([pts, np.full(len(pts), 0.5488)]), n, axis=0)
        down = np.tile([0, 0, -1.0], (len(p), 1))
        white = np.zeros(len(p), int)                              # material 0: the white ceiling
        rad = reflected_radiance(dl, p, down, white, down, rng).reshape(len(pts), n, 3)
        tr.close()
        e = rad.mean(axis=1) * np.pi / np.array(scenes.WHITE)
        se = rad.std(axis=1) / np.sqrt(n) * np.pi / np.array(scenes.WHITE)
        if one_sided:
            assert np.all(e == 0)
            continue
        assert np.all(np.abs(e - exact) < 4.5 * se + 1e-9), (e / exact, se / exact)
        assert np.all(se < 0.02 * exact), se / exact          # bounded: solid-angle sampling near the lamp
    assert exact[0, 0] > 0.99 * np.pi * le[0] and exact[4, 0] < 0.01 * exact[0, 0]    # inside vs 7 mm outside


def plane_scene(**lights):
    v = np.array([[-5, -5, 0], [5, -5, 0], [5, 5, 0], [-5, 5, 0]], float)
    return build_scene(v, [[0, 1, 2], [0, 2, 3]], [0, 0], FLOOR, two_sided=True, **lights)


def direct_irradiance(sc, points, rng, n=20000):
    """Mean and standard error of the direct irradiance at ``points`` on the plane z = 0 (its upper side)."""
    tr = RayTracer(sc)
    dl = DirectLighting(sc, tr)
    k = len(points)
    p = np.repeat(points, n, axis=0)
    up = np.tile([0, 0, 1.0], (len(p), 1))
    rad = reflected_radiance(dl, p, up, np.zeros(len(p), int), up, rng).reshape(k, n, 3) / (0.5 / np.pi)
    tr.close()
    return rad.mean(axis=1), rad.std(axis=1) / np.sqrt(n)


def test_spot_light_cone_and_blend_match_cycles_formula(rng):
    """Spot (Blender's P = 100 W -> I = P / 4 pi) pointing down from 2 m, 60 degree cone,
    blend 0.3: E = I s(theta) cos / r^2 with Cycles' smoothstep attenuation."""
    intensity, h, cos_half, blend = 100 / (4 * np.pi), 2.0, np.cos(np.radians(30)), 0.3
    sc = plane_scene(point_lights=PointLights([[0, 0, h]], [[intensity] * 3], spot_direction=[[0, 0, -1]],
                                              spot_cos_half_angle=[cos_half], spot_blend=[blend]))
    xs = np.array([0.0, 0.8, 1.05, 1.1, 2.0])
    got, se = direct_irradiance(sc, np.stack([xs, 0 * xs, 0 * xs], axis=1), rng, n=4)
    r = np.hypot(xs, h)
    cos = h / r
    t = np.clip((cos - cos_half) / ((1 - cos_half) * blend), 0, 1)
    exact = intensity * (t * t * (3 - 2 * t)) * cos / r ** 2
    assert np.allclose(got[:, 0], exact, rtol=1e-9, atol=1e-12), (got[:, 0], exact)
    assert exact[0] > 0 and 0 < exact[2] < exact[1] and exact[-1] == 0


def test_sun_gives_irradiance_times_cosine(rng):
    d = np.array([0.6, 0.0, -0.8])
    sc = plane_scene(sun_lights=SunLights([d], [[3.0, 2.0, 1.0]], [np.radians(1.0)]))
    got, se = direct_irradiance(sc, np.array([[0.0, 0.0, 0.0], [1.0, -2.0, 0.0]]), rng, n=2000)
    exact = np.array([3.0, 2.0, 1.0]) * 0.8
    assert np.all(np.abs(got - exact) < 4.5 * se + 2e-4 * exact), (got, exact)   # 1 degree cone: cos varies 1e-4


@pytest.mark.parametrize("shape", [0, 1])
def test_area_light_rectangle_and_disk_match_form_factors(shape, rng):
    """A 0.4 m square (or 0.4 m disk) area light 0.5 m above the plane, facing down,
    L = P / (pi A): irradiance below its centre from the closed-form form factors."""
    h, half, le = 0.5, 0.2, np.array([1.0, 2.0, 3.0])
    sc = plane_scene(area_lights=AreaLights([[0, 0, h]], [[half, 0, 0]], [[0, half, 0]], [[0, 0, -1]], [shape], [le]))
    got, se = direct_irradiance(sc, np.zeros((1, 3)), rng)
    if shape == 1:
        exact = np.pi * le * half ** 2 / (half ** 2 + h ** 2)
    else:
        a = half / h
        exact = np.pi * le * 4 * (a / np.sqrt(1 + a * a) * np.arctan(a / np.sqrt(1 + a * a))) / np.pi
    assert np.all(np.abs(got[0] - exact) < 4.5 * se[0]), (got, exact, se)
    # one-sided: nothing below the light's plane is lit from its back
    sc_up = plane_scene(area_lights=AreaLights([[0, 0, h]], [[half, 0, 0]], [[0, half, 0]], [[0, 0, 1]], [shape], [le]))
    assert np.all(direct_irradiance(sc_up, np.zeros((1, 3)), rng, n=100)[0] == 0)


def test_point_light_with_radius_far_away_is_inverse_square(rng):
    sc = plane_scene(point_lights=PointLights([[0, 0, 3.0]], [[1.0, 1.0, 1.0]], radius=[0.05]))
    got, se = direct_irradiance(sc, np.array([[0.0, 0.0, 0.0], [2.0, 0.0, 0.0]]), rng, n=2000)
    r2 = np.array([9.0, 13.0])
    exact = np.array([1.0, 3 / np.sqrt(13)]) / r2
    assert np.allclose(got[:, 0], exact, rtol=1e-3), (got[:, 0], exact)


def test_npz_keeps_sides_lights_linking_and_world(tmp_path):
    from raybundle.scene.linking import LightLinking

    sc = blender_cornell(flip=[1, 5], environment=(0.1, 0.2, 0.3))
    sc.point_lights = PointLights([[0, 0, 1.0]], [[2.0, 2, 2]], spot_direction=[[0, 0, -1]],
                                  spot_cos_half_angle=[0.5], spot_blend=[0.2], radius=[0.1], shadow=[0], link=[1])
    sc.sun_lights = SunLights([[0, 0, -1.0]], [[1.0, 1, 1]], [0.01])
    sc.area_lights = AreaLights([[0, 0, 0.5]], [[0.1, 0, 0]], [[0, 0.2, 0]], [[0, 0, -1]], [1], [[5.0, 5, 5]])
    groups = np.arange(len(sc.triangles)) % 2
    sc.linking = LightLinking(groups, [[1, 1], [0, 1]], [[1, 1], [1, 0]])
    sc.save_npz(tmp_path / "s.npz")
    back = load_npz(tmp_path / "s.npz")
    assert np.array_equal(back.linking.receives, [[1, 1], [0, 1]]) and np.array_equal(back.linking.blocks,
                                                                                      [[1, 1], [1, 0]])
    assert np.array_equal(back.link_groups(np.arange(len(back.triangles))), groups[back.triangle_source])
    assert back.triangle_two_sided.all() and back.n_sides == 2 * back.n_patches
    assert back.world.is_constant and np.allclose(back.world.image[0, 0], [0.1, 0.2, 0.3])
    for group in ("point_lights", "sun_lights", "area_lights"):
        for k, v in vars(getattr(sc, group)).items():
            assert np.allclose(getattr(getattr(back, group), k), v), (group, k)


def test_world_alone_is_a_light_and_bad_lights_are_errors():
    from raybundle.scene.model import SceneError

    v = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0]], float)
    assert build_scene(v, [[0, 1, 2]], [0], FLOOR, environment=(0.5, 0.5, 0.5)).n_sides == 1
    with pytest.raises(SceneError, match="no lights"):
        build_scene(v, [[0, 1, 2]], [0], FLOOR)
    with pytest.raises(SceneError, match="unit vectors"):
        build_scene(v, [[0, 1, 2]], [0], FLOOR, sun_lights=SunLights([[0, 0, -2.0]], [[1.0, 1, 1]], [0.0]))
    with pytest.raises(SceneError, match="zero size"):
        build_scene(v, [[0, 1, 2]], [0], FLOOR, area_lights=AreaLights([[0, 0, 1.0]], [[0, 0, 0]], [[0, 1, 0]],
                                                                          [[0, 0, -1]], [0], [[1.0, 1, 1]]))
    with pytest.raises(SceneError, match="sun lights"):
        build_scene(v, [[0, 1, 2]], [0], FLOOR, sun_lights=SunLights([[0, 0, -1.0]], [[1.0, 1, 1]] * 2, [0.0]))
    with pytest.raises(SceneError, match="environment"):
        build_scene(v, [[0, 1, 2]], [0], FLOOR, environment=(np.nan, 0, 0))


@pytest.mark.parametrize("spec", [dict(base_color=(0.8, 0.5, 0.2), roughness=0.4),
                                  dict(base_color=(0.9, 0.6, 0.3), metallic=1.0, roughness=0.3)],
                         ids=["dielectric", "metal"])
def test_principled_plane_under_a_white_world_renders_its_albedo(spec):
    """A two-sided Principled plane that sees only a world of radiance Lw reflects
    Lw a(w_out) towards every viewer, a the directional albedo (one bounce, exact):
    the image's diffuse part (W_d kd/pi E_bar), glossy gather (sample_glossy, rays
    escaping to the world) and the solver's layered radiance together must give it.
    Tolerance: 4.5 standard errors of the mean ratio, from two seeds, plus 0.5% for
    the albedo tables' interpolation."""
    from raybundle.scene.camera import Camera
    from raybundle.scene.principled import principled_material

    mats = MaterialTable.from_list([principled_material(**spec)])
    v = np.array([[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]], float)
    lw = np.array([1.0, 0.8, 0.6])
    cam = Camera.look_at((0, -2.0, 1.2), (0, 0, 0), (0, 0, 1), 50.0, 36.0, (24, 24))
    sc = build_scene(v, [[0, 1, 2], [0, 2, 3]], [0, 0], mats, camera=cam, two_sided=True, environment=lw)
    ratios = []
    for seed in (1, 2):
        r = pipeline.make_renderer(pipeline.prepare(sc, patches=50), RenderSettings(seed=seed))
        img = r.run(iterations=20).image.reshape(-1, 3)
        g = r.trace_gbuffer(np.full((24 * 24, 2), 0.5))
        hit = g.hit.copy()
        for corner in ((0.001, 0.001), (0.999, 0.001), (0.001, 0.999), (0.999, 0.999)):   # not the plane's rim
            hit &= r.trace_gbuffer(np.broadcast_to(corner, (24 * 24, 2))).hit
        cos_o = np.einsum("ij,ij->i", g.normal, g.w_eye)
        expect = lw * mats.albedo(np.zeros(hit.sum(), int), cos_o[hit])
        ratios.append(img[hit].mean(axis=0) / expect.mean(axis=0))
        r.tracer.close()
    ratio = 0.5 * (ratios[0] + ratios[1])
    se = np.abs(ratios[0] - ratios[1]) / 2
    assert np.all(np.abs(ratio - 1) < 4.5 * se + 0.005), (ratio, se)
