"""One builder of the exported scene: each object's triangles, materials, shading normals,
textures and link set collected as it is met, and the core's scene made of them at the end."""
from __future__ import annotations

import warnings as _warnings
from dataclasses import dataclass

import numpy as np

from .mesh_data import world_normals


@dataclass
class _Part:
    """One exported object's triangles."""
    vertices: np.ndarray            # (V, 3) world space
    triangles: np.ndarray           # (T, 3) int64, into the whole scene's vertices
    materials: np.ndarray           # (T,) int64 material ids
    polygons: np.ndarray            # (T,) the mesh polygon of each triangle
    loops: np.ndarray               # (T, 3) the mesh corner of each triangle corner
    normals: np.ndarray | None      # (T, 3, 3) world-space corner normals, None where the API lacks them
    emitter_set: int                # an emitting mesh's own link set
    textured: tuple | None          # :func:`.mesh_data.texture_uvs`'s arrays, None when untextured
    geometry_offset: float          # the object's shadow terminator geometry offset


class SceneBuilder:
    """Collects the export object by object (:meth:`add_object`, :attr:`lights`), converting
    each material once (``converter``, :class:`.shaders.MaterialConverter`), and makes the
    core's scene (:meth:`scene`).  ``images`` (key -> (index, image, kind, closest, extend)) grows as
    the objects' textures meet new images (:func:`.mesh_data.texture_uvs`)."""

    def __init__(self, converter):
        self.converter = converter
        self.parts: list[_Part] = []
        self.objects: list = []                 # ObjectInfo per part
        self.lights = {"point": [], "sun": [], "area": []}
        self.images: dict = {}
        self._material_index: dict = {}
        self._material_specs: list = []
        self.n_vertices = self.n_triangles = 0

    def material_id(self, mat):
        """The id of bpy material ``mat`` (None: the default material), converted when first met."""
        key = None if mat is None else mat.name_full
        if key not in self._material_index:
            self._material_index[key] = len(self._material_specs)
            self._material_specs.append(self.converter.convert(mat))
        return self._material_index[key]

    def add_object(self, info, arrays, M, slots, textured, emitter_set, geometry_offset):
        """Object ``info`` (an ObjectInfo) with the mesh ``arrays`` (positions, triangles, loops,
        triangle polygons, polygon material indices, corner normals: :func:`.mesh_data.mesh_arrays`,
        its left-out faces removed), world matrix ``M``, material ``slots``, textures, link set
        and shadow terminator geometry offset."""
        pos, tri, loops, tp, mi, cn = arrays
        ids = np.array([self.material_id(m) for m in slots] or [self.material_id(None)], np.int64)
        self.parts.append(_Part(pos @ M[:3, :3].T.astype(np.float64) + M[:3, 3], tri.astype(np.int64) + self.n_vertices,
                                ids[np.clip(mi[tp], 0, len(ids) - 1)], tp, loops,
                                None if cn is None else world_normals(cn[loops], M), emitter_set, textured,
                                geometry_offset))
        self.objects.append(info)
        self.n_vertices += len(pos)
        self.n_triangles += len(tri)

    def joined(self, name):
        """The parts' arrays ``name`` (a :class:`_Part` field) end to end."""
        return np.concatenate([getattr(p, name) for p in self.parts])

    def triangle_object(self):
        """(T,) int32: the object (index into :attr:`objects`) of each triangle."""
        return np.concatenate([np.full(len(p.triangles), k, np.int32) for k, p in enumerate(self.parts)])

    def texture(self, corners):
        """The scene's :class:`~raybundle.scene.textures.SurfaceTexture` for triangle ``corners``
        (T, 3, 3), or None when no object reads an image; untextured objects' faces read none."""
        tex = [p.textured for p in self.parts]
        if not any(x is not None and (np.any(x[1] != -1) or np.any(x[3] != -1) or np.any(x[4] != -1)) for x in tex):
            return None
        from raybundle.scene.textures import SurfaceTexture, half_precision

        size = [len(p.triangles) for p in self.parts]

        def faces(k, fill, shape=(), dtype=np.int64):
            return np.concatenate([np.full((n, *shape), fill, dtype) if x is None else x[k] for n, x in zip(size, tex)])

        # albedo maps are the image over its mean (the material holds the mean; a byte sRGB image's
        # texels encoded, as Cycles keeps them), coverage and normal maps as they are; float
        # texels in half precision where that holds them
        ordered = sorted(self.images.values(), key=lambda x: x[0])
        maps = [self.converter.albedo_map(im) if kind == "albedo"
                else (half_precision(np.asarray(self.converter.image_pixels(im), np.float32)), None, None)
                for _, im, kind, *_ in ordered]
        image = faces(1, -1)
        return SurfaceTexture([m for m, *_ in maps], image, corners, faces(0, 0.0, (3, 2), float),
                              faces(2, 0.0, (3, 3), float) if (image == -2).any() else None,     # color attributes
                              faces(3, -1), faces(4, -1), faces(5, False, (), bool),
                              encoded=[e for _, e, _ in maps], byte_values=[b for *_, b in maps],
                              closest=[closest for *_, closest, _ in ordered],
                              extend=[extend for *_, extend in ordered])

    def scene(self, world, camera, name, link_sets, warn):
        """``(scene, vertices, triangles, materials)``: the validated two-sided
        :class:`~raybundle.scene.model.PatchScene` of everything added, the Python warnings of
        building it passed to ``warn``."""
        from raybundle.scene.build import build_scene
        from raybundle.scene.materials import MaterialTable
        from raybundle.scene.model import AreaLights, PointLights, SunLights
        from raybundle.scene.shading import ShadingNormals

        v, t, m = self.joined("vertices"), self.joined("triangles"), self.joined("materials")
        mats = MaterialTable.from_list(self._material_specs)
        with _warnings.catch_warnings(record=True) as caught:
            _warnings.simplefilter("always")
            corners, shading = v[t], None
            if all(p.normals is not None for p in self.parts):
                offsets = np.concatenate([np.full(len(p.triangles), p.geometry_offset, np.float32) for p in self.parts])
                shading = ShadingNormals.of_faces(corners, self.joined("normals"), geometry_offset=offsets)
            # the input faces in 32 bits, one array for the shading normals and the textures
            corners = corners.astype(np.float32) if shading is None else shading.face_corners
            texture = self.texture(corners)
            sc = build_scene(v, t, m, mats, point_lights=_records(PointLights, self.lights["point"]),
                             sun_lights=_records(SunLights, self.lights["sun"]),
                             area_lights=_records(AreaLights, self.lights["area"]),
                             world=world, camera=camera, two_sided=True,
                             triangle_solid=np.zeros(len(t), bool),    # two-sided surfaces are never solids
                             name=name, texture=texture, shading=shading,
                             linking=link_sets.linking([(o.original, o.instancer) for o in self.objects],
                                                       self.triangle_object(),
                                                       np.array([p.emitter_set for p in self.parts], np.int64)))
        for w in caught:
            warn(str(w.message))
        return sc, v, t, mats


def _records(cls, rows):
    """The lights ``rows`` (dicts of :func:`.lights.convert_light`) as one ``cls`` of arrays;
    photometric profiles become an index into their list (one per profile), -1 for none."""
    if not rows:
        return cls()
    profiles = [r.pop("profile") for r in rows if "profile" in r]
    if profiles:
        index = {}
        for r, p in zip(rows, profiles):
            r["profile"] = -1 if p is None else index.setdefault(id(p), (len(index), p))[0]
        kept = [p for _, p in sorted(index.values(), key=lambda x: x[0])]
        return cls(**{k: np.array([r[k] for r in rows]) for k in rows[0]}, profiles=kept)
    return cls(**{k: np.array([r[k] for r in rows]) for k in rows[0]})
