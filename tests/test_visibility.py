"""Bundle visibility against the brute-force twin, and the unbiasedness of the bundle estimate."""
import numpy as np
import pytest

from raybundle.patches.layout import subdivide
from raybundle.scene import builtin as scenes
from raybundle.scene.build import build_scene
from raybundle.scene.builtin import _box_quads, _mesh, _oriented
from raybundle.scene.materials import MaterialTable
from raybundle.tracing.sampling import uniform_sphere
from raybundle.tracing.brute_force import brute_force_bundle, brute_force_hits
from raybundle.tracing.visibility import ENVIRONMENT, RayTracer, bundle_from_hits

MATS = MaterialTable.from_list([dict(name="w", diffuse=(0.5, 0.5, 0.5), emission=(1, 1, 1))])


def box_in_box(thickness=None):
    """Closed room with a closed block inside (non-convex), optionally a thin slab wall."""
    quads = [(_oriented(q, towards=[1, 1, 1]), 0) for q in _box_quads([0, 0, 0], [2, 2, 2])]
    quads += [(_oriented(q, away=[1.2, 1.1, 0.9]), 0) for q in _box_quads([0.9, 0.8, 0.5], [1.5, 1.4, 1.3])]
    if thickness:
        c = [0.5, 1.0, 1.0]
        quads += [(_oriented(q, away=c), 0) for q in _box_quads([0.5 - thickness / 2, 0.2, 0.2],
                                                                  [0.5 + thickness / 2, 1.8, 1.8])]
    v, t, m = _mesh(quads)
    return build_scene(v, t, m, MATS)


def pair_counts(bundle):
    keys, w = bundle.aggregated()
    return {tuple(k): round(x / bundle.cell_area) for k, x in zip(keys, w)}


def two_sided_in_world(sc, flip=()):
    """``sc`` with Blender's semantics: two-sided triangles under a grey world, the
    triangles ``flip`` turned around (a .blend with flipped normals).  Faces lying
    on other faces (block bottoms on the floor) are left out: which of two
    coincident sides a ray meets is arbitrary."""
    t = sc.triangles.copy()
    t[list(flip)] = t[list(flip)][:, ::-1]
    keep = ~(sc.triangle_solid & np.isclose(sc.triangle_corners[:, :, 2], 0).all(axis=1))
    return build_scene(sc.vertices, t[keep], sc.triangle_material[keep], sc.materials, camera=sc.camera,
                       two_sided=True, environment=(0.2, 0.2, 0.2))


SCENES = {
    "cornell": lambda: scenes.cornell(),                        # open, non-convex, blocks on the floor
    "cornell-two-sided-world": lambda: two_sided_in_world(scenes.cornell(), flip=range(0, 40, 3)),
    "cornell-sub": lambda: subdivide(scenes.cornell(), patches=300),   # shared edges, T-junctions
    "box-in-box": lambda: box_in_box(),                         # closed, non-convex
    "thin-wall": lambda: box_in_box(thickness=1e-3),            # walls 1 mm apart
}


@pytest.mark.parametrize("name", sorted(SCENES))
def test_bundle_equals_brute_force(name, rng):
    sc = SCENES[name]()
    tr = RayTracer(sc)
    for _ in range(4):
        u = rng.random(5)
        d = uniform_sphere(u[0], u[1])
        origins, delta = tr.bundle_origins(d, 24, (u[2], u[3]), u[4])
        world = sc.world.emits
        up, down, _, _, *ends = tr.all_hit_pairs(origins, d, ends=world)
        fast = bundle_from_hits(sc, d, delta, up, down, len(origins), 0, *ends)
        slow = brute_force_bundle(sc, origins, d, delta, tr.eps)
        assert pair_counts(fast) == pair_counts(slow)
        assert len(fast.receiver) > 0
        assert np.any(fast.sender == ENVIRONMENT) == world
    tr.close()


