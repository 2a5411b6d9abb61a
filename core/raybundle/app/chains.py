"""Independent chains and their exact merge.

Stochastic iteration is a Markov chain; chains run with different seeds on the same
prepared scene are independent, and everything an image or a bake reads from a chain is
a running average, so chains merge exactly by pooling sums and counts:

    E_bar = sum_c n_c E_bar_c / sum_c n_c         (n_c: iterations in chain c's average)
    first shot of tside t = sum_c e_sum_c,t / sum_c count_c,t
    caustic shot = sum_c sum_c / sum_c samples_c
    pixel = sum_c S_c / sum_c P_c                  (S: sums over image passes, P: passes;
                                                    emission seen, glossy iterations and caustic
                                                    splats alike)

:class:`ChainState` holds those sums and counts as plain arrays (picklable: what a worker
sends back, :mod:`raybundle.app.distributed`); :func:`merge` pools them; :func:`apply` puts a
state into a renderer (or a solver, for bakes) built on the same prepared scene, whose
image or bake is then that of all the chains together.  The state of the last iterate
(what the next iteration would start from) is that of the first chain: it matters only
for continuing a chain, not for the averages.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


@dataclass
class ChainState:
    """Sums and counts of one chain (or of merged chains).

    ``averaged``: iterations in ``mean_incoming`` (S, 3); ``first_shot``: the per-tside
    sums ``(e_sum, d_sum, count)`` of :class:`~raybundle.lights.first_shot.PatchFirstShot`;
    ``caustic``: ``(sum, dsum, samples)`` of :class:`~raybundle.lights.caustics.CausticShot` or None;
    ``image``: the renderer's pass sums and counts (None for a solver alone);
    ``stats``: iterations, directions, rays and seconds added up; ``chains``: how many
    chains were pooled; ``mean_world_incoming`` (S, 3): the part of ``mean_incoming`` straight
    from the world, averaged alike (zeros where the image does not take it apart)."""

    averaged: int
    mean_incoming: np.ndarray
    first_shot: tuple
    caustic: tuple | None = None
    image: dict | None = None
    stats: dict = field(default_factory=dict)
    chains: int = 1
    mean_world_incoming: np.ndarray | None = None


def _renderer_and_solver(renderer_or_solver):
    """(renderer or None, solver) of a renderer or a solver."""
    if hasattr(renderer_or_solver, "solver"):
        return renderer_or_solver, renderer_or_solver.solver
    return None, renderer_or_solver


def state(renderer_or_solver) -> ChainState:
    """The :class:`ChainState` of a renderer (image included) or a solver (copies)."""
    renderer, solver = _renderer_and_solver(renderer_or_solver)
    fs, cs = solver.first_shot, solver.caustic
    image = None
    if renderer is not None:
        image = renderer.sums()
    st = solver.stats
    return ChainState(solver.averaged, solver.mean_incoming.copy(),
                      fs.sums(), None if cs is None else cs.sums(),
                      image, dict(iterations=st.iterations, directions=st.directions, rays=st.rays,
                                  seconds=st.seconds), mean_world_incoming=solver.mean_world_incoming.copy())


def merge(states) -> ChainState:
    """Pool the sums and counts of ``states`` (chains of one prepared scene)."""
    states = list(states)
    if not states:
        raise ValueError("nothing to merge")
    n = sum(s.averaged for s in states)
    mean = (sum(s.averaged * s.mean_incoming for s in states) / n) if n else states[0].mean_incoming.copy()
    first = tuple(sum(s.first_shot[k] for s in states) for k in range(3))
    caustic = None
    if states[0].caustic is not None:
        caustic = tuple(sum(s.caustic[k] for s in states) for k in range(3))
    image = None
    if all(s.image is not None for s in states):
        image = {k: sum(s.image[k] for s in states) for k in states[0].image if k != "shadow_flags"}
        image["shadow_flags"] = np.bitwise_or.reduce([s.image["shadow_flags"] for s in states])
    stats = {k: sum(s.stats.get(k, 0) for s in states) for k in states[0].stats}
    world = None
    if all(s.mean_world_incoming is not None for s in states):
        world = (sum(s.averaged * s.mean_world_incoming for s in states) / n) if n \
            else states[0].mean_world_incoming.copy()
    return ChainState(n, mean, first, caustic, image, stats, sum(s.chains for s in states), world)


def apply(merged: ChainState, renderer_or_solver):
    """Make a renderer (or solver) built on the same prepared scene hold ``merged``: its
    image (:meth:`~raybundle.imaging.renderer.Renderer.image`) or bake is then the pooled one."""
    renderer, solver = _renderer_and_solver(renderer_or_solver)
    if merged.mean_incoming.shape != solver.mean_incoming.shape:
        raise ValueError("the state comes from another scene or patch layout")
    solver.averaged = merged.averaged
    solver.mean_incoming = merged.mean_incoming.copy()
    if merged.mean_world_incoming is not None:
        solver.mean_world_incoming = merged.mean_world_incoming.copy()
    solver.first_shot.set_sums(*merged.first_shot)
    if solver.caustic is not None and merged.caustic is not None:
        solver.caustic.set_sums(*merged.caustic)
    for k, v in merged.stats.items():
        setattr(solver.stats, k, v)
    if renderer is not None and merged.image is not None:
        renderer.set_sums(merged.image)
    return renderer_or_solver
