"""Scale bench: the Cornell box meshed with 4k to 4M triangles, its patches chosen by the code.

Usage (about 1 to 2 minutes per triangle count up to 1M, 4 minutes for 4M, on 2 cores)::

    python tools/bench_scale.py --out out/bench-scale [--triangles 4000 16000 64000 256000 1000000 4000000]
        [--time 20] [--one-patch-per-triangle 4000 16000 64000]

For each triangle count: the built-in ``cornell`` tessellated
(:func:`raybundle.patches.clusters.tessellate`: every reflecting face cut into small triangles, each
its own input face, the stand-in for a finely meshed Blender scene), laid out by
``pipeline.prepare`` with the default patch target, then rendered for ``--time`` seconds.
Each row runs in two fresh processes, one after the other:

1. *memory*: set-up, 4 iterations, one image pass and the image under ``tracemalloc`` (which
   sees every NumPy array but not Embree's BVH): the peak of traced memory, per triangle;
2. *render*: set-up (``prepare``; tracer, first shot and solver) and the render, timed,
   with the process's peak RSS; its error against the cached Cycles reference of the
   same box (``out/bench-cornell/reference-{1,2}.exr``, written by
   ``tools/bench_blender.py cornell``), by :func:`raybundle.app.metrics.image_error`: the
   lamp excluded, the reference's own noise subtracted.

``--one-patch-per-triangle`` adds rows of the old layout (``--patches 0``: every triangle
its own patch) of the same tessellations, for comparison.  Writes ``scale.csv``,
``summary.json`` and ``scale.png`` (error, set-up time and memory against triangles) into
``--out`` and prints one line per row.

``--stress`` (names, or none for all) renders instead the stress scenes of
``tools/stress_scenes.py`` (built once into ``--out``/stress) through the add-on for ``--time``
seconds, each in a fresh process timed from opening the file, and reports each phase's seconds
(as the progress display shows them) and the process's peak memory beyond the opened file's,
against the scene's triangles, objects and materials: ``stress.csv``, ``stress.json``.

``--rooms`` (names, or none for all) does the same for the bench rooms of ``demo_scenes/interiors``
at 320 x 180, each in clay and in its own materials: ``rooms.csv``, ``rooms.json``.
"""
from __future__ import annotations

import argparse
import csv
import json
import os
import subprocess
import sys

_ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path[:0] = [os.path.join(_ROOT, "tools"), _ROOT]          # bench_blender, stress_scenes; raybundle_addon

from raybundle.app.bench_page import add_page_argument, checked_page, command_line, table, write_section  # noqa: E402

REFERENCE = os.path.join(_ROOT, "out", "bench-cornell")


def one(triangles, seconds, patches, mode, reference=REFERENCE, resolution=None):
    """Run one row in this process; returns a dict (see the module docstring)."""
    import resource
    import time
    import tracemalloc

    import numpy as np

    from raybundle.app.pipeline import make_renderer, prepare
    from raybundle.imaging.settings import RenderSettings
    from raybundle.patches.clusters import tessellate
    from raybundle.scene.builtin import load_scene

    box = load_scene("cornell")
    if resolution:
        box.camera = box.camera.with_resolution(*resolution)
    scene = tessellate(box, triangles)
    if mode == "memory":
        tracemalloc.start()
        base = tracemalloc.get_traced_memory()[0]
    t0 = time.perf_counter()
    laid = prepare(scene, patches)
    t1 = time.perf_counter()
    renderer = make_renderer(laid, RenderSettings(seed=3))
    t2 = time.perf_counter()
    row = dict(triangles=len(scene.triangles), patches=laid.n_patches, patch_triangles=len(laid.triangles))
    if mode == "memory":
        for _ in range(4):
            renderer.solver.step()
        renderer.image_pass()
        renderer.image()
        peak = tracemalloc.get_traced_memory()[1] - base
        tracemalloc.stop()
        return dict(row, traced_peak_mb=peak / 1e6, traced_bytes_per_triangle=peak / len(scene.triangles))
    result = renderer.run(time_limit=seconds, started=t0)          # the budget covers the set-up too
    t3 = time.perf_counter()
    from raybundle.app.metrics import image_error, light_source_mask
    from raybundle.util.io import read_exr

    halves = [read_exr(os.path.join(reference, f"reference-{k}.exr")) for k in (1, 2)]
    reference = 0.5 * (halves[0] + halves[1])
    error = image_error(result.image, reference, reference_halves=halves,
                        exclude=light_source_mask(box))["error"]
    st = renderer.solver.stats
    # --time means the whole run: wall <= T + 10% + 1 s whenever set-up takes less than T / 2
    within = None if t2 - t0 >= seconds / 2 else bool(t3 - t0 <= 1.1 * seconds + 1.0)
    return dict(row, prepare_s=t1 - t0, solver_setup_s=t2 - t1, render_s=t3 - t2, wall_s=t3 - t0,
                within_budget=within, iterations=st.iterations,
                ms_per_iteration=1e3 * st.seconds / max(st.iterations, 1), error=error,
                peak_rss_gb=resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1e6)