@pytest.mark.parametrize("name", ["cornell", "cornell-two-sided-world"])
def test_a_bundle_crosses_each_side_in_proportion_to_its_projected_area(name, rng):
    """The rays of bundles cross each triangle as brute force finds (but where two coincident
    faces tie: a box's bottom on the floor, at z = 0), and each side's crossings average
    ``A |cos|`` / cell where nothing of it is buried or lies on another face: the expectation
    the solver's control variate rests on (:mod:`raybundle.methods.control_variate`).  The
    transfers alone fall short where a side sees a black back or a black world."""
    sc = SCENES[name]()
    tr = RayTracer(sc)
    d = uniform_sphere(0.3, 0.2)
    g = rng.random((200, 3))
    bundles, crossed = tr.bundles(np.repeat(d[None], len(g), axis=0), 24, g[:, :2], g[:, 2], crossings=True)
    origins, _ = tr.bundle_origins(d, 24, g[0, :2], g[0, 2])
    one = tr.bundles(d[None], 24, g[:1, :2], g[:1, 2], crossings=True)[1]
    slow = np.bincount([tri for seq in brute_force_hits(sc.triangle_corners, origins, d, tr.eps) for _, tri in seq],
                       minlength=len(sc.triangles))
    buried = np.bincount(sc.tside_side, tr.open_fraction() < 1, minlength=sc.n_sides) > 0
    tr.close()
    z0 = np.isclose(sc.triangle_corners[:, :, 2], 0).all(axis=1)
    assert np.array_equal(one[~z0], slow[~z0])
    cell = bundles[0].cell_area / len(g)
    every = np.bincount(sc.tside_side, crossed[sc.tside_triangle], minlength=sc.n_sides) * cell
    paired = sum(np.bincount(b.receiver, minlength=sc.n_sides) for b in bundles) * cell
    area = np.bincount(sc.tside_side, sc.triangle_area[sc.tside_triangle], minlength=sc.n_sides)
    projected = area * np.abs(sc.side_normal @ d)
    floor = np.bincount(sc.tside_side, z0[sc.tside_triangle], minlength=sc.n_sides) > 0
    seen = (projected > 0.2 * area) & ~buried & ~floor
    assert abs(every[seen].sum() / projected[seen].sum() - 1) < 0.01
    if not sc.world.emits:
        assert paired[seen].sum() / projected[seen].sum() < 0.9


@pytest.mark.parametrize("name", ["cornell-two-sided-world", "box-in-box"])
def test_bundles_traced_together_equal_brute_force_one_by_one(name, rng):
    """K grids traced in one query (the solver's batched step): each bundle holds
    exactly the pairs brute force finds for its own grid, world ends included."""
    sc = SCENES[name]()
    tr = RayTracer(sc, threads=2)
    k = 5
    u = rng.random((k, 5))
    dirs = np.array([uniform_sphere(a, b) for a, b in u[:, :2]])
    together = tr.bundles(dirs, 24, u[:, 2:4], u[:, 4])
    world = sc.world.emits
    assert len(together) == k
    for j, b in enumerate(together):
        origins, delta = tr.bundle_origins(dirs[j], 24, u[j, 2:4], u[j, 4])
        assert b.n_rays == len(origins) and np.isclose(b.cell_area, delta ** 2)
        assert pair_counts(b) == pair_counts(brute_force_bundle(sc, origins, dirs[j], delta, tr.eps))
        assert np.any(b.sender == ENVIRONMENT) == world
    tr.close()


def test_two_sided_sides_meet_by_ray_direction():
    """A two-sided quad between two parallel one-sided quads facing it: rays along
    +z link the lower quad's front to the middle's back side, the middle's front to
    the upper quad; flipping the middle quad's winding changes nothing."""
    v = np.array([[0, 0, z] for z in (0, 1, 2) for _ in range(4)], float)
    v[:, :2] = np.tile([[0, 0], [1, 0], [1, 1], [0, 1]], (3, 1))
    for flip in (False, True):
        mid = [[4, 5, 6], [4, 6, 7]] if not flip else [[4, 6, 5], [4, 7, 6]]
        t = np.array([[0, 1, 2], [0, 2, 3]] + mid + [[8, 10, 9], [8, 11, 10]])
        sc = build_scene(v, t, [0] * 6, MATS, two_sided=[False, False, True, True, False, False])
        assert sc.n_sides == sc.n_patches + 2
        tr = RayTracer(sc)
        b = tr.bundle([0, 0, 1], 16)
        tr.close()
        mid_up = set(sc.side_facing(np.array([2, 3]), [0, 0, 1]).tolist())
        mid_down = set(sc.side_facing(np.array([2, 3]), [0, 0, -1]).tolist())
        assert (mid_up == {2, 3}) == (not flip) and (mid_down == {2, 3}) == flip
        group = {0: "lower", 1: "lower", 4: "upper", 5: "upper"}
        group.update({k: "middle, upper side" for k in mid_up})
        group.update({k: "middle, lower side" for k in mid_down})
        linked = {(group[a], group[b]) for a, b in zip(b.sender.tolist(), b.receiver.tolist())}
        assert linked == {("lower", "middle, lower side"), ("middle, lower side", "lower"),
                          ("middle, upper side", "upper"), ("upper", "middle, upper side")}


