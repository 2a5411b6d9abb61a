"""Chains on Dask: one prepared scene, one chain per worker, merged exactly.

    python -m raybundle render SCENE --workers N            # a local cluster of N processes
    python -m raybundle render SCENE --scheduler ADDRESS    # an existing dask.distributed cluster

(``pip install raybundle[distributed]``; not part of the Blender extension.)  The prepared
scene is scattered once to every worker.  Chain k runs with seed ``seed + k`` until the
shared deadline (or for ``iterations``), and every ``report_seconds`` publishes its
:class:`~raybundle.app.chains.ChainState` in a ``distributed.Variable``.  The client polls
those, reports per-chain progress, and when every chain has finished (or the deadline and
a grace period have passed) merges the newest state of each (:func:`raybundle.app.chains.merge`)
into a renderer of its own, which resolves the image.  A worker lost mid-run loses only
what its chain did since its last report: the chain is not restarted elsewhere (its seed
would repeat), its last report counts.

Over ``c`` chains the pooled image has the error of one chain run ``c`` times as long, less
each chain's own start (warm-up, first image pass) and the client's resolve; on one machine
the chains share its cores, so ``--workers`` pays off only across machines (or with more
cores than one chain's threads use).
"""
from __future__ import annotations

import concurrent.futures
import time
import uuid

from . import chains

try:                                    # the distributed extra (not in the Blender extension)
    import distributed
except ImportError:                     # pragma: no cover - depends on the extra being installed
    distributed = None


def _run_chain(scene, method, settings_dict, seed, deadline, iterations, report_seconds, name):
    """On a worker: one chain, iterated by the run loop (:class:`~raybundle.imaging.run.RunLoop`) for
    ``iterations`` or until ``deadline`` (a ``time.time()``).  Every ``report_seconds`` its
    state goes to the Variable ``name`` and its iteration count to the scheduler's metadata
    ``[name, "iterations"]`` (small, polled by the client for progress); returns the final
    state."""
    from ..imaging.run import RunLoop
    from ..imaging.settings import RenderSettings
    from .pipeline import make_renderer

    settings = RenderSettings(**dict(settings_dict, seed=seed))
    renderer = make_renderer(scene, settings, solver=method)
    var, client = distributed.Variable(name), distributed.get_client()

    def report():
        var.set(chains.state(renderer))
        client.set_metadata([name, "iterations"], int(renderer.solver.stats.iterations))

    try:
        loop = RunLoop(renderer, iterations, None if iterations is not None else max(deadline - time.time(), 0.0))
        while loop.advance(max_seconds=report_seconds):
            report()
        report()
        return chains.state(renderer)
    finally:
        renderer.tracer.close()


