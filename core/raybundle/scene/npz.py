"""Reading the ``.npz`` scene format (written by :meth:`~raybundle.scene.model.PatchScene.save_npz`
and by the Blender add-on): every array checked, a bad file one line of :class:`SceneError`."""
from __future__ import annotations

import numpy as np

from .build import build_scene
from .camera import Camera
from .materials import MaterialTable
from .model import NPZ_FORMAT_VERSION, AreaLights, PatchScene, PointLights, SceneError, SunLights
from .world import World


def load_npz(path) -> PatchScene:
    """Read a scene written by :meth:`PatchScene.save_npz` (or by the add-on) and validate it.

    Required arrays: ``vertices`` (V,3), ``triangles`` (T,3), ``triangle_material`` (T,)
    and the ``material_*`` table; ``triangle_patch``, ``triangle_source``,
    ``triangle_two_sided`` (T,) bool (absent: one-sided, as files of format 1),
    ``point_light_*``, ``sun_light_*``, ``area_light_*``, ``world_image`` (H, W, 3) and ``world_camera_image`` (or
    the older constant ``environment`` (3,)), ``world_view`` (h, w, 3) with ``world_view_camera_*``,
    ``camera_*``, ``analytic_radiance`` and the ``texture_*`` arrays
    (:meth:`~raybundle.scene.textures.SurfaceTexture.to_arrays`) are optional.  A file that
    cannot be read or holds malformed arrays raises :class:`SceneError` (one line).
    """
    import zipfile

    try:
        # our own file object: np.load leaks the one it opens when the zip is broken
        with open(path, "rb") as f, np.load(f, allow_pickle=False) as z:
            d = {k: z[k] for k in z.files}
    except FileNotFoundError:
        raise SceneError(f"{path}: no such file") from None
    except (OSError, ValueError, EOFError, zipfile.BadZipFile, KeyError, TypeError) as e:
        raise SceneError(f"cannot read scene file {path}: {str(e) or type(e).__name__} (empty, truncated "
                         "or not an .npz file)") from None
    try:
        return _scene_from_arrays(path, d)
    except SceneError:
        raise
    except (ValueError, TypeError, IndexError, KeyError, AttributeError) as e:
        raise SceneError(f"{path}: malformed scene file ({type(e).__name__}: {e})") from None


def _scene_from_arrays(path, d):
    """:func:`load_npz`'s scene from the file's arrays ``d``."""
    from .linking import LightLinking
    from .shading import ShadingNormals
    from .textures import SurfaceTexture

    missing = [k for k in ("vertices", "triangles", "triangle_material", "material_names", "material_diffuse",
                           "material_glossy", "material_roughness", "material_glossy_weight", "material_emission")
               if k not in d]
    if missing:
        raise SceneError(f"{path}: not a raybundle scene (missing arrays {missing})")
    version = int(d.get("format_version", NPZ_FORMAT_VERSION))
    if version > NPZ_FORMAT_VERSION:
        raise SceneError(f"{path}: format version {version} is newer than this raybundle supports")
    lights = (PointLights.from_arrays(d), SunLights.from_arrays(d), AreaLights.from_arrays(d))
    return build_scene(d["vertices"], d["triangles"], d["triangle_material"],
                       MaterialTable.from_arrays(d), point_lights=lights[0], sun_lights=lights[1],
                       area_lights=lights[2], world=World.from_arrays(d),
                       camera=Camera.from_arrays(d), triangle_patch=d.get("triangle_patch"),
                       triangle_source=d.get("triangle_source"), triangle_solid=d.get("triangle_solid"),
                       two_sided=d.get("triangle_two_sided", False),
                       analytic_radiance=d.get("analytic_radiance"), name=str(d.get("name", "")),
                       texture=SurfaceTexture.from_arrays(d), shading=ShadingNormals.from_arrays(d),
                       linking=LightLinking.from_arrays(d))
