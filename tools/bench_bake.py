"""Bake bench: raybundle's point-domain bake against Cycles' bake to a color attribute
of the same vertices, side by side in one run; the time of a 1024² lightmap; and a 256²
lightmap against Cycles' bake of it.

Usage (the bpy module is in the project's venv; on ``cornell_bake.blend`` ~60 minutes on 2 cores
the first time, ~25 once its references come from the cache)::

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
5. With ``--lightmap-error-size`` S (the bench file's default 256, 0 for none): the floor's S²
   lightmap against Cycles' bake of it (two halves of ``--lightmap-reference-samples``, cached as
   ``reference-lightmap-<file>-<S>-<samples>.npz``), raybundle after each of ``--times`` and Cycles
   with 4, 16, 64, ... samples, each timed from opening the file to the lightmap written; the error
   over the texels at least 2 texels from a seam (an island's edge).  Cycles' bake averages a
   texel's footprint, raybundle's takes its centre: the texels whose footprint reaches under a
   block differ by that.

Writes ``bake-<file>.csv``, ``summary-<file>.json`` and ``bake-<file>.png`` (and ``lightmap-<file>.png``) into
``--out`` and prints, for
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


def floor_lightmap(size):
    """(size, size, 3) the open file's ``floor.lightmap`` Image, rows bottom-up."""
    import bpy

    px = np.empty(size * size * 4, np.float32)
    bpy.data.images["floor.lightmap"].pixels.foreach_get(px)
    return px.reshape(size, size, 4)[..., :3].astype(float)


def cycles_lightmap(blend, size, samples, seed):
    """Open ``blend``, bake the floor's lightmap with Cycles; ((size, size, 3), wall s, kept (size, size) bool:
    the texels at least 2 from a seam)."""
    import bpy
    from cycles_reference import bake_image, cycles_settings

    from raybundle.app.metrics import dilate
    from raybundle.imaging.lightmap import texel_points

    t0 = time.perf_counter()
    _open(blend)
    cycles_settings(samples, seed, world_strength=None)
    floor = bpy.data.objects["floor"]
    img = bake_image(floor, size)
    wall = time.perf_counter() - t0
    me = floor.data
    me.calc_loop_triangles()
    loops = np.empty(3 * len(me.loop_triangles), np.int64)
    me.loop_triangles.foreach_get("loops", loops)
    uv = np.empty(2 * len(me.loops))
    me.uv_layers.active.data.foreach_get("uv", uv)
    covered = np.zeros(size * size, bool)
    covered[texel_points(uv.reshape(-1, 2)[loops].reshape(-1, 3, 2), size, size).texel] = True
    return img.astype(float), wall, ~dilate(~covered.reshape(size, size), 2)


