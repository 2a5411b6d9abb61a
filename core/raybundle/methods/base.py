"""What every method declares: the small base class the registry, the plan and the front-ends
read (:mod:`raybundle.methods.registry`, :mod:`raybundle.app.plan`)."""
from __future__ import annotations

from dataclasses import dataclass


@dataclass
class SolverStats:
    """What a method has done so far (image-only methods count their passes as iterations)."""

    iterations: int = 0
    seconds: float = 0.0
    rays: int = 0           # Embree queries issued by the solver (bundles)
    bundle_rays: int = 0    # grid rays (one per line of the bundles)
    directions: int = 0     # global directions (bundles) used
    warm_up: int = 0        # transfers before the running average started (not iterations)


class Method:
    """A solution method of the rendering equation, known by :attr:`name`.

    Patch methods derive from :class:`~raybundle.methods.patch_solution.PatchSolution`
    (a solution per patch side: images and bakes); image-only methods from
    :class:`~raybundle.imaging.progressive.ProgressiveImage` too (camera images, no patches).
    Every method is made the same way, ``cls(scene, tracer, direct, settings, camera=None)``:
    the prepared scene, its ray tracer, its first-shot lights
    (:class:`~raybundle.lights.direct.DirectLighting`), the
    :class:`~raybundle.imaging.settings.RenderSettings`, and for image-only methods the camera
    (the scene's when None)."""

    #: the name users give (``--method``, the add-on's method list)
    name = ""
    #: renders camera images only: no patch layout, no bake, no chains to merge
    image_only = False
    #: each step applies a random operator to the previous iterate, so the random numbers must
    #: be completely uniformly distributed (thesis 1.2)
    iterates = False
    #: independent chains of it merge exactly (:mod:`raybundle.app.chains`)
    merges_chains = False
