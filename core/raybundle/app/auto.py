"""The ``auto`` method: pick the method (and its random numbers) from what the scene holds.

:func:`inspect` measures the scene (no name is read): the share of the reflected light that
glossy lobes carry, the glossy area that is nearly a mirror, the small emitters and lights
the first shot takes, and the area that emits.  :func:`choose` turns those figures into a
:class:`Choice` with a one-line reason, from what the methods bench measured
(``python -m raybundle bench``; the figures are in the docs/benchmarks.md, 'Measured choices behind the defaults'):

* no glossy lobe anywhere: the bundle iteration's view-independent path
  (``stochastic-iteration``), which measured ahead of radiosity and path tracing on ``cornell``
  and ``furnace``;
* glossy lobes carry more than :data:`GLOSSY_SHARE_LIMIT` of the reflected light *and* most of
  the area glows (:data:`EMITTING_SHARE_LIMIT`; no small light for the first shot to take):
  ``path-tracing`` as the randomised quasi-Monte Carlo walk, whose every path then gathers
  emission at every bounce while the bundles' glossy transfer stays their noisiest part: it
  measured ahead of the bundles there (``furnace-glossy``);
* any other glossy scene: the bundle iteration with its glossy lobes, whose first shot takes
  the small lights that make path tracing noisy: it measured ahead of path tracing on
  ``cornell-glossy``, ``near-mirror`` and the unseen ``glossy-room-11`` (85% of its reflection
  glossy: a rule on the glossy share alone had picked path tracing there).

``auto`` leaves the rest as it is: the first shot is on for every method (it takes the small
emitters and lights and changes nothing without them), and the patch count stays the user's or
the default (:data:`~raybundle.patches.clusters.DEFAULT_PATCHES`), which measured best at a fixed
time across scene sizes (finer layouts cost more per step than their smaller discretisation
error gains).
"""
from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

from ..lights.sources import small_emitters
from ..scene.materials import NEAR_MIRROR_ROUGHNESS

#: path tracing wins above this share of the reflected light carried by glossy lobes ...
GLOSSY_SHARE_LIMIT = 0.5
#: ... when this share of the area emits (large emitters, nothing for the first shot)
EMITTING_SHARE_LIMIT = 0.5


@dataclass
class SceneFigures:
    """What :func:`choose` decides from, all measured on the scene (areas in m^2)."""
    area: float                 # total triangle area
    reflecting_share: float     # of the area: materials that reflect
    glossy_share: float         # of the reflected light (area x albedo at cos 0.7): glossy lobes'
    near_mirror_share: float    # of the glossy lobes' part: roughness below NEAR_MIRROR_ROUGHNESS
    emitting_share: float       # of the area: emitting triangles
    small_emitters: int         # mesh emitters the first shot takes
    lights: int                 # point, spot, sun and area lights
    environment: bool           # the world emits


@dataclass
class Choice:
    method: str
    reason: str
    figures: SceneFigures
    #: the random numbers the method draws (None: the run's own ``sequence``)
    sequence: str | None = None

    def as_dict(self):
        return {"method": self.method, "sequence": self.sequence, "reason": self.reason,
                "figures": asdict(self.figures)}


def inspect(scene) -> SceneFigures:
    """The figures of a scene (raw triangles or patches): area-weighted shares of the
    reflected light ``sum_t A_t a_t`` with the albedo ``a`` at cos 0.7, mean over RGB."""
    mats = scene.materials
    area = np.asarray(scene.triangle_area, float)
    tm = np.asarray(scene.triangle_material)
    total = float(area.sum())
    per_mat = np.bincount(tm, weights=area, minlength=len(mats))          # area of each material
    ids = np.arange(len(mats))
    cos = np.full(len(mats), 0.7)
    albedo_all = mats.albedo(ids, cos).mean(axis=1)
    albedo_glossy = mats.albedo(ids, cos, diffuse=False).mean(axis=1)
    reflected = float((per_mat * albedo_all).sum())
    glossy = per_mat * albedo_glossy
    mirror = glossy * (np.asarray(mats.roughness, float) < NEAR_MIRROR_ROUGHNESS)
    share = (lambda part, whole: float(part / whole) if whole > 0 else 0.0)
    return SceneFigures(
        area=total,
        reflecting_share=share(per_mat[mats.reflects].sum(), total),
        glossy_share=share(glossy.sum(), reflected),
        near_mirror_share=share(mirror.sum(), glossy.sum()),
        emitting_share=share(per_mat[mats.is_emitter].sum(), total),
        small_emitters=len(small_emitters(scene)),
        lights=len(scene.point_lights) + len(scene.sun_lights) + len(scene.area_lights),
        environment=scene.world.emits)


def choose(scene) -> Choice:
    """The method for ``scene`` and why (module docstring)."""
    f = inspect(scene)
    first = f.small_emitters + f.lights
    light = (f"{first} small light(s) taken by the first shot" if first else
             "no small lights (the emitters are large: the first shot has nothing to take)")
    share = f"glossy lobes carry {100 * f.glossy_share:.0f}% of the reflected light"
    if f.glossy_share == 0:
        method, why = "stochastic-iteration", "every surface is Lambertian: the view-independent bundle iteration"
    elif f.glossy_share > GLOSSY_SHARE_LIMIT and f.emitting_share > EMITTING_SHARE_LIMIT:
        method, why = "path-tracing", (f"{share} and {100 * f.emitting_share:.0f}% of the area emits: every "
                                       "path gathers emission at every bounce, lobe-sampled paths beat the "
                                       "bundles' glossy transfer")
    else:
        method, why = "stochastic-iteration", (f"{share}, {100 * f.emitting_share:.1f}% of the area emits: the "
                                               "bundle iteration with glossy lobes and the first shot")
    if f.near_mirror_share > 0:
        why += (f"; {100 * f.near_mirror_share:.0f}% of the glossy reflection is near-mirror "
                f"(roughness < {NEAR_MIRROR_ROUGHNESS}), seen through the camera's glossy bounces")
    # path tracing as the randomised quasi-Monte Carlo walk, which measured ahead of the PRNG's
    # on every bench scene (docs/benchmarks.md, 'Measured choices behind the defaults')
    sequence = "halton" if method == "path-tracing" else None
    return Choice(method, f"{why}; {light}", f, sequence)
