"""Independent chains: their exact merge (:mod:`raybundle.app.chains`) and chains on a Dask
``LocalCluster`` of 2 worker processes (:mod:`raybundle.app.distributed`)."""
import gc
import os
import threading
import time

import numpy as np
import pytest

from raybundle.app import chains, pipeline
from raybundle.imaging.settings import RenderSettings
from raybundle.scene import builtin as scenes

SETTINGS = dict(resolve_samples=4)


def run_chain(scene, seed, iterations, method="stochastic-iteration"):
    """One chain as a worker runs it: renderer steps until ``iterations``."""
    r = pipeline.make_renderer(scene, RenderSettings(seed=seed, **SETTINGS), solver=method)
    while r.solver.stats.iterations < iterations:
        r.step()
    return r


def same_resolve(renderer):
    """Fix the sub-pixel positions of the diffuse resolve (seeded per renderer otherwise)."""
    renderer.indirect.rng = np.random.default_rng([0, 2])
    return renderer


def test_merged_chains_pool_their_sums_and_counts():
    """Two chains of 40 iterations: the merged image's passes and diffuse indirect are the
    two chains' averages (equal weights: same pass and iteration counts), emission seen is
    pooled by its per-pixel sample counts, and the first shot by its per-tside counts."""
    sc = pipeline.prepare(scenes.cornell(resolution=(32, 32)), patches=300)
    rs = [run_chain(sc, seed, 40) for seed in (1, 2)]
    merged = chains.merge([chains.state(r) for r in rs])
    assert merged.chains == 2 and merged.averaged == sum(r.solver.averaged for r in rs)
    fresh = same_resolve(chains.apply(merged, pipeline.make_renderer(sc, RenderSettings(seed=1, **SETTINGS))))
    assert [r.passes for r in rs] == [rs[0].passes] * 2 and fresh.passes == 2 * rs[0].passes
    diffuse = [same_resolve(r).diffuse_indirect() for r in rs]
    # (the projection is a CG solve to a relative 1e-10 of its residual: linear to about 1e-5)
    assert np.allclose(fresh.diffuse_indirect(), 0.5 * (diffuse[0] + diffuse[1]), rtol=1e-4, atol=1e-9)
    assert np.allclose(fresh.pass_sum, sum(r.pass_sum for r in rs), rtol=1e-12)
    assert np.array_equal(fresh.pass_samples, sum(r.pass_samples for r in rs))
    counts = sum(r.emission.count for r in rs)
    assert np.allclose(fresh.emission.sum, sum(r.emission.sum for r in rs)) and np.array_equal(fresh.emission.count,
                                                                                             counts)
    fs = [r.solver.first_shot for r in rs]
    # each receiving triangle side's mean weighted by the two chains' sample counts there (they
    # differ: the refinement goes where each chain's samples spread), then the side's area-weighted
    # sum, in 64 bits from the pooled 32-bit sums, as the first shot forms E
    (e0, _, c0), (e1, _, c1) = fs[0].sums(), fs[1].sums()
    mean = (e0 + e1) / np.maximum(c0 + c1, 1).astype(float)[:, None, None]
    ts = fs[0].receiving_tsides
    w = sc.triangle_area[sc.tside_triangle[ts]] / fs[0].receiving_area[sc.tside_side[ts]]
    want = np.zeros_like(fs[0].E)
    np.add.at(want, sc.tside_side[ts], w[:, None, None] * mean)
    assert not np.array_equal(c0, c1) and np.allclose(fresh.solver.first_shot.E, want, rtol=1e-10)
    assert not np.allclose(fs[0].E, fs[1].E)                                               # different samples
    with pytest.raises(ValueError, match="another scene"):
        chains.apply(merged, pipeline.make_solver(pipeline.prepare(scenes.cornell(), patches=100)))


