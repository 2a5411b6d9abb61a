"""Reconstruction of the diffuse light between patches: the L2 projection onto hat
functions (raybundle.patches.reconstruction.LinearReconstruction.projected) against closed forms,
and against averaging the patches around a vertex (LinearReconstruction.averaged), which
puts a patch-wide mean on a concave edge.

Deterministic: the patch values fed in are exact patch means (quadrature), so the tests
measure the reconstruction alone, not the solver's noise.
"""
import numpy as np
import pytest

from raybundle.app import pipeline
from raybundle.imaging.settings import RenderSettings
from raybundle.patches.layout import subdivide
from raybundle.scene.build import build_scene
from raybundle.scene.camera import Camera
from raybundle.scene.materials import MaterialTable
from raybundle.scene.model import SunLights
from raybundle.tracing.sampling import points_on_triangles


def floor_and_wall(patches=240):
    """Floor [-1, 1]^2 (z = 0, facing +z) and a wall on its edge x = 1 (facing -x, 2 m high)."""
    v = np.array([[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0],
                  [1, -1, 0], [1, 1, 0], [1, 1, 2], [1, -1, 2]], float)
    t = [[0, 1, 2], [0, 2, 3], [4, 6, 5], [4, 7, 6]]
    mats = MaterialTable.from_list([dict(name="floor", diffuse=(0.5, 0.5, 0.5)),
                                    dict(name="wall", diffuse=(0.5, 0.5, 0.5))])
    cam = Camera.look_at((-3, 0, 1.5), (0.5, 0, 0.5), (0, 0, 1), 35, 36, (8, 8))
    sun = SunLights([[0.0, 0.0, -1.0]], [[1.0, 1.0, 1.0]], [0.0])     # not used: the tests feed patch values
    sc = subdivide(build_scene(v, t, [0, 0, 1, 1], mats, sun_lights=sun, camera=cam), patches=patches)
    return pipeline.make_renderer(sc, RenderSettings(seed=1))


def wall_irradiance(p):
    """E(p) [W/m^2] on the wall x = 1 (normal -x) at points p (N, 3) from the floor
    [-1, 1]^2 at unit radiance: E = int (1 - x) z / r^4 dA, the y integral in closed form
    (int du / (a^2 + u^2)^2 = u / (2 a^2 (a^2 + u^2)) + atan(u / a) / (2 a^3)), the
    x integral by Gauss-Legendre on panels graded towards the edge."""
    g, w = np.polynomial.legendre.leggauss(16)
    edges = np.concatenate([[0.0], np.geomspace(1e-10, 2.0, 160)])
    s = (0.5 * (edges[1:] - edges[:-1])[:, None] * g + 0.5 * (edges[1:] + edges[:-1])[:, None]).ravel()
    ws = (0.5 * (edges[1:] - edges[:-1])[:, None] * w).ravel()           # s = 1 - x_floor
    y, z = p[:, 1:2], p[:, 2:3]
    a2 = s * s + z * z
    a = np.sqrt(a2)

    def prim(u):
        return u / (2 * a2 * (a2 + u * u)) + np.arctan(u / a) / (2 * a2 * a)

    return ((s * z * (prim(1 - y) - prim(-1 - y))) * ws).sum(axis=1)


def vertex_positions(sc, nv):
    ids = sc.smooth_vertex_ids
    pos = np.zeros((nv, 3))
    pos[ids.ravel()] = sc.triangle_corners[sc.tside_triangle].reshape(-1, 3)
    return pos


