"""Built-in scenes: the measured Cornell box, its glossy variant, and analytic furnaces.

* ``cornell``: the Cornell box geometry (Cornell data, mm, Y up) turned into
  metres, Z up, by (x, y, z) -> (-x, z, y) / 1000, with the common RGB stand-ins
  for the measured reflectances and the light lowered to y = 548.3 mm.  The
  blocks are closed (bottom faces added) and the ceiling has an opening above
  the light; both change nothing visible and keep hidden area out of patches.
* ``cornell-glossy``: the floor is Mix(Diffuse white, Glossy GGX white,
  roughness 0.3, factor 0.5) and the tall block pure Glossy GGX (0.8, r 0.2).
* ``small-light``: the Cornell box lit by a 20 x 20 mm lamp of the same power (34 times the
  radiance), the ceiling's opening closed: the small bright light of the thesis' first shot.
* ``near-mirror``: the Cornell box with the tall block a near-mirror (Glossy GGX 0.9,
  roughness 0.02): where the bundle transfer's variance grows.
* ``room-<seed>`` / ``glossy-room-<seed>`` (:func:`random_room`): seeded random rooms with
  boxes and ceiling lamps, Lambertian or mostly glossy, for checks on scenes nothing was tuned on.
* ``furnace``: a closed room with a closed block inside (non-convex); every
  surface emits Le and is Lambertian with albedo a, so L = Le / (1 - a) exactly.
* ``furnace-glossy``: the same enclosure with GGX and mixed materials emitting
  ``c (1 - a(w))`` (a(w) the directional albedo), so L = c exactly
  (``algorithms.md`` §5).
"""
from __future__ import annotations

import re

import numpy as np

from ..tracing.sampling import Stream, stream
from .build import build_scene
from .camera import Camera
from .materials import MaterialTable, color_text

WHITE = (0.725, 0.71, 0.68)
RED = (0.63, 0.065, 0.05)
GREEN = (0.14, 0.45, 0.091)
CORNELL_LIGHT = (18.387, 13.9873, 6.75357)

# Cornell box quads in mm (Cornell data, Y up)
_CORNELL_QUADS = {
    "floor": ([552.8, 0, 0], [0, 0, 0], [0, 0, 559.2], [549.6, 0, 559.2]),
    # the ceiling has an opening above the light (a recessed lamp): nothing lies
    # hidden 0.5 mm above the light quad
    "ceiling-front": ([556.0, 548.8, 0], [556.0, 548.8, 227.0], [0, 548.8, 227.0], [0, 548.8, 0]),
    "ceiling-back": ([556.0, 548.8, 332.0], [556.0, 548.8, 559.2], [0, 548.8, 559.2], [0, 548.8, 332.0]),
    "ceiling-left": ([556.0, 548.8, 227.0], [556.0, 548.8, 332.0], [343.0, 548.8, 332.0], [343.0, 548.8, 227.0]),
    "ceiling-right": ([213.0, 548.8, 227.0], [213.0, 548.8, 332.0], [0, 548.8, 332.0], [0, 548.8, 227.0]),
    "back": ([549.6, 0, 559.2], [0, 0, 559.2], [0, 548.8, 559.2], [556.0, 548.8, 559.2]),
    "green": ([0, 0, 559.2], [0, 0, 0], [0, 548.8, 0], [0, 548.8, 559.2]),
    "red": ([552.8, 0, 0], [549.6, 0, 559.2], [556.0, 548.8, 559.2], [556.0, 548.8, 0]),
    "light": ([343.0, 548.3, 227.0], [343.0, 548.3, 332.0], [213.0, 548.3, 332.0], [213.0, 548.3, 227.0]),
}
_SHORT_TOP = [(130, 65), (82, 225), (240, 272), (290, 114)]
_TALL_TOP = [(423, 247), (265, 296), (314, 456), (472, 406)]


def _block_quads(top_xz, height):
    """Top, four sides and bottom: a closed solid standing on the floor."""
    quads = [[(x, height, z) for x, z in top_xz], [(x, 0.0, z) for x, z in top_xz]]
    for k in range(4):
        (x0, z0), (x1, z1) = top_xz[k], top_xz[(k + 1) % 4]
        quads.append([(x0, 0, z0), (x1, 0, z1), (x1, height, z1), (x0, height, z0)])
    return [np.array(q, float) for q in quads]