def test_rays_through_shared_edges_and_vertices_hit_once():
    """Axis-aligned rays exactly through the diagonals and corners of subdivided quads."""
    sc = subdivide(box_in_box(), max_edge=0.5)          # vertices on a 0.25/0.5 m lattice
    tr = RayTracer(sc)
    d = np.array([0.0, 0.0, 1.0])
    xs = np.array([0.25, 0.5, 0.75, 1.0, 1.25, 0.6])
    ys = np.array([0.25, 0.5, 0.75, 1.0, 0.5, 0.6])
    origins = np.stack([xs, ys, np.full(len(xs), -1.0)], axis=1)
    up, down, ray, _ = tr.all_hit_pairs(origins, d)
    ref = brute_force_hits(sc.triangle_corners, origins, d, tr.eps)
    for r in range(len(origins)):
        n_pairs = int((ray == r).sum())
        assert n_pairs == len(ref[r]) - 1, (origins[r], ref[r])
        # the surfaces crossed are the planes z = 0, 2 (room) and 0.5, 1.3 (block) when inside it
        zs = sorted({round(t - 1.0, 6) for t, _ in ref[r]})
        inside = 0.9 <= xs[r] <= 1.5 and 0.8 <= ys[r] <= 1.4
        assert zs == ([0.0, 0.5, 1.3, 2.0] if inside else [0.0, 2.0])
    tr.close()


def test_bundle_projected_area_is_unbiased(rng):
    """E[count * delta^2] = A_i |cos_i|, hence mean of 2 count delta^2 / A_i over uniform d is 1.

    Per patch the estimate is a mean of N iid terms; we test the all-patch average against
    4.5 standard errors computed from the per-direction spread.
    """
    sc = subdivide(box_in_box(), patches=400)
    tr = RayTracer(sc)
    N = 300
    vals = np.empty((N, sc.n_patches))
    for k in range(N):
        u = rng.random(5)
        b = tr.bundle(uniform_sphere(u[0], u[1]), 40, (u[2], u[3]), u[4])
        vals[k] = 2 * np.bincount(b.receiver, minlength=sc.n_patches) * b.cell_area / sc.patch_area
    per_dir = vals.mean(axis=1)
    se = per_dir.std() / np.sqrt(N)
    assert abs(per_dir.mean() - 1.0) < 4.5 * se
    assert se < 0.02
    # no patch is systematically missed
    assert vals.mean(axis=0).min() > 0.5
    tr.close()


def test_grid_offsets_remove_the_bundles_aliasing():
    """Grid aliasing: a patch far smaller than a bundle cell at the centre of the bounding
    sphere lies, for every direction, exactly between four lines of a grid whose offset is
    fixed (even resolution, cells centred at (i + 1/2) delta - R): it never receives, whatever
    the direction (measured: 0 lines in 4,000 directions).  The solvers shift and rotate each
    grid at random (:meth:`~raybundle.tracing.visibility.RayTracer.bundles`' ``offsets``,
    ``rotations``), and the same patch then receives its projected area, 2 count delta^2 / A
    within 4.5 SE of 1 over the directions (measured: 1.000, SE 0.073)."""
    quads = [(_oriented(q, towards=[1, 1, 1]), 0) for q in _box_quads([0, 0, 0], [2, 2, 2])]
    v, t, m = _mesh(quads)
    res = 40
    h = 0.15 * 2 * np.sqrt(3) / res                      # a square of 0.3 cells (R = sqrt(3))
    tiny = np.array([[1 - h, 1 - h, 1], [1 + h, 1 - h, 1], [1 + h, 1 + h, 1], [1 - h, 1 + h, 1]])
    sc = build_scene(np.vstack([v, tiny]), np.vstack([t, len(v) + np.array([[0, 1, 2], [0, 2, 3]])]),
                     np.concatenate([m, [0, 0]]), MATS)
    tr = RayTracer(sc)
    rng = np.random.default_rng(7)
    n_dir = 4000
    d = uniform_sphere(rng.random(n_dir), rng.random(n_dir))
    fixed = tr.bundles(d, res, offsets=np.full((n_dir, 2), 0.5), rotations=np.zeros(n_dir))
    shifted = tr.bundles(d, res, offsets=rng.random((n_dir, 2)), rotations=rng.random(n_dir))
    tr.close()
    patch = [len(t), len(t) + 1]
    area = 4 * h * h

    def share(bundles):
        return np.array([2 * np.isin(b.receiver, patch).sum() * b.cell_area / area for b in bundles])

    assert share(fixed).sum() == 0
    got = share(shifted)
    assert abs(got.mean() - 1) < 4.5 * got.std() / np.sqrt(n_dir), (got.mean(), got.std())