def test_merged_solver_chains_bake_their_weighted_average():
    """Patch values (what bakes and color attributes read) pool by iterations averaged:
    chains of 30 and 60 iterations weigh 30 : 60 (their iterates warmed up by b transfers
    before, 20 in this furnace, mean albedo 0.7: 0.7^20 < 0.1%, none of them averaged)."""
    sc = pipeline.prepare(scenes.furnace(), patches=150)
    solvers = []
    for seed, its in ((1, 30), (2, 60)):
        s = pipeline.make_solver(sc, RenderSettings(seed=seed))
        for _ in range(its):
            s.step()
        solvers.append(s)
    merged = chains.merge([chains.state(s) for s in solvers])
    fresh = chains.apply(merged, pipeline.make_solver(sc, RenderSettings(seed=1)))
    assert solvers[0].warm_up_steps == solvers[0].stats.warm_up == 20
    w = np.array([30, 60]) / 90
    assert [s.averaged for s in solvers] == [30, 60] and fresh.averaged == 90
    assert np.allclose(fresh.mean_incoming, w[0] * solvers[0].mean_incoming + w[1] * solvers[1].mean_incoming)
    assert fresh.stats.iterations == 90
    # the first shot pools per-tside sample counts (different here: 30 and 60 refinements)
    fs = [s.first_shot for s in solvers]
    assert np.array_equal(fresh.first_shot._count, fs[0]._count + fs[1]._count)
    assert np.all(np.isfinite(fresh.patch_radiance()))


distributed = pytest.importorskip("distributed")


@pytest.fixture(scope="module")
def cluster():
    from distributed import Client, LocalCluster

    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None) as lc:
        with Client(lc) as client:
            yield lc, client


@pytest.mark.parametrize("method", ["stochastic-iteration", "radiosity"])
def test_chains_on_two_workers_equal_the_same_seeds_run_one_by_one(cluster, method):
    """The chains run the plan's method (before the one set-up path they ran the bundle
    iteration whatever --method said)."""
    from raybundle.app.distributed import render_chains
    from raybundle.app.plan import Plan

    _, client = cluster
    sc = pipeline.prepare(scenes.cornell(resolution=(24, 24)), patches=200)
    settings = RenderSettings(seed=5, **SETTINGS)
    lines = []
    image, merged, its = render_chains(sc, Plan(method, 200, 24, None, settings), client=client,
                                       report_seconds=0.2, progress=lines.append)
    assert its == [24, 24] and merged.chains == 2 and lines
    local = chains.merge([chains.state(run_chain(sc, seed, 24, method)) for seed in (5, 6)])
    expected = chains.apply(local, pipeline.make_renderer(sc, settings, solver=method)).image()
    assert np.allclose(image, expected, rtol=1e-6, atol=1e-9), np.abs(image - expected).max()


def test_timed_chains_get_the_final_gather_of_a_single_run(cluster):
    """A timed run of chains leaves the client's resolve the final image's share, as a single
    run's loop does: the automatic final gather runs next to the box's concave edges (before
    the run loop, chains resolved without it)."""
    from raybundle.app.distributed import render_chains
    from raybundle.app.plan import Plan

    _, client = cluster
    sc = pipeline.prepare(scenes.cornell(resolution=(24, 24)), patches=200)
    started = time.perf_counter()
    image, merged, its = render_chains(sc, Plan("stochastic-iteration", 200, None, 4.0, RenderSettings(seed=3)),
                                       client=client, report_seconds=0.5, started=started)
    assert merged.stats["gather_rays_per_pixel"] >= 256 and all(i >= 8 for i in its)
    assert time.perf_counter() - started < 4.0 + 3.0           # the budget, give or take a poll


def test_cli_workers_writes_the_merged_image(tmp_path):
    import json
    import subprocess
    import sys

    from raybundle.util.io import read_exr

    out, stats = tmp_path / "f.exr", tmp_path / "f.json"
    p = subprocess.run([sys.executable, "-m", "raybundle", "render", "furnace", "--iterations", "10",
                        "--patches", "100", "--resolution", "12", "12", "--workers", "2", "--out", str(out),
                        "--stats", str(stats)],
                       capture_output=True, text=True, timeout=300)
    assert p.returncode == 0, p.stderr
    s = json.loads(stats.read_text())
    assert s["chains"] == 2 and s["chain_iterations"] == [10, 10] and s["iterations"] == 20
    img = read_exr(out)
    assert img.shape == (12, 12, 3) and np.isfinite(img).all() and "chains: 10, 10" in p.stderr


def test_the_chains_see_the_workers_whatever_the_clients_refresh_left(cluster):
    """The client's periodic refresh of ``scheduler_info()`` asks for no workers: a poll that
    read that cache took every chain for lost ("no chain reported any state", a CI flake)."""
    from raybundle.app.distributed import _workers

    lc, client = cluster
    client.sync(client._update_scheduler_info)                   # what the periodic refresh does
    assert client._scheduler_identity["workers"] == {}           # the cache the old poll could read
    assert _workers(client) == set(lc.scheduler_info["workers"]) and len(_workers(client)) == 2


