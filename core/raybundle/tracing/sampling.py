"""Random and quasi-random numbers that drive the iteration, and direction maps.

Stochastic iteration multiplies each new random operator into a state built
from all earlier ones, so the numbers consumed iteration after iteration must be
*completely uniformly distributed* (thesis result 1.2; ``algorithms.md`` §1.2):

* :class:`PRNGSequence` (NumPy PCG64): works; the default.
* :class:`PiPowersSequence`, the fractional parts {pi^n}: works (the thesis'
  recommendation).  In doubles {pi^n} is exactly 0 from n ~ 33 on, so it is
  computed here in exact fixed-point integer arithmetic with enough bits.
* :class:`HaltonSequence` and :class:`SobolSequence`: low-discrepancy sequences whose
  consecutive points are strongly correlated.  They are here so that the failure they
  cause (a converged but *wrong* answer) can be shown; do not use them for iterations
  (path tracing randomises Halton points per pixel, :mod:`raybundle.methods.path_tracing`).

All sequences share one interface: ``next(dim)`` returns the next point of the
iteration as ``dim`` numbers in [0, 1).  Chosen by name via :data:`SEQUENCES`.
"""
from __future__ import annotations

import enum
import math

import numpy as np


@enum.unique
class Stream(enum.IntEnum):
    """Every random stream of a run, by name: :func:`stream` ``(seed, Stream.X)`` is the
    Generator ``np.random.default_rng([seed, X])``.  Each has a number of its own, so no two
    draw the same numbers.  A stream's number is part of what a seed means: changing it changes
    the images of that seed."""

    IMAGE_PASSES = 1            # the renderer's passes: lobe uniforms, interfaces, extra samples
    RESOLVE = 2                 # the diffuse resolve's sub-pixel offsets and gather shifts
    EDGE_GATHER = 3             # :class:`~raybundle.imaging.gather.EdgeGather`'s probe points
    EDGE_GATHER_PROBE = 4       # ... and the one-ray gathers that measure its noise
    LIGHT_SOURCE_MASK = 5       # :func:`~raybundle.app.metrics.light_source_mask`'s sub-pixel rays
    CAUSTIC_SPLATS = 6          # the caustic shot light-traced into the pixels
    FIRST_SHOT = 7              # the per-patch first shot's points and light samples
    SUBPIXEL_SHIFT = 8          # each pixel's shift of its R_2 sequence of sub-pixel positions
    LIGHT_SHIFT = 9             # each pixel's shift of its R_3 sequences of light samples
    CHOICE_SHIFT = 10           # each pixel's shift of its first interface's choice
    OPEN_AREA = 11              # the tracer's estimate of the patches' open (not buried) area
    CAUSTIC_SHOT = 12           # the caustic first shot's lobe rays
    LIGHT_TRACING = 13          # single-ray iteration's photons
    PATH_TRACING = 14           # the path tracer's walks
    ROULETTE = 15               # the bundle walk's Russian roulette
    BUNDLE_GRID = 16            # each bundle's grid offset and rotation
    STRATIFIED = 17             # :class:`StratifiedSequence`'s streams, one more number each
    OPEN_FRACTION_FRAMES = 18   # the patches' open-fraction probes' random turns
    WARM_UP = 19                # the iteration's warm-up directions and grids
    SOBOL_SHIFT = 23            # :class:`SobolSequence`'s digital shift
    RANDOM_ROOM = 29            # the built-in random rooms
    TEXTURE_MEANS = 31          # texture means over patches, by sampled points
    ENERGY_BALANCE = 32         # the sides' capture rays of the warm-up's energy balance


def stream(seed, which, *more):
    """The Generator of stream ``which`` (:class:`Stream`) for ``seed`` (``more``: further
    numbers that split it, e.g. one per sub-stream)."""
    return np.random.default_rng([int(seed), int(which), *more])