def test_projection_keeps_constants_and_halves_the_error_of_linear_functions():
    """A constant comes back exactly (the furnaces stay exact).  Patch means of a linear
    function come back with half the error of averaging the patches around each vertex
    (which is off by half a patch's slope on every boundary), in RMS and at the worst vertex."""
    r = floor_and_wall()
    sc = r.scene
    const = r.solver.reconstruction.projected(np.full((sc.n_sides, 1), 2.5))[:, 0]
    assert np.abs(const - 2.5).max() < 1e-12
    slope = np.array([0.3, -0.2, 0.5])
    centroid = sc.triangle_corners[sc.tside_triangle].mean(axis=1)        # a linear function's mean
    area = sc.triangle_area[sc.tside_triangle]
    f_side = np.bincount(sc.tside_side, area * (1.0 + centroid @ slope), minlength=sc.n_sides) / \
        np.bincount(sc.tside_side, area, minlength=sc.n_sides)
    proj = r.solver.reconstruction.projected(f_side[:, None])[:, 0]
    avg = r.solver.reconstruction.averaged(f_side[:, None])[:, 0]
    exact = 1.0 + vertex_positions(sc, len(proj)) @ slope
    rms = [np.sqrt(np.mean((x - exact) ** 2)) for x in (proj, avg)]
    assert rms[0] < 0.5 * rms[1], rms
    assert np.abs(proj - exact).max() < 0.5 * np.abs(avg - exact).max()


def test_projection_follows_the_corner_profile():
    """The wall's irradiance from a uniformly bright floor, E(z), falls by a quarter within
    the first patch row above the floor.  Fed the exact patch means, the projection's
    vertex values on the concave edge (z = 0) have less than half the error of averaging
    the patches around the vertex (measured: 4.3% against 11% on average), and the two
    rows above stay within 2% of E (measured 1.5%; averaging: 0.3%)."""
    r = floor_and_wall()
    sc = r.scene
    wall = sc.triangle_material[sc.tside_triangle] == 1
    # exact side means: 64 quadrature points per wall triangle (floor sides: any value)
    ts = np.nonzero(wall)[0]
    k = 8
    u1, u2 = np.meshgrid((np.arange(k) + 0.5) / k, (np.arange(k) + 0.5) / k)
    pts = points_on_triangles(np.repeat(sc.triangle_corners[sc.tside_triangle[ts]], k * k, axis=0),
                              np.tile(u1.ravel(), len(ts)), np.tile(u2.ravel(), len(ts)))
    e_ts = wall_irradiance(pts).reshape(len(ts), k * k).mean(axis=1)
    area = sc.triangle_area[sc.tside_triangle[ts]]
    side = sc.tside_side[ts]
    e_side = np.ones(sc.n_sides)
    walls = np.unique(side)
    e_side[walls] = (np.bincount(side, area * e_ts, minlength=sc.n_sides)
                     / np.maximum(np.bincount(side, area, minlength=sc.n_sides), 1e-300))[walls]
    proj = r.solver.reconstruction.projected(e_side[:, None])[:, 0]
    avg = r.solver.reconstruction.averaged(e_side[:, None])[:, 0]
    pos = vertex_positions(sc, len(proj))
    wall_v = np.unique(sc.smooth_vertex_ids[ts])
    inner = wall_v[np.abs(pos[wall_v, 1]) < 0.6]                  # away from the floor's side edges
    height = pos[inner, 2]
    edge = inner[height < 1e-9]
    exact = wall_irradiance(pos[edge] + [0, 0, 1e-7])
    err_proj = np.abs(proj[edge] / exact - 1)
    err_avg = np.abs(avg[edge] / exact - 1)
    assert np.all(err_proj < err_avg) and err_proj.mean() < 0.5 * err_avg.mean(), (err_proj, err_avg)
    above = inner[(height > 1e-9) & (height < 0.6)]                # the two rows above the edge
    err_above = np.abs(proj[above] / wall_irradiance(pos[above]) - 1)
    assert err_above.max() < 0.02, err_above



