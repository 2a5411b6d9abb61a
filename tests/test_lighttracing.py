"""Stochastic iteration with single rays (:mod:`raybundle.methods.single_ray_iteration`): the camera's inverse
projection against its rays, the photons' powers against each light's emitted power, the
furnaces against their analytic radiance, and every kind of light against the path tracer.

Statistical tolerances: fixed seeds; 4.5 standard errors, the SE of a mean estimated from the
samples themselves (photons), from the pixels' spread (furnaces), or from two independent
renders A and B (region means, ``test_pathtracing.region_means``).
"""
import numpy as np
import pytest
from test_blender_semantics import blender_cornell
from test_pathtracing import region_means

from raybundle.app import pipeline
from raybundle.imaging.settings import RenderSettings
from raybundle.methods.single_ray_iteration import LightEmission
from raybundle.scene import builtin as scenes
from raybundle.scene.camera import Camera
from raybundle.scene.materials import MaterialTable
from raybundle.scene.model import AreaLights, PointLights, SunLights
from raybundle.tracing.visibility import RayTracer


@pytest.mark.parametrize("ortho", [False, True])
def test_projection_inverts_the_camera_rays_and_its_density_is_the_pixel_area(ortho):
    """Points along camera rays project back to the ray's pixel, the eye direction is minus
    the ray's, the reach is the distance from the clip plane; the density (pixels^2 per m^2
    facing the eye) matches a small square's projected area (finite differences, 0.5%)."""
    cam = Camera.look_at((1.0, -2.0, 0.5), (0.2, 0.3, 0.1), (0, 0, 1), 35.0, 36.0, (64, 48))
    cam.clip_start = 0.3
    if ortho:
        cam = Camera(cam.width, cam.height, 20.0, 20.0, cam.cx + 3, cam.cy - 2, cam.matrix_world, True, 0.3)
    rng = np.random.default_rng(0)
    px, py = rng.uniform(0, 64, 50), rng.uniform(0, 48, 50)
    org, d = cam.rays(px, py)
    t = rng.uniform(0.5, 4.0, 50)
    x = org + t[:, None] * d
    qx, qy, to_eye, reach, density = cam.project(x)
    assert np.allclose(qx, px) and np.allclose(qy, py)
    assert np.allclose(to_eye, -d) and np.allclose(reach, t)
    h = 1e-4
    a = np.cross(to_eye, [0.3, 0.1, 1.0])
    a /= np.linalg.norm(a, axis=1, keepdims=True)
    b = np.cross(to_eye, a)
    corners = [cam.project(x + h * (sa * a + sb * b) / 2)[:2] for sa, sb in ((-1, -1), (1, -1), (1, 1), (-1, 1))]
    cx, cy = np.array([c[0] for c in corners]), np.array([c[1] for c in corners])
    area = 0.5 * np.abs(np.sum(cx * np.roll(cy, -1, axis=0) - np.roll(cx, -1, axis=0) * cy, axis=0))
    assert np.allclose(area / h ** 2, density, rtol=5e-3)
    behind = cam.project(cam.position[None] - 0.1 * d[:1])
    assert behind[4][0] == 0 and behind[3][0] == 0


def all_lights_box(resolution=32):
    """The two-sided Blender Cornell box with a glossy white, a world, a spot with a radius,
    an elliptic area light, a sun through the open front and the two-sided lamp."""
    mats = MaterialTable.from_list([dict(name="white", diffuse=(0.5, 0.5, 0.5), glossy=(0.9, 0.9, 0.9),
                                         roughness=0.3, glossy_weight=0.5),
                                    dict(name="red", diffuse=scenes.RED), dict(name="green", diffuse=scenes.GREEN),
                                    dict(name="light", emission=scenes.CORNELL_LIGHT)])
    sc = blender_cornell(materials=mats, environment=(0.05, 0.05, 0.08))
    sc.point_lights = PointLights([[-0.15, 0.3, 0.4]], [[0.3, 0.3, 0.25]], spot_direction=[[0, 0, -1]],
                                  spot_cos_half_angle=[0.7], spot_blend=[0.3], radius=[0.02])
    sc.area_lights = AreaLights([[-0.42, 0.2, 0.45]], [[0.04, 0, 0]], [[0, 0.06, 0]], [[0, 0, -1]], [1], [[4.0, 3, 2]])
    d = np.array([0.3, 1.0, -0.6])
    sc.sun_lights = SunLights([d / np.linalg.norm(d)], [[1.0, 0.9, 0.8]], [0.05])
    sc.camera = sc.camera.with_resolution(resolution, resolution)
    return sc


