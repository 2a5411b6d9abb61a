"""Benchmark: the methods' error against time, side by side in one run (``python -m raybundle bench``).

``python -m raybundle bench --scenes cornell furnace-glossy --methods all --time 60 [--out DIR]``
runs every method (:data:`METHODS`) on every scene for the same wall-clock budget, one after
the other on this machine, and records the image error at roughly doubling times.  Time counts
from loading the scene (patch layout, tracer, first shot included) to each image.  The error is
the project's one image error (:func:`raybundle.app.metrics.image_error`: RMSE / mean(reference)
over pixels at least 2 px from a directly seen light source, the reference's own noise
subtracted).  References: the analytic radiance for the furnaces (no noise); elsewhere two
independent halves ``DIR_REF/<scene>-<W>x<H>-{1,2}.exr`` (default ``out/reference``), made once by
the path tracer (``--reference-time`` seconds each, seeds 1001 and 1002) and reused; Cycles
halves (``tools/bench_blender.py``'s ``reference-{1,2}.exr``) may be copied there instead.

Writes into ``--out`` (default ``out/bench``): ``<scene>.csv`` (seconds, iterations, error per
method), ``<scene>.png`` (log-log error against seconds, one curve per method, the reference's
noise marked), ``summary.md`` (time to 5%, 2%, 1.5% and 1% per method and scene, and each
curve's slope) and ``summary.json``; with ``--page``, the bench's section of the benchmark page
(:mod:`raybundle.app.bench_page`).  ``--throughput`` adds the older figures: bundle
visibility against raw Embree queries (``visibility.csv``) and milliseconds per iteration
(``iterations.csv``).
"""
from __future__ import annotations

import csv
import json
import os
import signal
import subprocess
import sys
import tempfile
import threading
import time

import numpy as np

from ..imaging.settings import RenderSettings
from ..scene.builtin import load_scene
from ..tracing.sampling import DEFAULT_SEQUENCE, uniform_sphere
from ..tracing.visibility import RayTracer, bundle_from_hits
from ..util.io import read_exr, write_exr, write_json
from .bench_page import checked_page, write_section
from .metrics import image_error, light_source_mask
from .pipeline import build, make_renderer, prepare
from .plan import RunOptions, plan

#: bench method name -> (solver name, random sequence)
METHODS = {"stochastic-iteration": ("stochastic-iteration", DEFAULT_SEQUENCE),
           "ray-bundle-walk": ("ray-bundle-walk", DEFAULT_SEQUENCE),
           "radiosity": ("radiosity", DEFAULT_SEQUENCE),
           "point-collocation": ("point-collocation", DEFAULT_SEQUENCE),
           "path-tracing": ("path-tracing", "prng"),
           "path-tracing-qmc": ("path-tracing", "halton"),
           "single-ray-iteration": ("single-ray-iteration", "prng"),
           "auto": ("auto", None)}
#: error levels whose first crossing ``summary.md`` reports
LEVELS = (0.05, 0.02, 0.015, 0.01)
#: seeds of the two reference halves; of the timed runs
REFERENCE_SEEDS, SEED = (1001, 1002), 3


def bench_visibility(scene_name="cornell", patches=4000, resolution=128, bundles=40, rounds=7, seed=0):
    """Bundle queries/s vs raw Embree first-hit queries/s on the same rays (both threaded).

    The two are timed in alternation, ``rounds`` times, and the medians are
    reported, so that the ratio compares runs made under the same machine load.
    """
    sc = prepare(load_scene(scene_name), patches=patches)
    tr = RayTracer(sc)
    rng = np.random.default_rng(seed)
    dirs = [uniform_sphere(*rng.random(2)) for _ in range(bundles)]
    grids = [tr.bundle_origins(d, resolution, rng.random(2), rng.random()) for d in dirs]
    raw_o = np.concatenate([o for o, _ in grids])
    raw_d = np.concatenate([np.broadcast_to(d, (len(o), 3)) for d, (o, _) in zip(dirs, grids)])
    lines = len(raw_o)
    b_qps, r_qps = [], []
    for _ in range(rounds):
        t = time.perf_counter()
        casts = 0
        for d, (o, delta) in zip(dirs, grids):
            up, down, _, c = tr.all_hit_pairs(o, d)
            bundle_from_hits(sc, d, delta, up, down, len(o), c)
            casts += c
        b_qps.append(casts / (time.perf_counter() - t))
        reps = max(1, int(round(casts / lines)))     # as many raw queries as the bundles made
        t = time.perf_counter()
        for _ in range(reps):
            tr.first_hit(raw_o, raw_d)
        r_qps.append(reps * lines / (time.perf_counter() - t))
    tr.close()
    ratios = np.array(b_qps) / np.array(r_qps)
    return {"scene": scene_name, "patches": sc.n_patches, "bundle_resolution": resolution, "bundles": bundles,
            "rounds": rounds, "bundle_queries_per_s": float(np.median(b_qps)),
            "raw_first_hit_queries_per_s": float(np.median(r_qps)), "ratio": float(np.median(ratios)),
            "ratio_min": float(ratios.min()), "ratio_max": float(ratios.max()),
            "grid_rays_per_s": float(np.median(b_qps)) * lines / casts,
            "queries_per_grid_ray": casts / lines, "threads": tr.threads}


