"""Patches conform to contact lines (raybundle.patches.contacts): a box standing on a floor,
a lamp hanging just under a ceiling, a wall piercing a floor.

Geometry checks are exact (areas, orientations, which side of a line every
patch lies on); the leak check compares light inside a closed cavity with and
without the cut, from the solver's running averages at a fixed seed.
"""
import numpy as np
import pytest
from geometry_helpers import clipped_area

from raybundle.app import pipeline
from raybundle.imaging.settings import RenderSettings
from raybundle.patches.contacts import contact_segments
from raybundle.patches.layout import subdivide
from raybundle.scene.build import build_scene
from raybundle.scene.builtin import _mesh
from raybundle.scene.camera import Camera
from raybundle.scene.materials import MaterialTable
from raybundle.scene.model import PointLights

MATS = MaterialTable.from_list([dict(name="white", diffuse=(0.7, 0.7, 0.7)),
                                dict(name="lamp", emission=(10.0, 10.0, 10.0))])
ANGLE = np.radians(30.0)


def _rot(p):
    c, s = np.cos(ANGLE), np.sin(ANGLE)
    p = np.asarray(p, float)
    return np.stack([c * p[..., 0] - s * p[..., 1], s * p[..., 0] + c * p[..., 1], p[..., 2]], axis=-1)


def footprint(half=0.3):
    """The box's rotated square footprint: corners (4, 2) counter-clockwise."""
    sq = np.array([[-half, -half, 0], [half, -half, 0], [half, half, 0], [-half, half, 0]])
    return _rot(sq + [0.1, 0.05, 0])[:, :2]


def box_on_floor(height=0.4, light=True, flip_floor=False):
    """A 2 x 2 m floor with an open (bottomless) box standing on it, rotated 30 degrees
    so its edges cross the patch lattice; everything two-sided, a point light above."""
    floor = np.array([[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]], float)
    if flip_floor:
        floor = floor[::-1]
    f = np.column_stack([footprint(), np.zeros(4)])
    top = f + [0, 0, height]
    quads = [(floor, 0), (top, 0)] + [(np.array([f[i], f[(i + 1) % 4], top[(i + 1) % 4], top[i]]), 0)
                                      for i in range(4)]
    v, t, m = _mesh(quads)
    pl = PointLights(position=[[0.0, -0.6, 1.5]], intensity=[[20.0, 20.0, 20.0]]) if light else None
    cam = Camera.look_at((0, -3, 2), (0, 0, 0.2), (0, 0, 1), 35.0, 36.0, (16, 16))
    return build_scene(v, t, m, MATS, point_lights=pl, camera=cam, two_sided=True)


def inside(points2d, poly):
    """(N,) signed distance-like test: > 0 strictly inside the convex ccw polygon."""
    d = np.full(len(points2d), np.inf)
    for i in range(len(poly)):
        a, b = poly[i], poly[(i + 1) % len(poly)]
        e = (b - a) / np.linalg.norm(b - a)
        d = np.minimum(d, e[0] * (points2d[:, 1] - a[1]) - e[1] * (points2d[:, 0] - a[0]))
    return d


def floor_minority_fraction(sc, poly):
    """(patches,) for each floor patch: the smaller of its parts inside and outside the
    footprint, as a fraction of its area; and the floor's total area."""
    floor = np.nonzero(np.abs(sc.triangle_corners[:, :, 2]).max(axis=1) < 1e-12)[0]
    a_in = np.array([clipped_area(sc.triangle_corners[t, :, :2], poly) for t in floor])
    p = sc.triangle_patch[floor]
    inside_area = np.bincount(p, a_in, minlength=sc.n_patches)[np.unique(p)]
    area = sc.patch_area[np.unique(p)]
    return np.minimum(inside_area, area - inside_area) / area, float(area.sum())


