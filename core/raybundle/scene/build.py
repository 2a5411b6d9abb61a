"""A patch scene from arrays (:func:`build_scene`): validation of the triangles, materials,
patches and lights, coincident triangles merged, closed solids found."""
from __future__ import annotations

import warnings

import numpy as np

from ..util.arrays import unique_rows
from .model import AreaLights, PatchScene, PointLights, SceneError, SunLights
from .world import World, split_sun


def build_scene(vertices, triangles, triangle_material, materials, point_lights=None, camera=None,
                triangle_patch=None, triangle_source=None, analytic_radiance=None, name="",
                area_epsilon=1e-14, triangle_solid=None, two_sided=False,
                sun_lights=None, area_lights=None, environment=None, texture=None, world=None,
                shading=None, linking=None) -> PatchScene:
    """Validate raw triangles and make a :class:`PatchScene`.

    ``texture``: a :class:`~raybundle.scene.textures.SurfaceTexture` whose faces are the
    input triangles (indexed like ``triangle_source``); ``shading``: their
    :class:`~raybundle.scene.shading.ShadingNormals`, and ``linking`` their
    :class:`~raybundle.scene.linking.LightLinking`, the same way.

    ``two_sided``: bool or (T,) bool, Blender's semantics when true (module
    docstring); the default, one-sided, is the core's own convention.

    The world: ``world`` (a :class:`~raybundle.scene.world.World`) or ``environment``, a
    constant radiance (3,) [W m^-2 sr^-1].  A sun inside the world's image is taken out as
    a sun lamp (:func:`~raybundle.scene.world.split_sun`) once, when the world has no
    separate camera image yet.
    Errors (:class:`SceneError`): non-finite vertices, bad indices, an empty
    scene, no light at all (no emitter, light or environment), invalid
    materials (albedo > 1, NaN...) or lights.  Zero-area triangles (area <=
    ``area_epsilon`` m^2) are dropped and counted in ``dropped_triangles`` (a
    warning is issued).  Without ``triangle_patch`` each triangle is its own patch.
    """
    v, t, m = _checked_triangles(vertices, triangles, triangle_material, materials)
    src = np.arange(len(t)) if triangle_source is None else np.asarray(triangle_source).reshape(-1).astype(np.int64)
    patch = None if triangle_patch is None else np.asarray(triangle_patch).reshape(-1).astype(np.int64)
    two = np.broadcast_to(np.asarray(two_sided, bool), (len(t),)) if np.ndim(two_sided) == 0 \
        else np.asarray(two_sided, bool).reshape(-1)
    for label, arr in (("triangle_source", src), ("triangle_patch", patch), ("triangle_solid", triangle_solid),
                       ("two_sided", two)):
        if arr is not None and len(np.asarray(arr).reshape(-1)) != len(t):
            raise SceneError(f"{label} has {len(np.asarray(arr).reshape(-1))} entries for {len(t)} triangles")

    c = v[t]
    area = 0.5 * np.linalg.norm(np.cross(c[:, 1] - c[:, 0], c[:, 2] - c[:, 0]), axis=1)
    keep = area > area_epsilon
    dropped = int((~keep).sum())
    if dropped:
        warnings.warn(f"dropped {dropped} zero-area triangles", stacklevel=2)
    if not keep.any():
        raise SceneError("the scene is empty: every triangle has zero area")
    t, m, src, two = t[keep], m[keep], src[keep], np.array(two[keep])
    single, merge = coincident_triangles(v, t, m, two, merge=patch is None)
    if not single.all() or merge.any():
        warnings.warn(f"dropped {int((~single).sum())} triangles that repeat another's corners (they would "
                      f"z-fight); {int(merge.sum())} one-sided triangles with a reversed copy became two-sided",
                      stacklevel=2)
        two[merge] = True
        dropped += int((~single).sum())
        keep[np.nonzero(keep)[0][~single]] = False
        t, m, src, two = t[single], m[single], src[single], two[single]
    if patch is None:
        patch = np.arange(len(t))
    else:
        patch = np.unique(patch[keep], return_inverse=True)[1].reshape(-1)  # renumber densely
        _check_patches(v, t, m, patch, two)
    point_lights = PointLights() if point_lights is None else PointLights(**vars(point_lights))
    sun_lights = SunLights() if sun_lights is None else SunLights(**vars(sun_lights))
    area_lights = AreaLights() if area_lights is None else AreaLights(**vars(area_lights))
    _check_lights(point_lights, sun_lights, area_lights)
    _check_linking(linking, src, point_lights, sun_lights, area_lights)
    try:
        if world is None:
            world = World.constant(np.zeros(3) if environment is None else environment)
        elif not isinstance(world, World):
            world = World(world)
    except ValueError as e:
        raise SceneError(str(e)) from None
    world, sun_lights = _world_and_suns(world, sun_lights)
    _check_some_light(materials.is_emitter[np.unique(m)].any(), point_lights, sun_lights, area_lights, world)
    ar = None if analytic_radiance is None else np.asarray(analytic_radiance, float).reshape(3)
    solid = None if triangle_solid is None else np.asarray(triangle_solid, bool).reshape(-1)[keep] & ~two
    return PatchScene(v, t, m, patch, src, materials, point_lights, camera, ar, name, dropped, solid,
                      two, sun_lights, area_lights, world, texture=texture, shading=shading, linking=linking)


