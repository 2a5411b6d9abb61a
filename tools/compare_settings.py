"""Side-by-side settings on a scene: error, noise and bias against a cached Cycles reference.

Each variant (a JSON object of :class:`raybundle.imaging.settings.RenderSettings` fields, plus
``"patches"``, ``"solver"``: attributes to set on the solver, e.g.
``{"solver": {"caustic_refine": 4096}}``, and ``"renderer"``: attributes to set on the
renderer, e.g. ``{"renderer": {"FIRST_EDGE_SAMPLES": 8}}``, and ``"method"``: another method, e.g.
``{"method": "path-tracing"}``, whose mean tells an error of the export from one of the
bundles) renders the scene once per seed, for a fixed
time or iteration count, and prints its error (``raybundle.app.metrics.image_error``: pixels >= 2 px from the lamp, the
reference's own noise subtracted) and image mean against the reference.  With two seeds
or more it splits the error into per-image noise (from the difference of two seeds) and
bias (what the mean of the seeds keeps): ``e^2 = bias^2 + noise^2``.  ``--where`` then says where
that mean's error sits: its share in each of 3 x 3 image regions
(``raybundle.app.metrics.region_errors``) and how few pixels hold half of it, and ``--save DIR``
keeps the mean image (``DIR/variant-K.exr``) for a closer look.  The core's path tracer as one
variant (``{"method": "path-tracing"}``) tells what the file leaves open (faces of two objects
z-fighting, which Cycles renders darker) from the bundles' own bias: where it agrees with Cycles
and the bundles do not, the bias is the method's.

The reference halves are ``OUT/reference-1.exr`` and ``reference-2.exr`` as
``tools/bench_blender.py`` writes them (``make bench-boxes`` caches them in
``out/bench-cornell`` and ``out/bench-cornell-glossy``), or the two files ``--halves``.
The scene is a built-in scene's name or a ``.npz`` file (``python -m raybundle_addon ROOM.blend
--save-npz``; for the interior bench's clay, exported with the view layer's Material Override
set as ``tools/bench_blender.py --clay`` sets it).  Examples::

    python tools/compare_settings.py cornell --seconds 20 --seeds 3,4 \\
        '{}' '{"image_share": 0.5}' '{"patches": 6000}'
    python tools/compare_settings.py living-clay.npz --seconds 60 --seeds 3 --halves \\
        demo_scenes/interiors/references/living-room-clay-{1,2}.exr \\
        '{}' '{"patches": 16000}' '{"method": "path-tracing"}'
"""
from __future__ import annotations

import argparse
import json
import os
import time

