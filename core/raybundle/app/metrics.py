"""The image error every figure of the project quotes, from this one function.

Relative RMSE of an image ``x`` against a reference ``r`` (both (H, W, 3) linear
radiance)::

    e = sqrt(mean over kept pixels and channels of (x - r)^2) / mean(r over kept pixels)

Kept pixels are those at least 2 px away from a directly seen light source
(:func:`light_source_mask`: an emitter that lights the scene; a furnace's
glowing walls are not light sources here).  When the reference is the mean of
two independent halves A and B, its own noise is subtracted::

    sigma_ref^2 = mean((A - B)^2) / 4 / mean(r)^2         (same pixels, same units)
    error       = sqrt(max(0, e^2 - sigma_ref^2))

so a converging curve does not flatten at the reference's noise.

Beside it, for blotches and fireflies that an RMSE averages away: the 99.9th percentile
over kept pixels of the per-pixel relative error ``|x - r| / (r + 0.02)`` (x, r the
pixel's mean over its channels, 0.02 W m^-2 sr^-1 keeping dark pixels from dominating),
and the image mean against the reference's.
"""
from __future__ import annotations

import numpy as np


def dilate(mask, radius=2):
    """(H, W) bool: ``mask`` grown by ``radius`` pixels (square neighbourhood)."""
    out = np.array(mask, bool)
    h, w = out.shape
    src = out.copy()
    for dy in range(-radius, radius + 1):
        for dx in range(-radius, radius + 1):
            ys, yd = slice(max(0, -dy), h - max(0, dy)), slice(max(0, dy), h - max(0, -dy))
            xs, xd = slice(max(0, -dx), w - max(0, dx)), slice(max(0, dx), w - max(0, -dx))
            out[yd, xd] |= src[ys, xs]
    return out


def _primary_hits(camera, tracer, samples, seed):
    """``(origins, directions, triangles, distances)`` of ``samples`` jittered primary rays a
    pixel of ``camera`` (sample-major: row ``k * pixels + i`` is pixel i's k-th ray), from the
    stream of :func:`light_source_mask`."""
    from ..tracing.sampling import Stream, stream

    rng = stream(seed, Stream.LIGHT_SOURCE_MASK)
    py, px = np.divmod(np.arange(camera.width * camera.height), camera.width)
    j = rng.random((samples, len(px), 2)).reshape(-1, 2)        # the draws of one (N, 2) call a sample
    org, d = camera.rays(np.tile(px, samples) + j[:, 0], np.tile(py, samples) + j[:, 1])
    tri, dist, _, _ = tracer.first_hit(org, d)
    return org, d, tri, dist


def light_source_mask(scene, camera=None, samples=4, seed=0, radius=2, tracer=None):
    """(H, W) bool: pixels within ``radius`` px of a directly seen light source.

    A light source is a small emitter that the renderer treats as a light (the
    first-shot emitters of :class:`~raybundle.lights.direct.DirectLighting`); a pixel sees
    one when any of ``samples`` jittered primary rays hits its front.
    """
    from ..lights.direct import DirectLighting
    from ..tracing.visibility import RayTracer

    cam = camera if camera is not None else scene.camera
    own = tracer is None
    tracer = tracer or RayTracer(scene)
    try:
        lights = DirectLighting(scene, tracer).first_shot_material
        _, d, tri, _ = _primary_hits(cam, tracer, samples, seed)
        hit = tri >= 0
        ts = scene.seen_tside(np.where(hit, tri, 0), d)
        facing = np.einsum("ij,ij->i", scene.tside_normal[ts], d) < 0
        seen = hit & facing & lights[scene.triangle_material[np.maximum(tri, 0)]]
    finally:
        if own:
            tracer.close()
    return dilate(seen.reshape(samples, cam.height, cam.width).any(axis=0), radius)


