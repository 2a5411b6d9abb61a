"""Headless rendering and baking with the ``bpy`` module::

    raybundle-blender SCENE.blend --out out.exr [--time S] [--iterations N] [--seed K]
                      [--patches N] [--resolution-percentage P] [--save-npz scene.npz]
    raybundle-blender SCENE.blend --bake OUT.blend [--lightmaps DIR] [--lightmap-size N]
                      [--domain point|corner] [--subdivide LEVELS] [--time S] [--iterations N] ...

``raybundle-blender`` is this module's ``main`` installed as a command (the repository's
``pyproject.toml``: ``pip install ./core .`` beside ``bpy``); ``python -m raybundle_addon``
is the same from the repository's root.

Registers the add-on in the ``bpy`` module, opens the file, renders its scene
with the ``RAYBUNDLE`` engine through ``bpy.ops.render.render`` (the same code
path as ``blender -b SCENE.blend -E RAYBUNDLE -o //out -f 1``, with Blender's
render-time depsgraph: render modifier levels, render visibility) and writes
the linear radiance as a 32-bit float multilayer EXR as Blender names it: a
``<view layer>.Combined`` pass (RGBA) for each view layer the file renders (its enabled
ones, or the active one alone with Render Single Layer), plus an sRGB PNG preview of each
beside it (``OUT.png`` for one layer, ``OUT.<view layer>.png`` for several).
Options not given come from the file's ``scene.raybundle`` settings; those given replace
them in memory while it runs (:func:`options_applied`), as the panel would; the file is not
changed.

``--bake`` runs the ``raybundle.bake`` job instead (:mod:`.bake`): a ``RayBundle``
color attribute on every mesh and, with ``--lightmaps DIR``, a lightmap EXR per mesh
with a UV map in ``DIR`` (loaded into the file as Images), then saves the baked
copy of the file as ``OUT.blend`` (the input file is not changed).
``--save-npz`` also writes the exported scene in the core's ``.npz`` format
(``python -m raybundle render scene.npz`` renders it without Blender).

A progress bar goes to stderr; Ctrl-C stops after the current iteration and
still writes the image so far (exit status 130).  Bad arguments and scenes that
cannot be rendered give a one-line error and exit status 2.
"""
from __future__ import annotations

import contextlib
import os
import signal
import sys
import threading
import time
from dataclasses import replace


def build_parser():
    from raybundle.app.cli import COUNT, SECONDS, OneLineErrors, bounded_number

    p = OneLineErrors(prog="raybundle-blender",
                      description="Render a .blend with the Ray Bundle GI engine (bpy module, no Blender UI).")
    p.add_argument("blend", help="the .blend file")
    what = p.add_mutually_exclusive_group(required=True)
    what.add_argument("--out", help="render: the output EXR (linear radiance, 32-bit float)")
    what.add_argument("--bake", metavar="OUT.blend", help="bake: save the baked copy of the file here")
    p.add_argument("--lightmaps", metavar="DIR", help="bake: also a lightmap per mesh with a UV map, into DIR")
    p.add_argument("--lightmap-size", type=bounded_number(int, 16, 16384, "an integer in [16, 16384]"),
                   help="bake: lightmap width and height in texels (default: the file's)")
    p.add_argument("--domain", choices=("point", "corner"), help="bake: color attribute domain (default: the file's)")
    p.add_argument("--subdivide", metavar="LEVELS", type=bounded_number(int, 1, 6, "an integer in [1, 6]"),
                   help="bake: into a copy of each mesh cut up to LEVELS times where the light needs it")
    g = p.add_mutually_exclusive_group()
    g.add_argument("--time", type=SECONDS, help="seconds to iterate (default: the file's time limit)")
    g.add_argument("--iterations", type=bounded_number(int, 1, what="a positive integer"),
                   help="number of iterations (reproducible with --seed)")
    p.add_argument("--seed", type=COUNT, help="random seed (default: the file's)")
    p.add_argument("--patches", type=COUNT, help="target patch count (default: the file's)")
    p.add_argument("--resolution-percentage", type=bounded_number(int, 1, 1000, "an integer in [1, 1000]"),
                   help="override the file's resolution percentage")
    p.add_argument("--scene", help="scene name (default: the file's active scene)")
    p.add_argument("--save-npz", metavar="NPZ", help="also write the exported scene as .npz")
    return p


def _fail(message, status=2):
    print(f"raybundle-blender: error: {message}", file=sys.stderr)
    return status