def bench_iterations(names=("furnace", "furnace-glossy", "cornell", "cornell-glossy"), seconds=3.0):
    rows = []
    for name in names:
        sc = prepare(load_scene(name))
        r = make_renderer(sc, RenderSettings())
        s = r.solver
        for _ in range(5):      # warm up: albedo tables, thread pool
            s.step()
        n0, t = s.stats.iterations, time.perf_counter()
        while time.perf_counter() - t < seconds:
            s.step()
        dt = (time.perf_counter() - t) / (s.stats.iterations - n0)
        rows.append({"scene": name, "patches": sc.n_patches, "bundle_resolution": s.bundle_resolution,
                     "ms_per_iteration": 1e3 * dt, "queries_per_iteration": s.stats.rays / s.stats.iterations})
        r.tracer.close()
    return rows


def snapshot_times(seconds):
    """Run-clock times of the snapshots: 0.5 s doubling up to ``seconds`` (the end is always one)."""
    times, t = [], 0.5
    while t < seconds:
        times.append(t)
        t *= 2
    return times


def load(name, resolution=None):
    sc = load_scene(name)
    if resolution:
        sc.camera = sc.camera.with_resolution(*resolution)
    return sc


def setup(name, method, resolution=None, seed=SEED):
    """Scene loaded, laid out (patch methods only) and its renderer built: (scene, renderer, seconds)."""
    t0 = time.perf_counter()
    solver, sequence = METHODS[method]
    sc = load(name, resolution)                # auto decides on the scene, inside the timed set-up
    sc, r = build(sc, plan(sc, RunOptions(method=solver, sequence=sequence, seed=seed)))
    return sc, r, time.perf_counter() - t0


def label(name):
    """A scene's name in file names: the built-in name or the .npz file's stem."""
    return os.path.splitext(os.path.basename(str(name)))[0]


def reference_paths(name, sc, folder):
    """The two reference halves of scene ``name`` (loaded: ``sc``) at its camera's resolution;
    [] for a furnace."""
    if sc.analytic_radiance is not None:
        return []
    return [os.path.join(folder, f"{label(name)}-{sc.camera.width}x{sc.camera.height}-{k}.exr") for k in (1, 2)]


def reference(name, resolution, folder, seconds, log=print, stop=None):
    """(reference image, [half A, half B] or None): the analytic radiance of a furnace, else
    two cached independent halves, rendered by the path tracer when missing.  A half cut
    short (``stop``, Ctrl-C) is never cached: :class:`Interrupted` is raised instead."""
    sc = load(name, resolution)
    if sc.analytic_radiance is not None:
        return np.broadcast_to(np.asarray(sc.analytic_radiance, float), (sc.camera.height, sc.camera.width, 3)), None
    paths = reference_paths(name, sc, folder)
    halves = []
    for path, seed in zip(paths, REFERENCE_SEEDS):
        if not os.path.exists(path):
            log(f"reference half {path}: path tracing for {seconds:.0f} s (seed {seed}; cached)")
            if not seconds > 0:
                raise ValueError(f"reference half {path} is missing and --reference-time is {seconds:g} s: "
                                 "give it seconds (or copy Cycles halves there)")
            _, r, _ = setup(name, "path-tracing", resolution, seed)
            res = r.run(time_limit=seconds, stop=stop)
            r.tracer.close()
            if res.cancelled:
                raise Interrupted(f"reference half {path} cut short: not cached")
            write_exr(path, res.image, {"raybundle_samples_per_pixel": res.stats["iterations"],
                                        "raybundle_seconds": res.stats["seconds"]})
        halves.append(read_exr(path))
    return 0.5 * (halves[0] + halves[1]), halves


