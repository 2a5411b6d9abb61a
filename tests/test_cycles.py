"""Checks against Blender's Cycles through the real ``bpy`` module from PyPI.

* The directional albedo of our Glossy GGX lobe equals what Cycles renders for a
  Glossy BSDF (GGX) plane under a uniform white world (radiance seen = albedo).
* The Cornell box rendered by both has the same mean radiance (units, camera,
  light, materials agree) - a cheap end-to-end check; the full image comparison
  is in the bench.
"""
import os
import sys

import bpy  # noqa: E402  (the test set-up installs bpy: a missing one must fail)
import numpy as np
import pytest

sys.path.insert(0, os.path.join(os.path.dirname(__file__), "..", "tools"))
import cycles_reference as cr  # noqa: E402

from raybundle.app import pipeline
from raybundle.imaging.settings import RenderSettings
from raybundle.scene import builtin as scenes
from raybundle.scene.materials import MaterialTable


def cycles_plane_radiance(tmp_path, roughness, cos_view, samples=512, res=6):
    """Render a Glossy GGX plane (white) under a white world, seen at cos(theta) = cos_view."""
    cr.reset()
    mat = cr.make_material("glossy", (0, 0, 0), (1, 1, 1), roughness, 1.0, (0, 0, 0))
    path = tmp_path / f"plane-{roughness}-{cos_view}.exr"
    return cr.plane_under_white_world(mat, cos_view, res, samples, path)[:, 0]


@pytest.mark.parametrize("roughness", [0.2, 0.5])
@pytest.mark.parametrize("cos_view", [0.3, 0.7, 1.0])
def test_ggx_albedo_matches_cycles(tmp_path, roughness, cos_view):
    px = cycles_plane_radiance(tmp_path, roughness, cos_view)
    mt = MaterialTable.from_list([dict(glossy=(1, 1, 1), roughness=roughness, glossy_weight=1.0)])
    ours = mt.albedo(np.array([0]), np.array([cos_view]))[0, 0]
    se = px.std(ddof=1) / np.sqrt(len(px))
    # Cycles' per-pixel noise gives se; our albedo table is accurate to 3e-3 (test_materials)
    assert abs(px.mean() - ours) < 4.5 * se + 3e-3, (px.mean(), ours, se)


def test_cornell_mean_radiance_matches_cycles(tmp_path):
    sc = scenes.cornell(resolution=(48, 48))
    cyc = cr.render_scene(sc, 128, str(tmp_path / "cornell-cycles.exr"), seed=1)
    ours = pipeline.render(pipeline.prepare(sc, patches=1500), RenderSettings(seed=2), iterations=100).image
    m_c, m_o = cyc.reshape(-1, 3).mean(axis=0), ours.reshape(-1, 3).mean(axis=0)
    # image means over 2304 pixels: Monte Carlo noise well under 1%; the FE error of the
    # patch solution shifts the mean by less than 1.5% (bench: relative RMSE vs Cycles)
    assert np.all(np.abs(m_o / m_c - 1) < 0.02), (m_o, m_c)


@pytest.mark.parametrize("fit,res,shift,ortho", [("AUTO", (320, 200), (0.1, -0.05), None),
                                                 ("AUTO", (200, 320), (0.0, 0.2), None),
                                                 ("VERTICAL", (300, 240), (-0.1, 0.0), None),
                                                 ("AUTO", (320, 200), (0.1, 0.05), 2.5),
                                                 ("VERTICAL", (200, 320), (0.0, -0.1), 4.0)])
def test_camera_from_blender_matches_bpy_projection(fit, res, shift, ortho):
    """Project points with our Camera.from_blender and with bpy's world_to_camera_view."""
    from bpy_extras.object_utils import world_to_camera_view
    from mathutils import Euler, Vector

    from raybundle.scene.camera import Camera

    cr.reset()
    cd = bpy.data.cameras.new("cam")
    cd.lens, cd.sensor_width, cd.sensor_height, cd.sensor_fit = 42.0, 36.0, 24.0, fit
    cd.shift_x, cd.shift_y = shift
    if ortho:
        cd.type, cd.ortho_scale = "ORTHO", ortho
    ob = bpy.data.objects.new("cam", cd)
    ob.location = (1.0, -2.0, 0.5)
    ob.rotation_euler = Euler((1.2, 0.1, 0.3))
    sc = bpy.context.scene
    sc.collection.objects.link(ob)
    sc.camera = ob
    sc.render.resolution_x, sc.render.resolution_y = res
    bpy.context.view_layer.update()
    cam = Camera.from_blender(cd.lens, cd.sensor_width, cd.sensor_height, cd.sensor_fit, cd.shift_x, cd.shift_y,
                              res, np.array(ob.matrix_world), ortho_scale=ortho, clip_start=0.1)
    rng = np.random.default_rng(4)
    for _ in range(20):
        px, py = rng.random() * res[0], rng.random() * res[1]
        o, d = cam.rays(np.array([px]), np.array([py]))
        view_axis = -np.array(ob.matrix_world)[:3, 2]
        assert abs((o[0] - cam.position) @ view_axis - 0.1) < 1e-6      # on the clip-start plane (float32 matrix)
        p = o[0] + 3.0 * d[0]
        ndc = world_to_camera_view(sc, ob, Vector(p.tolist()))
        assert abs(ndc.x * res[0] - px) < 1e-3 and abs((1 - ndc.y) * res[1] - py) < 1e-3
