import numpy as np
import pytest

from raybundle.scene.materials import MaterialTable
from raybundle.scene.microfacet import ggx_albedo
from raybundle.tracing.sampling import uniform_sphere

MATS = MaterialTable.from_list([
    dict(name="lambert", diffuse=(0.8, 0.5, 0.2)),
    dict(name="ggx03", glossy=(1, 1, 1), roughness=0.3, glossy_weight=1.0),
    dict(name="ggx07", glossy=(0.9, 0.6, 0.3), roughness=0.7, glossy_weight=1.0),
    dict(name="mix", diffuse=(1, 1, 1), glossy=(1, 1, 1), roughness=0.3, glossy_weight=0.5),
])


def mc_albedo(mat, mu, rng, n=400_000):
    """4 pi f cos over uniform sphere directions: an unbiased albedo estimate and its standard error."""
    wo = np.array([np.sqrt(1 - mu * mu), 0.0, mu])
    d = uniform_sphere(rng.random(n), rng.random(n))
    f = MATS.brdf(np.full(n, mat), np.tile([0, 0, 1.0], (n, 1)), d, wo)
    y = 4 * np.pi * f * np.maximum(-d[:, 2:3], 0)
    return y.mean(axis=0), y.std(axis=0) / np.sqrt(n)


@pytest.mark.parametrize("mat", range(4))
@pytest.mark.parametrize("mu", [0.25, 0.6, 0.95])
def test_albedo_table_matches_numerical_integration(mat, mu, rng):
    est, se = mc_albedo(mat, mu, rng)
    table = MATS.albedo(np.array([mat]), np.array([mu]))[0]
    assert np.all(np.abs(est - table) < 4.5 * se + 1e-4), (est, se, table)


def test_lambert_albedo_is_exact(rng):
    est, se = mc_albedo(0, 0.5, rng)
    assert np.allclose(MATS.albedo(np.array([0]), np.array([0.5]))[0], [0.8, 0.5, 0.2])
    assert np.all(np.abs(est - [0.8, 0.5, 0.2]) < 4.5 * se)


def test_ggx_albedo_quadrature_is_converged():
    mu = [0.02, 0.1, 0.5, 1.0]
    for alpha in (0.04, 0.3):
        a1 = ggx_albedo(alpha, mu)
        a2 = ggx_albedo(alpha, mu, n_theta=2048, n_phi=512)
        assert np.all(np.abs(a1 - a2) < 2e-5), (alpha, a1 - a2)   # the accuracy the docstring states
        assert np.all(a1 <= 1.0) and np.all(a1 > 0.5)


def test_reciprocity_above_the_surface_and_no_light_from_below(rng):
    """Above the surface the BRDF is reciprocal; light from below it reflects nothing; a viewer
    below a lit point (a smooth normal that faces away from the eye) sees the diffuse lobe alone,
    as Cycles' Diffuse BSDF and its glossy closures do."""
    n = 10_000
    a = uniform_sphere(rng.random(n), rng.random(n))
    b = uniform_sphere(rng.random(n), rng.random(n))
    normal = np.tile([0, 0, 1.0], (n, 1))
    front = (a[:, 2] < 0) & (b[:, 2] > 0)
    below = (a[:, 2] < 0) & (b[:, 2] <= 0)
    for m in range(4):
        mats = np.full(n, m)
        f_ab = MATS.brdf(mats, normal, a, b)           # light travels along a, leaves along b
        f_ba = MATS.brdf(mats, normal, -b, -a)         # the reversed path
        assert np.allclose(f_ab[front], f_ba[front], rtol=1e-10, atol=1e-12)
        assert np.all(f_ab[a[:, 2] >= 0] == 0) and np.all(f_ab[front] >= 0)
        diffuse = MATS.brdf(mats[below], normal[below], a[below], b[below], glossy=False)
        assert np.allclose(f_ab[below], diffuse, rtol=1e-12, atol=0)
        assert np.all((diffuse > 0) == (MATS.diffuse_reflectance[m] > 0))


def test_energy_conservation_everywhere():
    mu = np.linspace(0.01, 1, 50)
    for m in range(4):
        a = MATS.albedo(np.full(len(mu), m), mu)
        assert np.all(a <= 1.0 + 1e-9)