def test_an_earlier_runs_late_release_of_the_same_scene_loses_nothing(cluster):
    """A run's scene release travels on the client's batched stream, the next run's scatter on
    an rpc of its own: when the release of the same scene lands after the new scatter (held
    back here until it returns), a scene scattered under its content hash was forgotten and
    every chain failed with "lost data" (a CI failure of the lost-worker test)."""
    from raybundle.app.distributed import render_chains
    from raybundle.app.plan import Plan

    _, client = cluster
    sc = pipeline.prepare(scenes.furnace(resolution=(8, 8)), patches=100)
    plan = Plan("stochastic-iteration", 100, 3, None, RenderSettings(seed=2, **SETTINGS))
    send, scatter, held = client._send_to_scheduler, client.scatter, []

    def late(msg):
        (held.append if msg.get("op") == "client-releases-keys" else send)(msg)

    def scatter_then_release(*args, **kwargs):
        out = scatter(*args, **kwargs)
        gc.collect()
        for msg in held:
            send(msg)
        held.clear()
        time.sleep(0.2)
        return out

    client._send_to_scheduler, client.scatter = late, scatter_then_release
    try:
        for _ in range(2):
            _, merged, its = render_chains(sc, plan, client=client, report_seconds=0.2)
            assert its == [3, 3] and merged.chains == 2
    finally:
        del client._send_to_scheduler, client.scatter                # the class's own again
        for msg in held:
            send(msg)


def furnace_chains_with(client, accident):
    """Two 12 s chains of the furnace with ``accident()`` befalling them 6 s in (on a thread):
    ``(scene, image, merged, iterations)`` as :func:`render_chains` returns them."""
    from raybundle.app.distributed import render_chains
    from raybundle.app.plan import Plan

    sc = pipeline.prepare(scenes.furnace(resolution=(16, 16)), patches=200)

    def later():
        time.sleep(6.0)
        accident()

    thread = threading.Thread(target=later)
    thread.start()
    try:
        image, merged, its = render_chains(sc, Plan("stochastic-iteration", 200, None, 12.0,
                                                    RenderSettings(seed=2, **SETTINGS)), client=client,
                                           report_seconds=0.5, grace_seconds=10.0)
    finally:
        thread.join()
    return sc, image, merged, its


def test_a_chain_the_scheduler_cancels_costs_only_its_last_segment(cluster):
    """A chain cancelled mid-run (as the scheduler cancels one whose inputs were lost with a
    worker, "lost dependencies"): its last report still counts and the other chain runs to the
    end, as for a lost worker.  Before, the cancellation escaped from the wait as
    FuturesCancelledError and the run ended with a traceback."""
    from distributed import Future

    lc, client = cluster

    def cancel():
        keys = sorted(k for k in list(client.futures) if str(k).startswith("chain-") and str(k).endswith("-0"))
        client.cancel([Future(k, client) for k in keys])

    sc, image, merged, its = furnace_chains_with(client, cancel)
    # (a task Dask cancels runs on in its worker's thread: the cancelled chain may report on)
    assert merged.chains == 2 and all(i is not None and i > 0 for i in its), its
    assert np.isfinite(image).all()


def test_a_lost_worker_costs_only_its_last_segment(cluster):
    """Killing one worker mid-run: its chain's last report still counts, the other chain
    runs to the end, and the pooled furnace image is right (image mean within 5 SE of the
    analytic radiance, SE from the pixel spread; each chain alone is unbiased)."""
    lc, client = cluster
    victim = sorted(client.nthreads())[0]

    def kill():
        try:
            client.run(lambda: os._exit(1), workers=[victim])
        except Exception:
            pass

    sc, image, merged, its = furnace_chains_with(client, kill)
    assert merged.chains == 2 and all(i is not None and i > 0 for i in its), its
    assert its[0] < its[1], its                          # the lost chain stopped early
    exact = sc.analytic_radiance
    px = image.reshape(-1, 3)
    se = px.std(axis=0) / np.sqrt(len(px))
    assert np.all(np.abs(px.mean(axis=0) - exact) < 5 * se + 0.01 * exact), (px.mean(axis=0), exact)
