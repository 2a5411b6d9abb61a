"""Light tracing's measurement: photon hits splatted into the camera's pixels
(:func:`splat_to_camera`), shared by single-ray iteration and the caustic splats."""
from __future__ import annotations

import numpy as np


def splat_to_camera(scene, camera, tracer, points, normals, triangles, travel, power, glossy=True):
    """Light tracing's measurement of photon hits: the radiance each hit makes its surface
    reflect towards the eye, as the pixels whose filter covers where it lands see it
    (:meth:`~raybundle.scene.camera.Camera.footprint`; with a box one pixel wide, the pixel it lands in)::

        dP = Phi f(d, w_e) cos_y density        [W m^-2 sr^-1]

    ``points`` (K, 3) on ``triangles`` (K,), unit ``normals`` (K, 3) of the lit side,
    ``travel`` (K, 3) the light's travel direction, ``power`` Phi (K, 3) [W];
    ``density`` :meth:`~raybundle.scene.camera.Camera.project`'s pixels per unit area facing the eye;
    only hits a shadow ray joins to the eye count; ``glossy``: include the glossy lobes of f
    (the diffuse lobe always, with its texture).  Returns ``(pixel (M,), dP (M, 3), rays)``,
    ``pixel`` a flat index ``y * width + x``, to be summed (repeats allowed)."""
    px, py, to_eye, reach, density = camera.project(points)
    cos_y = np.einsum("ij,ij->i", normals, to_eye)
    m = camera.filter_margin
    ok = (density > 0) & (cos_y > 0) & (px >= -m) & (px < camera.width + m) & (py >= -m) & (py < camera.height + m)
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
    sample, pix, weight = camera.footprint(px[j], py[j])
    return pix, (power[j] * f * (cos_y[j] * density[j])[:, None])[sample] * weight[:, None], rays
