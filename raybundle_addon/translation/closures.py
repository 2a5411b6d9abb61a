"""The closures a material's node tree delivers, summed with their mix weights, and flattened
into one core material: the Lambert + GGX mix of the :mod:`.shaders` docstring, or a Principled
BSDF's layered model where it stands alone (its inputs mapped by :func:`principled_to_material`),
with colors above 1 clipped (warned)."""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from raybundle.scene.materials import color_text
from raybundle.scene.principled import principled_material


@dataclass
class Closures:
    """A weighted sum of closures, as a material's Mix and Add Shaders build it."""

    diffuse: np.ndarray = field(default_factory=lambda: np.zeros(3))
    glossy: np.ndarray = field(default_factory=lambda: np.zeros(3))
    rough_sum: float = 0.0          # sum of lum(glossy_k) * roughness_k
    glossy_lum: float = 0.0
    multi_ggx: list = field(default_factory=list)     # per glossy lobe: uses Multiscatter GGX
    emission: np.ndarray = field(default_factory=lambda: np.zeros(3))
    principled: list = field(default_factory=list)    # [(weight, spec dict, simple spec dict)]
    #: dielectric interfaces: [(weight, refraction tint (3,), reflection tint (3,), ior, fresnel 0/1)]
    transmission: list = field(default_factory=list)
    translucent: np.ndarray = field(default_factory=lambda: np.zeros(3))


def luminance(c):
    """Rec. 709 luminance of linear RGB ``c``."""
    return float(np.dot(np.asarray(c, float)[:3], (0.2126, 0.7152, 0.0722)))


def flatten(name, acc, warn):
    """The core material spec of the closures ``acc`` of material ``name``: one Lambert + GGX mix
    (or a Principled BSDF's layered model alone), with its translucency and interfaces; what
    cannot be kept exactly is warned about (``warn``)."""
    spec = _flatten_opaque(name, acc, warn)
    if np.any(acc.translucent > 0):
        reflected = np.asarray(spec.get("diffuse", (0, 0, 0)), float) * (1 - spec.get("glossy_weight", 0.0))
        kt = np.minimum(acc.translucent, np.maximum(1.0 - reflected, 0.0))
        if np.any(kt < acc.translucent - 1e-6):
            warn(f"material {name!r}: its diffuse and translucent colors add up to more than 1 "
                      "(it would create energy): the translucent one is clipped")
        spec["translucent"] = tuple(kt)
    if acc.transmission:
        w = np.array([x[0] for x in acc.transmission])
        total = float(w.sum())
        if total > 1.0 + 1e-6:
            warn(f"material {name!r}: its glass and transparent shaders add up to {total:.3g} > 1: "
                      "scaled to 1")
            w, total = w / total, 1.0
        mean = lambda k: sum(wi * np.asarray(x[k], float) for wi, x in zip(w, acc.transmission)) / total
        kinds = {(x[3], x[4]) for x in acc.transmission}
        if len(kinds) > 1:
            warn(f"material {name!r}: interfaces of different IOR or kind are mixed: one of their mean "
                      "IOR is used")
        spec.update(transmission=total, transmission_color=tuple(mean(1)), transmission_reflection=tuple(mean(2)),
                    transmission_ior=float(mean(3)), transmission_fresnel=int(round(float(mean(4)))),
                    transmission_roughness=float(mean(5)))
    return spec

def _flatten_opaque(name, acc, warn):
    emission = np.maximum(acc.emission, 0.0)
    plain = not (np.any(acc.diffuse) or np.any(acc.glossy) or np.any(acc.translucent))
    if len(acc.principled) == 1 and plain and abs(acc.principled[0][0] - 1.0) < 1e-9:
        spec = dict(acc.principled[0][1], name=name)
        spec["emission"] = tuple(np.asarray(spec.get("emission", (0, 0, 0)), float) + emission)
        return clip_colors(spec, name, warn)
    if acc.principled:
        if len(acc.principled) > 1 or not plain or abs(acc.principled[0][0] - 1.0) > 1e-9:
            warn(f"material {name!r}: a Principled BSDF mixed with other shaders is approximated "
                      "by a plain Lambert + GGX mix (no Fresnel layer)")
        for w, spec, simple in acc.principled:
            d = np.asarray(simple["diffuse"], float) * (1 - simple["glossy_weight"])
            gl = np.asarray(simple["glossy"], float) * simple["glossy_weight"]
            acc.diffuse += w * d
            acc.glossy += w * gl
            acc.rough_sum += luminance(w * gl) * simple["roughness"]
            acc.glossy_lum += luminance(w * gl)
            acc.multi_ggx.append(False)
            emission = emission + w * np.asarray(spec.get("emission", (0, 0, 0)), float)
    d, gsum = np.maximum(acc.diffuse, 0.0), np.maximum(acc.glossy, 0.0)
    md, mg = float(d.max()), float(gsum.max())
    rough = acc.rough_sum / acc.glossy_lum if acc.glossy_lum > 0 else 0.5
    spec = dict(name=name, emission=tuple(emission), roughness=float(np.clip(rough, 0.0, 1.0)))
    if mg <= 0:
        spec.update(diffuse=tuple(d), glossy_weight=0.0)
    elif md <= 0:
        spec.update(glossy=tuple(gsum), glossy_weight=1.0)
    else:
        g = mg / (mg + md)
        spec.update(diffuse=tuple(d / (1 - g)), glossy=tuple(gsum / g), glossy_weight=g)
    if mg > 0 and all(acc.multi_ggx):
        spec["multiscatter"] = 1
    elif mg > 0 and any(acc.multi_ggx) and not all(acc.multi_ggx):
        warn(f"material {name!r}: GGX and Multiscatter GGX lobes are mixed; using single-scatter GGX")
    elif mg > 0 and any(acc.multi_ggx):
        warn(f"material {name!r}: Multiscatter GGX is approximated by GGX")
    return clip_colors(spec, name, warn)

