"""Image textures on the diffuse albedo: sharp texture detail over smooth light.

A textured material's diffuse reflectance varies over a surface as
``kd(x) = kd_m * M(uv(x))``: ``kd_m`` the material's reflectance from the image's
mean color (what :class:`~raybundle.scene.materials.MaterialTable` holds) and ``M`` the
*modulation map*, the image divided by its mean color per channel (mean 1), looked
up bilinearly with repeat at the point's UV (as Cycles' Image Texture node with
Linear interpolation and Repeat extension does; texel centres at (i + 0.5) / W).

The solver keeps one variable per patch side, so a patch reflects with its mean
albedo ``kd_m * mean_patch(M)`` (:meth:`SurfaceTexture.side_means`: the modulation
averaged over the patch at stratified points, as many as the patch covers texels,
up to :data:`MAX_SAMPLES` per triangle); images and bakes multiply the diffuse
light at each pixel or texel by ``kd_m * M(uv)`` (:meth:`SurfaceTexture.at`), so the
texture stays sharp while the light is interpolated smoothly.

A **color attribute** drives the albedo the same way, its color interpolated linearly
over each input face from its corners (``face_image`` -2; the material's reflectance
then holds white, so the color is the factor itself).

UVs live on the *input* faces (the exported triangles, before subdivision): a
point's UV is the input face's corner UVs weighted by the point's barycentrics on
that face, whatever patch triangle it lies on.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: most modulation samples per patch triangle for its mean
MAX_SAMPLES = 1024


@dataclass
class SurfaceTexture:
    """Modulation maps of the textured input faces.

    ``images``: list of (H, W, 3) float32 modulation maps (linear image / its mean);
    ``face_image`` (F,) int: the map of each input face (-1: untextured; -2: the face's
    corner colors, interpolated linearly: a color attribute, whose color is the albedo
    factor itself), indexed by :attr:`~raybundle.scene.model.PatchScene.triangle_source`;
    ``face_corners`` (F, 3, 3) [m] and ``face_uv`` (F, 3, 2): the input faces and their
    corner UVs; ``face_color`` (F, 3, 3) or None: their corner colors."""

    images: list
    face_image: np.ndarray
    face_corners: np.ndarray
    face_uv: np.ndarray
    face_color: np.ndarray | None = None

    def __post_init__(self):
        self.face_image = np.asarray(self.face_image, np.int64)
        self.face_corners = np.asarray(self.face_corners, float)
        self.face_uv = np.asarray(self.face_uv, float)
        if self.face_color is not None:
            self.face_color = np.asarray(self.face_color, float)
        self.images = [np.ascontiguousarray(im, np.float32) for im in self.images]

    def to_arrays(self):
        """Flat arrays for a scene's ``.npz`` (``texture_*``): the maps one after another."""
        d = {"texture_face_image": self.face_image, "texture_face_corners": self.face_corners,
             "texture_face_uv": self.face_uv,
             "texture_image_shapes": np.array([im.shape[:2] for im in self.images], np.int64).reshape(-1, 2),
             "texture_pixels": (np.concatenate([im.reshape(-1, 3) for im in self.images]) if self.images
                                else np.zeros((0, 3), np.float32))}
        if self.face_color is not None:
            d["texture_face_color"] = self.face_color
        return d

    @classmethod
    def from_arrays(cls, d):
        """The texture of :meth:`to_arrays`' arrays in ``d``, or None when there are none."""
        if "texture_face_image" not in d:
            return None
        images, k = [], 0
        for h, w in np.asarray(d["texture_image_shapes"], np.int64).reshape(-1, 2):
            images.append(np.asarray(d["texture_pixels"][k:k + h * w]).reshape(h, w, 3))
            k += h * w
        return cls(images, d["texture_face_image"], d["texture_face_corners"], d["texture_face_uv"],
                   d.get("texture_face_color"))

    def lookup(self, image, uv):
        """Bilinear, repeating lookup (N, 3) of map ``image`` at ``uv`` (N, 2)."""
        im = self.images[image]
        h, w = im.shape[:2]
        x = uv[:, 0] * w - 0.5
        y = uv[:, 1] * h - 0.5
        x0, y0 = np.floor(x), np.floor(y)
        fx, fy = (x - x0)[:, None], (y - y0)[:, None]
        x0, y0 = x0.astype(np.int64) % w, y0.astype(np.int64) % h
        x1, y1 = (x0 + 1) % w, (y0 + 1) % h
        return ((1 - fy) * ((1 - fx) * im[y0, x0] + fx * im[y0, x1])
                + fy * ((1 - fx) * im[y1, x0] + fx * im[y1, x1]))

    def uv_at(self, face, points):
        """UV (N, 2) of ``points`` (N, 3) on input faces ``face`` (N,)."""
        return np.einsum("nk,nkc->nc", self.bary_at(face, points), self.face_uv[face])

    def bary_at(self, face, points):
        """Barycentrics (N, 3) of ``points`` (N, 3) on input faces ``face`` (N,)."""
        from ..tracing.sampling import triangle_barycentrics

        return triangle_barycentrics(self.face_corners[face], points)

    def at(self, face, points):
        """Modulation M (N, 3) at ``points`` (N, 3) on input faces ``face`` (N,) (1 where untextured)."""
        face = np.asarray(face, np.int64)
        out = np.ones((len(face), 3))
        ok = (face >= 0) & (face < len(self.face_image))
        img = np.full(len(face), -1, np.int64)
        img[ok] = self.face_image[face[ok]]
        col = np.nonzero(img == -2)[0]
        if len(col):
            out[col] = np.einsum("nk,nkc->nc", self.bary_at(face[col], points[col]), self.face_color[face[col]])
        for k in np.unique(img[img >= 0]):
            sel = np.nonzero(img == k)[0]
            out[sel] = self.lookup(int(k), self.uv_at(face[sel], points[sel]))
        return out

    def side_means(self, scene, seed=0):
        """(S, 3) the area-weighted mean modulation over each patch side of ``scene``
        (stratified points on every triangle of a textured face, about one per texel it
        covers, 16 to :data:`MAX_SAMPLES`)."""
        from ..tracing.sampling import points_on_triangles, stratified_2d

        tri_face = scene.triangle_source
        img = self.face_image[tri_face]
        mod = np.ones((len(scene.triangles), 3))
        col = np.nonzero(img == -2)[0]
        if len(col):          # linear over the face: the mean over a triangle is at its centroid
            mod[col] = self.at(tri_face[col], scene.triangle_corners[col].mean(axis=1))
        textured = np.nonzero(img >= 0)[0]
        if len(textured):
            uv = self.face_uv[tri_face[textured]]
            du, dv = uv[:, 1] - uv[:, 0], uv[:, 2] - uv[:, 0]
            uv_area = 0.5 * np.abs(du[:, 0] * dv[:, 1] - du[:, 1] * dv[:, 0])
            c = self.face_corners[tri_face[textured]]
            src_area = 0.5 * np.linalg.norm(np.cross(c[:, 1] - c[:, 0], c[:, 2] - c[:, 0]), axis=1)
            texels = np.array([im.shape[0] * im.shape[1] for im in self.images], float)[img[textured]]
            share = scene.triangle_area[textured] / np.maximum(src_area, 1e-300)
            k = np.clip(np.ceil(uv_area * share * texels), 16, MAX_SAMPLES).astype(np.int64)
            rng = np.random.default_rng([seed, 31])
            for n in np.unique(k):
                sel = textured[k == n]
                st = np.concatenate([stratified_2d(int(n), rng) for _ in range(len(sel))])
                pts = points_on_triangles(np.repeat(scene.triangle_corners[sel], n, axis=0), st[:, 0], st[:, 1])
                m = self.at(np.repeat(tri_face[sel], n), pts)
                mod[sel] = m.reshape(len(sel), int(n), 3).mean(axis=1)
        area = scene.triangle_area[scene.tside_triangle]
        side = scene.tside_side
        num = np.stack([np.bincount(side, area * mod[scene.tside_triangle][:, c], minlength=scene.n_sides)
                        for c in range(3)], axis=1)
        den = np.bincount(side, area, minlength=scene.n_sides)
        return num / np.maximum(den, 1e-300)[:, None]


def modulation_map(image):
    """The modulation map of a linear image (H, W, 3+): image / its mean color per
    channel (channels with mean 0 stay 1), and that mean (3,)."""
    im = np.asarray(image, float)[..., :3]
    mean = im.reshape(-1, 3).mean(axis=0)
    safe = np.where(mean > 0, mean, 1.0)
    mod = np.where(mean > 0, im / safe, 1.0)
    return mod.astype(np.float32), mean
