import math

import mpmath
import numpy as np
import pytest

from raybundle.tracing.sampling import (
    HaltonSequence,
    PiPowersSequence,
    PRNGSequence,
    invert_uniform_sphere,
    radical_inverse,
    stratified_2d,
    uniform_sphere,
    uniform_triangle,
)


def chi2_uniform_sphere(d, n_theta=9, n_phi=17):
    """Pearson chi-square of directions against the uniform density over (cos theta, phi) cells."""
    z = d[:, 2]
    phi = np.arctan2(d[:, 1], d[:, 0]) % (2 * np.pi)
    h, _, _ = np.histogram2d(z, phi, bins=[n_theta, n_phi], range=[[-1, 1], [0, 2 * np.pi]])
    expected = len(d) / (n_theta * n_phi)       # equal solid angle per cell
    return ((h - expected) ** 2 / expected).sum(), n_theta * n_phi - 1


def test_uniform_sphere_is_uniform_chi_square(rng):
    d = uniform_sphere(rng.random(200_000), rng.random(200_000))
    assert np.allclose(np.linalg.norm(d, axis=1), 1.0)
    stat, dof = chi2_uniform_sphere(d)
    # 0.1% upper quantile of chi2(152) is about 213 (Wilson-Hilferty)
    assert stat < dof + 3.09 * math.sqrt(2 * dof) + 10, stat


def test_uniform_sphere_round_trip(rng):
    u1, u2 = rng.random(1000), rng.random(1000)
    v1, v2 = invert_uniform_sphere(uniform_sphere(u1, u2))
    assert np.allclose(u1, v1) and np.allclose(u2, v2)


def test_uniform_triangle_and_stratified(rng):
    b = uniform_triangle(rng.random(100_000), rng.random(100_000))
    assert np.all(b >= -1e-12) and np.allclose(b.sum(axis=1), 1)
    assert np.allclose(b.mean(axis=0), 1 / 3, atol=0.005)    # centroid; SE ~ 0.0007
    s = stratified_2d(16, rng)
    cells = (s * 4).astype(int)
    assert len({tuple(c) for c in cells}) == 16


def test_pi_powers_match_arbitrary_precision():
    seq = PiPowersSequence(start=1, capacity=64)
    got = np.concatenate([seq.next(7) for _ in range(100)])     # n = 1 .. 700, several rebuilds
    mpmath.mp.dps = 400
    for n in (1, 2, 10, 33, 34, 100, 399, 700):
        want = float(mpmath.frac(mpmath.pi ** n))
        assert abs(got[n - 1] - want) < 1e-15, n
    # in doubles the sequence collapses to 0 (the reason for exact arithmetic)
    assert math.modf(math.pi ** 40)[0] == 0.0
    assert 0.3 < got.mean() < 0.7 and got.min() >= 0 and got.max() < 1


def test_pi_fixed_point_matches_arbitrary_precision():
    from raybundle.tracing.sampling import pi_fixed_point

    for bits in (53, 1000, 20000):
        with mpmath.workprec(bits + 64):
            assert pi_fixed_point(bits) == int(mpmath.floor(mpmath.ldexp(mpmath.pi, bits))), bits


def test_halton_radical_inverse():
    assert [radical_inverse(2, i) for i in range(1, 5)] == [0.5, 0.25, 0.75, 0.125]
    assert radical_inverse(3, 5) == pytest.approx(2 / 3 + 1 / 9)   # 5 = 12 in base 3 -> 0.21
    h = HaltonSequence(start=1)
    assert np.allclose(h.next(2), [0.5, 1 / 3])


def toy_iteration(seq, n):
    """Stochastic iteration of x = 0.1 x + 1.8 with T* x = 0.2 u x (E[T*] = 0.1): exact 2."""
    x, avg = 0.0, 0.0
    for m in range(1, n + 1):
        x = 1.8 + 0.2 * seq.next(1)[0] * x
        avg += (x - avg) / m
    return avg


def test_toy_iteration_prng_and_pi_powers_converge():
    # x_n = e + t_n x_{n-1}, t ~ U[0, 0.2]: q = 0.1, s^2 = 0.04/3; stationary Var =
    # e^2 (s^2 - q^2) / ((1-q)^2 (1-s^2)) = 0.0133, Var(avg) ~ Var (1+q)/((1-q) m)
    for seq, n in ((PRNGSequence(3), 20_000), (PiPowersSequence(), 8_000)):
        var = 1.8 ** 2 * (0.04 / 3 - 0.01) / (0.81 * (1 - 0.04 / 3))
        se = math.sqrt(var * 1.1 / (0.9 * n))
        start_bias = 2.0 / n     # O(1/m) start-up from x0 = 0
        assert abs(toy_iteration(seq, n) - 2.0) < 5 * se + start_bias


