"""Bake bench: raybundle's point-domain bake against Cycles' bake to a color attribute
of the same vertices, side by side in one run; and the time of a 1024² lightmap.

Usage (the bpy module is in the project's venv; ~25 minutes on 2 cores the first
time, the reference then comes from the cache)::

    python tools/bench_bake.py --out out/bench-bake [--times 5 10 20] [--reference-samples 4096]

The scene (``--blend``, built by ``make_demo_scenes.py`` when missing) is
``demo_scenes/cornell_bake.blend``, the Cornell box with each of its 16 faces cut 16 x 16 into
its own 17 x 17 vertices, 4,624 in all; or ``demo_scenes/cornell_subdivided.blend``, the box
with every mesh subdivided in Edit Mode (15 cuts), 4,360 vertices, those along the blocks'
creases shared by faces of different normals.

1. A long Cycles bake (``bpy.ops.object.bake(type='COMBINED', target='VERTEX_COLORS')``,
   CPU, no denoising or clamping) to a POINT ``FLOAT_COLOR`` attribute of every mesh:
   two independent halves of ``--reference-samples`` each (seeds 1, 2), cached in ``--out``
   (``reference-<file>-<samples>.npz``).
2. raybundle bakes (``raybundle_addon.bake.BakeJob``, point domain) with ``--times``
   seconds of iteration, and Cycles bakes with 4, 8, 16, ... samples until its error is
   below every raybundle error or a bake takes ``--max-cycles-seconds``.  Each is timed
   from opening the ``.blend`` to the attribute written.
3. The error of each: :func:`raybundle.app.metrics.image_error` over the vertices (as a
   one-column image), the lamp's vertices excluded, the reference's own noise
   (from its halves) subtracted.
4. A 1024² lightmap of the floor (its lightmap UV tile) after a ``--lightmap-seconds``
   solve: the time of the whole job and of the lightmap itself.

Writes ``bake-<file>.csv``, ``summary-<file>.json`` and ``bake-<file>.png`` into ``--out`` and prints, for
every raybundle time, Cycles' error at the same time and Cycles' time for the same
error (log-log interpolation between its runs).
"""
from __future__ import annotations

import argparse
import csv
import json
import os
import sys
import time

import numpy as np

_TOOLS = os.path.dirname(os.path.abspath(__file__))
_ROOT = os.path.dirname(_TOOLS)
sys.path[:0] = [_TOOLS, _ROOT, os.path.join(_ROOT, "demo_scenes")]

from bench_blender import _open, chart, comparison_tables, side_by_side, time_to_errors  # noqa: E402
from raybundle.app.bench_page import add_page_argument, checked_page, command_line, write_section  # noqa: E402

BLEND = os.path.join(_ROOT, "demo_scenes", "cornell_bake.blend")
#: the page's section of each file (its name without ``.blend``)
SECTIONS = {"cornell_bake": "bake", "cornell_subdivided": "bake-subdivided"}
CYCLES_ATTRIBUTE = "CyclesBake"
EMITTERS = ("light",)


def ensure_blend(path=BLEND):
    if not os.path.exists(path):
        import make_demo_scenes

        make_demo_scenes.main(["--out", os.path.dirname(path), "--only", _stem(path)])
    return path


def _stem(path):
    return os.path.splitext(os.path.basename(path))[0]


def meshes():
    import bpy

    return sorted((o for o in bpy.context.scene.objects if o.type == "MESH"), key=lambda o: o.name)


def read_attribute(name):
    """(V, 3) the attribute ``name`` of every mesh in name order, and (V,) bool emitter vertices."""
    vals, emit = [], []
    for ob in meshes():
        a = ob.data.color_attributes[name]
        rgba = np.empty(4 * len(a.data), np.float32)
        a.data.foreach_get("color", rgba)
        vals.append(rgba.reshape(-1, 4)[:, :3].astype(float))
        emit.append(np.full(len(a.data), ob.name in EMITTERS))
    return np.concatenate(vals), np.concatenate(emit)