@pytest.mark.parametrize("flip_floor", [False, True])
def test_box_footprint_cuts_the_floor_patches_and_keeps_area_and_orientation(flip_floor):
    sc = box_on_floor(flip_floor=flip_floor)
    plain = subdivide(sc, patches=600, contacts=False)
    cut = subdivide(sc, patches=600)
    frac_plain, floor_area = floor_minority_fraction(plain, footprint())
    frac_cut, floor_area_cut = floor_minority_fraction(cut, footprint())
    assert frac_plain.max() > 0.3                      # the lattice does cross the outline
    # pieces under min_fraction (0.5%) of a patch may stay attached, nothing larger
    assert frac_cut.max() <= 0.005 + 1e-9, frac_cut.max()
    assert floor_area_cut == pytest.approx(floor_area, rel=1e-12) == pytest.approx(4.0, rel=1e-12)
    assert cut.patch_area.sum() == pytest.approx(plain.patch_area.sum(), rel=1e-12)
    # every piece keeps its face's orientation (two-sided sides stay consistent)
    up = np.abs(cut.triangle_corners[:, :, 2]).max(axis=1) < 1e-12
    assert np.allclose(cut.triangle_normal[up], [0, 0, -1 if flip_floor else 1], atol=1e-12)
    # patches are planar and convex pieces: every patch's triangles share one normal
    n = cut.triangle_normal
    for p in np.unique(cut.triangle_patch[up]):
        tri = np.nonzero(cut.triangle_patch == p)[0]
        assert np.allclose(n[tri], n[tri[0]], atol=1e-9)


def test_smooth_interpolation_does_not_weld_across_the_contact():
    """Corners on the outline weld only with corners on the same side of it."""
    cut = subdivide(box_on_floor(), patches=600)
    ids = cut.smooth_vertex_ids[:len(cut.triangles)]            # front tsides
    floor = np.nonzero(np.abs(cut.triangle_corners[:, :, 2]).max(axis=1) < 1e-12)[0]
    d = inside(cut.triangle_corners[floor].reshape(-1, 3)[:, :2], footprint()).reshape(-1, 3)
    dc = inside(cut.triangle_corners[floor].mean(axis=1)[:, :2], footprint())
    t_in, t_out = floor[(d >= -1e-9).all(axis=1) & (dc > 0)], floor[(d <= 1e-9).all(axis=1) & (dc < 0)]
    in_ids, out_ids = set(ids[t_in].ravel()), set(ids[t_out].ravel())
    assert len(t_in) > 20 and len(t_out) > 200
    assert not in_ids & out_ids
    # away from the outline the floor still welds: far fewer ids than corners
    assert len(out_ids) < 3 * len(t_out) / 2


def _cavity_ratio(contacts, iterations=4):
    sc = pipeline.prepare(box_on_floor(), patches=500) if contacts else subdivide(box_on_floor(), patches=500,
                                                                                  contacts=False)
    r = pipeline.make_renderer(sc, RenderSettings(seed=5))
    for _ in range(iterations):
        r.solver.step()
    e = r.solver.mean_incoming[:, 0] + r.solver.first_shot.E.sum(axis=1)[:, 0]
    area = r.solver.area
    # sides facing into the cavity: floor pieces inside the footprint (up) and the walls' inner sides
    c = sc.patch_centroid[sc.side_patch]
    n = sc.side_normal
    inside_fp = inside(c[:, :2], footprint()) > 1e-9
    on_floor = np.abs(c[:, 2]) < 1e-12
    walls = (c[:, 2] > 1e-6) & (c[:, 2] < 0.4 - 1e-6)
    to_centre = np.column_stack([_rot(np.array([[0.1, 0.05, 0.0]]))[0, :2] - c[:, :2], np.zeros(len(c))])
    cavity = (on_floor & inside_fp & (n[:, 2] > 0)) | (walls & (np.einsum("ij,ij->i", n, to_centre) > 0))
    lit = on_floor & ~inside_fp & (n[:, 2] > 0)
    return (e[cavity] * area[cavity]).sum() / area[cavity].sum() / ((e[lit] * area[lit]).sum() / area[lit].sum())


def test_no_light_leaks_into_a_box_standing_on_a_floor():
    """The inside of a closed cavity stays dark: with the floor cut at the box's
    footprint, the incoming radiance in the cavity is below 0.1% of the lit floor's
    (measured 0: only pieces under 0.5% of a patch stay attached, and rays exactly
    through the contact edge); without the cut the straddling floor patches carry
    light in (measured 7%, asserted > 1%)."""
    with_cut = _cavity_ratio(True)
    without = _cavity_ratio(False)
    assert with_cut < 1e-3, with_cut
    assert without > 1e-2, without


