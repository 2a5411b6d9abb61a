"""Gather rays: the radiance that reaches points along given rays, read from a patch solution
(:class:`~raybundle.methods.patch_solution.PatchSolution`): what the glossy sides send by their
traced lobes (:meth:`~raybundle.methods.patch_solution.PatchSolution.glossy_sent_radiance`) and
what sides much smaller than a bundle cell receive (``_gather_tiny``).

The surface a ray meets sends back its diffuse lobe from the running average
(:meth:`~raybundle.methods.patch_solution.PatchSolution.received`), without the first-shot lights'
emission (the first shot carries it); a ray that leaves sees the world.  The hit's glossy lobe
comes from the iterate, ``E_j f_g(t_j, -w)``, where that lobe is rough
(:meth:`~raybundle.methods.patch_solution.PatchSolution.sharp_lobes`).  A traced (sharp) lobe is
followed instead by one ray drawn from it, ``weight L(y, -w')`` with the weight at most the lobe's
albedo, whose own hit reads its glossy lobe as if it spread its light evenly
(``glossy_as_diffuse``, as an eye path does once it has followed a lobe).

The iterate's ``E_j f_g`` of a sharp lobe is unbiased but heavy-tailed, about ``E_j / alpha^2``
where ``-w`` meets the lobe around ``t_j``, and the bundles carry such a reading on into the
running average of the sides it is sent to.  The as-if-diffuse end reads a lobe's incoming light
spread over the lobe: exact where that light is uniform (a furnace), a bias only along two sharp
lobes in a row.
"""
from __future__ import annotations

import numpy as np


def gather(solver, points, normals, w):
    """The radiance (N, 3) that reaches ``points`` (N, 3) on surfaces of (triangle) normals
    ``normals`` from ``w`` (N, 3, unit, leaving the surface) in ``solver``'s solution, and which of
    the rays left the scene (N,) (the module docstring)."""
    return _trace(solver, points, normals, w, solver.received(), follow=True)


def _trace(solver, points, normals, w, received, follow):
    """:func:`gather` with the sides' ``received`` light (S, 3), the hits' traced lobes followed or
    (not ``follow``) read as if diffuse."""
    sc = solver.scene
    origin = points + normals * solver.tracer.eps
    tri, dist, _, _ = solver.tracer.first_hit(origin, w)
    solver.stats.rays += len(points)
    hit = tri >= 0
    got = np.zeros((len(points), 3))
    if np.any(hit):
        back = -w[hit]
        xs = sc.side_facing(tri[hit], back)
        ok = xs >= 0
        rows, xs, back = np.nonzero(hit)[0][ok], xs[ok], back[ok]
        lobe = solver.traced_side[xs] & follow
        for part, traced in ((~lobe, False), (lobe, True)):
            if part.any():
                got[rows[part]] = solver.radiance(xs[part], back[part], diffuse_incoming=received[xs[part]],
                                                  first_shot_emission=False, sharp_interfaces=True,
                                                  glossy_iterate=not traced, glossy_as_diffuse=not follow)
        if lobe.any():
            r = rows[lobe]
            got[r] += _follow_lobe(solver, origin[r] + dist[r, None] * w[r], tri[r], xs[lobe], back[lobe], received)
    if solver.world.emits:
        got[~hit] = solver.world.radiance(w[~hit])
    return got, ~hit


def _follow_lobe(solver, points, tri, sides, w_out, received):
    """The glossy radiance (N, 3) that ``sides`` (N,) send from ``points`` (N, 3) on triangles
    ``tri`` towards ``w_out`` (N, 3), by one ray each drawn from their lobe."""
    n = solver.scene.triangle_normal[tri]
    n = n * np.where(np.einsum("ij,ij->i", n, w_out) < 0, -1.0, 1.0)[:, None]     # the side that w_out leaves
    w_i, weight = solver.scene.materials.sample_glossy(solver.patch_material[sides], n, w_out,
                                                        solver.grid_rng.random((len(sides), 2)))
    live = np.nonzero(np.any(weight > 0, axis=1))[0]
    out = np.zeros((len(sides), 3))
    out[live] = weight[live] * _trace(solver, points[live], n[live], w_i[live], received, follow=False)[0]
    return out