def test_photons_carry_each_lights_emitted_power():
    """The mean photon power of each source equals what it emits: pi A Le per emitting side
    (the lamp is two-sided), I times the spot's attenuation integrated over the sphere, pi A Le
    for the area light, E pi R^2 for the sun and 4 pi^2 R^2 L for the world over the disc of
    radius R that photons from afar cross (within 4.5 SE of the photons' spread)."""
    sc = all_lights_box()
    tr = RayTracer(sc)
    try:
        em = LightEmission(sc, tr)
        kinds = [kind for kind, _ in em.sources]
        assert kinds == ["mesh", "point", "area", "sun", "world"]
        rng = np.random.default_rng(5)
        n = 400_000
        _, d, power = em.sample(n, rng)
        assert np.allclose(np.linalg.norm(d, axis=1), 1.0)
        mats, R = sc.materials, em.radius
        lamp = sc.triangle_material == 3
        cos = np.linspace(-1, 1, 200_001)
        spot = sc.point_lights.spot_factor(0, np.stack([np.sqrt(1 - cos ** 2), 0 * cos, cos], axis=1))
        expected = (np.pi * 2 * sc.triangle_area[lamp].sum() * mats.emission[3]
                    + 2 * np.pi * 2 * spot.mean() * sc.point_lights.intensity[0]
                    + np.pi * sc.area_lights.area[0] * sc.area_lights.radiance[0]
                    + np.pi * R ** 2 * sc.sun_lights.irradiance[0]
                    + 4 * np.pi ** 2 * R ** 2 * sc.world.image[0, 0])
        mean, se = power.mean(axis=0), power.std(axis=0) / np.sqrt(n)
        assert np.all(np.abs(mean - expected) < 4.5 * se), (mean, expected, se)
    finally:
        tr.close()


@pytest.mark.parametrize("name", ["furnace", "furnace-glossy"])
def test_furnaces_converge_to_the_analytic_radiance(name):
    """Closed furnaces: every pixel's expectation is the analytic radiance (the glossy one's
    emission makes up a direction-dependent albedo: the scattering weights must be exact).
    The image mean lies within 4.5 SE (pixels' spread) of it."""
    sc = scenes.load_scene(name)
    sc.camera = sc.camera.with_resolution(24, 24)
    out = pipeline.render(sc, RenderSettings(seed=3), iterations=160, solver="single-ray-iteration")
    img = out.image.reshape(-1, 3).astype(float)
    exact = np.broadcast_to(np.asarray(sc.analytic_radiance, float), (3,))
    se = img.std(axis=0, ddof=1) / np.sqrt(len(img))
    assert np.isfinite(img).all() and out.stats["iterations"] == 160
    assert np.all(np.abs(img.mean(axis=0) - exact) < 4.5 * se), (img.mean(axis=0), exact, se)
    assert 1.0 < out.stats["mean_path_length"] < 1.0 / (1.0 - 0.75)


def test_every_kind_of_light_matches_the_path_tracer():
    """The two-sided box with a glossy white, a world, a spot, an area light, a sun and the
    two-sided lamp: light tracing and the path tracer (both unbiased) agree on the whole image
    and its quadrants within 4.5 combined SE + 0.5% (two seeds each).  Measured: within 1.6 SE."""
    sc = all_lights_box()
    quads = [np.s_[:, :], np.s_[:16, :16], np.s_[:16, 16:], np.s_[16:, :16], np.s_[16:, 16:]]
    pt = [pipeline.render(sc, RenderSettings(seed=k), iterations=96, solver="path-tracing").image for k in (1, 2)]
    lt = [pipeline.render(sc, RenderSettings(seed=k), iterations=300, solver="single-ray-iteration").image
          for k in (1, 2)]
    for (mp, sp), (ml, sl), q in zip(region_means(*pt, quads), region_means(*lt, quads), quads):
        assert abs(ml - mp) < 4.5 * np.hypot(sp, sl) + 0.005 * mp, (q, ml, mp, sl, sp)
