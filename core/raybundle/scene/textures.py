"""Image textures on the diffuse albedo and cut-outs: sharp texture detail over smooth light.

A textured material's diffuse reflectance varies over a surface as
``kd(x) = kd_m * M(uv(x))``: ``kd_m`` the material's reflectance from the image's
mean color (what :class:`~raybundle.scene.materials.MaterialTable` holds) and ``M`` the
*modulation map*, the image divided by its mean color per channel (mean 1), looked
up bilinearly with repeat at the point's UV (as Cycles' Image Texture node with
Linear interpolation and Repeat extension does; texel centres at (i + 0.5) / W), or with its
edge texels extended beyond [0, 1] (Extend extension, and graphs baked on one object), or at the
nearest texel (Closest interpolation).  A byte image in the sRGB color space is kept as Cycles
keeps it, its texels sRGB-encoded: a lookup interpolates the encoded values, then decodes them
and scales them by the inverse of the image's linear mean (interpolating the decoded values
instead makes the blend between a bright and a dark texel brighter than Cycles').

The solver keeps one variable per patch side, so a patch reflects with its mean
albedo ``kd_m * mean_patch(M)`` (:meth:`SurfaceTexture.side_means`: the modulation
averaged over the patch at stratified points, as many as the patch covers texels, up to
:data:`MAX_SAMPLES` per triangle, on the level of the map's pyramid of 2 x 2 means where the
triangle covers no more texels than that); images and bakes multiply the diffuse
light at each pixel or texel by ``kd_m * M(uv)`` (:meth:`SurfaceTexture.at`), so the
texture stays sharp while the light is interpolated smoothly.

A **color attribute** drives the albedo the same way, its color interpolated linearly
over each input face from its corners (``face_image`` -2; the material's reflectance
then holds white, so the color is the factor itself).

UVs live on the *input* faces (the exported triangles, before subdivision): a
point's UV is the input face's corner UVs weighted by the point's barycentrics on
that face, whatever patch triangle it lies on.

**Cut-outs.** A face may also have a *coverage* map ``alpha(uv)`` in [0, 1] (``face_alpha``,
Blender's Alpha of a Principled BSDF): as in Cycles, a fraction ``alpha`` of the light that
reaches the point meets the surface and ``1 - alpha`` passes on unchanged, as through a hole.
The tracer (:mod:`raybundle.tracing.visibility`) keeps a hit on such a face with probability
``alpha`` at the hit point, so bundles, shadow rays and eye rays see the surface that often;
a patch then receives light on its covered area only (:meth:`SurfaceTexture.triangle_coverage`
scales its receiving area), so its radiance is that of the surface where it is, and the eye
sees it with the coverage of each pixel.

**Normal and bump maps.** A face may also have a *normal map* (``face_normal``): the normal
Blender's nodes give a material's shader (Normal Map, Bump, anything between), evaluated by
Blender over a unit square whose UV is its position, so that each texel holds the perturbed
normal ``(x, y, z)`` in the frame (dP/du, dP/dv, N) of a surface with one metre per UV unit.
On a face, :meth:`SurfaceTexture.shading_normals` turns it into the normal to shade with:

* a *normal map* (``face_bump`` False; Normal Map node, tangent space): ``n' = normalize(x T + y B
  + z N)``, ``T`` the unit tangent along dP/du in the plane of ``N`` and ``B = s N x T``, ``s``
  the UV's handedness (MikkTSpace's frame, taken per face rather than per vertex);
* a *bump* (``face_bump`` True; Bump node): the height's slope is per metre of the surface, so
  the bake's slope per UV unit, ``-(x, y) / z``, is carried by the dual basis ``(T*, B*)`` of
  the face's (dP/du, dP/dv) in the plane of ``N``: ``n' = normalize(N + (x T* + y B*) / z)``,
  Cycles' ``N - distance grad H`` with the gradient in metres (exact for strength 1; a lower
  strength's blend with ``N`` is scaled with it).

The perturbed normal shades what the eye sees (direct light of lamps and the world, glossy
lobes); where it would face away from the eye, the point keeps its unperturbed normal.  The
patches keep their flat normals.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

#: most modulation samples per triangle for its mean (per patch for a patch's mean albedo)
MAX_SAMPLES = 256
#: points a patch's mean albedo takes at the least (:meth:`SurfaceTexture.side_means`)
PATCH_SAMPLES = 16
#: points whose look-ups a mean takes at once (:meth:`SurfaceTexture._triangle_means`): a point's
#: temporaries are a couple of hundred bytes
MEAN_POINTS = 1 << 16
#: fewest samples per triangle for its mean coverage: a patch's radiance is the light it
#: receives over its covered area, so an error there is an error of the patch
MIN_COVERAGE_SAMPLES = 64


@dataclass
class SurfaceTexture:
    """Modulation maps of the textured input faces.

    ``images``: list of (H, W, 3) float32 modulation maps (linear image / its mean; float16 maps
    are kept so, :func:`half_precision`);
    ``face_image`` (F,) int: the map of each input face (-1: untextured; -2: the face's
    corner colors, interpolated linearly: a color attribute, whose color is the albedo
    factor itself), indexed by :attr:`~raybundle.scene.model.PatchScene.triangle_source`;
    ``face_corners`` (F, 3, 3) [m] and ``face_uv`` (F, 3, 2), float32: the input faces and their
    corner UVs; ``face_color`` (F, 3, 3) or None: their corner colors; ``face_alpha`` (F,) int
    or None: the map of each face's coverage (its first channel; -1: opaque); ``face_normal``
    (F,) int or None: the map of each face's normal, its texels the perturbed normal (x, y, z)
    (-1: none), ``face_bump`` (F,) bool or None: that map is a bump's (module docstring).
    ``encoded`` (one per map, or None for none): None for a map of linear values, or the (3,)
    scale of a map whose texels are sRGB-encoded (``M = scale * decode(lookup)``); ``closest``
    (one bool per map, or None for none): the map is read at the nearest texel; ``extend`` (one
    bool per map, or None for none): beyond [0, 1] the map's edge texels are read, else it repeats;
    ``byte_values`` (one per map, or None for none): None for a map of float32 texels, or the
    (256,) float32 value each texel of a map of uint8 texels stands for (a byte image's encoded
    values as Blender holds them: a quarter of the memory, the same values read)."""

    images: list
    face_image: np.ndarray
    face_corners: np.ndarray
    face_uv: np.ndarray
    face_color: np.ndarray | None = None
    face_alpha: np.ndarray | None = None
    face_normal: np.ndarray | None = None
    face_bump: np.ndarray | None = None
    encoded: list | None = None
    closest: list | None = None
    extend: list | None = None
    byte_values: list | None = None
    _pyramids: dict = field(default_factory=dict, repr=False, compare=False)

    def __post_init__(self):
        self.face_image = np.asarray(self.face_image, np.int32)
        self.face_alpha = (np.full(len(self.face_image), -1, np.int32) if self.face_alpha is None
                           else np.asarray(self.face_alpha, np.int32))
        self.face_normal = (np.full(len(self.face_image), -1, np.int32) if self.face_normal is None
                            else np.asarray(self.face_normal, np.int32))
        self.face_bump = (np.zeros(len(self.face_image), bool) if self.face_bump is None
                          else np.asarray(self.face_bump, bool))
        self.face_corners = np.asarray(self.face_corners, np.float32)
        self.face_uv = np.asarray(self.face_uv, np.float32)          # as Blender keeps UVs
        if self.face_color is not None:
            self.face_color = np.asarray(self.face_color, float)
        self.byte_values = [None if b is None else np.asarray(b, np.float32).reshape(256)
                            for b in (self.byte_values or [None] * len(self.images))]
        if len(self.byte_values) != len(self.images):
            raise ValueError("texture: 'byte_values' needs one entry per map")
        self.images = [np.ascontiguousarray(im, np.uint8 if b is not None else
                                            np.float16 if np.asarray(im).dtype == np.float16 else np.float32)
                       for im, b in zip(self.images, self.byte_values)]
        self.encoded = [None if e is None or not np.all(np.isfinite(e)) else np.asarray(e, float).reshape(3)
                        for e in (self.encoded or [None] * len(self.images))]
        self.closest = [bool(c) for c in (self.closest if self.closest is not None else [False] * len(self.images))]
        self.extend = [bool(c) for c in (self.extend if self.extend is not None else [False] * len(self.images))]
        if not len(self.encoded) == len(self.closest) == len(self.extend) == len(self.images):
            raise ValueError("texture: 'encoded', 'closest' and 'extend' need one entry per map")

    def to_arrays(self):
        """Flat arrays for a scene's ``.npz`` (``texture_*``): the maps one after another."""
        d = {"texture_face_image": self.face_image, "texture_face_corners": self.face_corners,
             "texture_face_uv": self.face_uv,
             "texture_image_shapes": np.array([im.shape[:2] for im in self.images], np.int64).reshape(-1, 2),
             "texture_pixels": (np.concatenate([self.texels(k).reshape(-1, 3) for k in range(len(self.images))])
                                if self.images else np.zeros((0, 3), np.float32))}
        if self.face_color is not None:
            d["texture_face_color"] = self.face_color
        if self.has_cutouts:
            d["texture_face_alpha"] = self.face_alpha
        if self.has_normal_maps:
            d["texture_face_normal"], d["texture_face_bump"] = self.face_normal, self.face_bump
        if any(e is not None for e in self.encoded) or any(self.closest):
            d["texture_encoded"] = np.array([np.full(3, np.nan) if e is None else e for e in self.encoded]).reshape(-1, 3)
            d["texture_closest"] = np.array(self.closest, bool)
        if any(self.extend):
            d["texture_extend"] = np.array(self.extend, bool)
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
        encoded = d.get("texture_encoded")
        return cls(images, d["texture_face_image"], d["texture_face_corners"], d["texture_face_uv"],
                   d.get("texture_face_color"), d.get("texture_face_alpha"), d.get("texture_face_normal"),
                   d.get("texture_face_bump"), None if encoded is None else list(np.asarray(encoded, float)),
                   d.get("texture_closest"), d.get("texture_extend"))

    def texels(self, image):
        """(H, W, 3) float32 map ``image``'s texels, read through :attr:`byte_values` for a map of bytes."""
        im, values = self.images[image], self.byte_values[image]
        return im.astype(np.float32, copy=False) if values is None else values[im]

    def lookup(self, image, uv, level=0):
        """Lookup (N, 3) of map ``image`` at ``uv`` (N, 2), repeating or with its edges extended
        (:attr:`extend`), bilinear or at the nearest texel (:attr:`closest`), on ``level`` of its
        pyramid (0: the map itself, decoded after the lookup where its texels are sRGB-encoded;
        each next level the 2 x 2 means of the one below, of decoded values)."""
        im = self.level(image, level)
        if level == 0 and self.byte_values[image] is not None:
            im = _ByteTexels(im, self.byte_values[image])
        h, w = im.shape[:2]
        x = uv[:, 0] * w - 0.5
        y = uv[:, 1] * h - 0.5
        wrap = (lambda i, n: np.clip(i, 0, n - 1)) if self.extend[image] else (lambda i, n: i % n)
        if self.closest[image] and level == 0:
            out = im[wrap(np.floor(y + 0.5).astype(np.int64), h), wrap(np.floor(x + 0.5).astype(np.int64), w)]
            out = out.astype(np.float32, copy=False)
        else:
            x0, y0 = np.floor(x), np.floor(y)
            fx, fy = (x - x0)[:, None], (y - y0)[:, None]
            x0, y0 = x0.astype(np.int64), y0.astype(np.int64)
            x0, y0, x1, y1 = wrap(x0, w), wrap(y0, h), wrap(x0 + 1, w), wrap(y0 + 1, h)
            out = ((1 - fy) * ((1 - fx) * im[y0, x0] + fx * im[y0, x1])
                   + fy * ((1 - fx) * im[y1, x0] + fx * im[y1, x1]))
        if level == 0 and self.encoded[image] is not None:
            out = srgb_to_linear(out) * self.encoded[image]
        return out

    def level(self, image, level):
        """Level ``level`` of map ``image``'s pyramid (kept until :meth:`_triangle_means` ends,
        the set-up's reads of it): level 0 is the map as
        stored (bytes for a map of :attr:`byte_values`), each next level the means of 2 x 2 texels
        of decoded values (an odd row or column is averaged with the first, as the map repeats, or
        with itself where its edges extend)."""
        if level == 0:
            return self.images[image]
        key = (image, level)
        if key not in self._pyramids:
            values = self.byte_values[image]
            if level > 1:
                im = self.level(image, level - 1)
            elif self.encoded[image] is None:
                im = self.texels(image)
            else:             # a map of bytes decodes its 256 values, not each texel (the same floats)
                im = srgb_to_linear(self.texels(image)) if values is None else \
                    srgb_to_linear(values)[self.images[image]]
                im = im * np.asarray(self.encoded[image], np.float32)
            for axis in (0, 1):
                if im.shape[axis] > 1:
                    if im.shape[axis] % 2:
                        im = np.concatenate([im, np.take(im, [-1 if self.extend[image] else 0], axis=axis)],
                                            axis=axis)
                    even = (slice(None),) * axis + (slice(0, None, 2),)
                    odd = (slice(None),) * axis + (slice(1, None, 2),)
                    im = 0.5 * (im[even] + im[odd])
            self._pyramids[key] = np.ascontiguousarray(im, np.float32)
        return self._pyramids[key]

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

    @property
    def has_cutouts(self):
        """Whether any face has a coverage map."""
        return bool(np.any(self.face_alpha >= 0))

    @property
    def cutout_faces(self):
        """(F,) bool: the faces with a coverage map."""
        return self.face_alpha >= 0

    def alpha_at(self, face, points):
        """(N,) coverage in [0, 1] at ``points`` (N, 3) on input faces ``face`` (N,) (1 where opaque)."""
        face = np.asarray(face, np.int64)
        out = np.ones(len(face))
        k_of = self.face_alpha[face]
        for k in np.unique(k_of[k_of >= 0]):
            sel = np.nonzero(k_of == k)[0]
            out[sel] = self.lookup(int(k), self.uv_at(face[sel], points[sel]))[:, 0]
        return np.clip(out, 0.0, 1.0)

    @property
    def has_normal_maps(self):
        """Whether any face has a normal or bump map."""
        return bool(np.any(self.face_normal >= 0))

    def shading_normals(self, face, points, normals):
        """The normals (N, 3) to shade ``points`` (N, 3) on input faces ``face`` (N,) with:
        ``normals`` (N, 3) (unit, on the side seen) perturbed by the faces' normal or bump maps
        (module docstring), kept where a face has none.  A perturbed normal that faces away from
        the eye is kept as it is, as Cycles' Normal Map and Bump nodes give it: a diffuse lobe
        takes it so, a specular one made valid for the eye
        (:func:`~raybundle.scene.shading.valid_specular_normals`)."""
        face = np.asarray(face, np.int64)
        out = np.array(normals, float)
        k_of = self.face_normal[face]
        mapped = np.nonzero(k_of >= 0)[0]
        if len(mapped) == 0:
            return out
        f, n = face[mapped], out[mapped]
        c, uv = self.face_corners[f], self.face_uv[f]
        e1, e2 = c[:, 1] - c[:, 0], c[:, 2] - c[:, 0]
        d1, d2 = uv[:, 1] - uv[:, 0], uv[:, 2] - uv[:, 0]
        det = d1[:, 0] * d2[:, 1] - d2[:, 0] * d1[:, 1]
        inv = np.where(np.abs(det) > 1e-300, 1.0 / np.where(det != 0, det, 1.0), 0.0)[:, None]
        dpdu = (e1 * d2[:, 1:] - e2 * d1[:, 1:]) * inv          # [e1 e2] [[du1 du2], [dv1 dv2]]^-1
        dpdv = (e2 * d1[:, :1] - e1 * d2[:, :1]) * inv
        a = dpdu - np.einsum("ij,ij->i", dpdu, n)[:, None] * n  # in the plane of the normal
        b = dpdv - np.einsum("ij,ij->i", dpdv, n)[:, None] * n
        v = np.empty((len(mapped), 3))
        for k in np.unique(k_of[mapped]):
            sel = np.nonzero(k_of[mapped] == k)[0]
            v[sel] = self.lookup(int(k), self.uv_at(f[sel], points[mapped[sel]]))
        x, y, z = v[:, 0:1], v[:, 1:2], np.maximum(v[:, 2:3], 1e-3)
        bump = self.face_bump[f]
        # a normal map: the unit tangent frame (T, B = s N x T, N)
        t = a / np.maximum(np.linalg.norm(a, axis=1, keepdims=True), 1e-300)
        s = np.where(np.einsum("ij,ij->i", np.cross(dpdu, dpdv), n) < 0, -1.0, 1.0)[:, None]
        tangent = x * t + y * s * np.cross(n, t) + z * n
        # a bump: the slope per UV unit carried by the dual basis of (dP/du, dP/dv)
        aa, ab, bb = (np.einsum("ij,ij->i", p, q)[:, None] for p, q in ((a, a), (a, b), (b, b)))
        g = aa * bb - ab * ab
        g = np.where(g > 1e-300, g, np.inf)
        dual = n + (x * (bb * a - ab * b) + y * (aa * b - ab * a)) / (g * z)
        m = np.where(bump[:, None], dual, tangent)
        m /= np.maximum(np.linalg.norm(m, axis=1, keepdims=True), 1e-300)
        ok = np.all(np.isfinite(m), axis=1) & (np.abs(det) > 0)
        out[mapped[ok]] = m[ok]
        return out

    def triangle_coverage(self, scene, seed=0):
        """(T,) the mean coverage over each triangle of ``scene`` (1 where opaque), from
        stratified points as :meth:`side_means` takes them."""
        return np.clip(self._triangle_means(scene, self.face_alpha, seed, MIN_COVERAGE_SAMPLES)[:, 0], 0.0, 1.0)

    def side_means(self, scene, seed=0):
        """(S, 3) the area-weighted mean modulation over each patch side of ``scene``
        (:meth:`_triangle_means` of the albedo maps): a patch takes :data:`PATCH_SAMPLES` to
        :data:`MAX_SAMPLES` points, shared among its triangles by area (at least one each), an
        unbiased mean of the patch whatever the number of its triangles."""
        tri_face = scene.triangle_source
        share = scene.triangle_area / np.maximum(scene.patch_area[scene.triangle_patch], 1e-300)
        mod = self._triangle_means(scene, self.face_image, seed,
                                   np.clip(np.ceil(PATCH_SAMPLES * share), 1, PATCH_SAMPLES),
                                   2.0 ** np.floor(np.log2(np.maximum(MAX_SAMPLES * share, 1.0))))
        col = np.nonzero(self.face_image[tri_face] == -2)[0]
        if len(col):          # linear over the face: the mean over a triangle is at its centroid
            mod[col] = self.at(tri_face[col], scene.triangle_corners[col].mean(axis=1))
        area = scene.triangle_area[scene.tside_triangle]
        side = scene.tside_side
        num = np.stack([np.bincount(side, area * mod[scene.tside_triangle][:, c], minlength=scene.n_sides)
                        for c in range(3)], axis=1)
        den = np.bincount(side, area, minlength=scene.n_sides)
        return num / np.maximum(den, 1e-300)[:, None]

    def _triangle_means(self, scene, face_map, seed, fewest=16, most=MAX_SAMPLES):
        """(T, 3) the mean over each triangle of ``scene`` of the map ``face_map`` (F,) gives its
        face (ones where it gives none): the map at stratified points, one per texel the triangle
        covers, ``fewest`` to ``most`` (numbers, or one per triangle; ``most`` a power of 2).  A
        triangle that covers more texels reads a coarser level of the map's pyramid (each texel
        the mean of 2 x 2 of the level below), where it covers at most ``most``.  The points' UVs are the triangle's corner
        UVs interpolated (UV is affine over a face)."""
        from ..tracing.sampling import Stream, stratified_2d_sets, stream, uniform_triangle

        tri_face = scene.triangle_source
        img = face_map[tri_face]
        mean = np.ones((len(scene.triangles), 3))
        textured = np.nonzero(img >= 0)[0]
        if len(textured) == 0:
            return mean
        face = tri_face[textured]
        uv = np.stack([self.uv_at(face, scene.triangle_corners[textured, j]) for j in range(3)], axis=1)
        du, dv = uv[:, 1] - uv[:, 0], uv[:, 2] - uv[:, 0]
        texels = np.array([im.shape[0] * im.shape[1] for im in self.images], float)[img[textured]]
        covered = 0.5 * np.abs(du[:, 0] * dv[:, 1] - du[:, 1] * dv[:, 0]) * texels
        most = np.broadcast_to(most, img.shape)[textured]
        level = np.maximum(0, np.ceil(np.log(np.maximum(covered, 1.0) / most) / np.log(4.0))).astype(np.int64)
        # points per triangle: the texels it covers on its level, rounded up to a power of 2
        k = np.clip(np.ceil(covered / 4.0 ** level), np.broadcast_to(fewest, img.shape)[textured], most)
        k = np.minimum(2 ** np.ceil(np.log2(k)), most).astype(np.int64)
        rng = stream(seed, Stream.TEXTURE_MEANS)
        groups, which = np.unique(np.stack([k, level, img[textured]], axis=1), axis=0, return_inverse=True)
        order = np.argsort(which.ravel(), kind="stable")
        try:
            for (n, lev, m), sel in zip(groups, np.split(order, np.cumsum(np.bincount(which.ravel()))[:-1])):
                n = int(n)
                st = stratified_2d_sets(len(sel), n, rng).reshape(len(sel), n, 2)
                step = max(1, MEAN_POINTS // n)       # the points' look-ups a few triangles at a time
                for lo in range(0, len(sel), step):
                    t = sel[lo:lo + step]
                    s = st[lo:lo + step].reshape(-1, 2)
                    w = uniform_triangle(s[:, 0], s[:, 1]).reshape(len(t), n, 3)
                    got = self.lookup(int(m), np.einsum("tnk,tkc->tnc", w, uv[t]).reshape(-1, 2), int(lev))
                    mean[textured[t]] = got.reshape(len(t), n, -1).mean(axis=1)
        finally:           # the coarser levels serve these means alone: not held through the render
            self._pyramids.clear()
        return mean


class _ByteTexels:
    """A map of bytes indexed as its float32 values: ``[rows, cols]`` reads ``values[bytes[rows, cols]]``."""

    def __init__(self, texels, values):
        self.texels, self.values, self.shape = texels, values, texels.shape

    def __getitem__(self, at):
        return self.values[self.texels[at]]


def srgb_to_linear(c):
    """The sRGB transfer function's inverse (IEC 61966-2-1), elementwise, in float32 for a
    float32 array (an image's pyramid) and in float64 otherwise."""
    c = np.asarray(c)
    c = c if c.dtype == np.float32 else c.astype(float)
    one = c.dtype.type
    curve = ((np.maximum(c, one(0.04045)) + one(0.055)) * one(1 / 1.055)) ** one(2.4)
    return np.where(c <= one(0.04045), c * one(1 / 12.92), curve)


#: the largest finite float16
HALF_MAX = float(np.finfo(np.float16).max)


def half_precision(texels):
    """``texels`` (a float map) in float16 where that holds every texel (all finite and below
    :data:`HALF_MAX`): 11 bits of precision, finer than a byte image's steps, in half the memory
    of float32; else as they are."""
    texels = np.asarray(texels)
    if texels.size and np.isfinite(texels).all() and np.abs(texels).max() < HALF_MAX:
        return texels.astype(np.float16)
    return texels


def modulation_map(image):
    """The modulation map of a linear image (H, W, 3+): image / its mean color per
    channel (channels with mean 0 stay 1), and that mean (3,)."""
    image = np.asarray(image)[..., :3]
    mean = np.asarray(image, float).reshape(-1, 3).mean(axis=0)
    safe = np.where(mean > 0, mean, 1.0)
    mod = np.empty(image.shape, np.float32)
    step = max(1, (1 << 20) // max(image.shape[1], 1))          # rows at a time: float64 temporaries bounded
    for lo in range(0, len(image), step):
        mod[lo:lo + step] = np.where(mean > 0, np.asarray(image[lo:lo + step], float) / safe, 1.0)
    return mod, mean