def lightmap_errors(blend, a, out_rows):
    """Item 5 of the module docstring: rows of (engine, setting, seconds, error) into ``out_rows``;
    the text for the page."""
    from raybundle.app.metrics import image_error

    size, n = a.lightmap_error_size, a.lightmap_reference_samples
    cache = os.path.join(a.out, f"reference-lightmap-{_stem(blend)}-{size}-{n}.npz")
    if not os.path.exists(cache):
        halves = []
        for seed in (1, 2):
            print(f"Cycles reference lightmap, half {seed}: {size}², {n} samples ...", flush=True)
            img, wall, kept = cycles_lightmap(blend, size, n, seed)
            print(f"  {wall:.0f} s", flush=True)
            halves.append(img)
        np.savez(cache, a=halves[0], b=halves[1], kept=kept)
    ref = np.load(cache)
    halves, exclude = [ref["a"], ref["b"]], ~ref["kept"]
    reference = 0.5 * (halves[0] + halves[1])

    def error(img):
        return image_error(img, reference, reference_halves=halves, exclude=exclude)

    for t in a.times:
        _, _, wall, out = raybundle_bake(blend, t, seed=3, lightmap_size=size,
                                         directory=os.path.abspath(os.path.join(a.out, "lightmaps")))
        e = error(floor_lightmap(size))
        out_rows.append(dict(engine="raybundle", setting=t, seconds=wall, error=e["error"], raw=e["raw"],
                             iterations=out.stats["iterations"], mean=e["mean_ratio"]))
        print(f"raybundle lightmap {size}², {t:g} s: {wall:.1f} s wall, error {e['error']:.4f}, mean "
              f"x{e['mean_ratio']:.4f}, {out.stats['iterations']} iterations", flush=True)
    samples = 4
    while True:
        img, wall, _ = cycles_lightmap(blend, size, samples, seed=7)
        e = error(img)
        out_rows.append(dict(engine="cycles", setting=samples, seconds=wall, error=e["error"], raw=e["raw"],
                             iterations=samples, mean=e["mean_ratio"]))
        print(f"cycles lightmap {size}², {samples} spp: {wall:.1f} s wall, error {e['error']:.4f}", flush=True)
        if (e["error"] < min(r["error"] for r in out_rows if r["engine"] == "raybundle")
                or wall > a.max_cycles_seconds):
            break
        samples *= 4
    lines = ["| raybundle Time Limit | seconds | iterations | error | mean |", "|---|---|---|---|---|"]
    lines += [f"| {r['setting']:g} s | {r['seconds']:.1f} | {r['iterations']} | {100 * r['error']:.2f}% | "
              f"×{r['mean']:.4f} |" for r in out_rows if r["engine"] == "raybundle"]
    return (f"\n\nThe floor's {size}² lightmap against Cycles' bake of it (2 × {n} samples, its noise "
            "subtracted), over the texels at least 2 from a seam, each timed from opening the file to the "
            "lightmap written:\n\n" + "\n".join(lines) + "\n")


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
    p.add_argument("--lightmap-error-size", type=int, default=None,
                   help="the lightmap compared with Cycles' (default 256 on cornell_bake.blend, else 0: none)")
    p.add_argument("--lightmap-reference-samples", type=int, default=4096)
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
                        lightmap_seconds=out.stats["lightmap_seconds"])
        lightmap_text = (f"\nA {a.lightmap_size}² lightmap of the floor after a {a.lightmap_seconds:g} s solve: "
                         f"{wall:.1f} s from opening the file, of which {out.stats['lightmap_seconds']:.1f} s for the "
                         "lightmap itself.")
        print(lightmap_text.strip())
    lightmap_rows = []
    if a.lightmap_error_size is None:
        a.lightmap_error_size = 256 if _stem(blend) == "cornell_bake" else 0
    if a.lightmap_error_size:
        lightmap_text += lightmap_errors(blend, a, lightmap_rows)
        lm_summary = side_by_side(lightmap_rows)
        lm_targets = time_to_errors(lightmap_rows, goals=(0.05, 0.02, 0.01))
        lightmap_text += "\n" + comparison_tables(lightmap_rows, lm_summary, lm_targets)
        lm_png = os.path.join(a.out, f"lightmap-{_stem(blend)}.png")
        chart(lm_png, lightmap_rows, f"{_stem(blend)}: the floor's {a.lightmap_error_size}² lightmap",
              ylabel="relative RMSE over the texels against a long Cycles bake",
              xlabel="seconds from loading the .blend to the lightmap written (2 cores)", all_pixels=False)
    with open(os.path.join(a.out, f"bake-{_stem(blend)}.csv"), "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    with open(os.path.join(a.out, f"summary-{_stem(blend)}.json"), "w") as f:
        json.dump(dict(blend=blend, reference_samples_per_half=a.reference_samples, rows=rows, summary=summary,
                       time_to_error=targets, lightmap=lightmap, raybundle=own, lightmap_rows=lightmap_rows), f,
                  indent=1)
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
                      [png] + ([lm_png] if lightmap_rows else []), command=command_line("tools/bench_bake.py", argv))
        print(f"wrote its section of {a.page}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