def test_contact_segments_of_a_lamp_under_a_ceiling_and_a_wall_through_a_floor():
    """A lamp 0.5 mm under a ceiling gives its outline (no inner diagonal) on the
    ceiling's plane; a wall crossing a floor gives the crossing line."""
    ceiling = np.array([[-1, -1, 1], [-1, 1, 1], [1, 1, 1], [1, -1, 1]], float)
    lamp = np.array([[-0.2, -0.1, 0], [0.2, -0.1, 0], [0.2, 0.1, 0], [-0.2, 0.1, 0]]) + [0, 0, 1 - 5e-4]
    floor = ceiling - [0, 0, 1]
    wall = np.array([[-0.5, 0.3, -0.2], [0.5, 0.3, -0.2], [0.5, 0.3, 0.6], [-0.5, 0.3, 0.6]])
    v, t, m = _mesh([(ceiling, 0), (lamp, 1), (floor, 0), (wall, 0)])
    sc = build_scene(v, t, m, MATS, two_sided=True)
    groups = {round(float(np.cross(e1, e2) @ o), 6): seg for g, o, e1, e2, seg, _ in
              contact_segments(sc, np.arange(8), tol=1e-3)}
    ceil_segs = next(s for k, s in groups.items() if abs(abs(k) - 1) < 1e-9)
    assert len(ceil_segs) == 4                                   # the outline, not the diagonal
    length = np.linalg.norm(ceil_segs[:, 1] - ceil_segs[:, 0], axis=1)
    assert np.sort(length) == pytest.approx([0.2, 0.2, 0.4, 0.4], abs=1e-9)
    floor_segs = groups[0.0]                                     # one piece per wall triangle
    assert np.linalg.norm(floor_segs[:, 1] - floor_segs[:, 0], axis=1).sum() == pytest.approx(1.0, abs=1e-9)
    g = next(x for x in contact_segments(sc, np.arange(8), tol=1e-3) if x[0][0] in (4, 5))
    world = g[1] + g[4] @ np.stack([g[2], g[3]])                 # back to 3D
    assert np.allclose(world[..., 1], 0.3) and np.allclose(world[..., 2], 0.0)


def test_straddling_finds_the_triangles_the_lamps_outline_crosses():
    """A ceiling meshed into ~20k triangles with a rotated lamp 0.5 mm under it: the triangles
    ``straddling`` flags are those whose area lies partly under the lamp and partly not
    (exact clipped areas, beyond a 2% margin either way), as brute force over all of them."""
    from raybundle.patches.clusters import tessellate
    from raybundle.patches.gaps import straddling
    from raybundle.tracing.visibility import RayTracer

    ceiling = np.array([[-1, -1, 1], [-1, 1, 1], [1, 1, 1], [1, -1, 1]], float)       # facing down
    lamp = np.concatenate([_rot(np.array([[-0.3, -0.3, 0], [0.3, -0.3, 0], [0.3, 0.3, 0], [-0.3, 0.3, 0]]))[:, :2],
                           np.full((4, 1), 1 - 5e-4)], axis=1)
    v, t, m = _mesh([(ceiling, 0), (lamp, 1)])
    sc = tessellate(build_scene(v, t, m, MATS, two_sided=True), 20000)
    faces = np.nonzero(sc.triangle_material == 0)[0]
    tr = RayTracer(sc)
    try:
        got = straddling(tr, sc, faces, tol=0.005)
    finally:
        tr.close()
    outline = footprint_of(lamp)
    corners = sc.triangle_corners[faces][:, :, :2]
    inside = np.array([clipped_area(c, outline) for c in corners]) / sc.triangle_area[faces]
    assert got[(inside > 0.02) & (inside < 0.98)].all()
    assert not got[(inside == 0) | (inside >= 1 - 1e-9)].any()
    assert 50 < got.sum() < 0.05 * len(faces)


def footprint_of(quad):
    """The xy outline (4, 2) of a quad, counter-clockwise."""
    p = np.asarray(quad, float)[:, :2]
    area = 0.5 * np.sum(p[:, 0] * np.roll(p[:, 1], -1) - np.roll(p[:, 0], -1) * p[:, 1])
    return p if area > 0 else p[::-1]


def test_box_query_equals_the_pass_over_all_boxes():
    """The sorted sweep that finds triangles near a plane returns exactly what testing every
    box does, long boxes (the 1% outside the sorted window) included."""
    from raybundle.patches.contacts import _BoxQuery

    rng = np.random.default_rng(5)
    lo = rng.uniform(-1, 1, (3000, 3))
    size = rng.exponential(0.02, (3000, 3))
    size[rng.random(3000) < 0.02] *= 60                 # a few long ones
    hi = lo + size
    query = _BoxQuery(lo, hi)
    for _ in range(200):
        a = rng.uniform(-1.2, 1, 3)
        b = a + rng.exponential(0.1, 3)
        brute = np.nonzero(np.all((hi >= a) & (lo <= b), axis=1))[0]
        assert np.array_equal(query(a, b), brute)


