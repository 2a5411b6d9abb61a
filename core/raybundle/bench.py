"""Benchmark: speed and accuracy, side by side in one run (``python -m raybundle bench``).

Prints and writes to ``--out`` (default ``out/bench``):

* ``visibility.csv``: bundle visibility throughput (Embree queries per second
  inside :meth:`RayTracer.bundle`, pairing included) next to raw first-hit
  queries per second on the same rays, and their ratio;
* ``iterations.csv``: seconds per solver iteration for each built-in scene;
* ``convergence.csv`` and ``convergence.png``: relative RMSE against a
  reference over time (log-log), the project's one image error
  (:func:`raybundle.metrics.image_error`: RMSE / mean(reference) over pixels at
  least 2 px from a directly seen light source).  References: the analytic radiance
  for the furnaces; for the Cornell boxes a long run of the same method
  (``reference-<scene>.exr``, reused when present), which measures noise, and,
  when ``cycles-<scene>.exr`` exists in the output folder (made by
  ``tools/cycles_reference.py``), Cycles, which also measures the method's
  bias (finite elements, first-shot discretisation).
"""
from __future__ import annotations

import csv
import os
import time

import numpy as np

from .imaging import RenderSettings
from .io import read_exr, write_exr, write_json
from .pipeline import make_renderer, prepare
from .sampling import uniform_sphere
from .scenes import load_scene
from .metrics import image_error, light_source_mask
from .visibility import RayTracer, bundle_from_hits

SNAPSHOTS = (0.5, 1, 2, 4, 8, 15)


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


def convergence(name, seconds, reference=None, seed=0, settings=None):
    """Snapshots of one run: rows (seconds, iterations, rel. RMSE vs each reference)."""
    sc = prepare(load_scene(name))
    refs = dict(reference or {})
    if sc.analytic_radiance is not None:
        refs["analytic"] = np.broadcast_to(sc.analytic_radiance, (sc.camera.height, sc.camera.width, 3))
    rows = []
    mask = light_source_mask(sc)

    def snap(t, it, img):
        row = {"scene": name, "seconds": round(t, 3), "iterations": it,
               **{f"rel_rmse_vs_{k}": image_error(img, v, exclude=mask)["error"] for k, v in refs.items()}}
        if sc.analytic_radiance is not None:      # error of the image mean (the furnace target)
            row["mean_error_vs_analytic"] = float(np.abs(img.reshape(-1, 3).mean(axis=0)
                                                         / sc.analytic_radiance - 1).max())
        rows.append(row)

    r = make_renderer(sc, settings or RenderSettings(seed=seed))
    res = r.run(seconds=seconds, snapshots=[t for t in SNAPSHOTS if t < seconds], on_snapshot=snap)
    r.tracer.close()
    snap(res.stats["seconds"], res.stats["iterations"], res.image)
    return rows, res


def reference_image(name, out, seconds):
    path = os.path.join(out, f"reference-{name}.exr")
    if os.path.exists(path):
        return read_exr(path)
    print(f"  reference for {name}: {seconds:.0f} s run (cached in {path})", flush=True)
    sc = prepare(load_scene(name))
    r = make_renderer(sc, RenderSettings(seed=1000))
    res = r.run(seconds=seconds)
    r.tracer.close()
    write_exr(path, res.image, {"raybundle_seconds": res.stats["seconds"],
                                "raybundle_iterations": res.stats["iterations"]})
    return res.image


def write_csv(path, rows):
    keys = []
    for row in rows:
        keys += [k for k in row if k not in keys]
    with open(path, "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=keys)
        w.writeheader()
        w.writerows(rows)


def chart(path, rows):
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        print("  (matplotlib is not installed: no chart)")
        return
    fig, ax = plt.subplots(figsize=(7, 5))
    series = {}
    for row in rows:
        for k, v in row.items():
            if k.startswith("rel_rmse_vs_"):
                series.setdefault((row["scene"], k[len("rel_rmse_vs_"):]), []).append((row["seconds"], v))
    for (scene, ref), pts in sorted(series.items()):
        t, e = zip(*sorted(pts))
        ax.loglog(t, e, "o-", label=f"{scene} vs {ref}")
    ax.axhline(0.02, color="grey", ls=":", lw=1)
    ax.set_xlabel("seconds (2 cores)")
    ax.set_ylabel("relative RMSE")
    ax.set_title("raybundle: stochastic iteration with ray bundles")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)


def run_bench(args):
    out = args.out
    os.makedirs(out, exist_ok=True)
    print("visibility throughput (cornell, 4000 patches, 128x128 bundles):", flush=True)
    vis = [bench_visibility()]
    v = vis[0]
    print(f"  bundle: {v['bundle_queries_per_s'] / 1e6:.2f} M queries/s ({v['grid_rays_per_s'] / 1e6:.2f} M grid "
          f"rays/s, {v['queries_per_grid_ray']:.2f} queries per ray); raw first hit: "
          f"{v['raw_first_hit_queries_per_s'] / 1e6:.2f} M/s; ratio {v['ratio']:.2f} "
          f"(median of {v['rounds']} alternating rounds, range {v['ratio_min']:.2f}-{v['ratio_max']:.2f})", flush=True)
    write_csv(os.path.join(out, "visibility.csv"), vis)
    print("time per iteration (default settings):", flush=True)
    its = bench_iterations()
    for row in its:
        print(f"  {row['scene']:15s} {row['patches']:5d} patches, grid {row['bundle_resolution']:3d}: "
              f"{row['ms_per_iteration']:.2f} ms/iteration", flush=True)
    write_csv(os.path.join(out, "iterations.csv"), its)
    rows, summary = [], {}
    for name in ("furnace", "furnace-glossy", "cornell", "cornell-glossy"):
        refs = {}
        if name.startswith("cornell"):
            refs["long-run"] = reference_image(name, out, args.reference_seconds)
            cyc = os.path.join(out, f"cycles-{name}.exr")
            if os.path.exists(cyc):
                refs["cycles"] = read_exr(cyc)
        r, res = convergence(name, args.seconds, refs)
        rows += r
        write_exr(os.path.join(out, f"{name}.exr"), res.image)
        summary[name] = r[-1]
        errs = ", ".join(f"{k[len('rel_rmse_vs_'):]} {v:.4f}" for k, v in r[-1].items() if k.startswith("rel_rmse"))
        if "mean_error_vs_analytic" in r[-1]:
            errs += f"; image mean off by {r[-1]['mean_error_vs_analytic']:.4f}"
        print(f"{name}: {r[-1]['iterations']} iterations in {r[-1]['seconds']:.1f} s; relative RMSE: {errs}",
              flush=True)
    write_csv(os.path.join(out, "convergence.csv"), rows)
    chart(os.path.join(out, "convergence.png"), rows)
    write_json(os.path.join(out, "summary.json"), {"visibility": vis, "iterations": its, "final": summary})
    print(f"wrote {out}/visibility.csv, iterations.csv, convergence.csv, convergence.png, summary.json")
    return 0
