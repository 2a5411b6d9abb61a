"""Light tracing's measurement: photon hits splatted into the camera's pixels
(:func:`splat_to_camera`), shared by single-ray iteration and the caustic splats."""
from __future__ import annotations

import numpy as np


def splat_to_camera(scene, camera, tracer, points, normals, triangles, travel, power, glossy=True):
    """Light tracing's measurement of photon hits: the radiance each hit makes its surface
    reflect towards the eye, as the pixel it lands on sees it (box filter one pixel wide)::

        dP = Phi f(d, w_e) cos_y density        [W m^-2 sr^-1]

    ``points`` (K, 3) on ``triangles`` (K,), unit ``normals`` (K, 3) of the lit side,
    ``travel`` (K, 3) the light's travel direction, ``power`` Phi (K, 3) [W];
    ``density`` :meth:`~raybundle.scene.camera.Camera.project`'s pixels per unit area facing the eye;
    only hits a shadow ray joins to the eye count; ``glossy``: include the glossy lobes of f
    (the diffuse lobe always, with its texture).  Returns ``(pixel (M,), dP (M, 3), rays)``,
    ``pixel`` a flat index ``y * width + x``, to be summed (repeats allowed)."""
    px, py, to_eye, reach, density = camera.project(points)
    cos_y = np.einsum("ij,ij->i", normals, to_eye)
    ok = (density > 0) & (cos_y > 0) & (px >= 0) & (px < camera.width) & (py >= 0) & (py < camera.height)
    j = np.nonzero(ok)[0]
    if not len(j):
        return np.zeros(0, np.int64), np.zeros((0, 3)), 0
    eps = tracer.eps
    blocked = tracer.occluded(points[j] + normals[j] * eps, to_eye[j], np.maximum(reach[j] - 2 * eps, 0.0))
    rays = len(j)
    j = j[~blocked]
    tex = None if scene.texture is None else scene.texture.at(scene.triangle_source[triangles[j]], points[j])
    f = scene.materials.brdf(scene.triangle_material[triangles[j]], normals[j], travel[j], to_eye[j],
                             glossy=glossy, diffuse_scale=tex)
    pix = np.floor(py[j]).astype(np.int64) * camera.width + np.floor(px[j]).astype(np.int64)
    return pix, power[j] * f * (cos_y[j] * density[j])[:, None], rays