class Interrupted(Exception):
    """Ctrl-C during the bench: it stops as a whole, its results so far marked partial."""


def run_method(name, method, seconds, ref, halves, resolution=None, log=print, stop=None):
    """One timed run: rows (scene, method, seconds from loading, iterations, error, reference noise)."""
    sc, r, t_setup = setup(name, method, resolution)
    mask = light_source_mask(sc)
    rows = []

    def snap(t, it, img):
        e = image_error(img, ref, reference_halves=halves, exclude=mask)
        rows.append({"scene": name, "method": method, "seconds": round(t_setup + t, 3), "iterations": it,
                     "error": e["error"], "raw_error": e["raw"], "reference_noise": e["reference_noise"]})
        log(f"  {name} / {method}: {t_setup + t:6.1f} s, {it} iterations, error {100 * e['error']:.2f}%")

    res = r.run(time_limit=max(seconds - t_setup, 0.0), snapshots=snapshot_times(seconds - t_setup),
                on_snapshot=snap, stop=stop)
    r.tracer.close()
    snap(res.stats["seconds"], res.stats["iterations"], res.image)
    # a snapshot's time includes forming it, the run's clock leaves that out: on a loaded
    # machine a late snapshot can cost more than the whole run did, and it is no stopping point
    rows = [row for i, row in enumerate(rows) if all(row["seconds"] < later["seconds"] for later in rows[i + 1:])]
    return rows, res


def run_cycles(name, seconds, ref, halves, script, resolution=None, log=print):
    """Cycles as one more curve: renders of 1, 2, 4, ... samples per pixel, each timed from
    loading the scene to the EXR written, by ``script --curve`` (the repository's
    ``tools/cycles_reference.py``) in a subprocess (the core never imports ``bpy``).  Rows as :func:`run_method`'s;
    raises ValueError where Cycles cannot be used (no script or ``bpy``, a scene it cannot
    build)."""
    if not os.path.isfile(script):
        raise ValueError(f"--cycles {script}: no such file (the repository's tools/cycles_reference.py)")
    sc = load(name, resolution)
    mask = light_source_mask(sc)
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        cmd = [sys.executable, script, str(name), "--curve", str(seconds), "--seed", str(SEED), "--out", tmp,
               "--resolution", str(sc.camera.width), str(sc.camera.height)]
        p = subprocess.run(cmd, capture_output=True, text=True)
        if p.returncode != 0:
            raise ValueError((p.stderr.strip().splitlines() or [f"Cycles failed ({p.returncode})"])[-1])
        for line in p.stdout.splitlines():
            if not line.startswith("{"):
                continue
            r = json.loads(line)
            e = image_error(read_exr(r["path"]), ref, reference_halves=halves, exclude=mask)
            rows.append({"scene": name, "method": "cycles", "seconds": r["seconds"], "iterations": r["samples"],
                         "error": e["error"], "raw_error": e["raw"], "reference_noise": e["reference_noise"]})
            log(f"  {name} / cycles: {r['seconds']:6.1f} s, {r['samples']} samples, error {100 * e['error']:.2f}%")
    return rows


def time_to(rows, level):
    """First time [s] the error falls to ``level``, interpolated log-log between snapshots; None if never."""
    prev = None
    for row in rows:
        if row["error"] <= level:
            if prev is None or prev["error"] <= 0 or row["error"] <= 0:
                return row["seconds"]
            f = np.log(prev["error"] / level) / np.log(prev["error"] / row["error"])
            return float(np.exp(np.log(prev["seconds"]) + f * np.log(row["seconds"] / prev["seconds"])))
        prev = row
    return None


def slope(rows, from_seconds=2.0):
    """Least-squares slope of log(error) against log(seconds) over snapshots after ``from_seconds``
    (-0.5 for unbiased Monte Carlo noise; towards 0 where a bias takes over)."""
    pts = [(r["seconds"], r["error"]) for r in rows if r["seconds"] >= from_seconds and r["error"] > 0]
    if len(pts) < 2:
        return None
    t, e = np.log(np.array(pts)).T
    return float(np.polyfit(t, e, 1)[0])


