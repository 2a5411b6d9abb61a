"""The pictures of the README and the manual, made from the code as it is (``make docs-images``).

Usage (the bpy module is in the project's venv; about 10 minutes on 2 cores)::

    python tools/docs_images.py --out docs/images [--seconds 60] [--room demo_scenes/interiors/living-room.blend]

1. ``readme-room.png``: a real room (``--room``, at its references' 320 x 180) in clay and in
   its own materials, rendered by raybundle with a Time Limit of ``--seconds`` and by Cycles
   for the same wall time, each timed from opening the file to the EXR written, each labelled
   with its relative RMSE against the committed Cycles references
   (``<room>-<clay|full>-<1|2>.exr`` in ``--references``; rendered there with
   ``--reference-samples`` when missing) by :func:`raybundle.app.metrics.image_error`.
   Cycles gets the time by its own Time Limit, less what opening the file and its first
   sample cost (measured by a one-sample render first).
2. ``manual-render-and-bake.png``: the demo Cornell box rendered by raybundle, beside the
   bake of ``cornell_bake.blend`` to a point-domain color attribute, shown by Blender's
   Workbench with flat lighting (the attribute's colors as they are).

Every panel goes through the same sRGB transfer (clipped, no tone map), as Blender's Standard
view shows it; the room's rows are each scaled by one exposure, the same for both engines.
"""
from __future__ import annotations

import argparse
import os
import sys
import time

_TOOLS = os.path.dirname(os.path.abspath(__file__))
_ROOT = os.path.dirname(_TOOLS)
sys.path[:0] = [_TOOLS, _ROOT, os.path.join(_ROOT, "demo_scenes")]

from bench_blender import OPEN_SETTINGS, _open, light_mask, reference_halves, reference_paths, render  # noqa: E402

from raybundle.util.io import check_output, linear_to_srgb, read_exr  # noqa: E402


def cycles_for(blend, path, seconds, seed=7):
    """Cycles from opening ``blend`` to the EXR ``path`` in about ``seconds`` of wall time: its
    Time Limit is ``seconds`` less the wall time of a one-sample render (opening, scene
    sync, BVH).  Returns (image, wall seconds)."""
    import bpy
    from cycles_reference import cycles_settings, exr_output

    _, overhead = render(blend, path, "CYCLES", samples=1, seed=seed)
    t0 = time.perf_counter()
    _open(blend)
    cycles_settings(1 << 20, seed, world_strength=None)
    bpy.context.scene.cycles.time_limit = max(seconds - overhead, 0.1)
    exr_output(path)
    bpy.ops.render.render(write_still=True)
    return read_exr(path), time.perf_counter() - t0


def room_panels(a, work):
    """[(title, image, exposure)] for the room: raybundle and Cycles, in clay and in its own
    materials, each row under one exposure that brings the reference's median to 0.3."""
    import numpy as np

    from raybundle.app.metrics import image_error

    panels = []
    for clay in (True, False):
        halves = reference_halves(a.room, reference_paths(a.room, a.references, clay), a.reference_samples)
        OPEN_SETTINGS.update(clay=clay, resolution=halves[0].shape[1::-1])
        reference, mask = 0.5 * (halves[0] + halves[1]), light_mask(a.room)
        kind = "clay" if clay else "own materials"
        exposure = 0.3 / max(float(np.median(reference.mean(axis=2)[~mask])), 1e-9)
        ours, wall = render(a.room, os.path.join(work, f"raybundle-{kind}.exr"), "RAYBUNDLE", seconds=a.seconds,
                            seed=3)
        theirs, c_wall = cycles_for(a.room, os.path.join(work, f"cycles-{kind}.exr"), wall)
        for engine, img, w in (("raybundle", ours, wall), ("Cycles", theirs, c_wall)):
            e = image_error(img, reference, reference_halves=halves, exclude=mask)["error"]
            panels.append((f"{engine}, {kind}: {w:.0f} s, error {100 * e:.1f}%", img, exposure))
            print(panels[-1][0], flush=True)
    OPEN_SETTINGS.update(clay=False, resolution=None)
    return panels


