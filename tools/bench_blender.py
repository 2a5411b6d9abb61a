"""Blender bench: raybundle against Cycles on the same scene, side by side in one run.

Usage (the bpy module is in the project's venv; about 15 minutes on 2 cores)::

    python tools/bench_blender.py demo_scenes/cornell_box.blend --out out/bench-blender
    python tools/bench_blender.py cornell --times 5 10 30 60 --out out/bench-cornell
    python tools/bench_blender.py demo_scenes/interiors/living-room.blend --clay --resolution 320 180 \
        --references demo_scenes/interiors/references --reference-samples 4096 --times 60 300 --out out/x

The scene is a ``.blend`` (rendered by the RAYBUNDLE engine and by Cycles, each
opening the file) or a built-in scene of the core (``cornell``, ``cornell-glossy``:
the core renders it from ``load_scene`` to the EXR written; Cycles renders the same
triangles, built in ``bpy`` by ``tools/cycles_reference.py``).

1. A long Cycles reference (CPU, no denoising or clamping, box filter one pixel,
   Standard view): two independent halves with ``--reference-samples`` each
   (seeds 1 and 2), kept in ``--out`` (or ``--references``: committed ones, named
   ``<file>-<clay|full>-<seed>.exr``) and reused.
   ``--clay`` renders with the view layer's Material Override set to a white diffuse
   material (albedo 0.8) in every engine; ``--resolution W H`` overrides the file's.
2. RAYBUNDLE renders with ``--times`` seconds of iteration, and Cycles renders
   with 1, 2, 4, ... samples until its error is below every RAYBUNDLE error and a render
   has taken as long as the longest RAYBUNDLE run (or a render takes 8 times the longest
   RAYBUNDLE run, at most ``--max-cycles-seconds``).  Every render is timed from opening the ``.blend`` to the EXR written.
3. The error of each, :func:`raybundle.app.metrics.image_error` (RMSE / mean of the
   reference over pixels at least 2 px from a directly seen light, with the
   reference's own noise from its halves subtracted), and over all pixels; for
   RAYBUNDLE also the set-up's seconds (export, world, patches, first shot) and the
   warnings of its run.

Writes ``bench.csv``, ``summary.json`` and ``bench.png`` (error against seconds,
log-log) into ``--out`` and prints, for every RAYBUNDLE time, Cycles' error at the
same time and the time Cycles needs for RAYBUNDLE's error (log-log
interpolation between the Cycles runs), and the time each engine needs to reach
5%, 2%, 1.5% and 1% (interpolated the same way; "> T" when its last run is above).
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
sys.path[:0] = [_TOOLS, os.path.dirname(_TOOLS)]          # cycles_reference; raybundle_addon

from raybundle.app.bench_page import add_page_argument, checked_page, command_line, table, write_section  # noqa: E402


#: what every render of a run does right after opening the file: ``clay`` (the Material
#: Override) and ``resolution`` (W, H or None), set by ``main``
OPEN_SETTINGS = {"clay": False, "resolution": None, "components": False}


def _open(path):
    import bpy

    import raybundle_addon
    from raybundle_addon.translation import bake_cache

    if not hasattr(bpy.types.Scene, "raybundle"):
        raybundle_addon.register()
    bake_cache.KEEP = False             # timed as a session's first run: Blender's world and graph bakes included
    bpy.ops.wm.open_mainfile(filepath=os.path.abspath(path))
    scene = bpy.context.scene
    if OPEN_SETTINGS["resolution"]:
        r = scene.render
        r.resolution_x, r.resolution_y = OPEN_SETTINGS["resolution"]
        r.resolution_percentage = 100
    if OPEN_SETTINGS["clay"]:
        bpy.context.view_layer.material_override = clay_material()
    return scene


def _passes(engine):
    """With ``OPEN_SETTINGS["components"]``, the opened file's view layer writes the passes
    of the error's breakdown (:mod:`breakdown`) into a multilayer EXR."""
    import bpy
    from breakdown import enable_passes, multilayer_output

    if OPEN_SETTINGS["components"]:
        enable_passes(bpy.context.view_layer, engine)
        multilayer_output(bpy.context.scene)


