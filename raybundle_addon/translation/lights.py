"""Blender's lights in the core's records, in Blender's units as Cycles converts them
(``blender.md`` §4.4).

Every light's color is ``color x 2**exposure`` (x ``temperature_color`` when
``use_temperature`` is on), times:

============  =====================================================================
point, spot   intensity ``I = P / (4 pi)`` [W/sr]; the spot cone (``spot_size``,
              ``spot_blend``) masks it and does **not** renormalise it
sun           irradiance ``E = strength`` [W/m^2] on a plane facing the sun
area          radiance ``L = P / (pi A)`` [W m^-2 sr^-1], one-sided (local -Z),
              ``A`` the world-space area: ``size x size_y`` (square, rectangle)
              or ``pi/4 size x size_y`` (disk, ellipse), object scale included
============  =====================================================================

With ``normalize`` off (Cycles' "unnormalized" lights) the area factor is
dropped: area ``L = P / pi``, point/spot ``I = P r^2 / 4`` for radius r > 0, sun
``E = strength x pi tan^2(angle / 2)`` for angle > 0.

A light's own node tree scales its color (:mod:`.light_nodes`).  With Cast Shadow off
(``use_shadow``) nothing blocks its direct light, as in Cycles; its light and shadow linking
is :mod:`.light_linking`'s.
"""
from __future__ import annotations

import math

import numpy as np

from .light_nodes import light_node_factor


def light_color(ld):
    """(3,) color x 2**exposure (x temperature color when enabled) of a bpy Light."""
    c = np.array(ld.color[:3], float) * 2.0 ** float(getattr(ld, "exposure", 0.0))
    if getattr(ld, "use_temperature", False) and hasattr(ld, "temperature_color"):
        c = c * np.array(ld.temperature_color[:3], float)
    return c


def convert_light(ld, M, warn, nodes=None):
    """(kind, dict) for a bpy Light ``ld`` with world matrix ``M`` (4, 4):
    kind "point" (position, intensity, spot_*, radius), "sun" (direction,
    irradiance, angle) or "area" (center, axis_u, axis_v, normal, shape, radiance), each with
    ``shadow`` (1, or 0 with Cast Shadow off).  Formulas: module docstring.  ``nodes``: a dict
    that keeps each light data-block's :func:`.light_nodes.light_node_factor` (its instances share
    one reading and one profile)."""
    if nodes is None:
        nodes = {}
    if ld.name_full not in nodes:
        nodes[ld.name_full] = light_node_factor(ld, warn)
    got = _convert_light(ld, M, warn, *nodes[ld.name_full])
    if got is not None:
        got[1]["shadow"] = float(bool(getattr(ld, "use_shadow", True)))
    return got


def _convert_light(ld, M, warn, factor, profile):
    color = light_color(ld) * factor
    power = float(ld.energy)
    normalize = bool(getattr(ld, "normalize", True))
    pos = M[:3, 3].copy()
    z = M[:3, 2]
    zn = np.linalg.norm(z)
    down = -z / zn if zn > 0 else np.array([0.0, 0.0, -1.0])
    if power < 0:
        warn(f"light {ld.name!r} has negative power: ignored")
        return None
    if ld.type in ("POINT", "SPOT"):
        r = float(ld.shadow_soft_size)
        intensity = color * power / (4 * math.pi)
        if not normalize and r > 0:
            intensity = intensity * math.pi * r * r
        axes = M[:3, :3].T / np.maximum(np.linalg.norm(M[:3, :3], axis=0), 1e-30)[:, None]
        d = dict(position=pos, intensity=intensity, radius=r, spot_direction=np.zeros(3),
                 spot_cos_half_angle=-1.0, spot_blend=0.0, profile=profile, axes=axes)
        if getattr(ld, "use_soft_falloff", False) and r > 0:
            warn(f"light {ld.name!r}: soft falloff is not modelled (a sphere light is used)")
        if ld.type == "SPOT":
            d.update(spot_direction=down, spot_cos_half_angle=math.cos(float(ld.spot_size) / 2),
                     spot_blend=float(ld.spot_blend))
            sx, sy = np.linalg.norm(M[:3, 0]), np.linalg.norm(M[:3, 1])
            if abs(sx - sy) > 1e-6 * max(sx, sy):
                warn(f"spot light {ld.name!r}: a non-uniformly scaled (elliptic) cone is treated as round")
        return "point", d
    if ld.type == "SUN":
        angle = float(ld.angle)
        irradiance = color * power
        if not normalize and angle > 0:
            irradiance = irradiance * math.pi * math.tan(angle / 2) ** 2
        return "sun", dict(direction=down, irradiance=irradiance, angle=angle)
    if ld.type == "AREA":
        sx = float(ld.size)
        sy = float(ld.size_y) if ld.shape in ("RECTANGLE", "ELLIPSE") else sx
        u, v = M[:3, 0] * sx / 2, M[:3, 1] * sy / 2
        ellipse = ld.shape in ("DISK", "ELLIPSE")
        area = (math.pi if ellipse else 4.0) * np.linalg.norm(u) * np.linalg.norm(v)
        if area <= 0:
            warn(f"area light {ld.name!r} has zero size: ignored")
            return None
        radiance = color * power / (math.pi * (area if normalize else 1.0))
        if float(getattr(ld, "spread", math.pi)) < math.pi - 1e-6:
            warn(f"area light {ld.name!r}: spread is not modelled (a Lambertian emitter is used)")
        return "area", dict(center=pos, axis_u=u, axis_v=v, normal=down, shape=int(ellipse), radiance=radiance)
    warn(f"light {ld.name!r} of type {ld.type} is not supported: ignored")
    return None