def _oriented(quad, towards=None, away=None):
    """Order a planar quad so that its normal points towards/away from a point."""
    q = np.asarray(quad, float)
    n = np.cross(q[1] - q[0], q[2] - q[0])
    c = q.mean(axis=0)
    ref = (np.asarray(towards) - c) if towards is not None else (c - np.asarray(away))
    return q if n @ ref > 0 else q[::-1]


def _mesh(quads_with_material):
    verts, tris, mats = [], [], []
    for q, m in quads_with_material:
        base = len(verts) * 4
        verts.append(q)
        tris += [[base, base + 1, base + 2], [base, base + 2, base + 3]]
        mats += [m, m]
    return np.concatenate(verts), np.array(tris), np.array(mats)


def cornell_to_blender(p_mm):
    """Cornell coordinates (mm, Y up) -> metres, Z up: (x, y, z) -> (-x, z, y) / 1000."""
    p = np.asarray(p_mm, float)
    return np.stack([-p[..., 0], p[..., 2], p[..., 1]], axis=-1) / 1000.0


def cornell_camera(resolution=(256, 256)):
    """The Cornell camera: at (278, 273, -800) mm looking +z, 35 mm lens, 25 mm sensor."""
    pos = cornell_to_blender([278.0, 273.0, -800.0])
    return Camera.look_at(pos, pos + np.array([0.0, 1.0, 0.0]), (0.0, 0.0, 1.0),
                          lens=35.0, sensor_width=25.0, resolution=resolution)


def cornell(glossy=False, resolution=(256, 256), light_mm=None, mirror_roughness=None, name=None):
    """The Cornell box (module docstring).  ``light_mm``: a square lamp of that side (mm) at the
    lamp's centre instead of the 130 x 105 mm one, with the same power (its radiance scaled by
    the area ratio) and the ceiling's opening closed; ``mirror_roughness``: the tall block a
    near-mirror, Glossy GGX (0.9, that roughness)."""
    specs = [dict(name="white", diffuse=WHITE), dict(name="red", diffuse=RED),
             dict(name="green", diffuse=GREEN), dict(name="light", emission=CORNELL_LIGHT)]
    if glossy:
        specs += [dict(name="floor_mix", diffuse=(1, 1, 1), glossy=(1, 1, 1), roughness=0.3, glossy_weight=0.5),
                  dict(name="tall_glossy", glossy=(0.8, 0.8, 0.8), roughness=0.2, glossy_weight=1.0)]
    tall = 5 if glossy else 0
    if mirror_roughness is not None:
        specs.append(dict(name="tall_mirror", glossy=(0.9, 0.9, 0.9), roughness=float(mirror_roughness),
                          glossy_weight=1.0))
        tall = len(specs) - 1
    centre = np.array([278.0, 274.4, 279.6])
    mat_of = {"floor": 4 if glossy else 0, "back": 0, "green": 2, "red": 1, "light": 3}
    cornell_quads = dict(_CORNELL_QUADS)
    if light_mm is not None:
        lamp = np.array(cornell_quads["light"], float)
        lamp_area = np.ptp(lamp[:, 0]) * np.ptp(lamp[:, 2])
        specs[3]["emission"] = tuple(np.asarray(CORNELL_LIGHT) * lamp_area / float(light_mm) ** 2)
        c, h = lamp.mean(axis=0), float(light_mm) / 2
        cornell_quads["light"] = [c + (h, 0, -h), c + (h, 0, h), c + (-h, 0, h), c + (-h, 0, -h)]
        cornell_quads["ceiling-opening"] = [np.array(p) + (0, 0.5, 0) for p in _CORNELL_QUADS["light"]]
    quads = []
    for key, q in cornell_quads.items():
        q = np.array(q, float)
        quads.append((_oriented(q, away=q.mean(axis=0) + [0, 1, 0]) if key == "light"
                       else _oriented(q, towards=centre), mat_of.get(key, 0)))
    for top, h, m in ((_SHORT_TOP, 165.0, 0), (_TALL_TOP, 330.0, tall)):
        blk = _block_quads(top, h)
        c = np.mean([b.mean(axis=0) for b in blk], axis=0) - [0, h / 2, 0]
        quads += [(_oriented(b, away=c), m) for b in blk]
    v, t, m = _mesh(quads)
    return build_scene(cornell_to_blender(v), t, m, MaterialTable.from_list(specs),
                       camera=cornell_camera(resolution), name=name or ("cornell-glossy" if glossy else "cornell"))