def cycles_bake(blend, samples, seed):
    """Open ``blend``, bake every mesh with Cycles into a POINT attribute; (values, emitters, wall s)."""
    import bpy
    from cycles_reference import cycles_settings

    t0 = time.perf_counter()
    _open(blend)
    cycles_settings(samples, seed, world_strength=None)
    for ob in meshes():
        a = ob.data.color_attributes.new(CYCLES_ATTRIBUTE, "FLOAT_COLOR", "POINT")
        ob.data.color_attributes.active_color = a
        ob.select_set(True)
        bpy.context.view_layer.objects.active = ob
    bpy.ops.object.bake(type="COMBINED", target="VERTEX_COLORS")
    wall = time.perf_counter() - t0
    return (*read_attribute(CYCLES_ATTRIBUTE), wall)


def raybundle_bake(blend, seconds, seed, lightmap_size=None, directory=None):
    """Open ``blend``, bake with raybundle (point domain; with ``lightmap_size``, only the
    floor's lightmap); (values or None, emitters, wall s, BakeOutcome)."""
    import bpy

    from raybundle_addon.bake import BakeJob

    t0 = time.perf_counter()
    scene = _open(blend)
    rb = scene.raybundle
    rb.time_limit, rb.iterations, rb.seed = float(seconds), 0, seed
    rb.bake_domain = "POINT"
    rb.bake_color_attribute = lightmap_size is None
    rb.bake_lightmaps = lightmap_size is not None
    if lightmap_size:
        rb.lightmap_size, rb.bake_directory = lightmap_size, directory
    out = BakeJob(bpy.context.evaluated_depsgraph_get(), lightmap_objects=["floor"]).run()
    wall = time.perf_counter() - t0
    if lightmap_size:
        return None, None, wall, out
    return (*read_attribute("RayBundle"), wall, out)