def test_touching_pairs_are_the_pass_over_all_pairs():
    """The pairs of a triangle and a contact segment that touch, found among the pairs whose
    boxes overlap, are exactly those that testing every pair finds: segments along edges,
    through corners, ending at corners, long ones and short ones."""
    from raybundle.patches.contacts import _crosses, _on_segment, _touching, _touching_pairs

    rng = np.random.default_rng(7)
    corner = rng.uniform(0, 1, (400, 2))
    tri = corner[:, None] + rng.normal(0, 0.03, (400, 3, 2))
    along = tri[rng.integers(0, 400, 150)][:, :2]                       # along a triangle's edge
    ends = tri[rng.integers(0, 400, 150)][:, :2] * np.array([1, 0.5])[:, None] + 0.01   # from a corner
    free = rng.uniform(0, 1, (300, 2, 2))
    free[:30, 1] = free[:30, 0] + rng.normal(0, 0.5, (30, 2))            # a few long ones
    seg = np.concatenate([along, ends, free])
    f, k = np.meshgrid(np.arange(len(tri)), np.arange(len(seg)), indexing="ij")
    f, k = f.reshape(-1), k.reshape(-1)
    brute = _touching(tri[f], seg[k], 1e-9) | _on_segment(tri[f], seg[k], 1e-9).any(axis=1)
    pf, pk, crosses = _touching_pairs(tri, seg, 1e-9)
    assert 500 < len(pf) < 0.2 * len(f)
    assert np.array_equal(pf, f[brute]) and np.array_equal(pk, k[brute])
    assert np.array_equal(crosses, _crosses(tri[pf], seg[pk], 1e-9)) and 0 < crosses.sum() < len(pf)


def shelf_through_a_wall(triangles=4000):
    """A closed 2 m room (everything two-sided, nothing lit inside) with a shelf sunk through
    its wall at x = 1, lit from outside by a point light above the shelf's outer end; every
    face meshed into many small triangles, as a furnished model is."""
    from raybundle.patches.clusters import tessellate
    c = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)], float)
    room = [c[[0, 1, 3, 2]], c[[4, 6, 7, 5]], c[[0, 4, 5, 1]], c[[2, 3, 7, 6]], c[[0, 2, 6, 4]], c[[1, 5, 7, 3]]]
    shelf = np.array([[0.45, -0.3, 0.0], [1.6, -0.3, 0.0], [1.6, 0.3, 0.0], [0.45, 0.3, 0.0]])
    v, t, m = _mesh([(q, 0) for q in room] + [(shelf, 0)])
    pl = PointLights(position=[[1.4, 0.0, 0.6]], intensity=[[20.0, 20.0, 20.0]])
    return tessellate(build_scene(v, t, m, MATS, point_lights=pl, two_sided=True), triangles)


#: the lamp under the grid ceiling: x and y ranges [m]; two of its sides run along grid lines
LAMP_X, LAMP_Y = (-0.3, 0.33), (-0.5, 0.52)


def grid_ceiling_with_a_lamp(n=40, shift=0.0):
    """A 2 x 2 m ceiling meshed as Edit Mode's Subdivide makes it (an n x n grid of quads sharing
    their vertices, facing down) with a lamp 0.5 mm under it (:data:`LAMP_X`, :data:`LAMP_Y`:
    two sides of its outline run along grid lines, through the grid's vertices; the other two
    cross the grid's triangles; ``shift`` [m] moves the lamp along x, so the grid's vertices lie
    that far inside the outline); a floor 1 m below.  Everything two-sided."""
    x = np.linspace(-1.0, 1.0, n + 1)
    gx, gy = np.meshgrid(x, x)
    verts = np.column_stack([gx.ravel(), gy.ravel(), np.ones(gx.size)])
    j, i = np.divmod(np.arange(n * n), n)
    a = j * (n + 1) + i
    quads = np.stack([a, a + n + 1, a + n + 2, a + 1], axis=1)
    tris = np.concatenate([quads[:, [0, 1, 2]], quads[:, [0, 2, 3]]])
    (x0, x1), (y0, y1) = LAMP_X, LAMP_Y
    lamp = np.array([[x0, y0, 0], [x1, y0, 0], [x1, y1, 0], [x0, y1, 0]]) + [shift, 0, 1 - 5e-4]
    floor = np.array([[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]], float)
    v, t, m = _mesh([(lamp, 1), (floor, 0)])
    return build_scene(np.concatenate([verts, v]), np.concatenate([tris, t + len(verts)]),
                       np.concatenate([np.zeros(len(tris), np.int64), m]), MATS, two_sided=True)


