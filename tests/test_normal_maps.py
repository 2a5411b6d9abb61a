"""Normal and bump maps (raybundle.scene.textures.SurfaceTexture.shading_normals) against
closed forms: the perturbed normal in the face's frame, and the image of a plane under a point
light shaded about it (the Blender side, against Cycles, is in test_addon_materials.py)."""
import numpy as np
import pytest

from raybundle.app import pipeline
from raybundle.imaging.settings import RenderSettings
from raybundle.scene.build import build_scene
from raybundle.scene.camera import Camera
from raybundle.scene.materials import MaterialTable
from raybundle.scene.model import PointLights
from raybundle.scene.textures import SurfaceTexture

SQUARE = np.array([[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]], float)
TRIS = np.array([[0, 1, 2], [0, 2, 3]])


def mapped(value, uv_of_xy, bump):
    """A 2 x 2 m plane in z = 0 whose two faces carry a constant normal map ``value`` (x, y, z)
    through UVs ``uv_of_xy((N, 2) positions)``, a bump's when ``bump``."""
    corners = SQUARE[TRIS]
    uv = uv_of_xy(corners[..., :2].reshape(-1, 2)).reshape(2, 3, 2)
    img = np.broadcast_to(np.asarray(value, np.float32), (2, 2, 3)).copy()
    return SurfaceTexture([np.ones((1, 1, 3), np.float32), img], [-1, -1], corners, uv,
                          face_normal=[1, 1], face_bump=[bump, bump])


@pytest.mark.parametrize("flip", [False, True])
def test_a_normal_map_turns_the_normal_in_the_faces_tangent_frame_and_a_bump_by_its_slope_per_metre(flip):
    """UV u = x / 2 (mirrored: -x / 2), v = y / 3: a normal map's (x, y, z) is x along dP/du, y along
    dP/dv, z along N whatever the scale and handedness; a bump's slope per UV unit -(x, y) / z is
    divided by the metres per UV unit (2 and 3)."""
    su = -1.0 if flip else 1.0
    value = np.array([0.3, -0.2, 0.9])
    pts = np.array([[0.1, 0.2, 0.0], [-0.5, 0.7, 0.0]])
    up = np.tile([0.0, 0.0, 1.0], (2, 1))
    tex = mapped(value, lambda p: np.stack([su * p[:, 0] / 2, p[:, 1] / 3], axis=1), bump=False)
    n = tex.shading_normals([0, 1], pts, up)
    want = np.array([su * value[0], value[1], value[2]]) / np.linalg.norm(value)
    assert np.allclose(n, want, atol=1e-9), n
    tex = mapped(value, lambda p: np.stack([su * p[:, 0] / 2, p[:, 1] / 3], axis=1), bump=True)
    n = tex.shading_normals([0, 1], pts, up)
    # height slope per metre: dH/dx = (dH/du) (du/dx) with d * dH/du = -x / z
    want = np.array([value[0] / value[2] / 2 * su, value[1] / value[2] / 3, 1.0])
    assert np.allclose(n, want / np.linalg.norm(want), atol=1e-9), n


@pytest.mark.parametrize("bump,view", [(False, 0), (True, 0), (False, 60)])
def test_the_eye_sees_a_plane_shaded_about_its_mapped_normal(bump, view):
    """A plane (albedo 0.6) 1.5 m under a 100 W/sr point light, its normal tilted 30 degrees
    (45 seen from the side) towards -x by a constant map (UV = position / 2, so a bump's baked
    slope is halved per metre), seen from above or ``view`` degrees from above on the +x side
    (where the mapped normal faces away from the eye, as Cycles' Diffuse BSDF takes it): each
    pixel is 0.6 / pi I max(0, n'.l) / r^2 at the plane's points its rays meet (no indirect
    light), box-filtered; the flat normal's image (the code before normal maps) differs by up
    to 40%; seen from the side, the code that kept the unmapped normal where the mapped one
    faced away from the eye read the flat normal's image."""
    th = np.radians(45.0 if view else 30.0)
    value = np.array([-np.sin(th), 0.0, np.cos(th)])
    if bump:                      # the same normal from a bump: slope per UV unit twice that per metre
        value = np.array([2 * value[0] / value[2], 0.0, 1.0])
    tex = mapped(value, lambda p: p / 2 + 0.5, bump)
    mats = MaterialTable.from_list([dict(name="plane", diffuse=(0.6, 0.6, 0.6))])
    light = PointLights([[0.3, -0.2, 1.5]], [[100.0, 100.0, 100.0]])
    a = np.radians(view)
    m = np.eye(4)
    m[:3, :3] = [[np.cos(a), 0, np.sin(a)], [0, 1, 0], [-np.sin(a), 0, np.cos(a)]]      # about y, towards +x
    m[:3, 3] = 3 * np.array([np.sin(a), 0, np.cos(a)])
    res = 24
    cam = Camera.from_blender(50, 36, 36, "AUTO", 0, 0, (res, res), m, ortho_scale=1.6 * np.cos(a))
    sc = build_scene(SQUARE, TRIS, [0, 0], mats, point_lights=light, camera=cam, texture=tex)
    r = pipeline.make_renderer(pipeline.prepare(sc, patches=50), RenderSettings(seed=3))
    img = r.run(iterations=40).image
    s = (np.arange(8) + 0.5) / 8
    sub = (np.arange(res)[:, None] + s[None, :]).ravel()
    px, py = np.meshgrid(sub, sub)
    o, w = cam.rays(px.ravel(), py.ravel())
    p = o - (o[:, 2] / w[:, 2])[:, None] * w                  # where the rays meet z = 0
    assert np.abs(p[:, :2]).max() < 1
    d = np.array([0.3, -0.2, 1.5]) - p
    r2 = (d * d).sum(axis=1)
    n = np.array([-np.sin(th), 0.0, np.cos(th)])
    assert (n @ (o[0] - p[0])) < 0 if view else True           # seen from the side, the normal faces away
    ref = (0.6 / np.pi * 100.0 * np.maximum(d @ n, 0.0) / np.sqrt(r2) / r2).reshape(res, 8, res, 8).mean(axis=(1, 3))
    flat = (0.6 / np.pi * 100.0 * d[:, 2] / np.sqrt(r2) / r2).reshape(res, 8, res, 8).mean(axis=(1, 3))
    assert np.abs(flat / ref - 1).max() > 0.3
    rel = img.mean(axis=2) / ref - 1
    # measured: |mean| 1e-4, largest 0.6% (jitter of the passes over 40 iterations)
    assert abs(rel.mean()) < 0.003 and np.abs(rel).max() < 0.02, (rel.mean(), np.abs(rel).max())
    r.tracer.close()


def test_normal_maps_survive_the_npz_round_trip():
    tex = mapped([0.1, 0.2, 0.9], lambda p: p / 2 + 0.5, True)
    back = SurfaceTexture.from_arrays(tex.to_arrays())
    assert np.array_equal(back.face_normal, tex.face_normal) and np.array_equal(back.face_bump, tex.face_bump)
    assert back.has_normal_maps and not mapped([0, 0, 1], lambda p: p, False).face_bump.any()
