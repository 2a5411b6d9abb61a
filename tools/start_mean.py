#!/usr/bin/env python3
"""The image mean of short runs against the reference: the start-up bias of the running average.

    python tools/start_mean.py demo_scenes/interiors/living-room.blend [more.blend ...] --clay \
        --resolution 320 180 --references demo_scenes/interiors/references --iterations 8 32 --seeds 1 2 3 4 \
        [--seconds 10 60]

Each file is opened and exported once (as the bench opens it: :mod:`bench_blender`'s ``--clay`` and
``--resolution``), then rendered by the core with the file's settings at each number of iterations
and seed; each image's mean over the compared pixels (``raybundle.app.metrics.image_error``: 2 px
from directly seen lights left out) is divided by the reference's, the mean of the two committed
Cycles halves. With ``--seconds``, also runs of each Time Limit, counted from the export's start as
the add-on counts it. Prints one row per file and iteration count or Time Limit: the mean ratio
averaged over the seeds, its spread, and the error.
"""
from __future__ import annotations

import argparse
import dataclasses
import os
import sys
import time

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

import bench_blender  # noqa: E402


def exported(blend):
    """``(scene, run options, light mask)`` of ``blend`` opened as the bench opens it."""
    import bpy

    from raybundle.app.metrics import light_source_mask
    from raybundle_addon import register
    from raybundle_addon.properties import run_options
    from raybundle_addon.translation.export import export_scene

    if not hasattr(bpy.types.Scene, "raybundle"):
        register()
    bench_blender._open(blend)
    ex = export_scene(bpy.context.evaluated_depsgraph_get())
    return ex.scene, run_options(bpy.context.scene), light_source_mask(ex.scene, ex.scene.camera), ex.seconds


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("blends", nargs="+")
    p.add_argument("--clay", action="store_true")
    p.add_argument("--resolution", nargs=2, type=int, metavar=("W", "H"))
    p.add_argument("--references", required=True, help="folder of <file>-<clay|full>-<1|2>.exr")
    p.add_argument("--iterations", nargs="*", type=int, default=[8, 32])
    p.add_argument("--seeds", nargs="+", type=int, default=[1, 2, 3, 4])
    p.add_argument("--seconds", nargs="*", type=float, default=[], help="Time Limits (the export's time included)")
    a = p.parse_args(argv)
    bench_blender.OPEN_SETTINGS.update(clay=a.clay, resolution=a.resolution)
    from raybundle.app.metrics import image_error
    from raybundle.app.pipeline import run_plan
    from raybundle.app.plan import plan
    from raybundle.util.io import read_exr

    print("| file | iterations or Time Limit | mean / reference (mean of seeds) | spread (sd) | error "
          "| seconds a run |", flush=True)
    print("|---|---|---|---|---|---|")
    for blend in a.blends:
        paths = bench_blender.reference_paths(blend, a.references, a.clay)
        halves = [read_exr(path) for path in paths]
        reference = 0.5 * (halves[0] + halves[1])
        scene, options, mask, export_seconds = exported(blend)
        for its, limit in [(n, None) for n in a.iterations] + [(None, t) for t in a.seconds]:
            ratios, errors, seconds = [], [], []
            for seed in a.seeds:
                t0 = time.perf_counter()
                o = dataclasses.replace(options, iterations=its, time_limit=limit, seed=seed)
                _, result = run_plan(scene, plan(scene, o), started=t0 - export_seconds)
                got = image_error(result.image, reference, halves, mask)
                ratios.append(got["mean_ratio"])
                errors.append(got["error"])
                seconds.append(time.perf_counter() - t0)
            what = its if limit is None else f"{limit:g} s"
            spread = np.std(ratios, ddof=1) if len(ratios) > 1 else 0.0
            print(f"| {os.path.basename(blend)} | {what} | {np.mean(ratios):.3f} | {spread:.3f} "
                  f"| {100 * np.mean(errors):.1f}% | {np.mean(seconds):.1f} |", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