#: the benches' columns: each phase the progress display shows, by the start of its text
PHASES = {"exporting": "export", "laying out": "layout", "cutting faces": "layout", "cutting patches": "contacts",
          "grouping": "layout", "welding": "welding", "waiting for Blender": "world", "compiling": "kernels",
          "building the ray tracer": "tracer",
          "first shot": "first shot", "warming up": "warm-up", "iterating": "iterating", "forming": "final image"}
#: the set-up's phases, in order
SETUP = ("export", "layout", "contacts", "welding", "world", "kernels", "tracer", "first shot", "warm-up")


def phase_seconds(phases):
    """{column of :data:`PHASES`: seconds} of a run's phases (``stats["phases"]``), summed."""
    out = {}
    for p in phases:
        col = next((c for start, c in PHASES.items() if p["name"].startswith(start)), "other")
        out[col] = out.get(col, 0.0) + p["seconds"]
    return out


ROOMS = os.path.join(_ROOT, "demo_scenes", "interiors")


def stress_one(blend, seconds, clay=False, resolution=None, exr=None):
    """Render the stress scene ``blend`` through the add-on in this process (a fresh one) into
    ``exr`` (default: beside ``blend``), with
    the bench's ``clay`` and ``resolution`` (:data:`bench_blender.OPEN_SETTINGS`): its counts,
    each phase's seconds, the iterations, the peak memory beyond the opened file's and the
    phase that reached it."""
    import time

    import bench_blender

    from raybundle.app.phases import peak_rss_mb

    bench_blender.OPEN_SETTINGS.update(clay=clay, resolution=resolution)
    bench_blender._open(blend)
    with open("/proc/self/statm") as f:
        opened_mb = int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE") / 2 ** 20
    t0 = time.perf_counter()
    bench_blender.render(blend, exr or os.path.splitext(blend)[0] + ".exr", "RAYBUNDLE", seconds=seconds)
    wall = time.perf_counter() - t0
    import bpy

    from raybundle_addon.engine import LAST_RUN

    st = LAST_RUN[bpy.context.scene.name]["stats"]
    peak = peak_rss_mb()
    peak_phase = next((p["name"] for p in st["phases"] if p["peak_rss_mb"] >= peak - 16), "the end")
    return dict(scene=os.path.splitext(os.path.basename(blend))[0] + (" (clay)" if clay else ""),
                triangles=st["scene_triangles"],
                objects=st["scene_objects"], materials=st["scene_materials"], patches=st["patches"],
                iterations=st["iterations"], setup_s=st["setup_seconds"], wall_s=wall,
                beyond_file_gb=(peak - opened_mb) / 1024, peak_phase=peak_phase, phases=st["phases"],
                **{f"{k}_s": v for k, v in phase_seconds(st["phases"]).items()})


def run_stress(names, out, seconds, rooms=False):
    """Build (once) and render each stress scene in a fresh process, or with ``rooms`` each
    bench room in clay and in its own materials at 320 x 180; the rows."""
    folder = os.path.join(out, "stress")
    rows = []
    for name, clay in [(n, c) for n in names for c in ((True, False) if rooms else (False,))]:
        blend = os.path.join(ROOMS if rooms else folder, name + ".blend")
        if not os.path.exists(blend):
            subprocess.run([sys.executable, os.path.join(_ROOT, "tools", "stress_scenes.py"), "--out", folder,
                            "--only", name], check=True, capture_output=True)
        job = [blend, seconds, clay, [320, 180] if rooms else None,
               os.path.join(out, f"{name}-{'clay' if clay else 'full'}.exr") if rooms else None]
        got = subprocess.run([sys.executable, __file__, "--stress-one", json.dumps(job)], check=True,
                             capture_output=True, text=True).stdout
        row = json.loads(got.strip().splitlines()[-1])
        rows.append(row)
        print(f"{row['scene']:>20}: {row['triangles']:>9,} triangles, {row['objects']:>5} objects, {row['materials']:>3} "
              f"materials: set-up {row['setup_s']:.1f} s (" + ", ".join(
                  f"{c} {row.get(c + '_s', 0):.1f}" for c in SETUP) + f"), {row['iterations']} iterations, "
              f"wall {row['wall_s']:.1f} s, peak {row['beyond_file_gb']:.2f} GB beyond the file "
              f"({row['peak_phase']})", flush=True)
    return rows