@pytest.mark.parametrize("spec,msg", [
    (dict(diffuse=(1.2, 0.5, 0.5)), "component > 1"),
    (dict(glossy=(0.5, 1.5, 0.5), glossy_weight=1), "component > 1"),
    (dict(diffuse=(np.nan, 0.5, 0.5)), "not finite"),
    (dict(emission=(-1, 0, 0)), "negative"),
    (dict(roughness=1.5), "roughness"),
])
def test_invalid_materials_are_rejected(spec, msg):
    with pytest.raises(ValueError, match=msg):
        MaterialTable.from_list([dict(name="bad", **spec)]).validate()


def test_emission_one_sided_and_albedo_complement():
    mt = MaterialTable.from_list([dict(glossy=(1, 1, 1), roughness=0.5, glossy_weight=1,
                                       emission_albedo_complement=(2, 2, 2))])
    mu = np.array([0.3, 0.9, -0.2])
    le = mt.emitted_radiance(np.zeros(3, int), mu)
    a = mt.albedo(np.zeros(3, int), mu)
    assert np.allclose(le[:2], 2 * (1 - a[:2]))
    assert np.all(le[2] == 0)


# ---------------------------------------------------------- Principled (layered) materials
from raybundle.scene.principled import principled_material

LAYERED = MaterialTable.from_list([
    principled_material((0.8, 0.5, 0.2), metallic=0.0, roughness=0.3),                    # dielectric over Lambert
    principled_material((0.9, 0.6, 0.3), metallic=1.0, roughness=0.5),                    # F82 conductor
    principled_material((0.9, 0.6, 0.3), metallic=0.4, roughness=0.6, specular_tint=(1, .5, .2)),
    principled_material((1, 1, 1), metallic=0.0, roughness=0.5, ior=2.0, distribution="GGX"),
    dict(name="glossy_multiscatter", glossy=(0.9, 0.7, 0.5), roughness=0.7, glossy_weight=1.0, multiscatter=1),
    dict(name="conductor_single", glossy=(0.9, 0.6, 0.3), roughness=0.4, glossy_weight=1.0, glossy_fresnel=1),
])


def mc_albedo_of(mt, mat, mu, rng, n=400_000, **lobes):
    wo = np.array([np.sqrt(1 - mu * mu), 0.0, mu])
    d = uniform_sphere(rng.random(n), rng.random(n))
    f = mt.brdf(np.full(n, mat), np.tile([0, 0, 1.0], (n, 1)), d, wo, **lobes)
    y = 4 * np.pi * f * np.maximum(-d[:, 2:3], 0)
    return y.mean(axis=0), y.std(axis=0) / np.sqrt(n)


@pytest.mark.parametrize("mat", range(len(LAYERED)))
@pytest.mark.parametrize("mu", [0.25, 0.95])
def test_layered_albedo_table_matches_numerical_integration(mat, mu, rng):
    est, se = mc_albedo_of(LAYERED, mat, mu, rng)
    table = LAYERED.albedo(np.array([mat]), np.array([mu]))[0]
    # quadrature tables: < 2e-4 (ggx_fresnel_moments); linear interpolation in mu on 65 points: < 5e-4
    assert np.all(np.abs(est - table) < 4.5 * se + 7e-4), (est, se, table)


def test_layered_energy_conservation_and_white_furnace():
    mu = np.linspace(0.01, 1, 60)
    for m in range(len(LAYERED)):
        a = LAYERED.albedo(np.full(len(mu), m), mu)
        assert np.all(a <= 1.0 + 1e-9) and np.all(a >= 0)
    # multiscatter restores a white conductor to albedo 1 exactly (C E = E + Fms (1 - E), Fms = 1)
    mt = MaterialTable.from_list([principled_material((1, 1, 1), metallic=1.0, roughness=r) for r in (0.2, 0.6, 1.0)])
    for m in range(3):
        assert np.allclose(mt.albedo(np.full(len(mu), m), mu), 1.0, atol=1e-9)
    # a white dielectric Principled loses at most ~1% (Cycles: 0.991 at roughness 0.5, 80 degrees) and gains nothing
    mt = MaterialTable.from_list([principled_material((1, 1, 1), roughness=r) for r in (0.0, 0.2, 0.5, 0.8)])
    for m in range(4):
        a = mt.albedo(np.full(len(mu), m), mu)
        assert np.all(a <= 1 + 1e-9) and np.all(a > 0.985), a.min()


def test_conductor_without_multiscatter_is_reciprocal(rng):
    n = 10_000
    a = uniform_sphere(rng.random(n), rng.random(n))
    b = uniform_sphere(rng.random(n), rng.random(n))
    normal = np.tile([0, 0, 1.0], (n, 1))
    mats = np.full(n, 5)
    f_ab = LAYERED.brdf(mats, normal, a, b)
    assert np.allclose(f_ab, LAYERED.brdf(mats, normal, -b, -a), rtol=1e-10, atol=1e-12)
    front = (a[:, 2] < 0) & (b[:, 2] > 0)
    assert np.all(f_ab[~front] == 0) and np.all(f_ab[front] >= 0) and np.any(f_ab[front] > 0)