def own_table(own):
    """raybundle's bakes, a row each: the Time Limit, the wall seconds, iterations, the gather's
    rays per point, the error and the mean against the reference's (Markdown)."""
    lines = ["| raybundle Time Limit | seconds | iterations | gather rays a point | error | mean |",
             "|---|---|---|---|---|---|"]
    lines += [f"| {r['limit']:g} s | {r['seconds']:.1f} | {r['iterations']} | {r['gather_rays']:,} | "
              f"{100 * r['error']:.2f}% | ×{r['mean']:.4f} |" for r in own]
    return "\n".join(lines) + "\n"


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--out", default="out/bench-bake")
    p.add_argument("--blend", default=BLEND, help="the file to bake (default: demo_scenes/cornell_bake.blend; "
                   "demo_scenes/cornell_subdivided.blend: the harder one)")
    p.add_argument("--times", type=float, nargs="+", default=[5.0, 10.0, 20.0])
    p.add_argument("--reference-samples", type=int, default=4096)
    p.add_argument("--max-cycles-seconds", type=float, default=400.0)
    p.add_argument("--lightmap-size", type=int, default=1024, help="0: no lightmap (a file without UV maps)")
    p.add_argument("--lightmap-seconds", type=float, default=5.0)
    p.add_argument("--reference-only", action="store_true", help="make the cached reference and stop")
    add_page_argument(p, "bake")
    a = p.parse_args(argv)
    checked_page(a.page, "bench_bake")
    from raybundle.app.metrics import image_error

    os.makedirs(a.out, exist_ok=True)
    blend = ensure_blend(os.path.abspath(a.blend))
    cache = os.path.join(a.out, f"reference-{_stem(blend)}-{a.reference_samples}.npz")
    if not os.path.exists(cache):
        halves = []
        for seed in (1, 2):
            print(f"Cycles reference bake, half {seed}: {a.reference_samples} samples ...", flush=True)
            v, emit, wall = cycles_bake(blend, a.reference_samples, seed)
            print(f"  {wall:.0f} s", flush=True)
            halves.append(v)
        np.savez(cache, a=halves[0], b=halves[1], emitters=emit)
    if a.reference_only:
        return 0
    ref = np.load(cache)
    halves = [ref["a"][:, None, :], ref["b"][:, None, :]]
    reference = 0.5 * (halves[0] + halves[1])
    exclude = ref["emitters"][:, None]

    def error(values):
        return image_error(values[:, None, :], reference, reference_halves=halves, exclude=exclude)

    lit = ~exclude[:, 0]

    def mean(values):
        return float(values[lit].mean() / reference[lit, 0].mean())

    rows, own = [], []
    for t in a.times:
        v, _, wall, out = raybundle_bake(blend, t, seed=3)
        e = error(v)
        rows.append(dict(engine="raybundle", setting=t, seconds=wall, error=e["error"], raw=e["raw"],
                         iterations=out.stats["iterations"]))
        own.append(dict(limit=t, seconds=wall, iterations=out.stats["iterations"],
                        gather_rays=out.stats.get("gather_rays", 0), error=e["error"], mean=mean(v)))
        print(f"raybundle {t:g} s: {wall:.1f} s wall, error {e['error']:.4f} (raw {e['raw']:.4f}, "
              f"reference noise {e['reference_noise']:.4f}), mean x{mean(v):.4f}, {out.stats['iterations']} "
              f"iterations, {own[-1]['gather_rays']} gather rays a point", flush=True)
    samples = 4
    while True:
        v, _, wall = cycles_bake(blend, samples, seed=7)
        e = error(v)
        rows.append(dict(engine="cycles", setting=samples, seconds=wall, error=e["error"], raw=e["raw"],
                         iterations=samples))
        print(f"cycles {samples} spp: {wall:.1f} s wall, error {e['error']:.4f}", flush=True)
        if e["error"] < min(r["error"] for r in rows if r["engine"] == "raybundle") or wall > a.max_cycles_seconds:
            break
        samples *= 2
    summary = side_by_side(rows)
    targets = time_to_errors(rows, goals=(0.05, 0.02, 0.015, 0.01))
    lightmap, lightmap_text = None, ""
    if a.lightmap_size:
        _, _, wall, out = raybundle_bake(blend, a.lightmap_seconds, seed=3, lightmap_size=a.lightmap_size,
                                         directory=os.path.abspath(os.path.join(a.out, "lightmaps")))
        lightmap = dict(size=a.lightmap_size, solve_seconds=a.lightmap_seconds, wall_seconds=wall,
                        lightmap_seconds=out.stats["bake_seconds"])
        lightmap_text = (f"\nA {a.lightmap_size}² lightmap of the floor after a {a.lightmap_seconds:g} s solve: "
                         f"{wall:.1f} s from opening the file, of which {out.stats['bake_seconds']:.1f} s for the "
                         "lightmap itself.")
        print(lightmap_text.strip())
    with open(os.path.join(a.out, f"bake-{_stem(blend)}.csv"), "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    with open(os.path.join(a.out, f"summary-{_stem(blend)}.json"), "w") as f:
        json.dump(dict(blend=blend, reference_samples_per_half=a.reference_samples, rows=rows, summary=summary,
                       time_to_error=targets, lightmap=lightmap, raybundle=own), f, indent=1)
    png = os.path.join(a.out, f"bake-{_stem(blend)}.png")
    chart(png, rows, f"{_stem(blend)}, {len(reference):,} vertices: point-domain bake",
          ylabel="relative RMSE over the vertices against a long Cycles bake",
          xlabel="seconds from loading the .blend to the attribute written (2 cores)", all_pixels=False)
    print(f"wrote {png} and its .csv and summary")
    if a.page:
        title = ("Bakes: color attributes and a lightmap against Cycles' bake" if _stem(blend) == "cornell_bake" else
                 f"Bakes: {_stem(blend)}.blend's color attributes against Cycles' bake")
        write_section(a.page, a.section or SECTIONS.get(_stem(blend), _stem(blend)), title,
                      f"`{os.path.relpath(blend)}`, {len(reference):,} vertices baked to a point-domain color "
                      "attribute, each bake timed from opening the file to the attribute written. Reference: "
                      f"Cycles' bake of the same vertices, 2 × {a.reference_samples} samples, its own noise "
                      "subtracted; the lamp's vertices left out. Error: relative RMSE over the vertices; "
                      "mean: raybundle's over the reference's.\n\n"
                      + own_table(own) + "\n" + comparison_tables(rows, summary, targets) + lightmap_text,
                      [png], command=command_line("tools/bench_bake.py", argv))
        print(f"wrote its section of {a.page}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