@pytest.mark.parametrize("shift", [0.0, -2e-5])
def test_a_grid_ceiling_does_not_weld_the_light_above_a_lamp_to_the_ceiling_beside_it(monkeypatch, shift):
    """A large scene is cut at contacts only where triangles straddle a gap or pierce a surface
    (``CONTACT_ALL_MAX``, set to 0 here): the grid ceiling's triangles along the lamp's sides that
    cross them.  The triangles along its other two sides straddle nothing (the outline runs
    along their edges), yet their corners on it must not weld with those of the triangles above
    the lamp: the light trapped there (the lamp's back, 0.5 mm below) would be interpolated into
    the ceiling beside it.  (The old code tagged only the corners of the triangles it could cut:
    a ceiling subdivided in Edit Mode over the Cornell box's lamp had corner values of 71 W/m^2
    from the lamp's back where its patches held 0.15, and every bake's gather read them.)  With
    the lamp shifted 20 microns, the grid's vertices on the outline lie inside it: the triangles
    beside it cross the outline by a sliver too small to cut off, and their corners in the sliver
    are on the contact all the same."""
    from raybundle.patches import layout
    monkeypatch.setattr(layout, "CONTACT_ALL_MAX", 0)
    sc = pipeline.prepare(grid_ceiling_with_a_lamp(shift=shift), patches=300)
    ids = sc.smooth_vertex_ids[:len(sc.triangles)]
    c = sc.triangle_corners
    ceiling = np.nonzero((np.abs(c[:, :, 2] - 1) < 1e-12).all(axis=1))[0]
    (x0, x1), (y0, y1) = LAMP_X, LAMP_Y
    x0, x1 = x0 + shift, x1 + shift
    x, y = c[ceiling, :, 0], c[ceiling, :, 1]
    tol = 1e-9 + abs(shift)
    within = (x >= x0 - tol) & (x <= x1 + tol) & (y >= y0 - tol) & (y <= y1 + tol)      # (T, 3)
    beyond = (x <= x0 + tol) | (x >= x1 - tol) | (y <= y0 + tol) | (y >= y1 - tol)
    cx, cy = x.mean(axis=1), y.mean(axis=1)
    centre_in = (cx > x0) & (cx < x1) & (cy > y0) & (cy < y1)
    t_in, t_out = ceiling[within.all(axis=1) & centre_in], ceiling[beyond.all(axis=1) & ~centre_in]
    assert (within & beyond)[np.isin(ceiling, t_out)].sum() > 40          # corners on the outline
    assert not set(ids[t_in].ravel()) & set(ids[t_out].ravel())
    solver = pipeline.make_solver(sc, RenderSettings(seed=5))
    e = solver.first_shot.E.sum(axis=1)[:, 0]
    down = sc.tside_normal[:, 2] < -0.5
    inner = np.isin(sc.tside_triangle, t_in) & down
    outer = np.isin(sc.tside_triangle, t_out) & down
    assert e[sc.tside_side[inner]].mean() > 20 * e[sc.tside_side[outer]].max()      # the trapped light
    vert = solver.reconstruction.smooth_and_sharp(e[:, None], None)
    corner_values = vert[solver.reconstruction.ids[np.nonzero(outer)[0]]]
    assert corner_values.max() <= 2 * e[sc.tside_side[outer]].max()


def test_no_light_leaks_along_a_shelf_sunk_through_a_wall(monkeypatch):
    """A large scene is cut at contacts only where triangles straddle a gap or pierce another
    surface (``CONTACT_ALL_MAX``, set to 0 here).  The shelf's small triangles that pierce the
    wall are cut along it, and neither a patch nor a welded corner joins the pieces in the
    room with those outside: the first shot of the light outside gives the shelf's part in
    the room exactly nothing, at the patches and at the corners the image interpolates
    (the old layout grouped the pieces across the wall: up to 4.6% of the outer part's mean
    irradiance on the room's shelf patches, 4.5% at their corners)."""
    from raybundle.patches import layout
    monkeypatch.setattr(layout, "CONTACT_ALL_MAX", 0)
    assert_the_shelf_is_dark_in_the_room(pipeline.prepare(shelf_through_a_wall(), patches=300))