import numpy as np


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("scene", help="a built-in scene name or a .npz file")
    p.add_argument("variants", nargs="+", help="JSON objects of RenderSettings fields (and 'patches')")
    g = p.add_mutually_exclusive_group(required=True)
    g.add_argument("--seconds", type=float)
    g.add_argument("--iterations", type=int)
    p.add_argument("--seeds", type=lambda t: [int(x) for x in t.split(",")], default=[3, 4],
                   help="comma-separated seeds (default 3,4)")
    p.add_argument("--reference", default=None, help="folder of reference-1/2.exr (default out/bench-SCENE)")
    p.add_argument("--halves", nargs=2, metavar=("A", "B"), help="the reference's two halves (instead of --reference)")
    p.add_argument("--where", action="store_true", help="where the seeds' mean's error sits: by region, and how "
                                                        "few pixels hold half of it")
    p.add_argument("--save", metavar="DIR", help="write each variant's mean over the seeds as DIR/variant-K.exr")
    a = p.parse_args(argv)

    from raybundle.app.metrics import image_error, light_source_mask
    from raybundle.app.pipeline import make_renderer, prepare
    from raybundle.imaging.settings import RenderSettings
    from raybundle.methods.registry import image_only
    from raybundle.patches.clusters import DEFAULT_PATCHES
    from raybundle.scene.builtin import load_scene
    from raybundle.util.io import read_exr, write_exr

    folder = a.reference or os.path.join("out", f"bench-{a.scene}")
    files = a.halves or [os.path.join(folder, f"reference-{k}.exr") for k in (1, 2)]
    missing = [f for f in files if not os.path.isfile(f)]
    if missing:
        raise SystemExit(f"compare_settings: no reference half {missing[0]} (--halves, or --reference with "
                         "reference-1.exr and reference-2.exr)")
    halves = [read_exr(f)[..., :3] for f in files]
    ref = 0.5 * (halves[0] + halves[1])
    scene = load_scene(a.scene)
    h, w = ref.shape[:2]
    scene.camera = scene.camera.with_resolution(w, h)
    mask = light_source_mask(scene)
    keep = ~mask
    run = {"time_limit": a.seconds} if a.seconds is not None else {"iterations": a.iterations}
    if a.save:
        os.makedirs(a.save, exist_ok=True)
    for number, text in enumerate(a.variants, 1):
        v = json.loads(text)
        method = v.pop("method", "stochastic-iteration")
        patches = v.pop("patches", DEFAULT_PATCHES)
        prepared = scene if image_only(method) else prepare(scene, patches)
        solver_attrs = v.pop("solver", {})
        renderer_attrs = v.pop("renderer", {})
        images = []
        for seed in a.seeds:
            r = make_renderer(prepared, RenderSettings(seed=seed, **v), solver=method)
            for target, attrs in ((r.solver, solver_attrs), (r, renderer_attrs)):
                for k, x in attrs.items():
                    if not hasattr(target, k):
                        raise SystemExit(f"compare_settings: {type(target).__name__} has no attribute {k!r}")
                    setattr(target, k, x)
            t0 = time.perf_counter()
            res = r.run(**run)
            img, st = res.image[..., :3], res.stats
            wall = time.perf_counter() - t0
            r.tracer.close()
            images.append(img)
            e = image_error(img, ref, reference_halves=halves, exclude=mask)["error"]
            passes = (f", {st['image_passes']} image passes taking {100 * st['image_pass_seconds'] / st['seconds']:.0f}%"
                      if "image_pass_seconds" in st else "")
            passes += f", {st['gather_rays_per_pixel']} gather rays" if st.get("gather_rays_per_pixel") else ""
            print(f"{text} seed {seed}: {wall:.1f} s, error {100 * e:.2f}%, "
                  f"mean ratio {img[keep].mean() / ref[keep].mean():.4f}, {st['iterations']} iterations{passes}",
                  flush=True)
        if len(images) > 1:
            noise = np.sqrt(np.mean((images[0] - images[1])[keep] ** 2) / 2) / ref[keep].mean()
            e_mean = image_error(np.mean(images, axis=0), ref, reference_halves=halves, exclude=mask)["error"]
            bias = np.sqrt(max(e_mean ** 2 - noise ** 2 / len(images), 0.0))
            print(f"  per-image noise {100 * noise:.2f}%, error of the {len(images)}-seed mean "
                  f"{100 * e_mean:.2f}%, bias about {100 * bias:.2f}%", flush=True)
        mean_image = np.mean(images, axis=0)
        if a.where:
            where(mean_image, ref, halves, mask)
        if a.save:
            write_exr(os.path.join(a.save, f"variant-{number}.exr"), mean_image.astype(np.float32))


def where(image, ref, halves, mask):
    """Print where ``image``'s error against ``ref`` sits: each of 3 x 3 regions' share of the
    squared error and its mean against the reference's, and the fewest pixels holding half and
    four fifths of the squared error (the reference's noise taken out per pixel)."""
    from raybundle.app.metrics import pixel_errors, region_errors

    regions = region_errors(image, ref, reference_halves=halves, exclude=mask)
    print("  by region (top row first): " + "; ".join(
        " ".join(f"x{g['mean_ratio']:.3f} {100 * g['share']:.0f}%" for g in regions[i:i + 3]) for i in (0, 3, 6)))
    d2 = np.sort(np.maximum(pixel_errors(image, ref, halves)[~mask], 0.0))[::-1]
    share = np.cumsum(d2) / max(d2.sum(), 1e-300)
    print(f"  half of the squared error in {np.searchsorted(share, 0.5) + 1:,} pixels, four fifths in "
          f"{np.searchsorted(share, 0.8) + 1:,}, of {d2.size:,}", flush=True)


if __name__ == "__main__":
    main()
