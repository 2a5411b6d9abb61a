"""The eye's rays: primary rays through the pixels' sample positions, followed through glass
and mirrors.

:class:`EyeRays` traces the camera's rays at the sub-pixel positions of each pixel's own
randomly shifted R_2 sequence (:meth:`EyeRays.subpixel_sequence`) and follows them through
the interfaces of glass and other transmissive surfaces as Cycles does, and off sharp mirrors
(:meth:`EyeRays.through_interfaces`), into a :class:`GBuffer` of the surfaces they see: what
a mirror shows is shaded per pixel as what the camera sees, not read from the patches.
"""
from __future__ import annotations

from dataclasses import dataclass, fields

import numpy as np

from ..lights.sources import ShapeLight
from ..scene.shading import sided_normals, specular_normals, valid_specular_normals
from ..scene.transmission import scatter
from ..tracing.sampling import Stream, kronecker_alpha, stream
from ..util.arrays import ranges


@dataclass
class GBuffer:
    """Visible surface per pixel: triangle (-1 = nothing), the triangle side seen
    ``tside`` (:meth:`~raybundle.scene.model.PatchScene.seen_tside`), point, the normal it
    is shaded with (that side's, on smooth-shaded faces the shading normal:
    :meth:`EyeRays._shading_normals`), material, direction to the eye ``w_eye``, barycentrics (N, 3)."""

    triangle: np.ndarray
    tside: np.ndarray
    point: np.ndarray
    normal: np.ndarray
    material: np.ndarray
    w_eye: np.ndarray
    bary: np.ndarray
    #: (N,) the pixel (row-major index) of each primary ray, None for other rays
    pixel: np.ndarray | None = None
    #: (N, 3) what the eye path's reflections and refractions on the way let through
    #: (:meth:`EyeRays.trace`), None: 1 (a scene without transmissive surfaces)
    weight: np.ndarray | None = None
    #: (N,) bool: the eye path was reflected or refracted on its way (None: none was)
    bounced: np.ndarray | None = None
    #: (N, 3) the area lamps the eye path met after it was turned, times :attr:`weight` there
    #: (None: none)
    lamps: np.ndarray | None = None
    #: (N,) bool: the eye path was reflected on its way (by a mirror or glass; None: none was):
    #: light-traced caustics, splatted straight to the camera, miss what it sees
    reflected: np.ndarray | None = None

    @property
    def hit(self):
        return self.triangle >= 0

    def front(self, scene):
        """(N,) the rays that see a side facing them (by its flat normal: a smooth-shaded
        face's shading normal may face away from the eye) of ``scene``'s."""
        h = np.nonzero(self.hit)[0]
        return h[np.einsum("ij,ij->i", scene.tside_normal[self.tside[h]], self.w_eye[h]) > 0]

    def weighted(self, values, idx=None):
        """``values`` (N, 3) (of the rays ``idx``, default all) times what the eye path's way
        through transmissive surfaces let through (:attr:`weight`)."""
        if self.weight is None:
            return values
        return values * (self.weight if idx is None else self.weight[idx])