def _checked_triangles(vertices, triangles, triangle_material, materials):
    """``(vertices (V, 3), triangles (T, 3), materials (T,))`` as arrays, or a :class:`SceneError`
    naming what is wrong with them: no triangles, bad indices or material ids, non-finite
    vertices, invalid materials."""
    v = np.asarray(vertices, float).reshape(-1, 3)
    t = np.asarray(triangles).reshape(-1, 3).astype(np.int64)
    m = np.asarray(triangle_material).reshape(-1).astype(np.int64)
    if len(t) == 0:
        raise SceneError("the scene is empty: it has no triangles")
    if len(m) != len(t):
        raise SceneError(f"{len(m)} material ids for {len(t)} triangles")
    if t.min() < 0 or t.max() >= len(v):
        raise SceneError(f"triangle vertex indices must lie in [0, {len(v)})")
    bad_v = ~np.isfinite(v).all(axis=1)
    bad_t = bad_v[t].any(axis=1)
    if bad_t.any():
        raise SceneError(f"{int(bad_v.sum())} vertices are NaN or infinite (used by {int(bad_t.sum())} "
                         "triangles); fix or delete them before rendering")
    if m.min() < 0 or m.max() >= len(materials):
        raise SceneError(f"triangle material ids must lie in [0, {len(materials)})")
    try:
        materials.validate()
    except ValueError as e:
        raise SceneError(str(e)) from e
    return v, t, m


def _world_and_suns(world, sun_lights):
    """``(world, sun_lights)`` with a sun inside the world's image taken out as one more sun
    lamp (:func:`~raybundle.scene.world.split_sun`), once: when the world has no separate
    camera image yet."""
    if world.camera_image is None and not world.stand_in:
        world, sun = split_sun(world)
        if sun is not None:
            sun_lights = SunLights(np.vstack([sun_lights.direction, sun["direction"]]),
                                   np.vstack([sun_lights.irradiance, sun["irradiance"]]),
                                   np.append(sun_lights.angle, sun["angle"]), np.append(sun_lights.shadow, 1.0),
                                   np.append(sun_lights.link, 0))
    return world, sun_lights


def _check_linking(linking, source, *lights):
    """A :class:`SceneError` for link sets the linking does not have, or input faces it does not cover."""
    sets = np.concatenate([np.asarray(lg.link, np.int64) for lg in lights])
    n_sets = 1 if linking is None else linking.n_sets
    if len(sets) and (sets.min() < 0 or sets.max() >= n_sets):
        raise SceneError(f"light link sets must lie in [0, {n_sets}): the scene's light linking has {n_sets}")
    if linking is not None and len(source) and source.max() >= len(linking.face_group):
        raise SceneError(f"light linking: a link group for {len(linking.face_group)} input faces, "
                         f"where the triangles come from {int(source.max()) + 1}")


def _check_some_light(has_emitter, point_lights, sun_lights, area_lights, world):
    if not has_emitter and not world.emits and not any(
            (np.asarray(x) > 0).any() for x in (point_lights.intensity, sun_lights.irradiance, area_lights.radiance)):
        raise SceneError("the scene has no lights: no emitting material, no light and a black world "
                         "(add an Emission shader, a light or a world color)")


def attach_world(scene: PatchScene, world: World) -> PatchScene:
    """Give ``scene`` (built with a stand-in world, :attr:`~raybundle.scene.world.World.stand_in`,
    laid out or not) its ``world``, as :func:`build_scene` would have: a sun inside it
    becomes a sun lamp.  Changes ``scene`` in place and returns it; raises
    :class:`SceneError` when nothing lights the scene after all."""
    world, suns = _world_and_suns(world, scene.sun_lights)
    _check_some_light(scene.materials.is_emitter[np.unique(scene.triangle_material)].any(), scene.point_lights,
                      suns, scene.area_lights, world)
    scene.world, scene.sun_lights = world, suns
    return scene