def overlap_mask(scene, groups, camera=None, samples=4, seed=0, tracer=None):
    """(H, W) bool: pixels that see a coplanar overlap of two of ``groups`` (T,) (the objects of
    ``scene``'s triangles), where Cycles z-fights and renders darker than either face alone
    (:mod:`raybundle.scene.overlaps`): any of ``samples`` jittered primary rays (those of
    :func:`light_source_mask`) meets a point covered by another group's triangle in the same
    plane, facing the same way.  Not left out of :func:`image_error`: a breakdown's region."""
    from ..scene.overlaps import covered_points
    from ..tracing.visibility import RayTracer

    cam = camera if camera is not None else scene.camera
    own = tracer is None
    tracer = tracer or RayTracer(scene)
    try:
        org, d, tri, dist = _primary_hits(cam, tracer, samples, seed)
        seen = covered_points(scene.triangle_corners, groups, org + d * np.where(tri >= 0, dist, 0.0)[:, None], tri)
    finally:
        if own:
            tracer.close()
    return seen.reshape(samples, cam.height, cam.width).any(axis=0)


#: W m^-2 sr^-1 added to the reference in the per-pixel relative error's denominator
TAIL_FLOOR = 0.02


def image_error(image, reference, reference_halves=None, exclude=None):
    """Relative RMSE of ``image`` against ``reference`` (module docstring).

    ``reference_halves``: (A, B), two independent halves whose mean is the
    reference, to subtract its noise; ``exclude``: (H, W) bool pixels left out
    (:func:`light_source_mask`).  Returns a dict: ``error`` (noise-corrected),
    ``raw`` (uncorrected e), ``reference_noise`` (sigma_ref, relative),
    ``pixels`` (kept), ``mean_ratio`` (mean of x / mean of r), ``p99_9`` (the
    per-pixel tail of the module docstring) and, with halves, ``reference_p99_9``:
    the same percentile of the reference's own per-pixel noise ``|A - B| / 2 / (r + 0.02)``,
    below which ``p99_9`` cannot be read.
    """
    x = np.asarray(image, float)
    r = np.asarray(reference, float)
    if x.shape != r.shape:
        raise ValueError(f"image {x.shape} and reference {r.shape} differ in shape")
    keep = np.ones(x.shape[:2], bool) if exclude is None else ~np.asarray(exclude, bool)
    mean = r[keep].mean()
    if not mean > 0:
        raise ValueError("the reference is black over the compared pixels")
    e2 = ((x[keep] - r[keep]) ** 2).mean() / mean ** 2
    grey = r[keep].mean(axis=-1) + TAIL_FLOOR
    out = {"pixels": int(keep.sum()), "mean_ratio": float(x[keep].mean() / mean),
           "p99_9": float(np.percentile(np.abs(x[keep].mean(axis=-1) - r[keep].mean(axis=-1)) / grey, 99.9))}
    s2 = 0.0
    if reference_halves is not None:
        a, b = (np.asarray(h, float) for h in reference_halves)
        s2 = ((a[keep] - b[keep]) ** 2).mean() / 4.0 / mean ** 2
        half = np.abs(a[keep].mean(axis=-1) - b[keep].mean(axis=-1)) / 2
        out["reference_p99_9"] = float(np.percentile(half / grey, 99.9))
    return {"error": float(np.sqrt(max(0.0, e2 - s2))), "raw": float(np.sqrt(e2)),
            "reference_noise": float(np.sqrt(s2)), **out}


def bias_and_noise(image, twin, reference, reference_halves=None, exclude=None):
    """:func:`image_error` of ``image`` split into its noise and its bias, from ``twin``: the
    same render with another seed.  Per render, relative to the reference's mean::

        noise^2 = mean((x1 - x2)^2) / 2 / mean(r)^2
        bias    = sqrt(max(0, error^2 - noise^2))

    (``error`` noise-corrected as in :func:`image_error`; the bias is what more time at the
    same settings does not remove).  Returns ``error``, ``noise``, ``bias`` and
    ``mean_ratio``, each of ``image``."""
    one = image_error(image, reference, reference_halves, exclude)
    x1, x2, r = (np.asarray(a, float) for a in (image, twin, reference))
    keep = np.ones(r.shape[:2], bool) if exclude is None else ~np.asarray(exclude, bool)
    n2 = ((x1[keep] - x2[keep]) ** 2).mean() / 2.0 / r[keep].mean() ** 2
    return {"error": one["error"], "noise": float(np.sqrt(n2)),
            "bias": float(np.sqrt(max(0.0, one["error"] ** 2 - n2))), "mean_ratio": one["mean_ratio"]}