def test_stratified_sequence_covers_every_cell_and_keeps_consecutive_steps_independent():
    """Each stream deals all k x k cells once per block; step n and n+1 come from different
    streams, so their joint distribution is uniform on cell pairs (chi-square over
    16 x 16 pairs of 4 x 4 cells, 255 dof: mean 255, sd 22.6; bound mean + 5 sd).  With
    one stream the same check fails: a cell cannot follow itself within a block."""
    from raybundle.tracing.sampling import StratifiedSequence

    seq = StratifiedSequence(seed=4, strata=256, streams=4)
    first = np.array([seq.next(2) for _ in range(4 * 256)])
    for s in range(4):                                       # stream s: steps s, s+4, ...
        cells = np.floor(first[s::4] * 16).astype(int)
        assert len(np.unique(cells[:, 0] * 16 + cells[:, 1])) == 256

    def pair_chi2(seq, n=40_000):
        u = np.array([seq.next(2) for _ in range(n + 1)])
        c = np.floor(u[:, 0] * 4).astype(int) * 4 + np.floor(u[:, 1] * 4).astype(int)
        counts = np.bincount(c[:-1] * 16 + c[1:], minlength=256)
        return ((counts - n / 256) ** 2 / (n / 256)).sum()

    assert pair_chi2(StratifiedSequence(seed=5, strata=16, streams=16)) < 255 + 5 * 22.6
    assert pair_chi2(StratifiedSequence(seed=5, strata=16, streams=1)) > 255 + 10 * 22.6


def test_toy_iteration_stratified_converges():
    """The toy iteration driven by the first coordinate of the stratified directions."""
    from raybundle.tracing.sampling import StratifiedSequence

    class FirstOfTwo:
        def __init__(self):
            self.seq = StratifiedSequence(seed=9)

        def next(self, dim):
            return self.seq.next(2)[:dim]

    n = 20_000
    var = 1.8 ** 2 * (0.04 / 3 - 0.01) / (0.81 * (1 - 0.04 / 3))
    se = math.sqrt(var * 1.1 / (0.9 * n))      # the PRNG's: stratification only lowers it
    assert abs(toy_iteration(FirstOfTwo(), n) - 2.0) < 5 * se + 2.0 / n


def test_toy_iteration_van_der_corput_is_wrong():
    # Halton's first coordinate (base 2) driving the iteration: a systematic error far
    # beyond Monte Carlo noise (algorithms.md 1.2: -0.0049 at 2e5 steps)
    err = toy_iteration(HaltonSequence(), 50_000) - 2.0
    assert err < -0.003


def test_kronecker_generators_and_stratification(rng):
    from raybundle.tracing.sampling import ShiftedKronecker, kronecker_alpha

    assert np.isclose(kronecker_alpha(1)[0], (math.sqrt(5) - 1) / 2)
    assert np.isclose(kronecker_alpha(2)[0], 1 / 1.324717957244746)      # plastic number
    s = ShiftedKronecker(3, 2, rng)
    pts = np.array([s.next() for _ in range(256)])                        # (pass, pixel, dim)
    # each pixel's 256 passes cover a 16 x 16 grid of cells far more evenly than random points
    for p in range(3):
        cells = np.histogram2d(pts[:, p, 0], pts[:, p, 1], bins=16, range=[[0, 1], [0, 1]])[0]
        assert cells.max() <= 3 and (cells == 0).sum() <= 60        # random: ~94 empty, max 4-6
    # and each pass, over pixels, is uniform: the shift is uniform per pixel
    many = ShiftedKronecker(20_000, 3, rng)
    many.next()
    u = many.next()
    assert np.allclose(u.mean(axis=0), 0.5, atol=0.01)


def test_pi_powers_refuse_runs_they_cannot_afford():
    from raybundle.tracing.sampling import make_sequence

    seq = PiPowersSequence(start=PiPowersSequence.MAX_N - 3)
    with pytest.raises(ValueError, match="use the 'prng'"):
        seq.next(8)
    with pytest.raises(ValueError, match="seed"):
        make_sequence("pi-powers", seed=5000)