def clay_material():
    """A white diffuse material (Diffuse BSDF, albedo 0.8): the clay of an architectural render."""
    import bpy
    from cycles_reference import new_with_nodes

    mat = new_with_nodes(bpy.data.materials, "raybundle bench clay")
    nt = mat.node_tree
    nt.nodes.clear()
    out, dif = nt.nodes.new("ShaderNodeOutputMaterial"), nt.nodes.new("ShaderNodeBsdfDiffuse")
    dif.inputs["Color"].default_value = (0.8, 0.8, 0.8, 1.0)
    nt.links.new(dif.outputs["BSDF"], out.inputs["Surface"])
    return mat


def peak_memory_gb():
    """This process's peak resident memory [GB] (every render of the run is in it)."""
    import resource

    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1e6


def is_blend(scene):
    return scene.endswith(".blend")


def render(blend, path, engine, seconds=None, samples=None, seed=0, patches=None):
    """Open ``blend`` (or build the built-in scene), render with ``engine`` to the EXR
    ``path``; returns (image, wall seconds)."""
    import bpy
    from cycles_reference import cycles_settings, exr_output, render_scene

    from raybundle.scene.builtin import load_scene
    from raybundle.util.io import read_exr, write_exr

    t0 = time.perf_counter()
    if not is_blend(blend):
        if engine == "CYCLES":
            img = render_scene(load_scene(blend), samples, path, seed)
        else:
            from raybundle.app.pipeline import make_renderer, prepare
            from raybundle.imaging.settings import RenderSettings
            from raybundle.patches.clusters import DEFAULT_PATCHES

            r = make_renderer(prepare(load_scene(blend), patches or DEFAULT_PATCHES), RenderSettings(seed=seed))
            img = r.run(time_limit=seconds).image
            r.tracer.close()
            write_exr(path, img)
        return img, time.perf_counter() - t0
    scene = _open(blend)
    if engine == "CYCLES":
        cycles_settings(samples, seed, world_strength=None)
    else:
        scene.render.engine = "RAYBUNDLE"
        rb = scene.raybundle
        rb.time_limit, rb.iterations, rb.seed = float(seconds), 0, seed
        if patches:
            rb.patches = patches
    exr_output(path)
    _passes(engine)
    bpy.ops.render.render(write_still=True)
    wall = time.perf_counter() - t0
    if engine != "CYCLES":
        from raybundle_addon.engine import LAST_RUN

        run = LAST_RUN.get(scene.name, {})
        LAST_RUN_FIGURES.clear()
        stats = run.get("stats", {})
        LAST_RUN_FIGURES.update(setup_seconds=stats.get("setup_seconds"), warnings=run.get("warnings", []),
                                run=" ".join(f"{k} {stats[k]}" for k in RUN_FIGURES if k in stats),
                                **{k: stats.get(k) for k in ("part_seconds", "phases", "world_samples",
                                                             "first_shot_lights", "iterations", "image_passes")})
    return read_exr(path), wall


#: the set-up seconds and warnings of the last RAYBUNDLE render of a .blend, and what its run did
LAST_RUN_FIGURES: dict = {}
#: the run's figures the bench prints beside its error
RUN_FIGURES = ("export_seconds", "prepare_seconds", "patches", "iterations", "image_passes", "gather_rays_per_pixel",
               "first_shot_lights", "world_samples")


def light_mask(blend, info=None):
    """Pixels within 2 px of a directly seen light, from the exported (or built-in) scene;
    ``info`` (a dict), if given, is told ``world_emits`` and, for a ``.blend``, ``overlaps``: the
    pixels that see two objects' faces overlapping in one plane
    (:func:`raybundle.app.metrics.overlap_mask`)."""
    import bpy

    from raybundle.app.metrics import light_source_mask, overlap_mask
    from raybundle.scene.builtin import load_scene
    from raybundle_addon.translation.export import export_scene

    scene = load_scene(blend) if not is_blend(blend) else None
    if scene is None:
        _open(blend)
        exported = export_scene(bpy.context.evaluated_depsgraph_get())
        scene = exported.scene
        if info is not None:
            info["overlaps"] = overlap_mask(scene, exported.triangle_object[scene.triangle_source])
    if info is not None:
        info["world_emits"] = bool(scene.world.emits)
    return light_source_mask(scene, scene.camera)


def reference_paths(blend, folder, clay):
    """The two Cycles halves of ``blend`` (clay or its own materials) kept in ``folder``:
    ``<file>-<clay|full>-<1|2>.exr``."""
    stem = os.path.splitext(os.path.basename(blend))[0]
    return [os.path.join(folder, f"{stem}-{'clay' if clay else 'full'}-{seed}.exr") for seed in (1, 2)]


