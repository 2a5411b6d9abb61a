"""Point collocation with linear basis functions (:mod:`raybundle.methods.point_collocation`).

Statistical tolerances: fixed seeds; 4.5 standard errors, estimated from batch means (the
furnace) or from the spread of independent directions (the collocation operator).
"""
import numpy as np
import pytest
from test_solver import assert_converged, batch_means

from raybundle.app import pipeline
from raybundle.imaging.settings import RenderSettings
from raybundle.scene import builtin as scenes
from raybundle.tracing.sampling import frames_from_normals, uniform_sphere


def collocation_renderer(name="furnace", patches=300, seed=0, res=(16, 16)):
    sc = pipeline.prepare(scenes.load_scene(name), patches=patches)
    sc.camera = sc.camera.with_resolution(*res)
    return pipeline.make_renderer(sc, RenderSettings(sequence="prng", seed=seed, resolve_samples=4),
                                  solver="point-collocation")


def test_furnace_converges_to_the_analytic_radiance():
    """The closed furnace: side means and image converge to Le / (1 - a) within 4.5 SE of
    their batch means; the unknowns are the welded vertices (226 here, against 276 sides)."""
    r = collocation_renderer()
    patch, img = batch_means(r, 8, 40)
    exact = r.scene.analytic_radiance
    assert_converged(patch, exact, max_se=0.01)
    assert_converged(img, exact, max_se=0.01)
    s = r.solver
    assert s.report()["vertices"] == s.reconstruction.n_vertices > 0
    r.tracer.close()


def test_collocation_equals_a_direct_integration_of_the_interpolant():
    """For a fixed vertex field (ten steps into the Cornell box), the operator's estimate at
    a vertex, 4 pi cos+ L(h(x, -d), d) over uniform d, equals the irradiance the same
    interpolated radiance gives by cosine-distributed rays (pi times their mean radiance),
    traced and read here independently: per vertex within 4.5 combined SE."""
    r = collocation_renderer("cornell", patches=200)
    s, sc, tr = r.solver, r.scene, r.tracer
    for _ in range(10):
        s.step()
    rng = np.random.default_rng(4)
    verts = rng.choice(np.nonzero(s.vertex_receives)[0], 12, replace=False)
    blocks, per_block = 200, 100                  # block means of 100 uniform directions each
    d = uniform_sphere(rng.random(blocks * per_block), rng.random(blocks * per_block)).reshape(blocks, per_block, 3)
    keep = s.vertex_receives.copy()
    s.vertex_receives = np.zeros_like(keep)
    s.vertex_receives[verts] = True
    per_block_e = np.stack([s.collocate(dk)[verts] for dk in d])                      # (blocks, 12, 3)
    s.vertex_receives = keep
    a_mean, a_se = per_block_e.mean(axis=0), per_block_e.std(axis=0) / np.sqrt(blocks)
    # cosine-distributed rays from the same points, the radiance read as the solver reads it
    x, n = s.vertex_point[verts], s.vertex_normal[verts]
    k = 20000
    tu, tv = frames_from_normals(np.repeat(n, k, axis=0))
    phi, rr = 2 * np.pi * rng.random(len(tu)), np.sqrt(rng.random(len(tu)))
    w = (tu * (rr * np.cos(phi))[:, None] + tv * (rr * np.sin(phi))[:, None]
         + np.repeat(n, k, axis=0) * np.sqrt(1 - rr * rr)[:, None])
    tri, _, bu, bv = tr.first_hit(np.repeat(x + n * tr.eps, k, axis=0), w)
    L = np.zeros((len(w), 3))
    h = np.nonzero(tri >= 0)[0]
    ts = sc.seen_tside(tri[h], w[h])
    front = np.einsum("ij,ij->i", sc.tside_normal[ts], -w[h]) > 0
    h, ts = h[front], ts[front]
    side = sc.tside_side[ts]
    bary = np.stack([1 - bu[h] - bv[h], bu[h], bv[h]], axis=1)
    e = np.einsum("nk,nkc->nc", bary, s.vertex_incoming[s.reconstruction.ids[ts]]) + s.first_shot.E.sum(axis=1)[side]
    L[h] = s.radiance(side, -w[h], diffuse_incoming=e, first_shot_emission=False)
    L = (np.pi * L).reshape(len(verts), k, 3)
    b_mean, b_se = L.mean(axis=1), L.std(axis=1) / np.sqrt(k)
    assert np.all(np.abs(a_mean - b_mean) <= 4.5 * np.hypot(a_se, b_se) + 1e-12), (a_mean, b_mean, a_se, b_se)
    assert np.any(a_mean > 0)
    tr.close()


def test_glossy_scenes_are_refused():
    with pytest.raises(ValueError, match="diffuse scenes only"):
        pipeline.make_solver(pipeline.prepare(scenes.load_scene("cornell-glossy"), patches=300),
                             solver="point-collocation")
