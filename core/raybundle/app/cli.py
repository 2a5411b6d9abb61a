"""Command line: ``python -m raybundle render SCENE ...`` and ``python -m raybundle bench``.

``render`` writes a linear EXR (and an sRGB PNG preview beside it), prints a
progress bar on stderr, and with ``--stats`` a JSON file with iterations,
seconds, rays traced, patches and, when the scene has an analytic answer, the
error against it.  Ctrl-C stops cleanly and still writes the image so far.
"""
from __future__ import annotations

import argparse
import os
import signal
import sys
import threading
import time

import numpy as np

from .. import __version__
from ..methods.registry import SOLVERS
from ..methods.stochastic_iteration import StochasticIterationSolver
from ..patches.clusters import DEFAULT_PATCHES
from ..tracing.sampling import DEFAULT_SEQUENCE, SEQUENCES
from .bench import METHODS
from .phases import PhaseClock
from .plan import DEFAULT_TIME_LIMIT


class ProgressBar:
    """A one-line progress bar on a stream, redrawn at most 10 times a second: the share done, then
    ``info``'s ``phase`` (what the job does now) or its ``iterations``, and its ``seconds``."""

    def __init__(self, stream=sys.stderr, width=30):
        self.stream, self.width, self._last = stream, width, 0.0
        self.enabled = stream.isatty() or os.environ.get("RAYBUNDLE_PROGRESS") == "1"
        self._drawn = False                   # the bar is on the current line

    def __call__(self, fraction, info):
        now = time.perf_counter()
        if not self.enabled or (now - self._last < 0.1 and fraction < 1):
            return
        self._last = now
        n = int(round(fraction * self.width))
        self.stream.write(f"\r[{'#' * n}{'.' * (self.width - n)}] {100 * fraction:5.1f}%  "
                          f"{info.get('phase') or str(info['iterations']) + ' iterations'}  {info['seconds']:.1f} s ")
        self.stream.flush()
        self._drawn = True

    def end_line(self):
        """End the bar's line, so that a message printed next starts on a line of its own."""
        if self.enabled and self._drawn:
            self.stream.write("\n")
            self.stream.flush()
            self._drawn = False

    def close(self):
        if self.enabled:
            self.stream.write("\n")
            self.stream.flush()


def analytic_error(image, exact):
    """Errors of an image against a constant exact radiance (RGB): mean relative
    error per channel, and relative RMSE over pixels."""
    exact = np.asarray(exact, float)
    img = np.asarray(image, float).reshape(-1, 3)
    mean = img.mean(axis=0)
    return {"analytic_radiance": exact.tolist(), "image_mean": mean.tolist(),
            "mean_relative_error": ((mean - exact) / exact).tolist(),
            "pixel_relative_rmse": float(np.sqrt((((img - exact) / exact) ** 2).mean()))}


def _write_outputs(args, scene, image, stats):
    """The EXR (stats in its header), the PNG beside it and ``--stats``; returns the stats
    with the version and, for scenes with an analytic answer, the error against it."""
    from ..util.io import write_exr, write_json, write_png

    stats = dict(stats, version=__version__)
    if scene.analytic_radiance is not None:
        stats.update(analytic_error(image, scene.analytic_radiance))
    write_exr(args.out, image, {"raybundle_" + k: v for k, v in stats.items() if isinstance(v, (int, float, str))})
    write_png(os.path.splitext(args.out)[0] + ".png", image)
    if args.stats:
        write_json(args.stats, stats)
    return stats