def _box_quads(lo, hi):
    """The six faces of an axis-aligned box (unoriented)."""
    x0, y0, z0 = lo
    x1, y1, z1 = hi
    return [np.array(q, float) for q in (
        [(x0, y0, z0), (x1, y0, z0), (x1, y1, z0), (x0, y1, z0)],
        [(x0, y0, z1), (x1, y0, z1), (x1, y1, z1), (x0, y1, z1)],
        [(x0, y0, z0), (x1, y0, z0), (x1, y0, z1), (x0, y0, z1)],
        [(x0, y1, z0), (x1, y1, z0), (x1, y1, z1), (x0, y1, z1)],
        [(x0, y0, z0), (x0, y1, z0), (x0, y1, z1), (x0, y0, z1)],
        [(x1, y0, z0), (x1, y1, z0), (x1, y1, z1), (x1, y0, z1)])]


FURNACE_LE = np.array([0.5, 0.5, 0.5])
FURNACE_ALBEDO = np.array([0.3, 0.5, 0.7])
FURNACE_GLOSSY_C = np.array([1.0, 0.8, 0.6])


def furnace(glossy=False, resolution=(128, 128), albedo=FURNACE_ALBEDO):
    """Closed room (2 x 2 x 1.5 m) with a closed block inside; exact radiance known.

    Diffuse: Le = 0.5, albedo (0.3, 0.5, 0.7) -> L = Le / (1 - a) = (0.714, 1, 1.667)
    (``albedo``: another RGB albedo, each component in [0, 1)).
    Glossy: walls Glossy GGX (0.7, roughness 0.7), block Mix(Diffuse 0.7,
    Glossy 0.7 r 0.5, factor 0.3), all emitting c (1 - a(w)) -> L = c = (1, 0.8, 0.6).
    (Sharper or brighter lobes make the iterates heavy-tailed: see ``solvers``.)
    """
    lo, hi = np.array([0.0, 0.0, 0.0]), np.array([2.0, 2.0, 1.5])
    blo, bhi = np.array([0.9, 1.0, 0.3]), np.array([1.5, 1.5, 0.9])
    centre = (lo + hi) / 2
    bc = (blo + bhi) / 2
    if glossy:
        specs = [dict(name="walls", glossy=(0.7, 0.7, 0.7), roughness=0.7, glossy_weight=1.0,
                      emission_albedo_complement=FURNACE_GLOSSY_C),
                 dict(name="block", diffuse=(0.7, 0.7, 0.7), glossy=(0.7, 0.7, 0.7), roughness=0.5,
                      glossy_weight=0.3, emission_albedo_complement=FURNACE_GLOSSY_C)]
        exact = FURNACE_GLOSSY_C
    else:
        albedo = np.broadcast_to(np.asarray(albedo, float), (3,))
        if not np.all((albedo >= 0) & (albedo < 1)):
            raise ValueError(f"the furnace's albedo must lie in [0, 1), not {color_text(albedo)} (no finite solution)")
        specs = [dict(name="walls", diffuse=tuple(albedo), emission=FURNACE_LE),
                 dict(name="block", diffuse=tuple(albedo), emission=FURNACE_LE)]
        exact = FURNACE_LE / (1 - albedo)
    # the block floats: a patch partly hidden under a block resting on the floor
    # would average its incoming radiance over a hidden part (an FE error)
    quads = [(_oriented(q, towards=centre), 0) for q in _box_quads(lo, hi)]
    quads += [(_oriented(q, away=bc), 1) for q in _box_quads(blo, bhi)]
    v, t, m = _mesh(quads)
    cam = Camera.look_at((0.25, 0.2, 1.2), (1.2, 1.25, 0.4), (0, 0, 1), lens=20.0, sensor_width=36.0,
                         resolution=resolution)
    return build_scene(v, t, m, MaterialTable.from_list(specs), camera=cam, analytic_radiance=exact,
                       name="furnace-glossy" if glossy else "furnace")


