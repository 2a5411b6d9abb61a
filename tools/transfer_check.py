"""The bundles' transfer against gather rays on one solution: do both read the same operator?

A patch method's iteration (``transfer``, with its control variate) and the gathers that read
its solution (the final gather, the tiny sides', the glossy senders') estimate the same thing:
each side's incoming irradiance ``E_i`` from the sides' current radiance, averaged over the side.
After ``--iterations`` steps the iterate is set to the running average, and each side's
``E_i`` is estimated twice: by ``--transfers`` transfers (each ``directions_per_step``
bundles, with the control variate, as the iteration does) and by ``--rays`` cosine-distributed
gather rays from uniform points of the side reading the same solution
(:meth:`~raybundle.methods.patch_solution.PatchSolution._gather`).  Their difference in power
(``E_i A_i``) is printed by the direction the sides face and by how open they are (the share of
gather rays that leave the scene), with its standard error, and the sides that differ most.

A difference beyond a few standard errors is an inconsistency between the two (a side partly
covered that lines cannot reach but gather points can, light lost between hits); an image bias
that both share is the finite elements' own (the patch values they both read).  The scene is a
built-in name or a ``.npz`` file (``python -m raybundle_addon ROOM.blend --save-npz``)::

    python tools/transfer_check.py room-1 --iterations 64
    python tools/transfer_check.py bathroom-clay.npz --iterations 128 --transfers 300 --rays 64
"""
from __future__ import annotations

import argparse
import time

import numpy as np


def estimates(solver, transfers, rays, rng):
    """``(Eb, var_b, Eg, var_g, open)``: per side (S,) the mean over RGB of the transfers' and
    the gathers' ``E_i``, the variances of those means, and the share of gather rays that left
    the scene."""
    from raybundle.patches.side_points import SidePoints
    from raybundle.tracing.sampling import cosine_directions, frames_from_normals

    n_sides = len(solver.area)
    total, squares = np.zeros(n_sides), np.zeros(n_sides)
    for _ in range(transfers):
        e = solver.transfer(control=solver.mean_incoming)[0].mean(axis=1)
        total += e
        squares += e * e
    eb = total / transfers
    var_b = np.maximum(squares / transfers - eb ** 2, 0.0) / transfers
    points = SidePoints(solver.scene, np.ones(n_sides, bool))
    eg, var_g, left = np.zeros(n_sides), np.zeros(n_sides), np.zeros(n_sides)
    step = max(1, (1 << 20) // rays)
    for lo in range(0, n_sides, step):
        sides = np.arange(lo, min(n_sides, lo + step))
        u = rng.random((len(sides) * rays, 5))
        p, n = points.draw(np.repeat(sides, rays), u[:, :3])
        t, b = frames_from_normals(n)
        got, sky = solver._gather(p, n, cosine_directions(u[:, 3:], t, b, n))
        got = np.pi * got.mean(axis=1).reshape(len(sides), rays)
        eg[sides] = got.mean(axis=1)
        var_g[sides] = got.var(axis=1) / rays
        left[sides] = sky.reshape(len(sides), rays).mean(axis=1)
    return eb, var_b, eg, var_g, left


def report(solver, eb, var_b, eg, var_g, left, top=10):
    """Print the differences in power by the axis the sides face, by their openness, and the
    sides that differ most."""
    a, n = solver.area, solver.normal
    d, se2 = (eg - eb) * a, (var_b + var_g) * a * a
    axis = np.argmax(np.abs(n), axis=1)
    facing = np.array(["-x", "+x", "-y", "+y", "-z", "+z"])[axis * 2 + (n[np.arange(len(a)), axis] > 0)]

    def row(name, m):
        power = (eb * a)[m].sum()
        print(f"  {name:<22} {int(m.sum()):>7,} sides {a[m].sum():>9.3f} m^2  power {power:>10.4g}  "
              f"gather - transfer {d[m].sum():+.4g} ({100 * d[m].sum() / max(power, 1e-300):+.2f}%, "
              f"{d[m].sum() / max(np.sqrt(se2[m].sum()), 1e-300):+.1f} SE)")
    print("by the direction the sides face:")
    for f in ("-x", "+x", "-y", "+y", "-z", "+z"):
        row(f"facing {f}", facing == f)
    print("by the share of gather rays that leave the scene:")
    for lo, hi in ((0.0, 0.05), (0.05, 0.3), (0.3, 0.8), (0.8, 1.01)):
        row(f"{lo:.2f}-{min(hi, 1):.2f}", (left >= lo) & (left < hi))
    row("all", np.ones(len(a), bool))
    z = (eg - eb) / np.maximum(np.sqrt(var_b + var_g), 1e-300)
    print("sides that differ most in power (|gather - transfer| x area; z in SE):")
    for i in np.argsort(-np.abs(d))[:top]:
        print(f"  side {i}: facing {facing[i]}, {a[i]:.4g} m^2, transfer {eb[i]:.4g}, gather {eg[i]:.4g}, "
              f"z {z[i]:+.1f}, {100 * left[i]:.0f}% of its rays leave")


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("scene", help="a built-in scene name or a .npz file")
    p.add_argument("--iterations", type=int, default=64, help="iterations before the check (default 64)")
    p.add_argument("--transfers", type=int, default=200, help="transfers averaged (default 200)")
    p.add_argument("--rays", type=int, default=64, help="gather rays per side (default 64)")
    p.add_argument("--patches", type=int, default=None, help="target patch count (default: the plan's)")
    p.add_argument("--seed", type=int, default=1)
    a = p.parse_args(argv)

    from raybundle.app import pipeline
    from raybundle.app.plan import RunOptions, plan
    from raybundle.scene.builtin import load_scene

    t0 = time.perf_counter()
    scene = load_scene(a.scene)
    chosen = plan(scene, RunOptions(iterations=a.iterations, seed=a.seed, patches=a.patches))
    solver = pipeline.make_solver(pipeline.lay_out(scene, chosen), chosen.settings)
    try:
        if not hasattr(solver, "transfer"):
            raise SystemExit(f"transfer_check: {chosen.method} has no bundle transfer")
        for _ in range(a.iterations):
            solver.step()
        solver.incoming = solver.mean_incoming.copy()          # both read the running average
        print(f"{a.scene}: {len(solver.area):,} sides, {a.iterations} iterations "
              f"({time.perf_counter() - t0:.1f} s)", flush=True)
        report(solver, *estimates(solver, a.transfers, a.rays, np.random.default_rng(a.seed)))
    finally:
        solver.tracer.close()
    print(f"{time.perf_counter() - t0:.1f} s in all")


if __name__ == "__main__":
    main()