class EyeRays:
    """The eye's rays of a camera over a scene.  ``rng`` (the renderer's pass stream) draws
    the interfaces' choices past the first; ``rays`` counts the rays traced."""

    def __init__(self, scene, camera, tracer, direct, settings, rng):
        self.scene, self.camera, self.tracer, self.settings, self.rng = scene, camera, tracer, settings, rng
        n = camera.width * camera.height
        py, px = np.divmod(np.arange(n), camera.width)
        #: (pixels, 2) each pixel's lower-left corner (x, y) in pixels, row-major
        self.pixel = np.stack([px, py], axis=1).astype(float)
        # the sub-pixel sequences (subpixel_sequence): a random shift and the next index per pixel,
        # and the first interface's choice, reflected or refracted (a 1-D Kronecker sequence)
        self._shift = stream(settings.seed, Stream.SUBPIXEL_SHIFT).random((n, 2))
        self._index = np.zeros(n, np.int64)
        self._choice_shift = stream(settings.seed, Stream.CHOICE_SHIFT).random(n)
        #: the area lamps an eye path turned by glass may meet (not geometry: tested by shape)
        self.shapes = [light for light in direct.area_lights if isinstance(light, ShapeLight)]
        mats = scene.materials
        #: (T,) bool: the triangles that turn the eye's paths, glass and sharp mirrors (None: none)
        turning = (mats.transmits | mats.is_mirror)[scene.triangle_material] if len(scene.triangles) else None
        self.turning = turning if turning is not None and turning.any() else None
        self.rays = 0

    def trace(self, jitter, pixels=None):
        """Primary rays through the pixels' sample positions for uniforms ``jitter`` (N, 2) in
        [0,1)^2 (:meth:`~raybundle.scene.camera.Camera.subpixel`: the pixel filter's), for all
        pixels or for the pixel indices ``pixels`` (N,), followed through the interfaces of
        glass and other transmissive surfaces (:meth:`through_interfaces`; a third column of
        ``jitter`` chooses at the first interface, reflected or refracted).  The rays are split
        into pieces run in parallel, each with random numbers of its own
        (:meth:`~raybundle.tracing.visibility.RayTracer.map_pieces`)."""
        jitter = np.asarray(jitter, float)
        pixels = np.arange(len(self.pixel)) if pixels is None else np.asarray(pixels)

        # only the interfaces past the first draw random numbers
        parts = self.tracer.map_pieces_of(self, lambda rays, a, b: rays._trace(jitter[a:b], pixels[a:b]), len(pixels),
                                          None if self.turning is None else self.rng)
        if len(parts) == 1:
            return parts[0]
        return GBuffer(*(None if getattr(parts[0], f.name) is None else
                         np.concatenate([getattr(p, f.name) for p in parts]) for f in fields(GBuffer)))

    def _trace(self, jitter, pixels):
        """:meth:`trace` of the rays in one piece."""
        cam = self.camera
        pos = self.pixel[pixels] + cam.subpixel(jitter[:, :2])
        org, dirs = cam.rays(pos[:, 0], pos[:, 1])
        tri, t, u, v = self.tracer.first_hit(org, dirs, glass=False)
        self.rays += len(dirs)
        weight = bounced = lamps = reflected = None
        if self.turning is not None:
            org, dirs, tri, t, u, v, weight, bounced, lamps, reflected = self.through_interfaces(
                org, dirs, tri, t, u, v, jitter[:, 2] if jitter.shape[1] > 2 else None)
        hit = tri >= 0
        sc = self.scene
        ts = sc.seen_tside(np.where(hit, tri, 0), dirs)
        point = org + np.where(hit, t, 0.0)[:, None] * dirs
        normal = sc.tside_normal[ts]
        if sc.shading is not None or (sc.texture is not None and sc.texture.has_normal_maps):
            h = np.nonzero(hit)[0]
            normal[h] = self._shading_normals(tri[h], point[h], normal[h], -dirs[h])
        return GBuffer(tri, ts, point, normal,
                       sc.triangle_material[sc.tside_triangle[ts]], -dirs, np.stack([1 - u - v, u, v], axis=1),
                       pixels, weight, bounced, lamps, reflected)

    def _shading_normals(self, tri, point, flat, w_eye):
        """The normals (N, 3) the points ``point`` seen on triangles ``tri`` are shaded with, from
        their ``flat`` normals (N, 3, facing the eye ``w_eye``): Blender's shading normal on the
        side seen (:func:`~raybundle.scene.shading.sided_normals`), as Cycles' Diffuse BSDF
        takes it even where it faces away from the eye, then the faces' normal and bump maps;
        on materials with a glossy lobe, made valid for the eye as Cycles' Bump Map Correction
        makes the normal of a specular closure (:func:`~raybundle.scene.shading.valid_specular_normals`),
        so the mirror direction stays above the surface; the diffuse lobe of such a material is
        shaded about the same normal."""
        sc = self.scene
        src = sc.triangle_source[tri]
        glossy = np.nonzero(sc.materials.is_glossy[sc.triangle_material[tri]])[0]
        n = flat if sc.shading is None else sided_normals(sc.shading, src, point, flat)
        if sc.texture is not None and sc.texture.has_normal_maps:
            n = sc.texture.shading_normals(src, point, n)
        n[glossy] = valid_specular_normals(flat[glossy], w_eye[glossy], n[glossy])
        return n

    def through_interfaces(self, org, dirs, tri, t, u, v, choice=None):
        """Eye rays ``org``, ``dirs`` (N, 3) with first hits ``(tri, t, u, v)`` followed through
        the transmissive surfaces they meet (:func:`~raybundle.scene.transmission.scatter`: by
        Fresnel, reflected or refracted, at the first by the uniforms ``choice`` (N,) where
        given) and off the sharp mirrors (:meth:`_turn`): as Cycles' transmission and glossy
        bounces, a path that has been refracted ``transmission_depth`` times or reflected
        ``glossy_depth`` times ends at the next interface it meets, black.  Returns the last segments' ``(org, dirs, tri, t, u, v)``, each ray's weight
        (N, 3), (N,) bool, whether it was turned, the area lamps (N, 3) its turned segments
        met before the surface they end on, weighted (or None where the scene has no area lamps),
        and (N,) bool, whether it was reflected.

        Blender's area lamps are not visible to the camera's own rays by default, but are to the
        glossy and transmission rays a turned path continues as: a lamp reflected in a pane or
        seen through it adds its radiance, and the path goes on (a lamp is not geometry and
        hides nothing behind it), as in Cycles."""
        sc, tracer = self.scene, self.tracer
        org, dirs = org.copy(), dirs.copy()
        weight = np.ones((len(tri), 3))
        bounced = np.zeros(len(tri), bool)
        reflections = np.zeros(len(tri), np.int64)
        refractions = np.zeros(len(tri), np.int64)
        shapes = self.shapes
        lamps = np.zeros((len(tri), 3)) if shapes else None
        live = np.nonzero(tri >= 0)[0]
        most_t, most_g = int(self.settings.transmission_depth), int(self.settings.glossy_depth)
        columns = 4 if np.any(sc.materials.transmission_roughness > 0) else 2     # rough ones draw microfacets
        for depth in range(most_t + most_g + 1):
            live = live[self.turning[tri[live]]]
            if len(live) == 0:
                break
            # as Cycles, a path that has spent its transmission or glossy bounces ends at the next
            # surface it meets (black where that is glass)
            spent = (refractions[live] >= most_t) | (reflections[live] >= most_g)
            weight[live[spent]], tri[live[spent]] = 0.0, -1
            live = live[~spent]
            if len(live) == 0:
                break
            d = dirs[live]
            p = org[live] + t[live, None] * d
            geo = sc.triangle_normal[tri[live]]
            facing = np.where((np.einsum("ij,ij->i", geo, d) < 0)[:, None], geo, -geo)
            shade = specular_normals(sc.shading, sc.triangle_source[tri[live]], p, facing, -d)
            uniforms = self.rng.random((len(live), columns))
            if depth == 0 and choice is not None:
                uniforms[:, 1] = choice[live]
            on, new, w = self._turn(sc.triangle_material[tri[live]], d, geo, shade, uniforms)
            weight[live] *= w
            turned = np.einsum("ij,ij->i", d, geo) * np.einsum("ij,ij->i", new, geo) < 0
            reflections[live] += on & turned
            refractions[live] += on & ~turned
            live = live[on]
            bounced[live] = True
            org[live] = p[on] + tracer.eps * new[on]
            dirs[live] = new[on]
            tri[live], t[live], u[live], v[live] = tracer.first_hit(org[live], dirs[live], glass=False)
            self.rays += len(live)
            if shapes and len(live):
                reach = np.where(tri[live] >= 0, t[live], np.inf)
                for light in shapes:
                    met, _ = light.hit(org[live], dirs[live], reach)
                    lamps[live[met]] += weight[live[met]] * light.radiance
            live = live[tri[live] >= 0]
        return org, dirs, tri, t, u, v, weight, bounced, lamps, reflections > 0

    def _turn(self, mat, travel, geometric, shading, u):
        """One event of eye paths that meet turning materials ``mat`` (N,): at glass
        :func:`~raybundle.scene.transmission.scatter` (its arguments); at a sharp mirror
        (:attr:`~raybundle.scene.materials.MaterialTable.is_mirror`) the mirror direction about
        ``shading`` (facing the path), weighted by its reflectance there, so the surface
        seen in the mirror is shaded as one the camera sees.  Returns ``(on, direction,
        weight)`` as ``scatter`` does."""
        mats = self.scene.materials
        mirror = mats.is_mirror[mat]
        if not mirror.any():
            return scatter(mats, mat, travel, geometric, shading, u)
        on, out, weight = np.ones(len(mat), bool), np.empty((len(mat), 3)), np.empty((len(mat), 3))
        g = np.nonzero(~mirror)[0]
        if len(g):
            on[g], out[g], weight[g] = scatter(mats, mat[g], travel[g], geometric[g], shading[g], u[g])
        m = np.nonzero(mirror)[0]
        out[m], weight[m] = mats.mirror_reflection(mat[m], shading[m], -travel[m])
        on[m] = np.any(weight[m] > 0, axis=1)
        return on, out, weight

    def subpixel_sequence(self, pixels, k):
        """``k`` (or (N,) counts) sub-pixel positions in each of ``pixels``, continuing one
        randomly shifted R_2 sequence per pixel (:func:`~raybundle.tracing.sampling.kronecker_alpha`) from
        pass to pass: returns (pixel ids (N k,), positions (N k, 3)), the third column the
        choice at the first interface of glass the eye path meets (:meth:`trace`), on a
        1-D Kronecker sequence per pixel: over a pixel's samples, the share reflected by a pane
        is F to within one sample, where independent choices left the reflection in a grazing
        balustrade a binomial speckle.  Every position is
        uniform in its pixel (the averages stay unbiased) and all of a pixel's samples (the
        passes' own and the extra ones) together fill it with discrepancy O(log n / n), where
        fresh jittered grids every pass left the coverage of an edge noisy as n^-3/4: a
        window bar against a sky 20 times brighter than the room is mostly that coverage."""
        pixels = np.asarray(pixels, np.int64)
        k = np.broadcast_to(k, len(pixels))
        pix = np.repeat(pixels, k)
        i = self._index[pix] + ranges(0, k)
        self._index[pixels] += k
        choice = (self._choice_shift[pix] + i * kronecker_alpha(1)[0]) % 1.0
        return pix, np.column_stack([(self._shift[pix] + i[:, None] * kronecker_alpha(2)) % 1.0, choice])