def test_the_compiled_kernels_give_the_numpy_paths_values(monkeypatch):
    """The reconstruction's kernels (:mod:`raybundle.util.compiled`) against its NumPy path on a
    room with a tessellated sphere (clusters, read through their fits) and plain walls (the
    projection), some triangle sides without receiving area: the same sums in another order."""
    from test_clusters import furnace_with_sphere

    from raybundle.patches.clusters import make_patches
    from raybundle.patches.reconstruction import LinearReconstruction
    from raybundle.util import compiled

    sc = make_patches(furnace_with_sphere(), patches=300)
    rng = np.random.default_rng(3)
    area = sc.triangle_area[sc.tside_triangle] * rng.uniform(0.5, 1.0, len(sc.tside_side))
    area[rng.random(len(area)) < 0.05] = 0.0
    rec = LinearReconstruction(sc, area)
    assert rec._fit is not None and len(rec._p_vertices) and len(rec._fallback_tsides)
    values = rng.random((sc.n_sides, 4))
    assert compiled.ENABLED
    got = [rec.averaged(values), rec.projected(values), rec.smooth_and_sharp(values, 0.3 * values)]
    got32 = rec.projected(values, np.float32)
    monkeypatch.setattr(compiled, "ENABLED", False)                  # as where Numba cannot be imported
    monkeypatch.setattr(compiled, "REASON", "ImportError: No module named 'numba'")
    monkeypatch.setattr(compiled, "_warned", False)
    with pytest.warns(RuntimeWarning, match="Numba is not available .*No module named 'numba'.*NumPy path"):
        want = [rec.averaged(values)]
    want += [rec.projected(values), rec.smooth_and_sharp(values, 0.3 * values)]   # said once
    for g, w in zip(got, want):
        assert g.shape == w.shape and np.allclose(g, w, rtol=1e-12, atol=1e-13 * np.abs(w).max())
    # into 32 bits (the final image's): the fits sum in single precision, both paths
    want32 = rec.projected(values, np.float32)
    assert got32.dtype == want32.dtype == np.float32
    np.testing.assert_allclose(got32, want[1], rtol=1e-6, atol=1e-6 * np.abs(want[1]).max())
    np.testing.assert_allclose(want32, want[1], rtol=1e-6, atol=1e-6 * np.abs(want[1]).max())


def test_a_32_bit_projection_sums_its_fallback_vertices_a_column_at_a_time():
    """Vertices that neither the projection nor a fit gives a value (all their triangle sides
    without receiving area: a floor under a solid) take the sides' mean around them, summed in
    64 bits a column at a time into the 32-bit result: 1.3 times the result's size at the peak,
    where a 64-bit (V, C) of those sums and its 32-bit copy took 3.0 (the bathroom's final
    image: 65 MB beside its vertex values)."""
    import tracemalloc

    from test_clusters import furnace_with_sphere

    from raybundle.patches.clusters import make_patches
    from raybundle.patches.reconstruction import LinearReconstruction

    sc = make_patches(furnace_with_sphere(96, 192), patches=300)
    area = sc.triangle_area[sc.tside_triangle].copy()
    floor = sc.triangle_corners[sc.tside_triangle][:, :, 2].max(axis=1) < sc.vertices[:, 2].min() + 1e-6
    area[floor] = 0.0
    rec = LinearReconstruction(sc, area)
    assert len(rec._fallback_tsides) and rec._fit is not None
    values = np.random.default_rng(3).random((sc.n_sides, 9))
    want = rec.projected(values)                   # kernels compiled, caches made
    tracemalloc.start()
    try:
        start = tracemalloc.get_traced_memory()[0]
        out = rec.projected(values, np.float32)
        peak = tracemalloc.get_traced_memory()[1] - start
    finally:
        tracemalloc.stop()
    assert peak < 1.6 * out.nbytes, peak / out.nbytes
    np.testing.assert_array_equal(out[rec._fallback], want[rec._fallback].astype(np.float32))


def test_the_projection_writes_the_fitted_vertices_into_its_result():
    """Projected values peak near their own size on a finely tessellated sphere (its vertices
    nearly all read from the cluster fits): the fits write their rows of the result where they
    made an array of them beside it (2.2 times the result's size at the peak, 1.2 now), which
    at the end of a run in a furnished room came to 60 MB more."""
    import tracemalloc

    from test_clusters import furnace_with_sphere

    from raybundle.patches.clusters import make_patches
    from raybundle.patches.reconstruction import LinearReconstruction

    sc = make_patches(furnace_with_sphere(96, 192), patches=300)
    rec = LinearReconstruction(sc, sc.triangle_area[sc.tside_triangle])
    values = np.random.default_rng(3).random((sc.n_sides, 6))
    rec.projected(values)                        # kernels compiled, caches made
    tracemalloc.start()
    try:
        out = rec.projected(values)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert len(rec._fit.vertices) > 0.9 * rec.n_vertices
    assert peak < 1.5 * out.nbytes, peak / out.nbytes