def stress_body(seconds, rows, rooms=False):
    """The stress bench's section of the benchmark page (``rooms``: the bench rooms')."""
    head = ["scene", "triangles", "objects", "materials", *SETUP, "set-up", "iterations", "wall",
            "peak beyond the file", "memory goal", "peak reached in"]
    what = ("Each bench room of `demo_scenes/interiors`, in clay and in its own materials," if rooms else
            "Each stress scene of `tools/stress_scenes.py` (what real rooms bring, alone in a plain room)")
    return (f"{what} rendered "
            f"through the add-on with a Time Limit of {seconds:g} s at 320 x 180, in a fresh process timed from "
            "opening the file. Seconds per phase as the progress display shows them (layout: cutting large faces "
            "and grouping small triangles; contacts: the cuts along contacts and piercings); memory: the process's "
            "peak beyond its size with the file open, against the goal of 0.5 GB + 1 KB per triangle, and the "
            "phase whose end first showed it.\n\n"
            + table(head, [(r["scene"], f"{r['triangles']:,}", r["objects"], r["materials"],
                            *(f"{r.get(c + '_s', 0):.1f}" for c in SETUP), f"{r['setup_s']:.1f} s", r["iterations"],
                            f"{r['wall_s']:.1f} s", f"{r['beyond_file_gb']:.2f} GB",
                            "met" if r["beyond_file_gb"] <= 0.5 + r["triangles"] * 1e3 / 2 ** 30 else "**over**",
                            r.get("peak_phase", ""))
                           for r in rows]))


def run_row(triangles, seconds, patches, reference, resolution):
    row = {}
    for mode in ("memory", "render"):
        job = json.dumps(dict(triangles=triangles, seconds=seconds, patches=patches, mode=mode, reference=reference,
                              resolution=resolution))
        out = subprocess.run([sys.executable, __file__, "--one", job], check=True, capture_output=True,
                             text=True).stdout
        row.update(json.loads(out.strip().splitlines()[-1]))
    return dict(row, layout="clusters" if patches else "one patch per triangle")