def test_spherical_triangle_sampling_is_uniform_in_solid_angle(rng):
    """Arvo's sampler: every direction meets the triangle, the solid angle equals the
    closed form, and the mean of a smooth function of the direction equals its mean
    under area sampling weighted by the solid-angle Jacobian cos_l / r^2."""
    from raybundle.tracing.sampling import points_on_triangles, sample_spherical_triangle, triangle_solid_angle

    tri = np.array([[0.3, -0.2, 1.0], [-0.5, 0.1, 0.4], [0.2, 0.6, 0.2]])     # seen from the origin
    n = 200_000
    corners = np.broadcast_to(tri, (n, 3, 3))
    d, omega = sample_spherical_triangle(corners[:, 0], corners[:, 1], corners[:, 2], rng.random(n), rng.random(n))
    assert np.allclose(omega, triangle_solid_angle(tri[0], tri[1], tri[2]))
    # each direction hits the triangle's plane inside the triangle (barycentrics >= 0)
    nrm = np.cross(tri[1] - tri[0], tri[2] - tri[0])
    t = (tri[0] @ nrm) / (d @ nrm)
    p = t[:, None] * d
    m = np.stack([tri[1] - tri[0], tri[2] - tri[0], nrm], axis=1)     # columns
    bary = np.linalg.solve(m, (p - tri[0]).T).T
    assert np.all(bary[:, :2] > -1e-9) and np.all(bary[:, 0] + bary[:, 1] < 1 + 1e-9)
    f = lambda x: (x[:, 2] ** 2 + 0.5 * x[:, 0]) ** 2     # smooth test function of the direction
    fs = f(d)
    u = rng.random((n, 2))
    y = points_on_triangles(corners, u[:, 0], u[:, 1])
    r = np.linalg.norm(y, axis=1)
    jac = np.abs(y @ nrm) / np.linalg.norm(nrm) / r ** 3      # cos_l / r^2: dw = jac dA
    area = 0.5 * np.linalg.norm(nrm)
    g = f(y / r[:, None]) * jac * area                       # estimates the integral of f over the solid angle
    se = np.hypot(fs.std() * omega[0], g.std()) / np.sqrt(n)
    assert abs(fs.mean() * omega[0] - g.mean()) < 4.5 * se, (fs.mean() * omega[0], g.mean(), se)


def test_sobol_is_a_0_2_sequence_and_its_shift_keeps_the_net_property():
    """Unshifted, the first points are (0, 0), (1/2, 1/2), (1/4, 3/4), (3/4, 1/4); shifted or
    not, every aligned block of 2^m points puts exactly one point into every dyadic box
    2^-a x 2^-(m-a) (the (0, m, 2)-net property), for m up to 8 and blocks up to 2^10."""
    from raybundle.tracing.sampling import SobolSequence

    plain = SobolSequence()
    plain.shift[:] = 0
    assert np.allclose([plain.point(i) for i in range(4)], [[0, 0], [.5, .5], [.25, .75], [.75, .25]])
    seq = SobolSequence(seed=7)
    pts = np.array([seq.next(2) for _ in range(1024)])
    assert np.all((pts >= 0) & (pts < 1)) and len(np.unique(pts[:, 0])) == 1024
    for m in range(1, 9):
        for block in pts.reshape(-1, 2 ** m, 2)[:4]:
            for a in range(m + 1):
                box = np.floor(block[:, 0] * 2 ** a).astype(int) * 2 ** (m - a) + np.floor(block[:, 1] * 2 ** (m - a)).astype(int)
                assert len(np.unique(box)) == 2 ** m, (m, a)
    with pytest.raises(ValueError, match="two dimensions"):
        seq.next(1)


def test_toy_iteration_sobol_is_wrong():
    """Sobol's first coordinate driving the toy iteration: consecutive points fall in opposite
    halves (points 2k and 2k + 1), the same systematic error as Halton's (-0.0049 at 5e4
    steps, 8.6 times the PRNG's SE of 0.00057), whatever the digital shift."""
    from raybundle.tracing.sampling import SobolSequence

    class FirstOfTwo:
        def __init__(self, seed):
            self.seq = SobolSequence(seed=seed)

        def next(self, dim):
            return self.seq.next(2)[:dim]

    for seed in (0, 1):
        assert toy_iteration(FirstOfTwo(seed), 50_000) - 2.0 < -0.003


def test_every_random_stream_has_a_number_of_its_own():
    """Two streams that share a number draw the same numbers: the per-pixel shift of the light
    samples and that of the first interface's choice once did, and so did the bundles' grid
    and the edge gather's probe points."""
    from raybundle.tracing.sampling import Stream

    assert len(Stream.__members__) == len({int(s) for s in Stream.__members__.values()})