def write_csv(path, rows):
    keys = []
    for row in rows:
        keys += [k for k in row if k not in keys]
    with open(path, "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=keys)
        w.writeheader()
        w.writerows(rows)


def chart(path, name, rows):
    """Log-log error against seconds, one curve per method, the reference's noise dotted."""
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        print("  (matplotlib is not installed: no chart)")
        return
    fig, ax = plt.subplots(figsize=(7, 5))
    for method in dict.fromkeys(r["method"] for r in rows):
        pts = [(r["seconds"], r["error"]) for r in rows if r["method"] == method and r["error"] > 0]
        if pts:
            ax.loglog(*zip(*pts), "o-", label=method)
    noise = max((r["reference_noise"] for r in rows), default=0.0)
    if noise > 0:
        ax.axhline(noise, color="grey", ls=":", lw=1, label=f"reference noise {100 * noise:.2f}% (subtracted)")
    for level in LEVELS:
        ax.axhline(level, color="lightgrey", lw=0.6)
    ax.set_xlabel("seconds from loading the scene (this machine)")
    ax.set_ylabel("relative RMSE")
    ax.set_title(name)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def summary_table(results, skipped=None):
    """``summary.md``'s text: per scene and method, the time to each level, the final error, the slope;
    ``skipped`` {scene: {method: reason}} rows say why a method did not run."""
    head = " | ".join(f"to {100 * lv:g}%" for lv in LEVELS)
    lines = ["| scene | method | " + head + " | final error (at s) | slope |",
             "|---|---|" + "---|" * len(LEVELS) + "---|---|"]
    for name, by_method in results.items():
        for method, rows in by_method.items():
            times = " | ".join("–" if (t := time_to(rows, lv)) is None else f"{t:.1f} s" for lv in LEVELS)
            s = slope(rows)
            lines.append(f"| {name} | {method} | {times} | {100 * rows[-1]['error']:.2f}% ({rows[-1]['seconds']:.0f})"
                         f" | {'–' if s is None else f'{s:.2f}'} |")
        for method, reason in (skipped or {}).get(name, {}).items():
            lines.append(f"| {name} | {method} | " + "n/a | " * len(LEVELS) + f"{reason.split(';')[0]} | |")
    return "\n".join(lines) + "\n"


def run_throughput(out):
    """The per-iteration figures: bundle visibility throughput and ms per iteration."""
    v = bench_visibility()
    print(f"bundle visibility: {v['bundle_queries_per_s'] / 1e6:.2f} M queries/s; raw first hit "
          f"{v['raw_first_hit_queries_per_s'] / 1e6:.2f} M/s; ratio {v['ratio']:.2f}", flush=True)
    write_csv(os.path.join(out, "visibility.csv"), [v])
    its = bench_iterations()
    for row in its:
        print(f"  {row['scene']:15s} {row['patches']:5d} patches: {row['ms_per_iteration']:.2f} ms/iteration", flush=True)
    write_csv(os.path.join(out, "iterations.csv"), its)
    return {"visibility": v, "iterations": its}


def _bench_scene(name, methods, args, ref, halves, log, stop, skipped):
    """{method: rows} of every method (and Cycles with ``args.cycles``) on scene ``name`` against
    reference ``ref``, its final images, CSV and chart written to ``args.out``; methods that do not
    apply go into ``skipped``."""
    out = args.out
    rows_scene, results = [], {}
    for method in methods:
        if stop.is_set():
            break
        try:
            rows, res = run_method(name, method, args.time, ref, halves, args.resolution, log, stop)
        except ValueError as e:          # a method that does not apply (radiosity on a glossy scene)
            log(f"  {name} / {method}: not applicable: {e}")
            skipped.setdefault(name, {})[method] = str(e)
            continue
        results[method] = rows
        rows_scene += rows
        write_exr(os.path.join(out, f"{label(name)}-{method}.exr"), res.image)
    if args.cycles and not stop.is_set():
        try:
            rows = run_cycles(name, args.time, ref, halves, args.cycles, args.resolution, log)
            results["cycles"] = rows
            rows_scene += rows
        except ValueError as e:
            log(f"  {name} / cycles: not applicable: {e}")
            skipped.setdefault(name, {})["cycles"] = str(e)
    if rows_scene:
        write_csv(os.path.join(out, f"{label(name)}.csv"), rows_scene)
        chart(os.path.join(out, f"{label(name)}.png"), label(name), rows_scene)
    return results


def run_bench(args):
    out = args.out
    page = checked_page(getattr(args, "page", None), "raybundle bench")
    os.makedirs(out, exist_ok=True)
    methods = list(METHODS) if "all" in args.methods else list(dict.fromkeys(args.methods))
    bad = [m for m in methods if m not in METHODS]
    if bad:
        print(f"raybundle bench: unknown method {bad[0]!r}; choose from {sorted(METHODS)} or all", file=sys.stderr)
        return 2
    try:
        scenes = {name: load(name) for name in args.scenes}
    except (ValueError, OSError) as e:
        print(f"raybundle bench: {e}", file=sys.stderr)
        return 2
    for sc in scenes.values():
        if args.resolution:
            sc.camera = sc.camera.with_resolution(*args.resolution)
    missing = sum(not os.path.exists(p) for name, sc in scenes.items()
                  for p in reference_paths(name, sc, args.reference_dir))
    total = len(scenes) * len(methods) * args.time + missing * args.reference_time
    t_start = time.perf_counter()

    def log(text):
        done = time.perf_counter() - t_start
        print(f"[{done:5.0f} s, about {max(total - done, 0):.0f} s left] {text}", file=sys.stderr, flush=True)

    results, summary, skipped = {}, {}, {}
    stop = threading.Event()
    old_handler = signal.signal(signal.SIGINT, lambda *_: stop.set())    # Ctrl-C: the bench stops as a whole
    try:
        for name in scenes:
            if stop.is_set():
                break
            try:
                ref, halves = reference(name, args.resolution, args.reference_dir, args.reference_time, log, stop)
            except Interrupted as e:
                log(str(e))
                break
            except ValueError as e:
                print(f"raybundle bench: {e}", file=sys.stderr)
                return 2
            results[name] = _bench_scene(name, methods, args, ref, halves, log, stop, skipped)
            summary[name] = {m: {"final_error": r[-1]["error"], "seconds": r[-1]["seconds"], "slope": slope(r),
                                 **{f"seconds_to_{lv:g}": time_to(r, lv) for lv in LEVELS}}
                             for m, r in results[name].items()}
    finally:
        signal.signal(signal.SIGINT, old_handler)
    partial = stop.is_set()
    if not partial and not any(results.values()):
        reasons = "; ".join(f"{n} / {m}: {r.split(';')[0]}" for n, d in skipped.items() for m, r in d.items())
        print(f"raybundle bench: no method applies to the scenes given ({reasons})", file=sys.stderr)
        return 2
    table = summary_table(results, skipped)
    with open(os.path.join(out, "summary.md"), "w") as f:
        f.write(("**Partial: stopped by Ctrl-C; the last method's rows end where it stopped.**\n\n" if partial else "")
                + f"Error (relative RMSE, reference noise subtracted) against seconds from loading the scene, "
                f"{args.time:g} s per method, one run on this machine.\n\n{table}")
    extra = run_throughput(out) if args.throughput and not partial else {}
    write_json(os.path.join(out, "summary.json"), {"seconds": args.time, "methods": methods, "scenes": summary,
                                                   "not_applicable": skipped, "partial": partial, **extra})
    if page and not partial:
        charts = [os.path.join(out, f"{label(n)}.png") for n in results if results[n]]
        write_section(page, "methods", "Methods: error against time on the built-in scenes",
                      f"Every method for {args.time:g} s on each scene, one after the other "
                      f"(`python -m raybundle bench --scenes {' '.join(args.scenes)} --time {args.time:g}`). "
                      f"Error: relative RMSE, the reference's noise subtracted.\n\n{table}",
                      [c for c in charts if os.path.exists(c)], command="make bench")
    print(table)
    print(f"wrote {out}/summary.md, summary.json and a CSV, a PNG and the final EXRs per scene"
          + (" (partial: stopped by Ctrl-C)" if partial else ""))
    return 130 if partial else 0
