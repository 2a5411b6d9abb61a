"""The control variate of a bundle transfer: what a radiance of 1 from every direction gives.

A transfer (:meth:`~raybundle.methods.patch_solution.PatchSolution.transfer`) estimates each
side's incoming irradiance ``E_i`` from K random directions; the same bundles give each side
also::

    M_i = (1/K) sum_k (2 pi / A_i) sum_j A(i, j, d_k) cos_i

over all the rays that cross it (``A_i`` its whole area; the crossings of its triangles,
:meth:`~raybundle.tracing.visibility.RayTracer.bundles`, whatever lies beyond: a side, a black
back or a black world), what a radiance of 1 arriving from every direction would give: its
expectation is exactly ``pi``.  With ``c_i`` any estimate of ``E_i`` made before the
directions were drawn (the running average), ``E_i - c_i (M_i / pi - 1)`` keeps E's
expectation and takes out the noise that the cosines of a few directions and the grid's
aliasing give light that arrives about evenly: the same factor on every side of one
orientation, noise at the scale of walls, which the running average keeps longest.

It serves the sides open all over: a ray crosses a cut-out or glass at random, and a side
partly buried under a solid lies on the solid's face there, where a ray's one hit crosses
either.  A side lying on another face (z-fighting) keeps a share ``m < 1`` of its crossings
and of its light, and comes out at its light over ``m``: lit as one surface, as the tracer
does (:mod:`raybundle.scene.overlaps`).
"""
from __future__ import annotations

import numpy as np


def controlled(solver, E, bundles, crossed, control):
    """``E`` (S, 3), the mean of the transfers along ``bundles`` (K of one resolution), less
    ``control`` (S, 3) times ``M_i / pi - 1`` on ``solver``'s sides open all over
    (``solver.wholly_open``); ``crossed`` (T,): the bundles' crossings of each triangle."""
    sc = solver.scene
    per_side = np.bincount(sc.tside_side, crossed[sc.tside_triangle], minlength=len(E))
    m = per_side * (bundles[0].cell_area * 2.0) / (solver.full_area * len(bundles))
    return E - control * np.where(solver.wholly_open, m - 1.0, 0.0)[:, None]