def _mix64(x):
    """SplitMix64's finaliser on uint64 arrays: a bijection whose output bits each depend on
    every input bit (wrapping arithmetic)."""
    x = x ^ (x >> np.uint64(30))
    x = x * np.uint64(0xBF58476D1CE4E5B9)
    x = x ^ (x >> np.uint64(27))
    x = x * np.uint64(0x94D049BB133111EB)
    return x ^ (x >> np.uint64(31))


class PointUniforms:
    """Uniform numbers tied to points, for estimates that decide a layout: ``random((N, k))``
    (the only call of a Generator it stands in for) gives row i as a hash of the bits of
    ``points[i]`` (N, 3), ``seed``, the call's count and the column, so each point's numbers
    are the same whatever the order or company the points are asked in (the same scene
    numbered otherwise is laid out the same)."""

    def __init__(self, points, seed=0):
        bits = np.ascontiguousarray(points, np.float64).view(np.uint64).reshape(len(points), -1)
        with np.errstate(over="ignore"):
            key = np.full(len(bits), _mix64(np.uint64(seed) + np.uint64(0x9E3779B97F4A7C15)), np.uint64)
            for c in range(bits.shape[1]):
                key = _mix64(key ^ bits[:, c])
        self.key, self.calls = key, 0

    def random(self, size):
        n, k = (size, 1) if np.isscalar(size) else (size[0], int(np.prod(size[1:])))
        if n != len(self.key):
            raise ValueError(f"PointUniforms: {n} rows asked of {len(self.key)} points")
        self.calls += 1
        with np.errstate(over="ignore"):
            salt = _mix64(np.uint64(self.calls) * np.uint64(0x9E3779B97F4A7C15) + np.arange(k, dtype=np.uint64))
            z = _mix64(self.key[:, None] ^ salt[None, :])
        return ((z >> np.uint64(11)).astype(np.float64) * 2.0 ** -53).reshape(size)

# ------------------------------------------------------------ direction maps
def uniform_sphere(u1, u2):
    """Map (u1, u2) in [0,1)^2 to a unit vector uniform on the sphere (pdf 1/(4 pi)).

    z = 1 - 2 u1, phi = 2 pi u2.  Accepts scalars or arrays; returns (..., 3).
    """
    u1 = np.asarray(u1, float)
    u2 = np.asarray(u2, float)
    z = 1.0 - 2.0 * u1
    r = np.sqrt(np.maximum(0.0, 1.0 - z * z))
    phi = 2.0 * np.pi * u2
    return np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=-1)


def uniform_sphere_pdf():
    """Solid-angle density of :func:`uniform_sphere`, 1/(4 pi) [1/sr]."""
    return 1.0 / (4.0 * np.pi)


def invert_uniform_sphere(d):
    """Inverse of :func:`uniform_sphere`: unit vectors (..., 3) -> (u1, u2)."""
    d = np.asarray(d, float)
    u1 = (1.0 - d[..., 2]) / 2.0
    u2 = (np.arctan2(d[..., 1], d[..., 0]) / (2 * np.pi)) % 1.0
    return u1, u2