def cmd_render(args):
    from ..scene.builtin import load_scene
    from ..scene.model import SceneError
    from ..util.io import OutputError, check_output
    from .pipeline import Cancelled, lay_out, run_plan
    from .plan import RunOptions, check, plan

    t_start = time.perf_counter()
    try:                              # outputs are checked before the work, not lost after it
        check_output(args.out, "--out", suffix=".exr")
        if args.stats:
            check_output(args.stats, "--stats")
    except OutputError as e:
        print(f"raybundle: error: {e}", file=sys.stderr)
        return 2

    bar = ProgressBar()

    def tell(text):
        bar.end_line()
        print(f"raybundle: {text} ({time.perf_counter() - t_start:.1f} s)", file=sys.stderr, flush=True)

    stage = PhaseClock(tell)

    stop = threading.Event()
    old = signal.signal(signal.SIGINT, lambda *_: stop.set())   # Ctrl-C: set-up stops, the iteration writes
    chains = bool(args.workers or args.scheduler)
    options = RunOptions(method=args.method, iterations=args.iterations, time_limit=args.time, seed=args.seed,
                         patches=args.patches, sequence=args.sequence, bundle_resolution=args.bundle_resolution,
                         gather_rays=args.gather_rays, threads=args.threads)
    try:
        check(options, chains=chains)
        scene = load_scene(args.scene)
        if args.resolution:
            if scene.camera is None:
                raise SceneError("the scene has no camera")
            scene.camera = scene.camera.with_resolution(*args.resolution)
        p = plan(scene, options, chains=chains)
        if chains:
            scene = lay_out(scene, p, stage=stage, stop=stop)
            return _render_chains(args, scene, p, stage, stop, t_start)
        scene, result = run_plan(scene, p, progress=bar, stop=stop, stage=stage, started=t_start)
    except (SceneError, ValueError) as e:
        print(f"raybundle: error: {e}", file=sys.stderr)
        return 2
    except Cancelled as e:
        print(f"raybundle: {e}: nothing written", file=sys.stderr)
        return 130
    finally:
        signal.signal(signal.SIGINT, old)
        bar.close()
    stats = dict(result.stats, phases=stage.finish())
    if p.choice:
        stats["auto"] = p.choice.as_dict()
    stats = _write_outputs(args, scene, result.image, stats)
    if "budget_note" in stats:
        print(f"raybundle: warning: {stats['budget_note']}: give --time more seconds", file=sys.stderr)
    state = "stopped early" if result.cancelled else "done"
    print(f"{state}: {stats['iterations']} iterations in {stats['seconds']:.1f} s, {scene.n_patches} patches, "
          f"{stats['rays_traced'] / 1e6:.1f} M rays -> {args.out}", file=sys.stderr)
    if "pixel_relative_rmse" in stats:
        print(f"error vs analytic: mean {np.round(stats['mean_relative_error'], 5).tolist()}, "
              f"pixel rel. RMSE {stats['pixel_relative_rmse']:.4f}", file=sys.stderr)
    return 130 if stop.is_set() else 0


def _render_chains(args, scene, plan, stage, stop, started):
    """``render --workers N`` / ``--scheduler ADDRESS``: independent chains on Dask of the
    laid-out ``scene``, merged; Ctrl-C (``stop``) merges what the chains have reported so far."""
    from .distributed import render_chains

    try:
        image, merged, its = render_chains(scene, plan, scheduler=args.scheduler, workers=args.workers, progress=stage,
                                           stop=stop, started=started)
    except (RuntimeError, ValueError, OSError) as e:
        print(f"raybundle: error: {e}", file=sys.stderr)
        return 2
    stats = _write_outputs(args, scene, image, dict(merged.stats, chains=merged.chains, chain_iterations=its,
                                                    patches=int(scene.n_patches)))
    state = "stopped early" if stop.is_set() else "done"
    print(f"{state}: {merged.chains} chains, {stats['iterations']} iterations ({its}), {scene.n_patches} patches "
          f"-> {args.out}", file=sys.stderr)
    return 130 if stop.is_set() else 0