def render_chains(scene, plan, chains_count=None, scheduler=None, workers=None, report_seconds=2.0,
                  grace_seconds=30.0, progress=None, client=None, stop=None, started=None):
    """Render ``scene`` (laid out) as independent chains of ``plan``'s method on Dask (the plan
    made with ``chains=True``: :func:`~raybundle.app.plan.plan`), for its iterations or time limit;
    returns ``(image, merged ChainState, per-chain iteration counts)``.

    ``client``: a ``distributed.Client`` to use; else one for ``scheduler`` (an address)
    or for a new local cluster of ``workers`` processes (closed afterwards).  One chain per
    worker unless ``chains_count`` says otherwise.  ``progress(text)`` gets a line per
    poll: each chain's iterations (``-`` before its first report, ``lost`` once its worker
    is gone).  ``stop`` (an object with ``is_set()``, Ctrl-C) ends the wait: every chain's
    last report is merged (:class:`~raybundle.app.pipeline.Cancelled` if none has reported yet).
    The plan's ``time_limit`` is the budget from ``started`` (a ``time.perf_counter()`` reading,
    default now): the cluster's start and the scene's scattering count."""
    if distributed is None:             # pragma: no cover - depends on the extra being installed
        raise RuntimeError("chains on Dask need the distributed extra: pip install raybundle[distributed]")
    settings, time_limit, iterations = plan.settings, plan.time_limit, plan.iterations
    from dataclasses import asdict

    from ..imaging.run import iteration_time
    from .pipeline import make_renderer

    own = client is None
    cluster = renderer = None
    if own:
        if scheduler:
            client = distributed.Client(scheduler)
        else:
            cluster = distributed.LocalCluster(n_workers=int(workers or 2), threads_per_worker=1, processes=True,
                                               dashboard_address=None)
            client = distributed.Client(cluster)
    try:
        addresses = sorted(_workers(client))
        n = int(chains_count or len(addresses))
        if n < 1 or not addresses:
            raise ValueError("no workers to run chains on")
        # a key of its own (not the scene's hash): an earlier run's release of the same scene's
        # key reaches the scheduler on another stream and may land after this scatter
        scene_future = client.scatter(scene, broadcast=True, hash=False)
        base = asdict(settings)
        renderer = make_renderer(scene, settings, solver=plan.method)     # the client's: merges, resolves
        # the chains iterate until the deadline; the client's resolve then has the final image's
        # share, as a single run has (run.RunLoop)
        share = renderer.final_share()
        chain_time = None if time_limit is None else iteration_time(
            time_limit, time.perf_counter() if started is None else started, share)
        deadline = None if time_limit is None else time.time() + chain_time
        names = [f"raybundle-chain-{uuid.uuid4().hex}-{k}" for k in range(n)]
        futures = [client.submit(_run_chain, scene_future, plan.method, base, settings.seed + k, deadline, iterations,
                                 report_seconds, names[k], workers=[addresses[k % len(addresses)]],
                                 allow_other_workers=False, pure=False, key=f"chain-{names[k]}")
                   for k in range(n)]
        end = None if deadline is None else deadline + grace_seconds
        lost = _wait_for_chains(client, futures, names, addresses, end, stop, progress, report_seconds)
        latest = _latest_states(client, futures, names, lost)
        states = [s for s in latest if s is not None]
        if not states and stop is not None and stop.is_set():
            from .pipeline import Cancelled

            raise Cancelled("stopped before any chain reported")
        if not states:
            raise RuntimeError("no chain reported any state (every worker was lost)")
        merged = chains.merge(states)
        chains.apply(merged, renderer)
        image = renderer.resolve(None if time_limit is None or (stop is not None and stop.is_set())
                                 else share * chain_time)
        merged.stats["gather_rays_per_pixel"] = renderer.gather_rays_used
        return image, merged, [None if s is None else s.stats["iterations"] for s in latest]
    finally:
        if renderer is not None:
            renderer.tracer.close()
        if own:
            client.close()
            if cluster is not None:
                cluster.close()


def _workers(client):
    """The addresses of the cluster's workers, asked of the scheduler now.  Not
    ``client.scheduler_info()``: the client's periodic refresh asks for no workers and
    overwrites the same cache, so a poll racing it saw none and took every chain for lost."""
    return set(client.nthreads())


def _wait_for_chains(client, futures, names, addresses, end, stop, progress, report_seconds):
    """Poll the chains until none runs, ``end`` (a ``time.time()``) has passed or ``stop`` is
    set, telling ``progress`` each chain's reported iterations; returns per chain whether its
    worker was lost."""
    n = len(futures)
    while True:
        status = [f.status for f in futures]
        alive = _workers(client)
        # a chain whose worker left, or that the scheduler cancelled (its inputs' data lost with a worker)
        lost = [st == "cancelled" or (st == "pending" and addresses[k % len(addresses)] not in alive)
                for k, st in enumerate(status)]
        reported = [client.get_metadata([name, "iterations"], None) for name in names]
        if progress is not None:
            progress("chains: " + ", ".join("lost" if lost[k] else "-" if reported[k] is None
                                            else str(reported[k]) for k in range(n)))
        running = any(st == "pending" and not lost[k] for k, st in enumerate(status))
        if not running or (end is not None and time.time() > end) or (stop is not None and stop.is_set()):
            return lost
        try:
            distributed.wait(futures, timeout=min(report_seconds, 1.0), return_when="ALL_COMPLETED")
        except (TimeoutError, concurrent.futures.CancelledError):       # cancelled: lost, next poll
            pass


def _latest_states(client, futures, names, lost):
    """Each chain's final state, or for a chain lost or past the deadline its last report
    (None if it never reported); a chain that failed raises RuntimeError."""
    latest = []
    for k, f in enumerate(futures):
        if f.status == "finished":
            latest.append(f.result())
        elif f.status == "error" and not lost[k]:
            raise RuntimeError(f"chain {k} failed: {f.exception()!r}")
        else:                        # lost (or past the deadline): its last report, if any
            f.cancel()
            got = client.get_metadata([names[k], "iterations"], None)
            latest.append(distributed.Variable(names[k], client=client).get(timeout=30) if got is not None else None)
    return latest
