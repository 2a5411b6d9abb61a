"""Shading normals: the normals Blender interpolates over smooth-shaded faces.

A smooth-shaded mesh (Shade Smooth, Auto Smooth, custom normals) is still flat triangles to
every ray, but Cycles evaluates its materials about the *shading normal*: the face's corner
normals (``Mesh.corner_normals``) interpolated linearly at the point and normalised,

    n_s(x) = normalize(sum_k b_k(x) n_k)

with ``b_k`` the point's barycentrics on its input face.  The cosine of the light a surface
receives is then ``max(0, n_s . w)``: on a curved chair the sun's stripes fade towards
its turned-away side instead of keeping the facet's one brightness.  A diffuse lobe takes
``n_s`` as it is, even where it faces away from the eye (near a silhouette), as Cycles'
Diffuse BSDF does; a specular one takes it made valid for the eye
(:func:`valid_specular_normals`).

Raybundle shades the points the camera sees (direct light of lamps and the world, the glossy
lobe) and a bake's points (direct light of lamps) about ``n_s``; the patches keep their flat
normals (a patch's irradiance is an area mean over its triangles).  Rays leave from and are
offset along the side the geometry has.

**Shadow terminator.**  A shadow ray towards a light that grazes the flat triangle would find
the facet's own neighbours in the way where the smooth surface it stands for is lit.  Cycles
(its object's *Shadow Terminator Geometry Offset* ``g``, 0.1 by default) lifts such a ray's
origin towards a parabolic patch through the corners along their normals: at barycentrics
``(u, v, w)`` of corners ``V_k`` with normals ``N_k``,

    h = a u (u - 1) + (a + b + c) u v + b v (v - 1),
    a = (N_2 - N_0).(V_0 - V_2),  b = (N_2 - N_1).(V_1 - V_2),  c = (N_1 - N_0).(V_1 - V_0),

bounded by the corners' linear envelopes (:meth:`ShadingNormals.terminator_lift`), and moves
the origin by ``t n h`` with ``n = sum_k b_k N_k``, for a light direction ``L`` at cosines
``c_s = n_s.L`` and ``c_g = n_g.L`` to the shading and flat normals:
``t = clamp(2 - (c_g + c_s) / g)`` where ``c_s < g``, else ``t = clamp(1 - c_g / g)``
(:func:`terminator_amount`).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: Blender's default Shadow Terminator Geometry Offset of an object
DEFAULT_GEOMETRY_OFFSET = 0.1


@dataclass
class ShadingNormals:
    """``face_corners`` (F, 3, 3) [m], float32: the input faces (indexed by
    :attr:`~raybundle.scene.model.PatchScene.triangle_source`); ``corner_normals`` (F, 3, 3):
    their unit corner normals, float32; ``geometry_offset`` (F,) float32: their object's shadow
    terminator geometry offset (module docstring; None: Blender's default, 0.1)."""

    face_corners: np.ndarray
    corner_normals: np.ndarray
    geometry_offset: np.ndarray | None = None

    def __post_init__(self):
        self.face_corners = np.asarray(self.face_corners, np.float32)
        self.corner_normals = np.asarray(self.corner_normals, np.float32)
        self.geometry_offset = np.broadcast_to(np.asarray(
            DEFAULT_GEOMETRY_OFFSET if self.geometry_offset is None else self.geometry_offset, np.float32),
            len(self.face_corners)).copy()

    @classmethod
    def of_faces(cls, face_corners, corner_normals, tol=1e-4, geometry_offset=None):
        """The shading normals of the faces, or None when every face's corner normals are its
        own flat normal (within ``tol``): a flat-shaded scene needs none."""
        c = np.asarray(face_corners, float)
        n = np.asarray(corner_normals, float)
        flat = np.cross(c[:, 1] - c[:, 0], c[:, 2] - c[:, 0])
        flat /= np.maximum(np.linalg.norm(flat, axis=1, keepdims=True), 1e-300)
        cos = np.abs(np.einsum("fkc,fc->fk", n, flat))
        if len(c) == 0 or np.all(cos > 1 - tol):
            return None
        return cls(c, n, geometry_offset)

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
        return {"shading_face_corners": self.face_corners, "shading_corner_normals": self.corner_normals,
                "shading_geometry_offset": self.geometry_offset}

    @classmethod
    def from_arrays(cls, d):
        """The shading normals of :meth:`to_arrays`' arrays in ``d``, or None."""
        if "shading_corner_normals" not in d:
            return None
        return cls(d["shading_face_corners"], d["shading_corner_normals"], d.get("shading_geometry_offset"))

    def terminator_lift(self, face, points, side):
        """(N, 3) float64: Cycles' lift of a shadow ray's origin at ``points`` (N, 3) on input
        faces ``face`` (N,) towards the smooth surface, for light on the side of the unit flat
        normals ``side`` (N, 3) (the module docstring's ``n h``; zero on a flat face).  Where the
        interpolated normal ``n`` faces ``side``, ``h = max(min_k h_k, h / 2)`` with ``h_k`` how
        far corner ``k``'s tangent plane, raised to clear the face's other corners, lies above the
        point; else ``h = min(-min_k h_k, h / 2)`` with the envelope taken below."""
        from ..tracing.sampling import triangle_barycentrics

        face = np.asarray(face, np.int64)
        V = self.face_corners[face].astype(float)
        N = self.corner_normals[face].astype(float)
        bary = triangle_barycentrics(V, points)
        P = np.einsum("nk,nkc->nc", bary, V)
        n = np.einsum("nk,nkc->nc", bary, N)

        def dot(p, q):
            return np.einsum("nc,nc->n", p, q)

        a = dot(N[:, 2] - N[:, 0], V[:, 0] - V[:, 2])
        b = dot(N[:, 2] - N[:, 1], V[:, 1] - V[:, 2])
        c = dot(N[:, 1] - N[:, 0], V[:, 1] - V[:, 0])
        u, v = bary[:, 0], bary[:, 1]
        h = a * u * (u - 1) + (a + b + c) * u * v + b * v * (v - 1)
        up = dot(n, side) > 0
        s = np.where(up, 1.0, -1.0)[:, None]           # the envelope above, or below
        hk = []
        for k in range(3):
            o1, o2 = (k + 1) % 3, (k + 2) % 3
            rise = np.maximum(np.maximum(dot(s * (V[:, o1] - V[:, k]), N[:, k]),
                                         dot(s * (V[:, o2] - V[:, k]), N[:, k])), 0.0)
            hk.append(np.maximum(dot(s * (V[:, k] - P), N[:, k]) + rise, 0.0))
        low = np.minimum(np.minimum(hk[0], hk[1]), hk[2])
        h = np.where(up, np.maximum(low, 0.5 * h), np.minimum(-low, 0.5 * h))
        return n * h[:, None]


@dataclass
class ShadowTerminator:
    """The shadow terminator at shading points of ``shading``'s faces: their input ``faces``
    (N,), ``points`` (N, 3) and unit flat normals ``flat`` (N, 3) on the side their light comes
    from (module docstring)."""

    shading: ShadingNormals
    faces: np.ndarray
    points: np.ndarray
    flat: np.ndarray

    def take(self, rows):
        """The terminator at the points ``rows`` (an index or a slice) of these."""
        return ShadowTerminator(self.shading, self.faces[rows], self.points[rows], self.flat[rows])

    def origins(self, origins, w, cos_shading):
        """The shadow rays' origins (N, 3), ``origins`` moved by the lift's share that light from
        the directions ``w`` (N, 3) at cosines ``cos_shading`` (N,) to the shading normals takes,
        or None where none of them is moved.  The lift is found only where it is taken."""
        t = terminator_amount(self.shading.geometry_offset[self.faces], cos_shading,
                              np.einsum("ij,ij->i", self.flat, w))
        k = np.nonzero(t > 0)[0]
        if len(k) == 0:
            return None
        out = np.array(origins, float)
        out[k] += t[k, None] * self.shading.terminator_lift(self.faces[k], self.points[k], self.flat[k])
        return out


def terminator_amount(cutoff, cos_shading, cos_flat):
    """(N,) the share in [0, 1] of :meth:`ShadingNormals.terminator_lift` a shadow ray's origin
    is moved by, for geometry offsets ``cutoff`` (N,) and a light direction at cosines
    ``cos_shading`` to the shading normal and ``cos_flat`` to the flat normal on its side (both
    (N,)); none where ``cutoff`` is 0 (module docstring)."""
    g = np.maximum(cutoff, 1e-30)
    t = np.where(cos_shading < g, 2.0 - (cos_flat + cos_shading) / g, 1.0 - cos_flat / g)
    return np.where(cutoff > 0, np.clip(t, 0.0, 1.0), 0.0)


def sided_normals(shading, faces, points, flat):
    """The shading normals (N, 3) at ``points`` on input ``faces``, turned to the side of the
    ``flat`` normals (N, 3)."""
    n = shading.at(faces, points)
    return n * np.where(np.einsum("ij,ij->i", n, flat) < 0, -1.0, 1.0)[:, None]


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