def coincident_triangles(v, t, m, two_sided, merge=True):
    """Triangles with the same three corner positions as another (duplicated faces).

    Along a bundle line, hits closer than the tracer's ``eps`` are one surface: only one of
    two coincident triangles takes part in each line's transfer, so a duplicated face
    receives on about half of its lines (a furnace's duplicated block came out dark: docs/benchmarks.md,
    'Where the method is weak'),
    and for a one-sided face with a reversed copy behind it (a sheet seen from both sides),
    eye rays and bundle lines meet the black back half of the time (half the sheet black,
    in the path tracer too).  Returns ``(keep (T,) bool, make_two_sided (T,) bool)``: of
    each group of coincident triangles the first is kept, and later copies are dropped
    where they add nothing: a same-facing copy of a one-sided triangle, any copy of a
    two-sided one; a reversed one-sided copy of the same material makes the first
    two-sided (``merge``; a reversed copy of another material stays, as it would in
    Blender, and z-fights).  Positions are compared to 1e-9 of the scene's extent."""
    keep = np.ones(len(t), bool)
    make_two = np.zeros(len(t), bool)
    c = v[t]
    scale = max(float(np.ptp(v, axis=0).max()), 1e-300) * 1e-9
    q = np.round(c / scale).astype(np.int64)                               # (T, 3, 3) integer corners
    # candidates: an order-free hash of the corners (int64 arithmetic wraps) met more than once
    with np.errstate(over="ignore"):
        h = q.sum(axis=1) @ np.array([0x9E3779B97F4A7C15 - (1 << 64), 0xC2B2AE3D27D4EB4F - (1 << 64),
                                      0x165667B19E3779F9], np.int64)
    hs = np.sort(h)
    repeated = hs[1:][hs[1:] == hs[:-1]]
    cand = np.nonzero(np.isin(h, repeated))[0]
    if not len(cand):
        return keep, make_two
    # exact check: the candidates' corners sorted, as one row each
    flat = q[cand].reshape(-1, 3)
    tri = np.repeat(np.arange(len(cand)), 3)
    key = flat[np.lexsort((flat[:, 2], flat[:, 1], flat[:, 0], tri))].reshape(len(cand), 9)
    _, group = unique_rows(key)
    n = np.cross(c[cand, 1] - c[cand, 0], c[cand, 2] - c[cand, 0])
    axis = np.argmax(np.abs(n) > 1e-9 * np.abs(n).max(axis=1, keepdims=True), axis=1)
    facing = n[np.arange(len(cand)), axis] > 0                           # orientation against a canonical normal
    # each group's first triangle is its head; the others are dropped where they add nothing
    order = np.argsort(group, kind="stable")
    g = group[order]
    start = np.ones(len(g), bool)
    start[1:] = g[1:] != g[:-1]
    head_pos = np.maximum.accumulate(np.where(start, np.arange(len(g)), 0))
    k, head = cand[order], cand[order][head_pos]
    f_k, f_head = facing[order], facing[order][head_pos]
    later = ~start
    merged = later & ~two_sided[head] & (m[k] == m[head]) & merge & (two_sided[k] | (f_k != f_head))
    drop = later & (two_sided[head] | merged | ((f_k == f_head) & ~two_sided[k]))
    keep[k[drop]] = False
    make_two[head[merged]] = True
    make_two &= ~two_sided
    return keep, make_two


def _check_lights(point, sun, area):
    """Lights must be finite, non-negative, and have usable directions and sizes."""
    for label, group in (("point/spot", point), ("sun", sun), ("area", area)):
        for k, a in vars(group).items():
            if k == "profiles":
                continue
            a = np.asarray(a, float)
            if not np.isfinite(a).all():
                raise SceneError(f"{label} light {k} has non-finite values")
    if len(point) and (point.profile.max() >= len(point.profiles) or point.profile.min() < -1):
        raise SceneError(f"point lights: profile indices must lie in [-1, {len(point.profiles)})")
    if (point.intensity < 0).any() or (point.radius < 0).any() or (sun.irradiance < 0).any() \
            or (sun.angle < 0).any() or (area.radiance < 0).any():
        raise SceneError("light intensities, irradiances, radiances and sizes must be non-negative")
    for label, dirs, live in (("sun", sun.direction, np.ones(len(sun), bool)),
                              ("area light", area.normal, np.ones(len(area), bool)),
                              ("spot", point.spot_direction, np.any(point.spot_direction != 0, axis=1))):
        norm = np.linalg.norm(dirs, axis=1)
        if np.any(live & (np.abs(norm - 1) > 1e-3)):
            raise SceneError(f"{label} directions must be unit vectors")
    if len(area) and np.any(area.area <= 0):
        raise SceneError("an area light has zero size")


def _check_patches(v, t, m, patch, two_sided):
    """A patch must have one material and one sidedness (one variable per side), and
    its triangles must face within 60 degrees of its mean normal (a cluster,
    :mod:`raybundle.patches.clusters`; a patch whose sides face opposite ways has no side)."""
    n_p = int(patch.max()) + 1
    first = np.full(n_p, -1)
    first[patch[::-1]] = np.arange(len(patch))[::-1]
    if np.any(m != m[first[patch]]):
        raise SceneError("a patch mixes materials: give each patch triangles of one material")
    if np.any(two_sided != two_sided[first[patch]]):
        raise SceneError("a patch mixes one-sided and two-sided triangles")
    c = v[t]
    cross = np.cross(c[:, 1] - c[:, 0], c[:, 2] - c[:, 0])
    mean = np.stack([np.bincount(patch, cross[:, k], minlength=n_p) for k in range(3)], axis=1)
    mean /= np.maximum(np.linalg.norm(mean, axis=1, keepdims=True), 1e-300)
    n = cross / np.linalg.norm(cross, axis=1, keepdims=True)
    if np.any(np.einsum("ij,ij->i", n, mean[patch]) < 0.5):
        raise SceneError("a patch mixes triangles that face more than 60 degrees from its mean normal: "
                         "split it (patches may be curved, not folded)")
