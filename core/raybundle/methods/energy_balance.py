"""The energy balance of a transfer: the level a diffuse iterate of a given shape must have.

In expectation, one transfer (:meth:`~raybundle.methods.patch_solution.PatchSolution.transfer`)
hands the sides the power the world shines straight onto them and the power the sides send
into directions that meet a side able to receive it::

    sum_i A_i E'_i = W + sum_j c_j pi A_j S_j                                        [W]

with ``S_j`` side j's sent radiance (the same into its whole hemisphere: diffuse sides), ``c_j``
the share of its cosine-weighted directions, from uniform points of it, whose first hit
(:meth:`~raybundle.tracing.visibility.RayTracer.first_hit`: through cut-outs and glass as the
bundles pass them) is a side that receives (not the world, not a black back), and
``W = sum_j A_j E_w,j`` the world's light received straight (``E_w,j = pi`` times the mean
world radiance along the directions that leave the scene).  ``S`` is linear in the iterate:
``S = S0 + S_E`` with ``S0`` the emission and the reflected first shot, ``S_E`` what the
iterate ``E`` adds (its diffuse reflection, a translucent side's light from its other side).
At the solution ``E' = E``, so an iterate of the right shape, ``k E``, has the level

    k = (W + sum_j c_j pi A_j S0_j) / (sum_j A_j E_j - sum_j c_j pi A_j S_E,j)

per colour channel.  The warm-up's iterate is noisiest in just this level (its coarse bundles'
sum of many random factors, :meth:`~raybundle.methods.stochastic_iteration.StochasticIterationSolver.warm_up`);
its shape is much closer to the solution's, so scaling it by ``k`` starts the running average
near the solution's level.  Only the start changes: the average stays the same consistent
estimate from any start.
"""
from __future__ import annotations

import numpy as np

from ..patches.side_points import SidePoints
from ..tracing.sampling import cosine_directions, frames_from_normals

#: cosine-weighted rays per side that measure its capture and its world light
RAYS_PER_SIDE = 8


def side_capture(scene, tracer, rng, rays=RAYS_PER_SIDE, chunk=1 << 18):
    """``(c, E_w)``: per side (S,) the share of ``rays`` cosine-weighted rays from uniform points
    of it whose first hit is a side that receives, and (S, 3) the world's irradiance ``E_w``
    straight from the sky along the others [W/m^2] (0 where the world does not emit).  Traced
    about ``chunk`` rays at a time."""
    n = scene.n_sides
    points = SidePoints(scene, np.ones(n, bool))
    world = scene.world if scene.world.emits else None
    caught, sky = np.zeros(n), np.zeros((n, 3))
    per = max(1, chunk // rays)
    for lo in range(0, n, per):
        sides = np.repeat(np.arange(lo, min(lo + per, n)), rays)
        p, nrm = points.draw(sides, rng.random((len(sides), 3)))
        t, b = frames_from_normals(nrm)
        w = cosine_directions(rng.random((len(sides), 2)), t, b, nrm)
        tri = tracer.first_hit(p + nrm * tracer.eps, w)[0]
        hit = np.nonzero(tri >= 0)[0]
        caught += np.bincount(sides[hit], scene.side_facing(tri[hit], -w[hit]) >= 0, minlength=n)
        if world is not None:
            out = np.nonzero(tri < 0)[0]
            L = world.radiance(w[out])
            for c in range(3):
                sky[:, c] += np.bincount(sides[out], L[:, c], minlength=n)
    return caught / rays, np.pi * sky / rays


def balanced_level(area, incoming, sent_fixed, sent_iterate, capture, world_incoming):
    """(3,) the factor ``k`` per channel that brings ``incoming`` (S, 3), the iterate of a
    diffuse solution, to the level of the energy balance (module docstring): ``sent_fixed``
    and ``sent_iterate`` (S, 3) are ``S0`` and ``S_E`` [W m^-2 sr^-1], ``capture`` (S,) and
    ``world_incoming`` (S, 3) :func:`side_capture`'s, ``area`` (S,) the sides' receiving areas.
    1 in a channel the iterate holds no light in, or whose balance has no solution (more
    captured than received: a capture estimate off on a scene of next to no escape)."""
    onward = (capture * np.pi * area)[:, None]
    source = area @ world_incoming + (onward * sent_fixed).sum(axis=0)
    held = area @ incoming - (onward * sent_iterate).sum(axis=0)
    ok = (area @ incoming > 0) & (held > 0) & (source > 0)
    return np.where(ok, source / np.where(ok, held, 1.0), 1.0)