def pixel_errors(image, reference, reference_halves=None):
    """(H, W): each pixel's squared error ``mean over channels (x - r)^2``, less the reference's
    own noise ``(A - B)^2 / 4`` with ``reference_halves`` (A, B): :func:`image_error`'s sum,
    pixel by pixel (a pixel within the reference's noise may come out below 0)."""
    x, r = np.asarray(image, float), np.asarray(reference, float)
    d2 = ((x - r) ** 2).sum(axis=-1) / r.shape[-1]
    if reference_halves is not None:
        a, b = (np.asarray(h, float) for h in reference_halves)
        d2 = d2 - ((a - b) ** 2).sum(axis=-1) / r.shape[-1] / 4.0
    return d2


def region_errors(image, reference, reference_halves=None, exclude=None, grid=(3, 3)):
    """The error by image region: ``grid`` (rows, columns) blocks, each block's share of the
    squared error (``share``; the shares sum to 1, a block within the reference's noise has
    none), its own error relative to the whole reference's mean (``error``, noise-corrected
    with the halves) and its mean against the reference's (``mean_ratio``).  A list of dicts,
    row by row from the top."""
    x, r = np.asarray(image, float), np.asarray(reference, float)
    keep = np.ones(r.shape[:2], bool) if exclude is None else ~np.asarray(exclude, bool)
    mean = r[keep].mean()
    d2 = pixel_errors(x, r, reference_halves)
    h, w = keep.shape
    rows, cols = np.linspace(0, h, grid[0] + 1).astype(int), np.linspace(0, w, grid[1] + 1).astype(int)
    out = []
    for i in range(grid[0]):
        for j in range(grid[1]):
            k = np.zeros_like(keep)
            k[rows[i]:rows[i + 1], cols[j]:cols[j + 1]] = True
            k &= keep
            s2 = max(float(d2[k].sum()), 0.0)          # below the reference's noise: none
            out.append({"row": i, "column": j, "s2": s2,
                        "error": float(np.sqrt(s2 / max(int(k.sum()), 1)) / mean),
                        "mean_ratio": float(x[k].mean() / r[k].mean()) if k.any() and r[k].mean() > 0 else 1.0})
    total = sum(g["s2"] for g in out)
    for g in out:
        g["share"] = g.pop("s2") / total if total > 0 else 0.0
    return out


def component_errors(parts, reference_halves, exclude=None, twins=None):
    """The error by component: for each name of ``reference_halves`` ({name: (A_c, B_c)}, the
    components of two independent halves, which sum to each half's image), ``parts[name]``
    against the halves' mean r_c over the kept pixels, both relative to the mean of the whole
    reference r (so that the components' squared errors add up to the image's, their cross
    terms aside)::

        error_c = sqrt(max(0, mean((x_c - r_c)^2) - mean((A_c - B_c)^2) / 4)) / mean(r)

    Returns {name: dict} with ``error``, ``share`` (the component's part of the reference's
    mean) and ``mean_ratio`` (its mean against r_c's, None where that is 0), and with
    ``twins`` ({name: the same component of a render with another seed}) ``noise`` and
    ``bias`` as in :func:`bias_and_noise`."""
    keep = None if exclude is None else ~np.asarray(exclude, bool)
    pick = (lambda a: np.asarray(a, float)) if keep is None else (lambda a: np.asarray(a, float)[keep])
    halves = {name: [pick(h) for h in pair] for name, pair in reference_halves.items()}
    total = sum(0.5 * (a + b) for a, b in halves.values()).mean()
    if not total > 0:
        raise ValueError("the reference is black over the compared pixels")
    out = {}
    for name, (a, b) in halves.items():
        x, r = pick(parts[name]), 0.5 * (a + b)
        e2 = max(0.0, ((x - r) ** 2).mean() - ((a - b) ** 2).mean() / 4.0) / total ** 2
        d = {"error": float(np.sqrt(e2)), "share": float(r.mean() / total),
             "mean_ratio": float(x.mean() / r.mean()) if r.mean() > 0 else None}
        if twins is not None:
            n2 = ((x - pick(twins[name])) ** 2).mean() / 2.0 / total ** 2
            d.update(noise=float(np.sqrt(n2)), bias=float(np.sqrt(max(0.0, e2 - n2))))
        out[name] = d
    return out