def assert_the_shelf_is_dark_in_the_room(sc):
    """The first shot of the light outside lights the shelf's upper side outside the wall and
    gives its part in the room exactly nothing, at the patches and at the corners the image
    interpolates."""
    solver = pipeline.make_solver(sc, RenderSettings(seed=5))
    e = solver.first_shot.E.sum(axis=1)[:, 0]                        # (S,) per side
    tri = sc.tside_triangle
    shelf = np.abs(sc.triangle_corners[tri][:, :, 2]).max(axis=1) < 1e-12
    x = sc.triangle_corners[tri][:, :, 0]
    up = sc.tside_normal[:, 2] > 0.5
    room, out = shelf & up & (x.max(axis=1) <= 1 + 1e-9), shelf & up & (x.min(axis=1) >= 1 - 1e-9)
    assert room.sum() > 50 and out.sum() > 50
    assert e[sc.tside_side[out]].mean() > 0.1
    assert e[sc.tside_side[room]].max() == 0.0
    vert = solver.reconstruction.smooth_and_sharp(e[:, None], None)
    assert np.abs(solver.reconstruction.at(vert, np.nonzero(room)[0], np.full((room.sum(), 3), 1 / 3))).max() == 0.0


def test_a_contact_across_the_cut_of_a_pierced_wall_keeps_both_tags(monkeypatch):
    """The shelf through the wall with a thin panel standing on it across the wall (at
    y = 0.15, x 0.7 to 1.3): the shelf's triangles there pierce two surfaces, the wall and the
    panel's foot.  They are cut along both planes (the pieces of the first cut again), the
    corners where two cuts meet get tags of their own, a contact's cut keeps the pierce tags,
    and no cluster holds shelf pieces from both sides of the wall.  So the light outside gives
    the room's part exactly nothing, at the patches and at the corners the image
    interpolates.  (The earlier code cut each triangle along one plane, here often the
    panel's, and grouped shelf triangles from x = 0.74 to 1.03 into one patch: up to
    2.5 W/m^2 on the room's part.)"""
    from raybundle.patches import layout
    from raybundle.patches.clusters import tessellate
    monkeypatch.setattr(layout, "CONTACT_ALL_MAX", 0)
    base = shelf_through_a_wall()
    panel = np.array([[0.7, 0.15, 0.0], [1.3, 0.15, 0.0], [1.3, 0.15, 0.3], [0.7, 0.15, 0.3]])
    v, t, m = _mesh([(panel, 0)])
    sc0 = build_scene(np.concatenate([base.vertices, v]), np.concatenate([base.triangles, t + len(base.vertices)]),
                      np.concatenate([base.triangle_material, m]), MATS, point_lights=base.point_lights,
                      two_sided=True)
    assert_the_shelf_is_dark_in_the_room(pipeline.prepare(tessellate(sc0, 4200), patches=300))


def test_a_small_round_footprint_does_not_shred_the_floor():
    """A 64-sided post 6 cm across standing on the floor beside the box: each of its edges on
    the floor is under 5% of a floor patch, so none cuts the patches (each would run across the
    whole patch, far from the post): the floor patches near the post stay whole (on the old code
    its 64 lines cut them into some 50 slivers under a tenth of a patch)."""
    sc = box_on_floor()
    ring = np.array([[0.6 + 0.03 * np.cos(a), -0.6 + 0.03 * np.sin(a), 0.0]
                     for a in np.linspace(0, 2 * np.pi, 64, endpoint=False)])
    quads = [(np.array([ring[i], ring[(i + 1) % 64], ring[(i + 1) % 64] + [0, 0, 0.2], ring[i] + [0, 0, 0.2]]), 0)
             for i in range(64)]
    v, t, m = _mesh(quads)
    both = build_scene(np.concatenate([sc.vertices, v]), np.concatenate([sc.triangles, t + len(sc.vertices)]),
                       np.concatenate([sc.triangle_material, m]), MATS, point_lights=sc.point_lights,
                       camera=sc.camera, two_sided=True)
    cut = subdivide(both, patches=600)
    floor = np.abs(cut.triangle_corners[:, :, 2]).max(axis=1) < 1e-12
    patches = np.unique(cut.triangle_patch[floor])
    centre = np.array([cut.triangle_corners[cut.triangle_patch == p].reshape(-1, 3).mean(axis=0) for p in patches])
    near = np.linalg.norm(centre[:, :2] - [0.6, -0.6], axis=1) < 0.25
    area = cut.patch_area[patches]
    assert near.sum() > 4 and area[near].min() > 0.5 * np.median(area), (near.sum(), area[near].min())