def manual_panels(a, work):
    """[(title, image, exposure 1)]: the demo box rendered by raybundle, and its bake seen in Workbench."""
    import bpy
    from bench_bake import ensure_blend, raybundle_bake
    from cycles_reference import exr_output

    OPEN_SETTINGS.update(resolution=a.manual_resolution)
    img, wall = render(os.path.join(_ROOT, "demo_scenes", "cornell_box.blend"), os.path.join(work, "render.exr"),
                       "RAYBUNDLE", seconds=a.manual_seconds, seed=3)
    raybundle_bake(ensure_blend(), a.manual_seconds, seed=3)
    scene = bpy.context.scene
    if a.manual_resolution:
        scene.render.resolution_x, scene.render.resolution_y = a.manual_resolution
        scene.render.resolution_percentage = 100
    scene.render.engine = "BLENDER_WORKBENCH"
    scene.display.shading.light = "FLAT"
    scene.display.shading.color_type = "VERTEX"
    scene.view_settings.view_transform = "Standard"
    path = os.path.join(work, "bake.exr")
    exr_output(path)
    bpy.ops.render.render(write_still=True)
    OPEN_SETTINGS.update(resolution=None)
    return [(f"render, {wall:.0f} s", img, 1.0),
            ("bake to a color attribute (Workbench, flat)", read_exr(path)[..., :3], 1.0)]


def compose(path, panels, columns, title):
    """The ``panels`` [(title, linear image, exposure)] on a grid of ``columns``, sRGB, written to ``path``."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = (len(panels) + columns - 1) // columns
    h, w = panels[0][1].shape[:2]
    fig, axes = plt.subplots(rows, columns, figsize=(4.2 * columns, 4.2 * rows * h / w + 0.5), squeeze=False)
    for ax, (label, img, exposure) in zip(axes.flat, panels):
        ax.imshow(linear_to_srgb(exposure * img[..., :3]), interpolation="nearest")
        ax.set_title(label, fontsize=9)
        ax.axis("off")
    fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    tmp = path + ".tmp.png"
    fig.savefig(tmp, dpi=110)
    os.replace(tmp, path)


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--out", default="docs/images")
    p.add_argument("--seconds", type=float, default=60.0, help="raybundle's Time Limit for the room")
    p.add_argument("--room", default=os.path.join(_ROOT, "demo_scenes", "interiors", "living-room.blend"))
    p.add_argument("--references", default=os.path.join(_ROOT, "demo_scenes", "interiors", "references"))
    p.add_argument("--reference-samples", type=int, default=1024, help="samples per half of a missing reference")
    p.add_argument("--manual-seconds", type=float, default=10.0)
    p.add_argument("--manual-resolution", type=int, nargs=2, metavar=("W", "H"))
    a = p.parse_args(argv)
    check_output(a.out, "--out", folder=True)
    work = os.path.join(a.out, ".work")
    os.makedirs(work, exist_ok=True)
    import raybundle_addon

    raybundle_addon.register()
    room = os.path.splitext(os.path.basename(a.room))[0]
    compose(os.path.join(a.out, "readme-room.png"), room_panels(a, work), 2,
            f"{room} on 2 cores, each engine timed from opening the file to the image written;\n"
            "error: relative RMSE against a long Cycles render; each row under one exposure")
    compose(os.path.join(a.out, "manual-render-and-bake.png"), manual_panels(a, work), 2,
            "The demo Cornell box: a render, and a bake to a color attribute")
    for name in os.listdir(work):
        os.remove(os.path.join(work, name))
    os.rmdir(work)
    print(f"wrote {a.out}/readme-room.png and {a.out}/manual-render-and-bake.png")
    return 0


if __name__ == "__main__":
    sys.exit(main())