def test_first_hit_and_occlusion_against_brute_force(rng):
    sc = scenes.cornell()
    tr = RayTracer(sc)
    o = np.tile([-0.278, 0.3, 0.27], (200, 1))
    d = uniform_sphere(rng.random(200), rng.random(200))
    tri, t, _, _ = tr.first_hit(o, d)
    for k in range(200):
        ref = brute_force_hits(sc.triangle_corners, o[k:k + 1], d[k], tr.eps)[0]
        if ref:
            assert tri[k] >= 0 and abs(t[k] - ref[0][0]) < 1e-5
        else:
            assert tri[k] == -1
    hit = tri >= 0
    assert not tr.occluded(o[hit], d[hit], t[hit] * 0.99).any()
    assert tr.occluded(o[hit], d[hit], t[hit] * 1.01).all()
    tr.close()


def shoelace(xz):
    x, z = np.asarray(xz, float).T
    return 0.5 * abs(np.dot(x, np.roll(z, 1)) - np.dot(z, np.roll(x, 1)))


def test_open_fraction_excludes_area_buried_under_solid_blocks():
    """Cornell: the floor under both (closed) blocks receives nothing; everything else is open."""
    sc = subdivide(scenes.cornell(), patches=800)
    tr = RayTracer(sc)
    open_area = tr.open_fraction() * sc.triangle_area
    names = sc.materials.names
    floor = np.isclose(sc.triangle_corners[:, :, 2], 0).all(axis=1) & ~sc.triangle_solid \
        & (sc.triangle_material == names.index("white"))
    footprints = (shoelace(scenes._SHORT_TOP) + shoelace(scenes._TALL_TOP)) * 1e-6
    assert abs(open_area[floor].sum() - (sc.triangle_area[floor].sum() - footprints)) < 0.01 * footprints
    rest = ~floor & ~sc.triangle_solid
    assert np.allclose(open_area[rest], sc.triangle_area[rest])
    tr.close()


def test_one_sided_shelf_buries_nothing():
    """A floor under a one-sided plane still receives light from the sides: nothing is buried."""
    quads = [(_oriented(q, towards=[1, 1, 1]), 0) for q in _box_quads([0, 0, 0], [2, 2, 2])]
    shelf = np.array([[0.2, 0.2, 0.08], [1.8, 0.2, 0.08], [1.8, 1.8, 0.08], [0.2, 1.8, 0.08]])
    quads.append((_oriented(shelf, towards=[1, 1, 2]), 0))
    v, t, m = _mesh(quads)
    sc = subdivide(build_scene(v, t, m, MATS), patches=400)
    shelf_tri = np.isclose(sc.triangle_corners[:, :, 2], 0.08).all(axis=1)
    assert shelf_tri.any() and not sc.triangle_solid[shelf_tri].any()   # the room is closed, the shelf not
    tr = RayTracer(sc)
    assert np.all(tr.open_fraction() == 1.0)
    tr.close()


def test_closed_solid_detection():
    from raybundle.scene.model import closed_solid_triangles

    oriented = np.array([_oriented(q, away=[0.5, 0.5, 0.5]) for q in _box_quads([0, 0, 0], [1, 1, 1])])
    vv = oriented.reshape(-1, 3)
    tt = np.array([[4 * k, 4 * k + 1, 4 * k + 2] for k in range(6)] + [[4 * k, 4 * k + 2, 4 * k + 3] for k in range(6)])
    assert closed_solid_triangles(vv, tt).all()
    assert not closed_solid_triangles(vv, tt[:-1]).any()              # a hole opens the solid
    flipped = tt.copy()
    flipped[0] = flipped[0][::-1]
    assert not closed_solid_triangles(vv, flipped).any()              # inconsistent orientation


def test_scene_far_from_origin_keeps_precision(rng):
    """Embree is single precision: a room 10 km from the origin must give the same pairs."""
    near = box_in_box()
    far = build_scene(near.vertices + 1e4, near.triangles, near.triangle_material, MATS)
    a, b = RayTracer(near), RayTracer(far)
    for _ in range(3):
        u = rng.random(5)
        d = uniform_sphere(u[0], u[1])
        fa = a.bundle(d, 32, (u[2], u[3]), u[4])
        fb = b.bundle(d, 32, (u[2], u[3]), u[4])
        assert pair_counts(fa) == pair_counts(fb)
        assert fa.n_casts == fb.n_casts
    a.close()
    b.close()