def random_room(seed, glossy=False, resolution=(96, 96)):
    """A room no test has seen: a seeded random size (3-6 x 3-6 x 2.4-3.2 m), 2-5 closed boxes
    standing at random places, one 20-40 cm ceiling lamp of random power, random colours.
    ``glossy``: the boxes and the floor Glossy GGX (roughness 0.2-0.5), the walls a Mix with
    a glossy weight of 0.5-0.9, plus a second, smaller lamp; otherwise everything is
    Lambertian.  The camera stands in a corner, looking at the far one."""
    rng = stream(seed, Stream.RANDOM_ROOM)
    size = np.array([rng.uniform(3, 6), rng.uniform(3, 6), rng.uniform(2.4, 3.2)])
    colour = (lambda lo=0.2, hi=0.8: tuple(rng.uniform(lo, hi, 3)))
    if glossy:
        specs = [dict(name="walls", diffuse=colour(), glossy=colour(0.6, 0.9), roughness=rng.uniform(0.2, 0.5),
                      glossy_weight=rng.uniform(0.5, 0.9)),
                 dict(name="floor", glossy=colour(0.6, 0.9), roughness=rng.uniform(0.2, 0.5), glossy_weight=1.0),
                 dict(name="boxes", glossy=colour(0.6, 0.9), roughness=rng.uniform(0.2, 0.5), glossy_weight=1.0)]
    else:
        specs = [dict(name="walls", diffuse=colour()), dict(name="floor", diffuse=colour()),
                 dict(name="boxes", diffuse=colour())]
    lamps = 2 if glossy else 1
    for k in range(lamps):
        specs.append(dict(name=f"lamp{k}", emission=tuple(rng.uniform(20, 60) * np.array([1.0, 0.9, 0.75]))))
    centre = size / 2
    quads = []
    for q in _box_quads(np.zeros(3), size):
        floor = np.allclose(q[:, 2], 0)
        quads.append((_oriented(q, towards=centre), 1 if floor else 0))
    for _ in range(int(rng.integers(2, 6))):
        half = rng.uniform(0.2, 0.6, 2)
        c = rng.uniform(half + 0.3, size[:2] - half - 0.3)
        lo, hi = np.append(c - half, 0.0), np.append(c + half, rng.uniform(0.4, 1.6))
        quads += [(_oriented(q, away=(lo + hi) / 2), 2) for q in _box_quads(lo, hi)]
    for k in range(lamps):
        side = rng.uniform(0.2, 0.4) / (k + 1)
        c = np.append(rng.uniform(size[:2] * 0.3, size[:2] * 0.7), size[2] - 0.01)
        lamp = np.array([c + (-side / 2, -side / 2, 0), c + (side / 2, -side / 2, 0),
                         c + (side / 2, side / 2, 0), c + (-side / 2, side / 2, 0)])
        quads.append((_oriented(lamp, away=c + (0, 0, 1)), 3 + k))
    v, t, m = _mesh(quads)
    eye = np.array([0.25, 0.25, 0.75 * size[2]])
    cam = Camera.look_at(eye, (size[0], size[1], 0.6), (0, 0, 1), lens=18.0, sensor_width=36.0,
                         resolution=resolution)
    return build_scene(v, t, m, MaterialTable.from_list(specs), camera=cam,
                       name=f"{'glossy-' if glossy else ''}room-{int(seed)}")


BUILTIN = {
    "cornell": lambda: cornell(False),
    "cornell-glossy": lambda: cornell(True),
    "furnace": lambda: furnace(False),
    "furnace-glossy": lambda: furnace(True),
    "small-light": lambda: cornell(light_mm=20.0, name="small-light"),
    "near-mirror": lambda: cornell(mirror_roughness=0.02, name="near-mirror"),
}


def load_scene(name_or_path):
    """A built-in scene by name, a random room (``room-<seed>``, ``glossy-room-<seed>``:
    :func:`random_room`), or a ``.npz`` scene file."""
    if name_or_path in BUILTIN:
        return BUILTIN[name_or_path]()
    room = re.fullmatch(r"(glossy-)?room-(\d+)", str(name_or_path))
    if room:
        return random_room(int(room.group(2)), glossy=bool(room.group(1)))
    if str(name_or_path).endswith(".npz"):
        from .npz import load_npz

        return load_npz(name_or_path)
    raise ValueError(f"unknown scene {name_or_path!r}: use one of {sorted(BUILTIN)}, room-<seed>, "
                     "glossy-room-<seed> or a .npz file")