def clip_colors(spec, name, warn):
    """Colors above 1 create energy (the core rejects them): clip, with a warning."""
    for k in ("diffuse", "glossy", "specular_tint", "transmission_color", "transmission_reflection"):
        if k in spec:
            c = np.asarray(spec[k], float)
            if np.any(c > 1.0 + 1e-6):
                warn(f"material {name!r}: {k} color {color_text(c)} has albedo > 1, clipped to 1 "
                          "(it would create energy)")
            spec[k] = tuple(np.clip(c, 0.0, 1.0))
    return spec


def principled_to_material(inputs, distribution="MULTI_GGX", warn=print, layered=True):
    """The core material spec of a Principled BSDF, from its input values.

    ``inputs``: socket name -> value (colors (3,) linear, floats), as on the node
    in Blender 4.x/5.x (``Base Color``, ``Metallic``, ``Roughness``, ``IOR``,
    ``Specular IOR Level``, ``Specular Tint``, ``Emission Color``,
    ``Emission Strength``, ``Coat Weight``...).  ``warn`` gets one message per
    ignored feature.

    With ``layered``, the core's Principled model
    (:func:`raybundle.scene.principled.principled_material`: a Fresnel-weighted dielectric
    GGX layer over Lambert, F82 conductor, multiscatter).
    Otherwise the plain Lambert + GGX mix: diffuse = base color, glossy weight
    ``g = metallic + (1 - metallic) F0`` with ``F0 = ((ior-1)/(ior+1))^2 * 2 *
    specular_level``, glossy tint ``(metallic * base + (1 - metallic) F0 tint) / g``.
    """
    get = inputs.get
    base = np.clip(np.asarray(get("Base Color", (0.8, 0.8, 0.8)), float)[:3], 0.0, None)
    if np.any(base > 1.0 + 1e-6):
        warn(f"Principled BSDF base color {color_text(base)} is above 1 (albedo > 1 creates energy): "
             "clipped to 1")
        base = np.minimum(base, 1.0)
    metallic = float(np.clip(get("Metallic", 0.0), 0.0, 1.0))
    roughness = float(np.clip(get("Roughness", 0.5), 0.0, 1.0))
    ior = float(get("IOR", 1.5))
    level = float(get("Specular IOR Level", 0.5))
    tint = np.asarray(get("Specular Tint", (1.0, 1.0, 1.0)), float)[:3]
    emission = np.asarray(get("Emission Color", (0.0, 0.0, 0.0)), float)[:3] * max(
        float(get("Emission Strength", 0.0)), 0.0)
    for key, label in (("Coat Weight", "coat"), ("Sheen Weight", "sheen"),
                       ("Subsurface Weight", "subsurface"),
                       ("Anisotropic", "anisotropy"), ("Thin Film Thickness", "thin film"),
                       ("Diffuse Roughness", "diffuse roughness")):
        if float(get(key, 0.0)) > 1e-6:
            warn(f"Principled BSDF {label} is ignored")
    if layered:
        return principled_material(base, metallic=metallic, roughness=roughness, ior=ior, specular_ior_level=level,
                                   emission=emission, specular_tint=tint, distribution=distribution)
    f0 = ((ior - 1.0) / (ior + 1.0)) ** 2 * 2.0 * max(level, 0.0)
    f0 = float(np.clip(f0, 0.0, 1.0))
    g = metallic + (1.0 - metallic) * f0
    gl = metallic * np.clip(base, 0, 1) + (1.0 - metallic) * f0 * np.clip(tint, 0, 1)
    return dict(diffuse=tuple(base), glossy=tuple(gl / g) if g > 0 else (0.0, 0.0, 0.0),
                glossy_weight=g, roughness=roughness, emission=tuple(emission))