def chart(path, rows):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 3, figsize=(14, 4))
    for layout, style in (("clusters", "o-"), ("one patch per triangle", "s--")):
        rs = [r for r in rows if r["layout"] == layout]
        if not rs:
            continue
        x = [r["triangles"] for r in rs]
        axes[0].loglog(x, [100 * r["error"] for r in rs], style, label=layout)
        axes[1].loglog(x, [r["prepare_s"] + r["solver_setup_s"] for r in rs], style, label=layout)
        axes[2].loglog(x, [r["traced_bytes_per_triangle"] for r in rs], style, label=layout)
    for ax, label in zip(axes, ("error after the render [%]", "set-up [s]", "traced peak bytes per triangle")):
        ax.set_xlabel("triangles")
        ax.set_ylabel(label)
        ax.grid(True, which="both", alpha=0.3)
        ax.legend()
    axes[2].axhline(1000, color="gray", lw=0.8)
    fig.tight_layout()
    fig.savefig(path, dpi=100)


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--out", default="out/bench-scale")
    p.add_argument("--triangles", type=int, nargs="+", default=[4000, 16000, 64000, 256000, 1000000, 4000000])
    p.add_argument("--time", type=float, default=20.0)
    p.add_argument("--patches", type=int, default=4000, help="target patch count (the default of render)")
    p.add_argument("--one-patch-per-triangle", type=int, nargs="*", default=[])
    p.add_argument("--reference", default=REFERENCE, help="folder of the box's reference halves reference-{1,2}.exr")
    p.add_argument("--resolution", type=int, nargs=2, metavar=("W", "H"), help="the box's camera (default: "
                   "the built-in's, as the reference)")
    p.add_argument("--stress", nargs="*", metavar="NAME", help="the stress scenes (none named: all) instead")
    p.add_argument("--rooms", nargs="*", metavar="NAME", help="the bench rooms (none named: all) instead, as --stress")
    p.add_argument("--one", help=argparse.SUPPRESS)
    p.add_argument("--stress-one", help=argparse.SUPPRESS)
    add_page_argument(p, "scale")
    a = p.parse_args(argv)
    if a.one:
        print(json.dumps(one(**json.loads(a.one))))
        return 0
    if a.stress_one:
        print(json.dumps(stress_one(*json.loads(a.stress_one))))
        return 0
    if a.stress is not None or a.rooms is not None:
        return stress_main(a, argv)
    if not all(os.path.exists(os.path.join(a.reference, f"reference-{k}.exr")) for k in (1, 2)):
        print(f"no Cycles reference in {a.reference}: run tools/bench_blender.py cornell --out {a.reference} first",
              file=sys.stderr)
        return 2
    checked_page(a.page, "bench_scale")
    os.makedirs(a.out, exist_ok=True)
    rows = []
    plan = [(n, a.patches) for n in a.triangles] + [(n, 0) for n in a.one_patch_per_triangle]
    for n, patches in plan:
        row = run_row(n, a.time, patches, a.reference, a.resolution)
        rows.append(row)
        print(f"{row['triangles']:>8} triangles, {row['layout']}: {row['patches']} patches, set-up "
              f"{row['prepare_s']:.1f} + {row['solver_setup_s']:.1f} s, {row['ms_per_iteration']:.1f} ms/iteration, "
              f"{row['iterations']} iterations, error {100 * row['error']:.2f}%, peak RSS {row['peak_rss_gb']:.2f} GB, "
              f"traced {row['traced_bytes_per_triangle']:.0f} B/triangle, wall {row['wall_s']:.1f} s "
              f"({ {None: 'set-up over T/2', True: 'within T + 10% + 1 s', False: 'OVER T + 10% + 1 s'}[row['within_budget']]})",
              flush=True)
    with open(os.path.join(a.out, "scale.csv"), "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    with open(os.path.join(a.out, "summary.json"), "w") as f:
        json.dump(dict(seconds=a.time, rows=rows), f, indent=1)
    chart(os.path.join(a.out, "scale.png"), rows)
    print(f"wrote {a.out}/scale.csv, summary.json, scale.png")
    if a.page:
        write_section(a.page, a.section or "scale", "Scale: the Cornell box meshed with more and more triangles",
                      page_body(a, rows), [os.path.join(a.out, "scale.png")],
                      command=command_line("tools/bench_scale.py", argv))
        print(f"wrote its section of {a.page}")
    return 0


def stress_main(a, argv):
    from stress_scenes import SCENES

    rooms = a.rooms is not None
    known = sorted(f[:-6] for f in os.listdir(ROOMS) if f.endswith(".blend")) if rooms else list(SCENES)
    names = (a.rooms if rooms else a.stress) or known
    unknown = sorted(set(names) - set(known))
    if unknown:
        print(f"bench_scale: no {'bench room' if rooms else 'stress scene'} {', '.join(unknown)} "
              f"(there are {', '.join(known)})", file=sys.stderr)
        return 2
    checked_page(a.page, "bench_scale")
    os.makedirs(a.out, exist_ok=True)
    rows = run_stress(names, a.out, a.time, rooms)
    kind = "rooms" if rooms else "stress"
    with open(os.path.join(a.out, f"{kind}.csv"), "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=[k for k in rows[0] if k != "phases"], extrasaction="ignore")
        w.writeheader()
        w.writerows(rows)
    with open(os.path.join(a.out, f"{kind}.json"), "w") as f:
        json.dump(dict(seconds=a.time, rows=rows), f, indent=1)
    print(f"wrote {a.out}/{kind}.csv, {kind}.json")
    if a.page:
        title = "The bench rooms: the set-up per phase" if rooms else "Stress scenes: the set-up per phase"
        write_section(a.page, a.section or kind, title, stress_body(a.time, rows, rooms), [],
                      command=command_line("tools/bench_scale.py", argv))
        print(f"wrote its section of {a.page}")
    return 0


def page_body(a, rows):
    """The bench's section of the benchmark page: one row per triangle count and layout."""
    within = {None: "set-up over half the time", True: "yes", False: "**no**"}
    return ("The built-in `cornell` tessellated into more and more triangles, each its own input face, laid out "
            f"and rendered for {a.time:g} s (set-up included), each row in a fresh process. Error: relative RMSE "
            "against the box's Cycles reference, its noise subtracted. Memory: the peak of NumPy's traced "
            "allocations (Embree's BVH not included) and the process's peak resident size.\n\n"
            + table(["triangles", "layout", "patches", "set-up", "ms / iteration", "iterations", "error",
                     "within the time + 10% + 1 s", "traced bytes / triangle", "peak RSS"],
                    [(f"{r['triangles']:,}", r["layout"], f"{r['patches']:,}",
                      f"{r['prepare_s'] + r['solver_setup_s']:.1f} s", f"{r['ms_per_iteration']:.1f}",
                      r["iterations"], f"{100 * r['error']:.2f}%", within[r["within_budget"]],
                      f"{r['traced_bytes_per_triangle']:.0f}", f"{r['peak_rss_gb']:.2f} GB") for r in rows]))


if __name__ == "__main__":
    sys.exit(main())