def reference_halves(blend, paths, samples):
    """The Cycles halves at ``paths`` (seeds 1 and 2), each rendered with ``samples`` where
    missing (with the current :data:`OPEN_SETTINGS`)."""
    from raybundle.util.io import read_exr

    for seed, path in enumerate(paths, 1):
        if not os.path.exists(path):
            print(f"Cycles reference half {seed} ({path}): {samples} samples ...", flush=True)
            os.makedirs(os.path.dirname(os.path.abspath(path)), exist_ok=True)
            render(blend, path, "CYCLES", samples=samples, seed=seed)
    return [read_exr(path) for path in paths]


def loglog_at(xs, ys, x):
    """y at x by linear interpolation in log-log over the sorted points (None outside)."""
    xs, ys = np.log(np.asarray(xs, float)), np.log(np.maximum(np.asarray(ys, float), 1e-12))
    lx = np.log(x)
    if lx < xs.min() or lx > xs.max():
        return None
    o = np.argsort(xs)
    return float(np.exp(np.interp(lx, xs[o], ys[o])))


def side_by_side(rows):
    """For every raybundle run (rows with ``engine``, ``seconds``, ``error``): Cycles' error
    at the same time and Cycles' time for the same error, by log-log interpolation between
    the Cycles runs (Cycles' error is monotone in time up to noise); printed, and returned
    as a list of dicts."""
    cyc = [r for r in rows if r["engine"] == "cycles"]
    summary = []
    for r in (r for r in rows if r["engine"] == "raybundle"):
        c_err = loglog_at([c["seconds"] for c in cyc], [c["error"] for c in cyc], r["seconds"])
        c_time = loglog_at([c["error"] for c in cyc][::-1], [c["seconds"] for c in cyc][::-1], r["error"])
        d = dict(raybundle_seconds=r["seconds"], raybundle_error=r["error"], cycles_error_same_time=c_err,
                 cycles_seconds_same_error=c_time)
        if "error_all_pixels" in r:
            d["raybundle_error_all_pixels"] = r["error_all_pixels"]
        off = ""
        if r.get("error_off_overlaps") is not None:
            c_off = loglog_at([c["seconds"] for c in cyc], [c["error_off_overlaps"] for c in cyc], r["seconds"])
            d.update(raybundle_error_off_overlaps=r["error_off_overlaps"], cycles_error_off_overlaps_same_time=c_off)
            off = (f"; off the overlaps raybundle {r['error_off_overlaps']:.4f}, Cycles "
                   f"{'n/a' if c_off is None else f'{c_off:.4f}'}")
        summary.append(d)
        print(f"at {r['seconds']:.1f} s: raybundle {r['error']:.4f}, Cycles "
              f"{'n/a' if c_err is None else f'{c_err:.4f}'}; Cycles reaches {r['error']:.4f} in "
              f"{'n/a' if c_time is None else f'{c_time:.1f} s'}{off}")
    return summary


