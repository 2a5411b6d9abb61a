"""Shading normals: the normals Blender interpolates over smooth-shaded faces.

A smooth-shaded mesh (Shade Smooth, Auto Smooth, custom normals) is still flat triangles to
every ray, but Cycles evaluates its materials about the *shading normal*: the face's corner
normals (``Mesh.corner_normals``) interpolated linearly at the point and normalised,

    n_s(x) = normalize(sum_k b_k(x) n_k)

with ``b_k`` the point's barycentrics on its input face.  The cosine of the light a surface
receives is then ``max(0, n_s . w)``: on a curved chair the sun's stripes fade towards
its turned-away side instead of keeping the facet's one brightness.

Raybundle shades the points the camera sees (direct light of lamps and the world, the glossy
lobe) and a bake's points (direct light of lamps) about ``n_s``; the patches keep their flat
normals (a patch's irradiance is an area mean over its triangles).  Rays leave from and are
offset along the side the geometry has.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass
class ShadingNormals:
    """``face_corners`` (F, 3, 3) [m], float32: the input faces (indexed by
    :attr:`~raybundle.scene.model.PatchScene.triangle_source`); ``corner_normals`` (F, 3, 3):
    their unit corner normals, float32."""

    face_corners: np.ndarray
    corner_normals: np.ndarray

    def __post_init__(self):
        self.face_corners = np.asarray(self.face_corners, np.float32)
        self.corner_normals = np.asarray(self.corner_normals, np.float32)

    @classmethod
    def of_faces(cls, face_corners, corner_normals, tol=1e-4):
        """The shading normals of the faces, or None when every face's corner normals are its
        own flat normal (within ``tol``): a flat-shaded scene needs none."""
        c = np.asarray(face_corners, float)
        n = np.asarray(corner_normals, float)
        flat = np.cross(c[:, 1] - c[:, 0], c[:, 2] - c[:, 0])
        flat /= np.maximum(np.linalg.norm(flat, axis=1, keepdims=True), 1e-300)
        cos = np.abs(np.einsum("fkc,fc->fk", n, flat))
        if len(c) == 0 or np.all(cos > 1 - tol):
            return None
        return cls(c, n)

    def at(self, face, points):
        """Unit shading normals (N, 3) at ``points`` (N, 3) on input faces ``face`` (N,) (the
        module docstring's ``n_s``), oriented as the input faces' corner normals."""
        from ..tracing.sampling import triangle_barycentrics

        face = np.asarray(face, np.int64)
        b = triangle_barycentrics(self.face_corners[face], points)
        n = np.einsum("nk,nkc->nc", b, self.corner_normals[face])
        return n / np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-300)

    def to_arrays(self):
        """Arrays for a scene's ``.npz`` (``shading_*``)."""
        return {"shading_face_corners": self.face_corners, "shading_corner_normals": self.corner_normals}

    @classmethod
    def from_arrays(cls, d):
        """The shading normals of :meth:`to_arrays`' arrays in ``d``, or None."""
        if "shading_corner_normals" not in d:
            return None
        return cls(d["shading_face_corners"], d["shading_corner_normals"])


def seen_normals(shading, faces, points, flat, w_eye):
    """The normals (N, 3) to shade the seen points with: the shading normal at ``points`` on
    input ``faces``, turned to the side of the ``flat`` normals (N, 3) seen, where it still
    faces the eye ``w_eye`` (N, 3); else the flat normal (a silhouette's smooth normal
    turned away from the camera, which Cycles bends back towards it)."""
    if shading is None or len(faces) == 0:
        return flat
    return facing_eye(sided_normals(shading, faces, points, flat), flat, w_eye)


def sided_normals(shading, faces, points, flat):
    """The shading normals (N, 3) at ``points`` on input ``faces``, turned to the side of the
    ``flat`` normals (N, 3)."""
    n = shading.at(faces, points)
    return n * np.where(np.einsum("ij,ij->i", n, flat) < 0, -1.0, 1.0)[:, None]


def facing_eye(normals, flat, w_eye):
    """``normals`` (N, 3) where they face the eye ``w_eye`` (N, 3), else the ``flat`` normals
    (:func:`seen_normals`)."""
    ok = np.einsum("ij,ij->i", normals, w_eye) > 1e-3
    return np.where(ok[:, None], normals, flat)


def valid_specular_normals(geometric, w_in, normals):
    """The normals (N, 3) a specular closure (glossy, metal, glass) is evaluated about, as Cycles
    does with a material's Bump Map Correction (on by default): each of ``normals`` (N, 3) (unit,
    on the side of ``geometric``) is kept where the mirror direction of ``w_in`` (N, 3, towards
    the viewer) about it lies at least ``t = min(0.9 cos_g, 0.01)`` above the surface
    (``cos_g = w_in . geometric``, ``geometric`` (N, 3) the unit flat normal facing ``w_in``);
    elsewhere it is turned towards ``geometric`` in their common plane just until the mirror
    direction is ``t`` above it: with ``x`` the unit tangent of the normal and ``(i_x, i_z)``
    the components of ``w_in`` on ``(x, geometric)``, the turned normal's ``n_z`` solves
    ``4 a n_z^4 - 2 b n_z^2 + c = 0`` (``a = i_x^2 + i_z^2``, ``b = 2 (a + i_z t)``,
    ``c = (t + i_z)^2``, the root that solves it unsquared) and is ``sqrt(1 - n_z^2) x + n_z
    geometric``.  On a smooth-shaded silhouette or a Shade Smooth cylinder's bevelled rim the
    glossy lobe then stays above the surface instead of reflecting into it."""
    ng = np.asarray(geometric, float)
    wi = np.asarray(w_in, float)
    n = np.asarray(normals, float)
    dot = lambda p, q: np.einsum("ij,ij->i", p, q)  # noqa: E731
    i_z = np.maximum(dot(wi, ng), 0.0)
    t = np.minimum(0.9 * i_z, 0.01)
    cos_n = dot(n, wi)
    bad = np.nonzero(dot(ng, 2.0 * cos_n[:, None] * n - wi) < t)[0]
    out = n.copy()
    if len(bad) == 0:
        return out
    ng, wi, n, i_z, t = ng[bad], wi[bad], n[bad], i_z[bad], t[bad]
    x = n - dot(n, ng)[:, None] * ng
    size = np.linalg.norm(x, axis=1, keepdims=True)
    x = np.where(size > 1e-12, x / np.maximum(size, 1e-300), n)
    i_x = dot(wi, x)
    a = np.maximum(i_x * i_x + i_z * i_z, 1e-300)
    b = 2.0 * (a + i_z * t)
    root = np.sqrt(np.maximum(b * b - 4.0 * a * (t + i_z) ** 2, 0.0))
    n_z2 = 0.25 * np.where(i_x < 0, b + root, b - root) / a
    out[bad] = np.sqrt(np.maximum(1.0 - n_z2, 0.0))[:, None] * x + np.sqrt(np.maximum(n_z2, 0.0))[:, None] * ng
    return out


def specular_normals(shading, faces, points, flat, w_in):
    """The normals (N, 3) a specular closure is evaluated about at ``points`` on input ``faces``:
    the shading normal turned to the side of the ``flat`` normals (N, 3, facing ``w_in``), made
    valid for ``w_in`` (:func:`valid_specular_normals`); ``flat`` where no face is smooth."""
    if shading is None or len(faces) == 0:
        return flat
    return valid_specular_normals(flat, w_in, sided_normals(shading, faces, points, flat))