def main(argv=None):
    # Ctrl-C from the very start (importing bpy, opening the file) is heard, not lost: before
    # the render nothing is written (exit 130); during it, the image so far is
    interrupted = threading.Event()
    old_handler = signal.signal(signal.SIGINT, lambda *_: interrupted.set())
    try:
        return _main(argv, interrupted)
    finally:
        signal.signal(signal.SIGINT, old_handler)


def _main(argv, interrupted):
    args = build_parser().parse_args(argv)
    problem = _bad_arguments(args)
    if problem:
        return _fail(problem)

    import bpy

    from raybundle.app.cli import ProgressBar

    from . import engine, register

    if not hasattr(bpy.types.Scene, "raybundle"):
        register()
    scene = _open_scene(args)
    if isinstance(scene, int):
        return scene
    from raybundle.app.plan import check

    from .properties import run_options

    with options_applied(scene.raybundle, args):
        options = run_options(scene)
    try:
        check(options, bake=args.bake is not None)
    except ValueError as e:
        return _fail(str(e))
    if args.resolution_percentage is not None:
        scene.render.resolution_percentage = args.resolution_percentage
    if interrupted.is_set():
        print("stopped before the render: nothing written", file=sys.stderr)
        return 130
    if args.bake is not None:
        return _bake(args, scene, options, interrupted)
    scene.render.engine = "RAYBUNDLE"

    bar = ProgressBar()
    state = {"job": None, "layers": {}}

    def observe(job, event):
        state["job"] = job
        state["layers"].setdefault(job.depsgraph.view_layer.name, job)
        if interrupted.is_set():          # Ctrl-C before the job existed
            job.stop.set()
        # the exported scene once its world is in it (a world Blender renders arrives after the layout)
        if args.save_npz and not state.get("saved") and job.export is not None and job.export.world_render is None:
            job.export.scene.save_npz(args.save_npz)
            state["saved"] = True
        if event in ("progress", "image") and job.renderer is not None:
            bar(job.fraction, {"iterations": job.renderer.solver.stats.iterations,
                               "seconds": time.perf_counter() - job.t_start})

    def on_interrupt(*_):
        interrupted.set()
        engine.cancel_all()

    old = signal.signal(signal.SIGINT, on_interrupt)
    engine.observers.append(observe)
    try:
        with options_applied(scene.raybundle, args):
            bpy.ops.render.render(write_still=False, scene=scene.name)
    except RuntimeError as e:                   # the engine's ERROR report
        bar.close()
        msg = str(e).strip().splitlines()[-1].removeprefix("Error: ").removeprefix("Ray Bundle GI: ")
        return _fail(msg)
    finally:
        engine.observers.remove(observe)
        signal.signal(signal.SIGINT, old)
    bar.close()
    job = state["job"]
    if job is not None and job.last_image is None and job.stop.is_set():
        print("stopped during set-up: nothing written", file=sys.stderr)
        return 130
    if job is None or job.last_image is None:
        return _fail("the render produced no image", 1)
    return _write_render(args, scene, job, state["layers"])


def _open_scene(args):
    """Open ``args.blend`` and make its scene ``args.scene`` (or the active one) the window's:
    the scene, or the exit code of a one-line error."""
    import bpy

    try:
        bpy.ops.wm.open_mainfile(filepath=os.path.abspath(args.blend))
    except RuntimeError as e:
        return _fail(f"cannot open {args.blend}: {str(e).strip().splitlines()[-1]}")
    scene = bpy.data.scenes.get(args.scene) if args.scene else bpy.context.scene
    if scene is None:
        return _fail(f"--scene {args.scene!r}: the file has scenes {[s.name for s in bpy.data.scenes]}")
    if bpy.context.window is not None and bpy.context.window.scene != scene:
        bpy.context.window.scene = scene
    return scene


def _write_render(args, scene, job, jobs):
    """Write the rendered view layers of ``jobs`` ({view layer: render job}) to ``args.out`` (an
    EXR of layers with the run's figures, a PNG a layer), print the warnings and a summary; the
    exit code (130 when ``job``, the last, was stopped early)."""
    from raybundle.util.io import write_layers_exr, write_png

    from .properties import LAST_RUN

    stats = LAST_RUN.get(scene.name, {}).get("stats", {})
    header = {"raybundle_" + k: v for k, v in stats.items() if isinstance(v, (int, float, str))}
    layers = {name: j.last_image for name, j in jobs.items() if j.last_image is not None}
    write_layers_exr(args.out, layers, header)
    stem = os.path.splitext(args.out)[0]
    for name, image in layers.items():
        write_png(f"{stem}.png" if len(layers) == 1 else f"{stem}.{name}.png", image)
    for w in LAST_RUN.get(scene.name, {}).get("warnings", []):
        print(f"warning: {w}", file=sys.stderr)
    cancelled = job.stop.is_set()
    print(f"{'stopped early' if cancelled else 'done'}: {stats.get('iterations', 0)} iterations in "
          f"{stats.get('seconds', 0):.1f} s, {stats.get('patches', 0)} patches, "
          f"{stats.get('rays_traced', 0) / 1e6:.1f} M rays -> {args.out}", file=sys.stderr)
    return 130 if cancelled else 0