def test_layered_brdf_factorizes_into_view_dependent_terms(rng):
    """The Principled BRDF is not reciprocal (Cycles scales by functions of w_out), but
    dividing out diffuse_weight(w_out) leaves the reciprocal Lambert term."""
    n = 5000
    a = uniform_sphere(rng.random(n), rng.random(n))
    b = uniform_sphere(rng.random(n), rng.random(n))
    normal = np.tile([0, 0, 1.0], (n, 1))
    mats = np.zeros(n, int)
    front = (a[:, 2] < 0) & (b[:, 2] > 0)
    fd = LAYERED.brdf(mats, normal, a, b, glossy=False)
    wd = LAYERED.diffuse_weight(mats, b[:, 2])
    assert np.all((wd > 0) & (wd < 1))
    assert np.allclose(fd[front], (LAYERED.diffuse_reflectance[mats] / np.pi * wd)[front])
    # the diffuse part of albedo() is diffuse_reflectance * diffuse_weight
    mu = np.linspace(0.05, 1, 20)
    assert np.allclose(LAYERED.albedo(np.zeros(20, int), mu, glossy=False),
                       LAYERED.diffuse_reflectance[0] * LAYERED.diffuse_weight(np.zeros(20, int), mu))


@pytest.mark.parametrize("mat", range(len(LAYERED)))
@pytest.mark.parametrize("mu", [0.3, 0.9])
def test_sample_glossy_weight_mean_is_glossy_albedo(mat, mu, rng):
    n = 200_000
    wo = np.array([np.sqrt(1 - mu * mu), 0.0, mu])
    normal = np.tile([0, 0, 1.0], (n, 1))
    w_i, wt = LAYERED.sample_glossy(np.full(n, mat), normal, wo, rng.random((n, 2)))
    assert np.all(wt[w_i[:, 2] <= 0] == 0) and np.all(wt >= 0)
    est, se = wt.mean(axis=0), wt.std(axis=0) / np.sqrt(n)
    ref = LAYERED.albedo(np.array([mat]), np.array([mu]), diffuse=False)[0]
    assert np.all(np.abs(est - ref) < 4.5 * se + 7e-4), (est, se, ref)


def test_sample_glossy_of_plain_materials_is_the_old_expression(rng):
    from raybundle.scene.microfacet import sample_ggx_reflection
    n = 1000
    mats = rng.integers(0, 4, n)
    normal = np.tile([0, 0, 1.0], (n, 1))
    wo = np.array([0.6, 0.0, 0.8])
    u = rng.random((n, 2))
    w_i, wt = MATS.sample_glossy(mats, normal, wo, u)
    w_i0, w0 = sample_ggx_reflection(MATS.alpha[mats], normal, np.broadcast_to(wo, normal.shape), u)
    assert np.array_equal(w_i, w_i0)
    assert np.array_equal(wt, MATS.glossy_weight[mats][:, None] * MATS.glossy[mats] * w0[:, None])
    assert np.array_equal(MATS.diffuse_weight(mats, np.full(n, 0.5)), np.ones((n, 3)))
    assert not MATS.is_layered.any()


def test_ggx_samples_weigh_at_most_one_at_grazing_views(rng):
    """Visible-normal sampling: ``weight = G2 / G1(w_out) <= 1`` for every view, grazing
    ones included (half vectors drawn from D(h) (n.h) weigh up to ~2 / alpha there:
    16 for alpha 0.04 at cos_out 0.02), and the weights still average to the lobe's
    albedo (within 4.5 standard errors)."""
    from raybundle.scene.microfacet import sample_ggx_reflection
    n = 200_000
    normal = np.tile([0, 0, 1.0], (n, 1))
    for alpha in (0.04, 0.3):
        for mu in (0.02, 0.2, 0.9):
            wo = np.broadcast_to([np.sqrt(1 - mu * mu), 0.0, mu], normal.shape)
            w_i, w = sample_ggx_reflection(np.full(n, alpha), normal, wo, rng.random((n, 2)))
            assert w.max() <= 1.0 + 1e-12 and w.min() >= 0.0 and np.all(w[w_i[:, 2] <= 0] == 0)
            ref = ggx_albedo(alpha, [mu])[0]
            assert abs(w.mean() - ref) < 4.5 * w.std() / np.sqrt(n) + 1e-5, (alpha, mu, w.mean(), ref)


