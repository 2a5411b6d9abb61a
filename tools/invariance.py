"""Invariance checks: the same light field described differently gives the same answer.

A case is a scene and a description of it that must light it the same way (subdivided,
flipped, scaled, reordered).  Each is solved once per patch layout; after a burn-in batch
the iterates of B batches give, per *region* (the sides the camera sees, grouped by which
way they face: floor, ceiling, back, left and right walls, and the blocks' faces towards the
camera), the area-weighted mean radiance towards the normal per batch.
Batch means are nearly independent (the iterates' autocorrelation q^k dies within a
batch), so their spread gives each region's standard error SE.

A case passes when every region agrees with the unmodified scene within
``4.5 SE + b``: ``b`` is the finite-element spread, the largest region difference between
two layouts of the unmodified scene at nearly equal patch counts (4,000 and 4,400 by
default), and must itself stay under 1%.
"""
from __future__ import annotations

import numpy as np

from raybundle.app import pipeline
from raybundle.imaging.settings import RenderSettings
from raybundle.patches.gaps import gap_sides

REGIONS = ("floor", "ceiling", "back", "left", "right", "front")


def _region_of(scene, solver):
    """(S,) region id of each side the camera sees (its centroid unoccluded, facing the
    camera), -1 for others; grouped by the way they face (Z up, the Blender Cornell box's
    camera looking along +y): ``back`` faces -y from the far end of the box, ``front`` are
    the other faces turned towards -y (the blocks').  What no pixel sees (the ceiling over a
    lamp hanging just under it, the inside of a block) is the layout's business, not the image's."""
    sc, tracer = scene, solver.tracer
    centroid = sc.patch_centroid[sc.side_patch]
    n = solver.normal
    lo, hi = sc.vertices.min(axis=0), sc.vertices.max(axis=0)
    axis = np.argmax(np.abs(n), axis=1)
    sign = np.take_along_axis(n, axis[:, None], 1)[:, 0] > 0
    far = centroid[:, 1] > hi[1] - 0.01 * (hi[1] - lo[1])
    region = np.full(len(n), -1)
    for r, sel in enumerate(((axis == 2) & sign, (axis == 2) & ~sign, (axis == 1) & ~sign & far,
                             (axis == 0) & ~sign, (axis == 0) & sign, (axis == 1) & ~sign & ~far)):
        region[sel] = r
    to_eye = sc.camera.position - centroid
    dist = np.linalg.norm(to_eye, axis=1)
    facing = np.einsum("ij,ij->i", n, to_eye) > 0
    seen = facing & ~tracer.occluded(centroid + n * tracer.eps, to_eye / dist[:, None], dist - 2 * tracer.eps)
    # a side in a contact gap (a strip of the ceiling over a lamp's edge) may see the camera past
    # the edge, but its light is the gap's: left out too
    trapped = gap_sides(tracer, centroid, n, 2e-3 * sc.bounding_sphere[1])[:, 0]
    reflects = sc.materials.reflects[sc.side_material]
    return np.where(seen & ~trapped & reflects & (solver.area > 0), region, -1)


def region_batches(scene, patches=4000, batches=20, per_batch=16, seed=1):
    """(B, 6) luminance of the area-weighted mean radiance of each region per batch."""
    sc = pipeline.prepare(scene, patches=patches)
    solver = pipeline.make_solver(sc, RenderSettings(seed=seed))
    try:
        region = _region_of(sc, solver)
        w = np.zeros((len(REGIONS), len(region)))
        for r in range(len(REGIONS)):
            sel = region == r
            w[r, sel] = solver.area[sel] / max(solver.area[sel].sum(), 1e-300)
        lum = np.array([0.2126, 0.7152, 0.0722])
        out = []
        for b in range(batches + 1):
            acc = np.zeros(len(REGIONS))
            for _ in range(per_batch):
                solver.step()
                acc += w @ (solver.iterate_radiance(solver.normal) @ lum)
            if b:                       # the first batch is the burn-in
                out.append(acc / per_batch)
        return np.array(out)
    finally:
        solver.tracer.close()


def compare(a, b):
    """Per region: relative difference of the means of batch sets ``a``, ``b`` (B, R) and
    its standard error (relative to ``a``'s mean)."""
    ma, mb = a.mean(axis=0), b.mean(axis=0)
    se = np.sqrt(a.var(axis=0, ddof=1) / len(a) + b.var(axis=0, ddof=1) / len(b))
    return (mb - ma) / ma, se / ma


def spread(scene, patches=(4000, 4400), **kw):
    """``b``: the largest relative region difference between two layouts of ``scene``."""
    d, _ = compare(region_batches(scene, patches[0], **kw), region_batches(scene, patches[1], **kw))
    return float(np.abs(d).max())


def check(base, case, b, patches=4000, allow=None, **kw):
    """Assert every region of ``case`` within 4.5 SE + b of ``base`` (both (B, R) batch sets),
    plus ``allow`` ({region: share}) for a region's known bias."""
    d, se = compare(base, case)
    extra = np.array([(allow or {}).get(r, 0.0) for r in REGIONS])
    bad = np.abs(d) > 4.5 * se + b + extra
    table = ", ".join(f"{r} {100 * x:+.2f}% (SE {100 * s:.2f}%)" for r, x, s in zip(REGIONS, d, se))
    assert not bad.any(), f"not invariant (b = {100 * b:.2f}%): {table}"
    return d, se