def bounded_number(kind, low, high=None, what="a number"):
    """An argparse type: ``kind`` (int or float) in [low, high], else a one-line error."""
    def parse(text):
        try:
            x = kind(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{text!r} is not {what}") from None
        if not (np.isfinite(x) and x >= low and (high is None or x <= high)):
            raise argparse.ArgumentTypeError(f"{text} is not {what}")
        return x
    return parse


POSITIVE_INT = bounded_number(int, 1, what="a positive integer")
COUNT = bounded_number(int, 0, what="a non-negative integer")
SECONDS = bounded_number(float, 0.0, what="a non-negative number of seconds")


class OneLineErrors(argparse.ArgumentParser):
    """argparse that reports a bad argument in one line (no usage dump), exit status 2."""

    def error(self, message):
        self.exit(2, f"{self.prog}: error: {message} (see --help)\n")


def build_parser():
    p = OneLineErrors(prog="raybundle", description="Global illumination with ray bundles.")
    p.add_argument("--version", action="version", version=f"raybundle {__version__}")
    sub = p.add_subparsers(dest="command", required=True)
    r = sub.add_parser("render", help="render a built-in scene or a .npz scene to EXR")
    r.add_argument("scene", help="a built-in scene (cornell, cornell-glossy, furnace, furnace-glossy, small-light, "
                   "near-mirror, room-<seed>, glossy-room-<seed>) or FILE.npz")
    g = r.add_mutually_exclusive_group()
    g.add_argument("--time", type=SECONDS, help=f"seconds of the whole run, from loading the scene to the image "
                   f"written (default {DEFAULT_TIME_LIMIT:g})")
    g.add_argument("--iterations", type=COUNT, help="number of iterations (path-tracing: samples per pixel; "
                   "single-ray-iteration: steps of every chain; reproducible with --seed)")
    r.add_argument("--seed", type=COUNT, default=0)
    r.add_argument("--patches", type=COUNT, help=f"target patch count (default {DEFAULT_PATCHES:,}, or auto's "
                   "choice; 0 = one patch per input triangle)")
    r.add_argument("--resolution", type=bounded_number(int, 1, 65536, "a resolution in [1, 65536]"), nargs=2,
                   metavar=("W", "H"))
    r.add_argument("--method", default=StochasticIterationSolver.name, choices=sorted(SOLVERS) + ["auto"],
                   help=f"{StochasticIterationSolver.name} (default; ray bundles), ray-bundle-walk (random walks "
                        "of bundles), radiosity (diffuse scenes), point-collocation (vertex unknowns, diffuse "
                        "scenes), path-tracing (the unbiased random walk, images only), single-ray-iteration (light "
                        "tracing as a stochastic iteration, images only) or auto (chosen from what the scene holds; "
                        "the choice and its reason are printed and written to --stats)")
    r.add_argument("--sequence", choices=sorted(SEQUENCES),
                   help=f"(default {DEFAULT_SEQUENCE}, or auto's choice) random numbers of the global directions "
                        "(ray bundles); halton and sobol bias the "
                        "iterations (thesis 1.2, a warning says so); path-tracing takes halton as randomised "
                        "quasi-Monte Carlo, prng or stratified as the PRNG; single-ray-iteration the PRNG only")
    r.add_argument("--bundle-resolution", type=bounded_number(int, 0, 4096, "an integer in [0, 4096]"), default=0,
                   help="rays per bundle side (0 = auto)")
    r.add_argument("--gather-rays", type=bounded_number(int, -1, 65536, "an integer in [-1, 65536]"), default=-1,
                   help="final-gather rays per pixel next to concave edges and contacts: -1 (default) as many as "
                        "a quarter of a --time run buys, none with --iterations; N a fixed count, reproducible")
    r.add_argument("--threads", type=POSITIVE_INT, default=None)
    d = r.add_mutually_exclusive_group()
    d.add_argument("--workers", type=POSITIVE_INT, help="run that many independent chains on a local Dask "
                   "cluster and merge them (needs raybundle[distributed])")
    d.add_argument("--scheduler", help="run one chain per worker of the Dask cluster at this address and merge them")
    r.add_argument("--out", default="out/render.exr")
    r.add_argument("--stats", help="write statistics as JSON")
    b = sub.add_parser("bench", help="the methods' error against time on each scene (CSV, PNG charts, summary.md)")
    b.add_argument("--scenes", nargs="+", default=["cornell", "cornell-glossy", "furnace", "furnace-glossy"],
                   help="built-in names or .npz files")
    b.add_argument("--methods", nargs="+", default=["all"], help="all, or some of: " + ", ".join(METHODS))
    b.add_argument("--time", type=SECONDS, default=60.0, help="seconds per method and scene, from loading the "
                   "scene (default 60)")
    b.add_argument("--resolution", type=bounded_number(int, 1, 65536, "a resolution in [1, 65536]"), nargs=2,
                   metavar=("W", "H"), help="image size (default: the scene's)")
    b.add_argument("--reference-dir", default="out/reference", help="cached reference halves (default out/reference)")
    b.add_argument("--reference-time", type=SECONDS, default=600.0,
                   help="seconds of path tracing per reference half when one is missing (default 600)")
    b.add_argument("--throughput", action="store_true", help="also bundle visibility and ms per iteration")
    b.add_argument("--cycles", metavar="SCRIPT", help="also Cycles (bpy, CPU, no denoising or clamping) at "
                   "1, 2, 4, ... samples per pixel, each render timed from loading the scene, by SCRIPT (the "
                   "repository's tools/cycles_reference.py; it needs the bpy module)")
    b.add_argument("--out", default="out/bench")
    b.add_argument("--page", metavar="FILE.md", help="also write this bench's section of the benchmark page, its "
                   "summary and charts (make bench: docs/benchmarks.md)")
    return p


def main(argv=None):
    args = build_parser().parse_args(argv)
    if args.command == "render":
        return cmd_render(args)
    from .bench import run_bench

    return run_bench(args)


if __name__ == "__main__":
    sys.exit(main())