def test_principled_mapping():
    s = principled_material((0.8, 0.5, 0.2, 1.0), metallic=0.3, roughness=0.4, emission=(2, 1, 0))
    assert s["diffuse"] == s["glossy"] == (0.8, 0.5, 0.2) and s["glossy_weight"] == 0.3
    assert s["specular_ior"] == 1.5 and s["glossy_fresnel"] == 1 and s["multiscatter"] == 1
    assert s["emission"] == (2, 1, 0)
    assert principled_material((1, 1, 1), specular_ior_level=0.0)["specular_ior"] == 0.0     # no layer, as Cycles
    eta = principled_material((1, 1, 1), ior=1.5, specular_ior_level=1.0)["specular_ior"]
    assert abs(((eta - 1) / (eta + 1)) ** 2 - 2 * 0.04) < 1e-12                               # F0 doubled
    assert principled_material((1, 1, 1), distribution="GGX")["multiscatter"] == 0
    mt = MaterialTable.from_list([s, principled_material((1, 1, 1), specular_ior_level=0.0)])
    mt.validate()
    assert list(mt.is_glossy) == [True, False] and list(mt.is_layered) == [True, False]   # level 0: plain Lambert


def test_layered_arrays_round_trip_and_old_files_load():
    d = LAYERED.to_arrays()
    back = MaterialTable.from_arrays(d)
    for k in ("specular_ior", "specular_tint", "glossy_fresnel", "multiscatter"):
        assert np.array_equal(getattr(back, k), getattr(LAYERED, k))
    mu = np.linspace(0.1, 1, 5)
    m = np.arange(len(LAYERED)).repeat(5)
    assert np.array_equal(back.albedo(m, np.tile(mu, len(LAYERED))), LAYERED.albedo(m, np.tile(mu, len(LAYERED))))
    old = {k: v for k, v in MATS.to_arrays().items()
           if not k.endswith(("specular_ior", "specular_tint", "glossy_fresnel", "multiscatter"))}
    legacy = MaterialTable.from_arrays(old)
    assert np.all(legacy.specular_ior == 0) and np.all(legacy.specular_tint == 1) and not legacy.is_layered.any()


@pytest.mark.parametrize("spec,msg", [
    (dict(specular_ior=0.7), "specular_ior"),
    (dict(glossy_fresnel=2), "glossy_fresnel"),
    (dict(specular_ior=1.5, specular_tint=(1.2, 1, 1)), "component > 1"),
    (dict(specular_ior=np.inf), "not finite"),
])
def test_invalid_layered_materials_are_rejected(spec, msg):
    with pytest.raises(ValueError, match=msg):
        MaterialTable.from_list([dict(name="bad", **spec)]).validate()


def test_the_untinted_f82_moment_is_the_quadrature_of_f82_and_one_quadrature_serves_every_color():
    """E[w F82(c)] of an untinted F82 (b = 0) comes from two scalar moments of the lobe (F82 is
    linear in f0 there): the same as the quadrature of F82 itself, for any f0; and the lobe's
    quadrature is made once for a roughness, an IOR and the mu grid, whatever the colors."""
    from raybundle.scene import microfacet as mf

    mu = np.linspace(0.05, 1.0, 7)
    f0 = np.array([0.9, 0.5, 0.04])
    got = mf.ggx_fresnel_moments(0.37, mu, eta=1.45, f82=(f0, np.zeros(3)), n_theta=64, n_phi=8)["F82"]
    want = np.stack([(w[:, None] * mf.fresnel_f82(c, f0, np.zeros(3))).mean(axis=0)
                     for w, _, c in mf._lobe_points(0.37, mu, 64, 8)])
    assert np.allclose(got, want, rtol=1e-12, atol=1e-15)
    hits = mf._moments.cache_info().hits
    mf.ggx_fresnel_moments(0.37, mu, eta=1.45, f82=(np.array([0.2, 0.3, 0.4]), np.zeros(3)), n_theta=64, n_phi=8)
    assert mf._moments.cache_info().hits == hits + 1
    tinted = mf.ggx_fresnel_moments(0.37, mu, f82=(f0, np.full(3, 0.3)), n_theta=64, n_phi=8)["F82"]
    assert np.allclose(tinted, [(w[:, None] * mf.fresnel_f82(c, f0, np.full(3, 0.3))).mean(axis=0)
                                for w, _, c in mf._lobe_points(0.37, mu, 64, 8)])