def _bad_arguments(args):
    """One line on what in ``args`` cannot run, or None; the outputs are checked writable
    before the work, not found unwritable after it."""
    if not os.path.isfile(args.blend):
        return f"{args.blend}: no such file"
    if not args.blend.endswith(".blend"):
        return f"{args.blend}: not a .blend file"
    if args.bake is None and (args.lightmaps or args.lightmap_size or args.domain or args.subdivide):
        return "--lightmaps, --lightmap-size, --domain and --subdivide go with --bake"
    from raybundle.util.io import OutputError, check_output

    try:
        if args.out is not None:
            check_output(args.out, "--out", suffix=".exr")
        if args.bake is not None:
            check_output(args.bake, "--bake", suffix=".blend")
        if args.lightmaps:
            check_output(args.lightmaps, "--lightmaps", folder=True)
        if args.save_npz:
            check_output(args.save_npz, "--save-npz", suffix=".npz")
    except OutputError as e:
        return str(e)
    return None


@contextlib.contextmanager
def options_applied(rb, args):
    """Within the block, the command line's ``--time``, ``--iterations``, ``--seed`` and
    ``--patches`` where given replace the scene's settings ``rb``, as the panel sets them; the
    settings are restored after it (a baked copy of the file keeps the file's own)."""
    names = ("time_limit", "iterations", "seed", "patches")
    saved, choice = {k: getattr(rb, k) for k in names}, rb.get("budget_choice")
    if args.time is not None:
        rb.budget, rb.time_limit = "TIME", args.time
    if args.iterations is not None:
        rb.budget, rb.iterations = "ITERATIONS", args.iterations
    if args.seed is not None:
        rb.seed = args.seed
    if args.patches is not None:
        rb.patches = args.patches
    try:
        yield
    finally:
        for k, v in saved.items():
            setattr(rb, k, v)
        if choice is None:
            rb.pop("budget_choice", None)
        else:
            rb["budget_choice"] = choice


def _bake(args, scene, options, interrupted):
    """The ``--bake`` path: :class:`.bake.BakeJob` with a progress bar, then save the copy."""
    import bpy

    from raybundle.app.cli import ProgressBar
    from raybundle.app.pipeline import Cancelled
    from raybundle.scene.model import SceneError

    from .bake import BakeJob
    from .properties import BakeSettings

    bake = replace(BakeSettings.from_scene(scene), color_attribute=True, lightmaps=bool(args.lightmaps))
    if args.domain:
        bake.domain = args.domain.upper()
    if args.subdivide:
        bake.subdivide, bake.subdivide_levels = True, args.subdivide
    if args.lightmaps:
        bake.directory = os.path.abspath(args.lightmaps)
    if args.lightmap_size:
        bake.lightmap_size = args.lightmap_size
    job = BakeJob(bpy.context.evaluated_depsgraph_get(), options, bake)
    bar = ProgressBar()
    if interrupted.is_set():
        job.stop.set()
    old = signal.signal(signal.SIGINT, lambda *_: job.stop.set())
    try:
        job.start()
        t0 = time.perf_counter()
        more = True
        while more:
            more = job.step(0.5)
            bar(job.fraction, {"iterations": job.solver.stats.iterations, "phase": job.phase,
                               "seconds": time.perf_counter() - t0})
        bar.close()
        out = job.finish()
    except (SceneError, ValueError) as e:
        bar.close()
        return _fail(str(e))
    except Cancelled as e:
        bar.close()
        print(f"{e}: nothing written", file=sys.stderr)
        return 130
    finally:
        signal.signal(signal.SIGINT, old)
    for w in out.warnings:
        print(f"warning: {w}", file=sys.stderr)
    target = os.path.abspath(args.bake)
    os.makedirs(os.path.dirname(target), exist_ok=True)
    bpy.ops.wm.save_as_mainfile(filepath=target, copy=True)
    st = out.stats
    print(f"{'stopped early' if out.cancelled else 'baked'}: {len(out.attributes)} color attributes, "
          f"{len(out.lightmaps)} lightmaps; {st['iterations']} iterations, {st['patches']} patches, "
          f"{st['total_seconds']:.1f} s -> {target}", file=sys.stderr)
    return 130 if out.cancelled else 0


if __name__ == "__main__":
    sys.exit(main())