def orthonormal_basis(d):
    """Two unit vectors (u, v) with (u, v, d) a right-handed orthonormal frame."""
    d = np.asarray(d, float)
    a = np.array([1.0, 0.0, 0.0]) if abs(d[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    u = np.cross(a, d)
    u /= np.linalg.norm(u)
    return u, np.cross(d, u)


def frames_from_normals(n):
    """Tangents (N, 3) and bitangents (N, 3) completing unit normals (N, 3) to
    right-handed orthonormal frames (branchless construction, Duff et al. 2017)."""
    n = np.asarray(n, float)
    sign = np.where(n[:, 2] >= 0, 1.0, -1.0)
    a = -1.0 / (sign + n[:, 2])
    b = n[:, 0] * n[:, 1] * a
    t = np.stack([1 + sign * n[:, 0] ** 2 * a, sign * b, -sign * n[:, 0]], axis=1)
    bt = np.stack([b, sign + n[:, 1] ** 2 * a, -n[:, 1]], axis=1)
    return t, bt


def cosine_directions(u, t, b, n):
    """Cosine-distributed unit directions (..., 3) about the unit normals ``n`` with tangents
    ``t`` and bitangents ``b`` (:func:`frames_from_normals`; all broadcast against ``u``'s
    leading axes) from ``u`` (..., 2): ``sqrt(u0)`` off the normal at azimuth ``2 pi u1``
    (density cos / pi)."""
    r, phi = np.sqrt(u[..., 0]), 2 * np.pi * u[..., 1]
    return (r * np.cos(phi))[..., None] * t + (r * np.sin(phi))[..., None] * b + np.sqrt(1 - u[..., :1]) * n


def uniform_triangle(u1, u2):
    """Barycentric weights (..., 3) uniform over a triangle (square-root map)."""
    s = np.sqrt(np.asarray(u1, float))
    b0 = 1.0 - s
    b1 = np.asarray(u2, float) * s
    return np.stack([b0, b1, 1.0 - b0 - b1], axis=-1)


def points_on_triangles(corners, u1, u2):
    """Uniform points (N, 3) on triangles with corners (N, 3, 3), from uniforms u1, u2 (N,)."""
    return np.einsum("nk,nkj->nj", uniform_triangle(u1, u2), corners)


def triangle_barycentrics(corners, points):
    """Barycentrics (N, 3) of ``points`` (N, 3) projected into the planes of triangles
    ``corners`` (N, 3, 3) (least squares; exact for points in the plane)."""
    c = np.asarray(corners, float)
    e1, e2 = c[:, 1] - c[:, 0], c[:, 2] - c[:, 0]
    d = np.asarray(points, float) - c[:, 0]
    d11, d12, d22 = (np.einsum("ij,ij->i", a, b) for a, b in ((e1, e1), (e1, e2), (e2, e2)))
    p1, p2 = np.einsum("ij,ij->i", d, e1), np.einsum("ij,ij->i", d, e2)
    det = np.maximum(d11 * d22 - d12 * d12, 1e-300)
    b1, b2 = (d22 * p1 - d12 * p2) / det, (d11 * p2 - d12 * p1) / det
    return np.stack([1 - b1 - b2, b1, b2], axis=1)


def triangle_solid_angle(a, b, c):
    """Solid angle [sr] (N,) of triangles seen from the origin, corners ``a, b, c``
    (N, 3) relative to the viewpoint (Van Oosterom & Strackee 1983):
    ``tan(O/2) = |a.(b x c)| / (|a||b||c| + (a.b)|c| + (a.c)|b| + (b.c)|a|)``."""
    la, lb, lc = (np.linalg.norm(x, axis=-1) for x in (a, b, c))
    num = np.abs(np.einsum("...i,...i->...", a, np.cross(b, c)))
    den = (la * lb * lc + np.einsum("...i,...i->...", a, b) * lc + np.einsum("...i,...i->...", a, c) * lb
           + np.einsum("...i,...i->...", b, c) * la)
    return 2.0 * np.arctan2(num, den)


def sample_spherical_triangle(a, b, c, u1, u2):
    """Directions (N, 3) uniform in solid angle over triangles with corners ``a, b, c``
    (N, 3) relative to the viewpoint (Arvo, "Stratified sampling of spherical
    triangles", SIGGRAPH 1995); pdf = 1 / :func:`triangle_solid_angle`.  Returns
    ``(directions, solid_angle)``."""
    A, B, C = (x / np.linalg.norm(x, axis=1, keepdims=True) for x in (a, b, c))

    def unit(x):
        return x / np.maximum(np.linalg.norm(x, axis=1, keepdims=True), 1e-300)

    def corner_angle(p, q, r):          # angle at p between the great arcs p-q and p-r
        return np.arccos(np.clip(np.einsum("ij,ij->i", unit(np.cross(p, q)), unit(np.cross(p, r))), -1, 1))

    alpha, beta, gamma = corner_angle(A, B, C), corner_angle(B, C, A), corner_angle(C, A, B)
    area = np.maximum(alpha + beta + gamma - np.pi, 0.0)
    a_hat = u1 * area
    s, t = np.sin(a_hat - alpha), np.cos(a_hat - alpha)
    uu = t - np.cos(alpha)
    vv = s + np.sin(alpha) * np.einsum("ij,ij->i", A, B)
    den = (vv * s + uu * t) * np.sin(alpha)
    q = np.clip(((vv * t - uu * s) * np.cos(alpha) - vv) / np.where(den != 0, den, 1e-300), -1.0, 1.0)
    c_hat = q[:, None] * A + np.sqrt(1 - q * q)[:, None] * unit(C - np.einsum("ij,ij->i", C, A)[:, None] * A)
    z = 1.0 - u2 * (1.0 - np.einsum("ij,ij->i", c_hat, B))
    d = z[:, None] * B + np.sqrt(np.maximum(0.0, 1 - z * z))[:, None] * unit(
        c_hat - np.einsum("ij,ij->i", c_hat, B)[:, None] * B)
    return d, area


def stratified_2d(n, rng):
    """n jittered points in [0,1)^2 on a ceil(sqrt n)^2 grid, shuffled, (n, 2)."""
    k = int(math.ceil(math.sqrt(n)))
    cells = rng.permutation(k * k)[:n]
    return (np.stack([cells % k, cells // k], axis=1) + rng.random((n, 2))) / k


def stratified_2d_sets(sets, n, rng):
    """``sets`` independent :func:`stratified_2d` sets of n points each, (sets, n, 2),
    drawn together (one sort instead of one permutation per set)."""
    k = int(math.ceil(math.sqrt(n)))
    cells = np.argsort(rng.random((sets, k * k)), axis=1)[:, :n]
    return (np.stack([cells % k, cells // k], axis=2) + rng.random((sets, n, 2))) / k


def kronecker_alpha(dim):
    """Generators of the R_d Kronecker sequence: alpha_j = phi_d^-j, j = 1..dim, where
    phi_d is the positive root of x^(d+1) = x + 1 (Roberts' generalized golden ratio)."""
    phi = 2.0
    for _ in range(60):
        phi = (1.0 + phi) ** (1.0 / (dim + 1))
    return (1.0 / phi) ** np.arange(1, dim + 1) % 1.0


class ShiftedKronecker:
    """Per-pixel randomly shifted R_d sequences for the image passes' lobe and light samples.

    Pass k of pixel p uses ``frac(shift_p + k alpha)``: every single pass is
    uniformly distributed (so each pass is an unbiased sample of the pixel
    integral) while successive passes fill [0,1)^d evenly in the long run.  For
    large d the generators lie near 1, so over the first passes the low-dimensional
    projections move little and along one line: the sub-pixel position, where a pixel
    holds an edge, is therefore not taken from here but from an R_2 sequence of its
    own (:meth:`~raybundle.imaging.renderer.Renderer.image_pass`).  (Image passes are
    plain averages, not iterations: completely uniform distribution is not needed here.)
    """

    def __init__(self, n, dim, rng):
        self.shift = rng.random((n, dim))
        self.alpha = kronecker_alpha(dim)
        self.k = 0

    def next(self):
        """(n, dim) points of the next pass."""
        u = (self.shift + self.k * self.alpha) % 1.0
        self.k += 1
        return u


# ---------------------------------------------------------------- sequences
class PRNGSequence:
    """Pseudo-random numbers from NumPy's PCG64, seeded."""

    name = "prng"

    def __init__(self, seed=0):
        self.rng = np.random.default_rng(seed)

    def next(self, dim):
        return self.rng.random(dim)


class StratifiedSequence:
    """Jittered strata of [0,1)^2, shuffled, dealt round-robin from independent streams.

    Step n takes its point from stream ``n mod streams``; each stream hands out
    blocks of ``strata`` = k x k jittered grid cells of [0,1)^2 in random order.
    Over a run every stream covers the square evenly, so the running average of
    terms that depend on one step's direction (most of the light: a patch's
    first bounce from the first shot) converges like a stratified estimate; on
    the Cornell box this cuts the region-mean noise several times at the same
    number of iterations.

    Each point is uniform on its own, and steps less than ``streams`` apart come
    from different, independent streams: the light that a chain of up to
    ``streams`` consecutive transfers carries is averaged exactly as with
    independent directions (stochastic iteration needs this, thesis 1.2: the
    Halton sequence fails it).  Steps of the same stream are negatively
    correlated (two cannot share a cell within a block), which touches only
    paths of more than ``streams`` bounces, attenuated by albedo^streams, and
    then by O(1/strata).  Only ``dim`` = 2 is stratified (the direction); other
    dimensions are plain pseudo-random numbers.
    """

    name = "stratified"

    def __init__(self, seed=0, strata=256, streams=16):
        self.k = max(1, int(round(math.sqrt(strata))))
        self.rngs = [stream(seed, Stream.STRATIFIED, s) for s in range(int(streams))]
        self.blocks = [np.empty((0, 2)) for _ in range(int(streams))]
        self.n = 0

    def next(self, dim):
        s = self.n % len(self.rngs)
        self.n += 1
        rng = self.rngs[s]
        if dim != 2:
            return rng.random(dim)
        if len(self.blocks[s]) == 0:
            self.blocks[s] = stratified_2d(self.k * self.k, rng)
        u, self.blocks[s] = self.blocks[s][-1], self.blocks[s][:-1]
        return u.copy()


_PI_CACHE = [0, 0]     # [bits, floor(pi 2^bits)] of the most precise pi computed so far


def pi_fixed_point(bits):
    """floor(pi * 2^bits) as an integer, by Machin's formula
    pi = 16 atan(1/5) - 4 atan(1/239) in integer arithmetic with 64 guard bits
    (exact except when pi 2^bits lies within 2^-40 of an integer; cached)."""
    if _PI_CACHE[0] < bits:
        work = bits + 64
        one = 1 << work

        def atan_inv(x):               # atan(1/x) * 2^work, alternating Taylor series
            total = term = one // x
            x2, k, sign = x * x, 1, -1
            while term:
                term //= x2
                k += 2
                total += sign * (term // k)
                sign = -sign
            return total

        _PI_CACHE[:] = [work, 16 * atan_inv(5) - 4 * atan_inv(239)]
    return _PI_CACHE[1] >> (_PI_CACHE[0] - bits)


class PiPowersSequence:
    """The sequence u_n = frac(pi^n), n = start, start+1, ... consumed in order.

    ``pi^n`` is kept as a fixed-point integer with ``B`` fraction bits,
    ``X_n = floor(X_{n-1} * PI_B / 2^B)``; each step truncates by < 1 ulp and the
    relative error grows by about 2^-B per step, so ``B = n_max log2(pi) + 80``
    bits give frac(pi^n) to far better than double precision for every
    n <= n_max.  Tables of ``capacity`` numbers are built as needed (the start
    is reached by binary powering).  The cost per number grows like n (about
    1.65 n bits per multiplication), so this sequence is for studies of up to
    ``MAX_N`` numbers; beyond that it raises ValueError (use ``prng``).
    """

    name = "pi-powers"
    MAX_N = 100_000

    def __init__(self, start=1, capacity=4096):
        if start < 1:
            raise ValueError("start must be >= 1")
        self.n = int(start)          # exponent of the next number
        self._table_start = self.n
        self._table = np.empty(0)
        self._capacity = int(capacity)

    def _build(self, n_first, count):
        n_max = n_first + count
        bits = int(n_max * math.log2(math.pi)) + 80
        pi_fixed = pi_fixed_point(bits)
        one = 1 << bits
        mask = one - 1
        x, base, e = one, pi_fixed, n_first          # x = pi^n_first by binary powering
        while e:
            if e & 1:
                x = (x * base) >> bits
            e >>= 1
            if e:
                base = (base * base) >> bits
        shift = bits - 53
        out = np.empty(count)
        for k in range(count):
            out[k] = ((x & mask) >> shift) * 2.0 ** -53   # frac(pi^(n_first + k)) to 53 bits
            x = (x * pi_fixed) >> bits
        return out

    def next(self, dim):
        off = self.n - self._table_start
        if off + dim > len(self._table):
            if self.n + dim > self.MAX_N:
                raise ValueError(f"the pi-powers sequence is limited to n <= {self.MAX_N} (each number costs "
                                 "~1.65 n bits of arithmetic); use the 'prng' sequence for long runs")
            count = max(self._capacity, dim)
            self._table_start = self.n
            self._table = self._build(self.n, count)
            off = 0
        self.n += dim
        return self._table[off:off + dim].copy()


_PRIMES = (2, 3, 5, 7, 11, 13, 17, 19, 23, 29, 31, 37, 41, 43, 47, 53, 59, 61, 67, 71, 73, 79, 83, 89)


def radical_inverse(base, index):
    """Van der Corput radical inverse of a non-negative integer in ``base``."""
    inv, f = 0.0, 1.0 / base
    while index > 0:
        index, digit = divmod(index, base)
        inv += digit * f
        f /= base
    return inv


def halton_points(index, dim, permutations=None):
    """Halton point number ``index`` (dim,): coordinate k is the radical inverse in the
    k-th prime (at most ``len(_PRIMES)`` = 24 dimensions).  With ``permutations`` (from
    :func:`halton_permutations`) every digit of coordinate k goes through its own random
    permutation of {0..b-1} (random digit scrambling), which removes the correlation between
    coordinates of large prime bases (for n < b, plain coordinates in bases b and b' are
    n/b and n/b': almost equal)."""
    if dim > len(_PRIMES):
        raise ValueError(f"Halton sequence supports at most {len(_PRIMES)} dimensions")
    if permutations is None:
        return np.array([radical_inverse(_PRIMES[k], int(index)) for k in range(dim)])
    out = np.zeros(dim)
    for k in range(dim):
        base, perm, i, f = _PRIMES[k], permutations[k], int(index), 1.0 / _PRIMES[k]
        for digit_perm in perm:                      # every digit, down to double precision
            i, digit = divmod(i, base)
            out[k] += digit_perm[digit] * f
            f /= base
    return np.minimum(out, 1.0 - 2.0 ** -53)


def halton_permutations(dim, rng):
    """Random digit permutations for :func:`halton_points`: for each of ``dim`` coordinates,
    one permutation of {0..b-1} per digit of a double (b the coordinate's prime)."""
    return [rng.permuted(np.tile(np.arange(b), (int(np.ceil(53 * np.log(2) / np.log(b))), 1)), axis=1)
            for b in _PRIMES[:dim]]


class HaltonSequence:
    """Halton points: iteration n gets point n, coordinate k in base prime_k.

    Deliberately *not* completely uniformly distributed: consecutive points are
    correlated, which makes stochastic iteration converge to a wrong value
    (thesis 1.2).  Kept for demonstrating that failure; the solver warns.
    """

    name = "halton"

    def __init__(self, start=1):
        self.index = int(start)

    def next(self, dim):
        out = halton_points(self.index, dim)
        self.index += 1
        return out


def sobol_direction_numbers(bits=32):
    """Direction numbers (2, bits) of the first two Sobol coordinates as ``bits``-bit
    integers: coordinate 1 is the van der Corput sequence in base 2 (``v_k = 2^(bits-k)``),
    coordinate 2 uses the primitive polynomial x + 1, ``m_k = 2 m_(k-1) xor m_(k-1)``,
    ``m_1 = 1``, ``v_k = m_k 2^(bits-k)``.  Together they form a (0, 2)-sequence in base 2:
    every block of 2^m consecutive points (aligned at multiples of 2^m) puts exactly one
    point into every dyadic box of area 2^-m."""
    v = np.zeros((2, bits), dtype=np.uint64)
    m = 1
    for k in range(1, bits + 1):
        v[0, k - 1] = 1 << (bits - k)
        if k > 1:
            m = (m << 1) ^ m
        v[1, k - 1] = m << (bits - k)
    return v


def sobol_points(index, shift, v=None):
    """Points ``index`` (N,) of the two-dimensional Sobol (0, 2)-sequence, each with its own
    digital shift ``shift`` (N, 2) of 32-bit words (:func:`sobol_direction_numbers`' bits),
    (N, 2) in [0, 1): the XOR of the shift and of the direction numbers ``v`` of the index's set
    bits.  With a uniformly random shift every point is uniform, and the first 2^m points of one
    shift still put exactly one point into every dyadic box of area 2^-m."""
    v = sobol_direction_numbers(32) if v is None else v
    index = np.asarray(index, np.uint64)
    x = np.array(shift, np.uint64, copy=True)
    for k in range(v.shape[1]):
        rest = index >> np.uint64(k)
        if not rest.any():
            break
        x ^= (rest & np.uint64(1))[:, None] * v[:, k]
    return x.astype(float) / float(1 << v.shape[1])


class SobolSequence:
    """The two-dimensional Sobol (0, 2)-sequence with a random digital shift (each
    coordinate's bits XORed with a seeded random word; the net property is kept).

    Like Halton it is a low-discrepancy sequence whose consecutive points are correlated
    (point 2k and 2k + 1 differ in the first bit of both coordinates), so stochastic
    iteration driven by it converges to a wrong answer (thesis 1.2); form factors
    integrated over its directions (:mod:`raybundle.methods.radiosity`) do not iterate and converge
    correctly.  Two dimensions only: the iteration methods draw one direction per call.
    """

    name = "sobol"
    BITS = 32

    def __init__(self, seed=0, start=0):
        self.v = sobol_direction_numbers(self.BITS)
        self.shift = stream(seed, Stream.SOBOL_SHIFT).integers(0, 1 << self.BITS, size=2, dtype=np.uint64)
        self.index = int(start)

    def point(self, index):
        """Point ``index`` (2,) in [0, 1)^2 (:func:`sobol_points`)."""
        return sobol_points(np.array([index]), self.shift[None], self.v)[0]

    def next(self, dim):
        if dim != 2:
            raise ValueError("the Sobol sequence here has two dimensions (one direction per call)")
        out = self.point(self.index)
        self.index += 1
        return out


#: sequences that are not completely uniformly distributed: iterations driven by them are biased
NOT_CUD = ("halton", "sobol")

#: the sequence a render uses unless told otherwise
DEFAULT_SEQUENCE = "stratified"

SEQUENCES = {"prng": PRNGSequence, "stratified": StratifiedSequence, "pi-powers": PiPowersSequence,
             "halton": HaltonSequence, "sobol": SobolSequence}


def make_sequence(name, seed=0):
    """A sequence by name; ``seed`` seeds the PRNG and offsets the start of the others
    (by 64 numbers per seed value, at most 1000)."""
    if name not in SEQUENCES:
        raise ValueError(f"unknown sequence {name!r}; choose one of {sorted(SEQUENCES)}")
    if name in ("prng", "stratified", "sobol"):
        return SEQUENCES[name](seed)
    if not 0 <= int(seed) <= 1000:
        raise ValueError(f"seed must lie in [0, 1000] for the {name} sequence")
    return SEQUENCES[name](start=1 + int(seed) * 64)