def time_to_errors(rows, goals):
    """{engine: {"5%": "12.3 s", ...}}: when each engine's error curve (rows with ``engine``,
    ``seconds``, ``error``) first reaches each goal, by log-log interpolation between its
    runs; "<= t" when its first run is already below, "> T" when its last is still above.
    Printed as it goes."""
    targets = {}
    for engine in dict.fromkeys(r["engine"] for r in rows):
        runs = sorted((r["seconds"], r["error"]) for r in rows if r["engine"] == engine)
        t, e = zip(*runs)
        targets[engine] = {}
        for goal in goals:
            hit = next((k for k in range(len(e)) if e[k] <= goal), None)
            if hit is None:
                got = f"> {t[-1]:.0f} s"
            elif hit == 0:
                got = f"<= {t[0]:.1f} s"
            else:
                got = f"{loglog_at(e[hit - 1:hit + 1][::-1], t[hit - 1:hit + 1][::-1], goal):.1f} s"
            targets[engine][f"{100 * goal:g}%"] = got
        print(f"{engine} reaches " + ", ".join(f"{g} in {v}" for g, v in targets[engine].items()))
    return targets


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("blend", help="a .blend file or a built-in scene name (cornell, cornell-glossy)")
    p.add_argument("--out", default="out/bench-blender")
    p.add_argument("--times", type=float, nargs="+", default=[10.0, 30.0])
    p.add_argument("--reference-samples", type=int, default=1024)
    p.add_argument("--max-cycles-seconds", type=float, default=300.0,
                   help="stop the Cycles ladder after a render this long")
    p.add_argument("--patches", type=int, default=None, help="RAYBUNDLE target patch count (default: the file's)")
    p.add_argument("--clay", action="store_true", help="render with the view layer's Material Override set to a "
                   "white diffuse material (every engine)")
    p.add_argument("--resolution", type=int, nargs=2, metavar=("W", "H"), help="override the file's resolution")
    p.add_argument("--references", help="folder of committed reference halves <file>-<clay|full>-<seed>.exr "
                   "(rendered there when missing)")
    p.add_argument("--twin", action="store_true", help="render each RAYBUNDLE time again with another seed, and "
                   "split its error into bias and noise (raybundle.app.metrics.bias_and_noise)")
    p.add_argument("--breakdown", action="store_true", help="split the last RAYBUNDLE time's error by component "
                   "against Cycles' light passes (tools/breakdown.py), beside Cycles' at the same time")
    p.add_argument("--breakdown-samples", type=int, default=256,
                   help="samples of each half of the Cycles pass references (kept beside the references)")
    add_page_argument(p, "blender-<file>[-clay]")
    a = p.parse_args(argv)
    checked_page(a.page, "bench_blender")
    OPEN_SETTINGS.update(clay=a.clay, resolution=a.resolution)
    from raybundle.app.metrics import bias_and_noise, image_error, region_errors
    from raybundle.util.io import read_exr_header

    os.makedirs(a.out, exist_ok=True)
    stem = os.path.splitext(os.path.basename(a.blend))[0]
    section = a.section or f"blender-{stem}{'-clay' if a.clay else ''}"
    paths = (reference_paths(a.blend, a.references, a.clay) if a.references
             else [os.path.join(a.out, f"reference-{seed}.exr") for seed in (1, 2)])
    halves = reference_halves(a.blend, paths, a.reference_samples)
    # a committed half says its own samples (Cycles' header); the smaller of the two counts
    reference_samples = min(int(read_exr_header(path).get("cycles.ViewLayer.samples", a.reference_samples))
                  for path in paths)
    reference = 0.5 * (halves[0] + halves[1])
    info = {}
    mask = light_mask(a.blend, info)
    overlaps = info.get("overlaps", np.zeros_like(mask)) & ~mask
    if overlaps.any():
        print(f"{overlaps.sum()} pixels see two objects' faces overlapping in one plane (z-fighting)", flush=True)

    def row(engine, setting, img, wall):
        e = image_error(img, reference, reference_halves=halves, exclude=mask)
        full = image_error(img, reference, reference_halves=halves)
        off = image_error(img, reference, reference_halves=halves, exclude=mask | overlaps)["error"] \
            if overlaps.any() else None
        setup = LAST_RUN_FIGURES.get("setup_seconds") if engine == "raybundle" else None
        print(f"{engine} {setting:g}{' s' if engine == 'raybundle' else ' spp'}: {wall:.1f} s wall"
              f"{'' if setup is None else f' (set-up {setup:.1f} s)'}, "
              f"error {e['error']:.4f} (all pixels {full['error']:.4f}), mean ratio {e['mean_ratio']:.4f}, "
              f"p99.9 {e['p99_9']:.3f}" + ("" if off is None else f", off the overlaps {off:.4f}"), flush=True)
        if engine == "raybundle" and LAST_RUN_FIGURES.get("run"):
            print(f"  run: {LAST_RUN_FIGURES['run']}", flush=True)
        return dict(engine=engine, setting=setting, seconds=wall, error=e["error"], error_all_pixels=full["error"],
                    mean_ratio=e["mean_ratio"], p99_9=e["p99_9"], error_off_overlaps=off, setup_seconds=setup,
                    iterations=LAST_RUN_FIGURES.get("iterations") if engine == "raybundle" else None)

    noise = image_error(reference, reference, reference_halves=halves, exclude=mask)
    print(f"reference: noise {noise['reference_noise']:.4f} per pixel (relative RMSE), its own p99.9 "
          f"{noise['reference_p99_9']:.3f}", flush=True)
    rows = []
    for t in a.times:
        img, wall = render(a.blend, os.path.join(a.out, f"raybundle-{t:g}s.exr"), "RAYBUNDLE", seconds=t,
                           seed=3, patches=a.patches)
        rows.append(row("raybundle", t, img, wall))
        rows[-1]["regions"] = region_errors(img, reference, halves, mask)
        print("  by region (mean ratio, share of the squared error), top row first: " + "; ".join(
            " ".join(f"x{g['mean_ratio']:.2f} {100 * g['share']:.0f}%" for g in rows[-1]["regions"][i:i + 3])
            for i in (0, 3, 6)), flush=True)
        if a.twin:          # with --breakdown the twin keeps its parts apart (the headline run does not)
            OPEN_SETTINGS["components"] = a.breakdown and t == max(a.times)
            twin, _ = render(a.blend, os.path.join(a.out, f"raybundle-{t:g}s-twin.exr"), "RAYBUNDLE", seconds=t,
                             seed=4, patches=a.patches)
            OPEN_SETTINGS["components"] = False
            split = bias_and_noise(img, twin, reference, halves, mask)
            rows[-1].update(bias=split["bias"], noise=split["noise"])
            print(f"  split: bias {split['bias']:.4f}, noise {split['noise']:.4f}", flush=True)
    warnings = list(LAST_RUN_FIGURES.get("warnings", []))
    for w in warnings:
        print(f"raybundle warning: {w}")
    samples = 1
    while True:
        img, wall = render(a.blend, os.path.join(a.out, f"cycles-{samples}spp.exr"), "CYCLES", samples=samples,
                           seed=7)
        rows.append(row("cycles", samples, img, wall))
        e = rows[-1]["error"]
        ours = [r for r in rows if r["engine"] == "raybundle"]
        longest = max(r["seconds"] for r in ours)
        # on until Cycles is below every RAYBUNDLE error and has run as long as the longest
        # RAYBUNDLE render (its error at each RAYBUNDLE time is then interpolated, not missing)
        if (e < min(r["error"] for r in ours) and wall >= longest) or wall > min(8 * longest, a.max_cycles_seconds):
            break
        samples *= 2
    summary = side_by_side(rows)
    targets = time_to_errors(rows, goals=(0.05, 0.02, 0.015, 0.01))
    split = component_breakdown(a, rows, mask, info) if a.breakdown else None
    with open(os.path.join(a.out, "bench.csv"), "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=[k for k in rows[0] if k != "regions"], extrasaction="ignore")
        w.writeheader()
        w.writerows(rows)
    with open(os.path.join(a.out, "summary.json"), "w") as f:
        json.dump(dict(blend=a.blend, clay=a.clay, resolution=a.resolution, warnings=warnings,
                       peak_memory_gb=peak_memory_gb(), reference_samples_per_half=reference_samples,
                       reference_noise=noise["reference_noise"], reference_p99_9=noise["reference_p99_9"],
                       rows=rows, summary=summary,
                       time_to_error=targets, breakdown=split),
                  f, indent=1)
    chart(os.path.join(a.out, "bench.png"), rows, os.path.basename(a.blend) + (" (clay)" if a.clay else ""))
    print(f"peak memory of the run {peak_memory_gb():.2f} GB")
    print(f"wrote {a.out}/bench.csv, summary.json, bench.png")
    if a.page:
        title = os.path.basename(a.blend) + (" in clay" if a.clay else "") + ": raybundle against Cycles"
        write_section(a.page, section, title, page_body(a, reference, reference_samples, noise, rows, summary,
                                                          targets, warnings, split, overlaps),
                      [os.path.join(a.out, "bench.png")], command=command_line("tools/bench_blender.py", argv))
        print(f"wrote its section {section!r} of {a.page}")
    return 0


def component_breakdown(a, rows, mask, info):
    """The error by component (:mod:`breakdown`, :func:`raybundle.app.metrics.component_errors`)
    of a RAYBUNDLE run of the longest time with its Light Components (seed 5: the Light
    Components cost a second BRDF evaluation per light sample, which the headline runs do not
    pay; with ``--twin``, whose run of that time keeps them too, split into bias and noise),
    beside that of Cycles at the ladder's sample count nearest that time, rendered again with
    its light passes; against two halves of ``--breakdown-samples`` with Cycles' light
    passes, kept in ``--references`` (or ``--out``) as ``<file>-<clay|full>-passes-<seed>.exr``.
    Pixels next to lights and where glass or a mirror turned RAYBUNDLE's eye rays are left
    out.  Printed and returned as a dict, with the run's seconds per part and phase."""
    from breakdown import (COMPONENTS, cycles_components, glass_pixels, load_components, merged_diffuse,
                           raybundle_components, save_components)

    from raybundle.app.metrics import component_errors, image_error
    from raybundle.util.io import read_exr_passes

    stem = os.path.splitext(os.path.basename(a.blend))[0]
    folder = a.references or a.out
    OPEN_SETTINGS["components"] = True
    paths = [os.path.join(folder, f"{stem}-{'clay' if a.clay else 'full'}-passes-{seed}.exr") for seed in (1, 2)]
    for seed, path in enumerate(paths, 1):
        if not os.path.exists(path):           # kept as its components (breakdown.save_components)
            print(f"Cycles pass reference half {seed} ({path}): {a.breakdown_samples} samples ...", flush=True)
            full = os.path.join(a.out, f"cycles-passes-{seed}.exr")
            render(a.blend, full, "CYCLES", samples=a.breakdown_samples, seed=seed)
            save_components(path, cycles_components(read_exr_passes(full)))
    t = max(a.times)
    cyc = min((r for r in rows if r["engine"] == "cycles"), key=lambda r: abs(np.log(r["seconds"] / t)))
    cycles_path = os.path.join(a.out, f"cycles-{cyc['setting']:g}spp-passes.exr")
    render(a.blend, cycles_path, "CYCLES", samples=int(cyc["setting"]), seed=7)
    ours_path = os.path.join(a.out, f"raybundle-{t:g}s-parts.exr")
    _, wall = render(a.blend, ours_path, "RAYBUNDLE", seconds=t, seed=5, patches=a.patches)
    run = dict(LAST_RUN_FIGURES)
    OPEN_SETTINGS["components"] = False
    twin_path = os.path.join(a.out, f"raybundle-{t:g}s-twin.exr")
    ours_passes = read_exr_passes(ours_path)
    exclude = mask | glass_pixels(ours_passes)
    # where the patches carry the world's direct light beside lamps, the diffuse lobe is compared whole
    # only; elsewhere also whole, beside its split (light through a pane is direct to raybundle's
    # lamp samples, indirect to Cycles')
    whole = info.get("world_emits") and not run.get("world_samples") and run.get("first_shot_lights")
    # each set of parts sums to the image (the errors are relative to its mean): the split one, and
    # the diffuse lobe whole beside it
    forms = [merged_diffuse] if whole else [lambda c: c, merged_diffuse]
    refs = [load_components(p) for p in paths]
    ours_c = raybundle_components(ours_passes)
    twin_c = raybundle_components(read_exr_passes(twin_path)) if a.twin and os.path.exists(twin_path) else None
    cycles_c = cycles_components(read_exr_passes(cycles_path))
    ours, theirs = {}, {}
    for form in forms:
        pairs = {k: (form(refs[0])[k], form(refs[1])[k]) for k in form(refs[0])}
        ours.update(component_errors(form(ours_c), pairs, exclude, None if twin_c is None else form(twin_c)))
        theirs.update(component_errors(form(cycles_c), pairs, exclude))
    order = (COMPONENTS[0], "diffuse", *COMPONENTS[1:])
    ours = {k: ours[k] for k in order if k in ours}
    whole_ref = [sum(r.values()) for r in refs]
    total = image_error(sum(ours_c.values()), 0.5 * (whole_ref[0] + whole_ref[1]), whole_ref, exclude)
    out = dict(seconds=t, wall_seconds=wall, part_seconds=run.get("part_seconds"), phases=run.get("phases"),
               iterations=run.get("iterations"), image_passes=run.get("image_passes"), cycles_samples=int(cyc["setting"]), cycles_seconds=cyc["seconds"],
               reference_samples=a.breakdown_samples, excluded_pixels=float(exclude.mean()), pixels=int(exclude.size),
               glass_pixels=float(glass_pixels(ours_passes).mean()), diffuse_whole=bool(whole),
               error=total["error"], components={k: dict(ours[k], cycles_error=theirs[k]["error"]) for k in ours})
    print(f"breakdown at {t:g} s (Cycles {out['cycles_samples']} spp in {out['cycles_seconds']:.1f} s; "
          f"{100 * out['excluded_pixels']:.1f}% of the pixels left out, {100 * out['glass_pixels']:.1f}% "
          f"through glass): error {total['error']:.4f}", flush=True)
    for k, d in out["components"].items():
        split = f", bias {d['bias']:.4f}, noise {d['noise']:.4f}" if "bias" in d else ""
        mean = "" if d["mean_ratio"] is None else f", mean x{d['mean_ratio']:.3f}"
        print(f"  {k}: share {100 * d['share']:.1f}%, raybundle {d['error']:.4f}{split}{mean}; "
              f"Cycles {d['cycles_error']:.4f}", flush=True)
    return out


#: the image passes' parts whose cost :func:`per_pixel_costs` gives per pixel sample
PASS_PARTS = ("eye rays", "lamps", "world", "glossy paths")


def per_pixel_costs(split):
    """One sentence: the breakdown's run's µs per pixel and image pass by part (its
    ``part_seconds`` over ``image_passes`` x ``pixels``), beside Cycles' µs per path (its
    seconds over its samples x pixels, its scene set-up included); None without the figures."""
    parts, passes, pixels = split.get("part_seconds"), split.get("image_passes"), split.get("pixels")
    if not (parts and passes and pixels):
        return None
    per = 1e6 / (passes * pixels)
    cycles = 1e6 * split["cycles_seconds"] / (split["cycles_samples"] * pixels)
    return ("µs per pixel and image pass: " + ", ".join(f"{k} {parts[k] * per:.2f}" for k in PASS_PARTS if k in parts)
            + f"; Cycles {cycles:.2f} µs per path (its whole path, its scene set-up included).")


def breakdown_table(split):
    """Markdown: the breakdown (:func:`component_breakdown`) and its run's seconds per part and phase."""
    rows = []
    for k, d in split["components"].items():
        rows.append([k, f"{100 * d['share']:.1f}%", percent(d["error"]), percent(d.get("bias")),
                     percent(d.get("noise")), "–" if d["mean_ratio"] is None else f"×{d['mean_ratio']:.3f}",
                     percent(d["cycles_error"])])
    text = [f"raybundle at {split['seconds']:g} s by component, against Cycles' light passes (2 × "
            f"{split['reference_samples']} spp, their noise subtracted), beside Cycles at {split['cycles_samples']} spp "
            f"({split['cycles_seconds']:.0f} s). Errors relative to the whole reference's mean; "
            f"{100 * split['excluded_pixels']:.1f}% of the pixels left out (next to lights, or seen through glass "
            f"or a mirror: {100 * split['glass_pixels']:.1f}%); the image's error over the rest "
            f"{percent(split['error'])}."
            + (" The patches carry the world's direct light here, so the diffuse lobe is compared whole only."
               if split["diffuse_whole"] else " `diffuse` is the diffuse lobe whole: the lamps' light through a "
               "glass pane is direct to raybundle's lamp samples and indirect to Cycles'."), "",
            table(["component", "share", "raybundle", "its bias", "its noise", "its mean", "Cycles"], rows)]
    if split.get("part_seconds"):
        text += ["", f"That run's seconds by part ({split['iterations']} iterations, {split['image_passes']} image "
                 "passes): " + ", ".join(f"{k} {v:.1f}" for k, v in split["part_seconds"].items()) + "."]
    line = per_pixel_costs(split)
    if line:
        text += ["", line]
    if split.get("phases"):
        text += ["", "Its phases: " + ", ".join(f"{p['name']} {p['seconds']:.1f} s" for p in split["phases"]) + "."]
    return "\n".join(text)


def page_body(a, reference, reference_samples, noise, rows, summary, targets, warnings, split=None,
              overlaps=None):
    """The bench's section of the benchmark page: the set-up, then :func:`comparison_tables`,
    the errors off the z-fighting ``overlaps`` (an (H, W) bool mask), the breakdown
    (:func:`breakdown_table`) and the run's warnings."""
    h, w = reference.shape[:2]
    text = [f"`{a.blend}`{' in clay (a white diffuse Material Override)' if a.clay else ', its own materials'}, "
            f"{w} × {h} px. Every render is timed from opening the scene to the EXR written. Reference: Cycles "
            f"2 × {reference_samples} spp, its own noise ({percent(noise['reference_noise'])} per pixel) "
            "subtracted. Error: relative RMSE over pixels at least 2 px from a directly seen light "
            "(`raybundle.app.metrics.image_error`).", "", comparison_tables(rows, summary, targets)]
    off = [d for d in summary if d.get("raybundle_error_off_overlaps") is not None]
    if off:
        text += ["", "Off the pixels that see two objects' faces overlapping in one plane "
                 f"({int(overlaps.sum())} px; `raybundle.app.metrics.overlap_mask`), where Cycles z-fights and "
                 "renders darker than either face alone and raybundle lights them as one surface: "
                 + "; ".join(f"raybundle {percent(d['raybundle_error_off_overlaps'])} at {d['raybundle_seconds']:.0f} s, "
                             f"Cycles {percent(d['cycles_error_off_overlaps_same_time'])}" for d in off) + "."]
    last = [r for r in rows if r.get("regions")][-1:]
    if last:
        g = last[0]["regions"]
        text += ["", f"raybundle at {last[0]['setting']:g} s by image region (3 × 3, top row first): its mean "
                 "against the reference's, and the region's share of the squared error.", "",
                 table(["", "left", "middle", "right"],
                       [[["top", "middle", "bottom"][i]] + [f"×{c['mean_ratio']:.3f}, {100 * c['share']:.0f}%"
                                                           for c in g[3 * i:3 * i + 3]] for i in range(3)])]
    if split is not None:
        text += ["", breakdown_table(split)]
    if warnings:
        text.append("raybundle's warnings: " + "; ".join(warnings))
    return "\n".join(text)


def percent(e):
    return "–" if e is None else f"{100 * e:.2f}%"


def comparison_tables(rows, summary, targets):
    """Markdown: one row per raybundle run (its set-up and mean when the rows have them) beside
    Cycles at the same time (``summary``, from :func:`side_by_side`), Cycles' ladder, and the
    time each engine needs for each error level (``targets``, from :func:`time_to_errors`)."""
    ours = [r for r in rows if r["engine"] == "raybundle"]
    names = {"setup_seconds": "set-up", "mean_ratio": "its mean", "bias": "its bias", "noise": "its noise"}
    shown = {"setup_seconds": lambda v: "–" if v is None else f"{v:.1f} s", "mean_ratio": lambda v: f"×{v:.3f}",
             "bias": percent, "noise": percent}
    extra = [k for k in names if any(r.get(k) is not None for r in ours)]
    cycles = [r for r in rows if r["engine"] == "cycles"]
    return "\n".join([
        table(["raybundle Time Limit", "seconds"] + [names[k] for k in extra]
              + ["raybundle", "Cycles, same time", "ratio", "Cycles' time for raybundle's error"],
              [[f"{r['setting']:g} s", f"{r['seconds']:.1f}"] + [shown[k](r.get(k)) for k in extra]
               + [percent(r["error"]), percent(s["cycles_error_same_time"]),
                  "–" if not s["cycles_error_same_time"] else f"{r['error'] / s['cycles_error_same_time']:.2f}",
                  "–" if s["cycles_seconds_same_error"] is None else f"{s['cycles_seconds_same_error']:.0f} s"]
               for r, s in zip(ours, summary)]),
        table(["Cycles spp"] + [f"{r['setting']:g}" for r in cycles],
              [["seconds"] + [f"{r['seconds']:.1f}" for r in cycles],
               ["error"] + [percent(r["error"]) for r in cycles]]),
        table(["time to an error of"] + list(next(iter(targets.values()))),
              [[engine] + list(t.values()) for engine, t in targets.items()])])


def chart(path, rows, title, ylabel="relative RMSE against a long Cycles render",
          xlabel="seconds from loading the scene to the EXR written (2 cores)", all_pixels=True):
    """Error against seconds, log-log, one curve per engine (and, with ``all_pixels``,
    the error over all pixels, faint)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 5))
    for engine, style in (("raybundle", "o-"), ("cycles", "s--")):
        pts = sorted((r["seconds"], r["error"], r.get("error_all_pixels")) for r in rows if r["engine"] == engine)
        t, e, full = zip(*pts)
        ax.loglog(t, e, style, label=f"{engine} (pixels 2 px from lights)" if all_pixels else engine)
        if all_pixels:
            ax.loglog(t, full, style, alpha=0.4, label=f"{engine} (all pixels)")
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    ax.set_title(title)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)


if __name__ == "__main__":
    sys.exit(main())
