"""The settings of a render (:class:`RenderSettings`): plain values shared by the CLI, the
add-on, the bench and the chains, validated before any work."""
from __future__ import annotations

from dataclasses import dataclass

from ..tracing.sampling import DEFAULT_SEQUENCE


@dataclass
class RenderSettings:
    """Settings shared by the CLI, the add-on and the bench (plain values only); each field is
    documented beside it.  :meth:`validate` checks them before any work."""

    #: rays per side of each bundle grid (0: about one cell per patch,
    #: :func:`~raybundle.methods.patch_solution.auto_bundle_resolution`)
    bundle_resolution: int = 0
    #: the random sequence's name (:mod:`raybundle.tracing.sampling`)
    sequence: str = DEFAULT_SEQUENCE
    #: the random seed: runs of given iterations are reproducible with it
    seed: int = 0
    #: 'auto': small lights and emitters are shot first (thesis 3.4); 'none': only the bundles
    first_shot: str = "auto"
    #: the first-shot lamps and emitting triangles chosen per point by a light tree
    #: (:mod:`raybundle.lights.light_tree`), ``light_samples`` of them per point and pass, in place
    #: of a shadow ray per lamp: 'on', 'off', or 'auto' (many lamps, or a curved mesh light of many
    #: triangles: :meth:`~raybundle.lights.direct.DirectLighting.wants_tree`)
    light_tree: str = "auto"
    #: shadow rays per light per pixel per image pass
    light_samples: int = 1
    #: the image passes' share of the work (the rest goes to the bundles' iterations): of the time
    #: in a run limited by time, of the traced rays in a run of given iterations (which repeats
    #: with its seed); 0: automatic, by whether the passes' eye paths carry glossy lobes
    #: (:class:`~raybundle.imaging.passes.PassSchedule`)
    image_share: float = 0.0
    #: sub-pixel positions at which the diffuse indirect part is resolved
    resolve_samples: int = 16
    #: interpolate the patch values across smooth surfaces
    smooth: bool = True
    #: the glossy lobe the eye sees by one importance-sampled eye ray per pixel and pass
    #: (:meth:`~raybundle.imaging.glossy_paths.GlossyEyePaths.gather`), not the per-iteration
    #: ``E f(t, w_eye)``
    glossy_gather: bool = True
    #: the glossy bounces those eye rays follow
    glossy_gather_depth: int = 3
    #: extra samples per pass (a jittered s x s grid, rounded to a square) for the pixels on the edge
    #: of a visible emitter and those whose passes disagree most (:meth:`~raybundle.imaging.passes.PassSchedule.noisy_pixels`)
    emission_edge_samples: int = 16
    #: bundle directions per iteration, traced together
    #: (:meth:`~raybundle.methods.stochastic_iteration.StochasticIterationSolver.step`)
    directions_per_step: int = 16
    #: the first shot's glossy reflection by lobe-sampled rays (:mod:`raybundle.lights.caustics`),
    #: not through the bundles
    caustics: bool = True
    #: with ``glossy_gather``, the mesh lights a glossy lobe reflects are estimated by light samples
    #: and by the lobe's ray together (multiple importance sampling, power heuristic)
    glossy_mis: bool = True
    #: lobe-sampled rays per glossy side and bundle direction that gather what the side's glossy lobe
    #: sends (:meth:`~raybundle.methods.patch_solution.PatchSolution.glossy_sent_radiance`)
    glossy_send_rays: int = 2
    #: final-gather rays per pixel where the patch values are not to be trusted (next to concave
    #: edges and contacts, :mod:`raybundle.imaging.gather`): 0 none; -1 as many as ``gather_share``
    #: of the run's seconds buys, in runs limited by time (none in runs of given iterations, which
    #: stay reproducible, nor in images formed without a budget of seconds):
    #: :meth:`~raybundle.imaging.resolve.DiffuseIndirect.image`
    gather_rays: int = -1
    #: the share of a timed run's seconds the automatic final gather may take
    gather_share: float = 0.25
    #: shadow rays per pass at the pixels where a light's earlier samples were both seen and blocked,
    #: shared by the lights whose shadow edges cross the pixel, at least one each (:mod:`~raybundle.imaging.pixel_light`)
    penumbra_samples: int = 8
    #: with a caustic first shot, its samples per pixel and image pass that light-trace the caustic on
    #: the surfaces the eye sees into the pixels (:meth:`~raybundle.imaging.caustic_splats.CausticSplats.splat`);
    #: 0: read it from the patches as the rest of the diffuse indirect light
    caustic_splats: float = 1.0
    #: shadow rays per visible point and image pass towards a world that changes with direction,
    #: drawn by its brightness and by where the bundles found the sky open from the point's side
    #: (:class:`~raybundle.lights.world_light.WorldLight`), for the diffuse lobe's direct light from
    #: the world; 0: the patches carry it; -1: 4 where the world is the only light, else 0
    #: (:meth:`Renderer.automatic_world_samples`)
    world_samples: int = -1
    #: the interfaces of glass, refraction and transparent surfaces an eye path is refracted by before
    #: it ends, black, at the next: Cycles' default transmission bounces
    #: (:mod:`raybundle.scene.transmission`, :meth:`~raybundle.imaging.eye_rays.EyeRays.trace`)
    transmission_depth: int = 12
    #: the reflections on them (total internal ones included) after which a path ends, black, at the
    #: next: Cycles' default glossy bounces
    glossy_depth: int = 4
    #: the ray tracer's threads (None: all cores)
    threads: int | None = None
    #: keep the image's parts apart (:mod:`~raybundle.imaging.components`): a pass costs a
    #: second BRDF evaluation per light sample and three more arrays per pixel
    components: bool = False


    def validate(self):
        """Raise ValueError on settings that cannot work (before any work is done)."""
        if not 0 <= int(self.bundle_resolution) <= 4096:
            raise ValueError("bundle_resolution must lie in [0, 4096] (0 = automatic)")
        if int(self.light_samples) < 1:
            raise ValueError("light_samples must be at least 1 (small lights are lit only by the first shot)")
        if int(self.resolve_samples) < 1 or int(self.emission_edge_samples) < 0:
            raise ValueError("resolve_samples must be >= 1 and emission_edge_samples >= 0")
        if not 0.0 <= float(self.image_share) < 1.0:
            raise ValueError("image_share must lie in [0, 1) (0 = automatic)")
        if self.first_shot not in ("auto", "none"):
            raise ValueError("first_shot must be 'auto' or 'none'")
        if self.light_tree not in ("auto", "on", "off"):
            raise ValueError("light_tree must be 'auto', 'on' or 'off'")
        if not 1 <= int(self.directions_per_step) <= 1024:
            raise ValueError("directions_per_step must lie in [1, 1024]")
        if not 1 <= int(self.glossy_send_rays) <= 64:
            raise ValueError("glossy_send_rays must lie in [1, 64]")
        if not 1 <= int(self.penumbra_samples) <= 4096:
            raise ValueError("penumbra_samples must lie in [1, 4096]")
        if not -1 <= int(self.world_samples) <= 4096:
            raise ValueError("world_samples must lie in [-1, 4096] (0 = the patches carry the world's direct light, "
                             "-1 = automatic)")
        if not -1 <= int(self.gather_rays) <= 65536:
            raise ValueError("gather_rays must lie in [-1, 65536] (0 = no final gather, -1 = automatic)")
        if not 0.0 <= float(self.gather_share) < 1.0:
            raise ValueError("gather_share must lie in [0, 1)")
        if not 0 <= int(self.transmission_depth) <= 1024:
            raise ValueError("transmission_depth must lie in [0, 1024]")
        if not 0 <= int(self.glossy_depth) <= 1024:
            raise ValueError("glossy_depth must lie in [0, 1024]")
        if not 0.0 <= float(self.caustic_splats) <= 64.0:
            raise ValueError("caustic_splats must lie in [0, 64] (0 = the caustic from the patches)")