def cut_out_planes(alpha_map):
    """Two unit squares facing each other along z (z = 1 front, z = 0 back), two-sided; the
    front has the coverage map ``alpha_map`` (H, W) over UV = (x, y)."""
    from raybundle.scene.textures import SurfaceTexture

    sq = np.array([(0, 0), (1, 0), (1, 1), (0, 1)], float)
    v = np.concatenate([np.c_[sq, np.ones(4)], np.c_[sq, np.zeros(4)]])
    t = np.array([[0, 1, 2], [0, 2, 3], [4, 5, 6], [4, 6, 7]])
    mats = MaterialTable.from_list([dict(diffuse=(0.5, 0.5, 0.5), emission=(1.0, 1.0, 1.0))])
    tex = SurfaceTexture([np.repeat(np.asarray(alpha_map, np.float32)[..., None], 3, axis=2)],
                         np.full(4, -1), v[t], v[t][..., :2], face_alpha=[0, 0, -1, -1])
    return build_scene(v, t, np.zeros(4, np.int64), mats, two_sided=True, texture=tex)


def test_cut_outs_pass_rays_where_they_are_cut_out_and_with_their_coverage_elsewhere():
    """A front square cut out on its left half (coverage 0 | 1): rays there reach the back
    square, in every query (first hits, shadow rays, bundle lines); with a constant coverage
    0.3 the front is met by 30% of the rays, within 4.5 standard errors."""
    from raybundle.scene.textures import SurfaceTexture

    left = np.zeros((8, 64))
    left[:, 32:] = 1.0
    sc = cut_out_planes(left)
    tr = RayTracer(sc)
    try:
        x = np.linspace(0.05, 0.95, 40)
        o = np.stack([x, np.full_like(x, 0.5), np.full_like(x, 2.0)], axis=1)
        d = np.array([0.0, 0.0, -1.0])
        tri, t, _, _ = tr.first_hit(o, d)
        inside = np.abs(x - 0.5) > 0.02                       # off the bilinear seam
        assert np.all((t[inside] < 1.5) == (x[inside] > 0.5)), (x, t)
        assert np.all(sc.triangle_source[tri[inside]] // 2 == np.where(x[inside] > 0.5, 0, 1))
        crossed = np.zeros(len(o), bool)
        shadow = tr.occluded(o + 1.5 * d, -d, np.full(len(o), 1.2), crossed=crossed)   # from z = 0.5 up to 1.7
        assert np.all(shadow[inside] == (x[inside] > 0.5))
        assert np.all(crossed[inside] == (x[inside] < 0.5))  # passed the cut-out: the outcome was random
        short = np.zeros(len(o), bool)                        # up to z = 0.8: nothing met, nothing crossed
        assert not tr.occluded(o + 1.5 * d, -d, np.full(len(o), 0.3), crossed=short).any() and not short.any()
        up, down, ray, _ = tr.all_hit_pairs(o, d)
        pairs = set(ray.tolist())                             # a front-back pair only where the front is kept
        assert {k for k in np.nonzero(inside)[0] if x[k] > 0.5} <= pairs
        assert not pairs & {k for k in np.nonzero(inside)[0] if x[k] < 0.5}
    finally:
        tr.close()

    again = SurfaceTexture.from_arrays(sc.texture.to_arrays())          # the .npz keeps the coverage
    assert np.array_equal(again.face_alpha, sc.texture.face_alpha) and again.has_cutouts

    sc = cut_out_planes(np.full((1, 1), 0.3))
    tr = RayTracer(sc)
    try:
        rng = np.random.default_rng(5)
        n = 20000
        o = np.c_[rng.uniform(0.01, 0.99, (n, 2)), np.full(n, 2.0)]
        d = np.array([0.0, 0.0, -1.0])
        front = tr.first_hit(o, d)[1] < 1.5
        shadow = tr.occluded(o + 1.5 * d, -d, np.full(n, 1.2))
        up, down, ray, _ = tr.all_hit_pairs(o, d)
        se = np.sqrt(0.3 * 0.7 / n)
        for got in (front.mean(), shadow.mean(), len(ray) / n):
            assert abs(got - 0.3) < 4.5 * se, (got, se)
        again = tr.first_hit(o, d)[1] < 1.5                  # a new query draws anew
        assert (front != again).any()
    finally:
        tr.close()
