"""raybundle.app.metrics.image_error on images whose errors are known by construction."""
import numpy as np
import pytest

from raybundle.app.metrics import TAIL_FLOOR, bias_and_noise, image_error, pixel_errors, region_errors


def test_the_reference_noise_is_subtracted_and_the_tail_and_mean_are_read():
    """Halves A, B = 1 + s u +- s v (u a +-1 checkerboard, v random signs, s = 0.1): the
    reference (A + B) / 2 = 1 + s u has noise s, and mean((A - B)^2) / 4 = s^2 says so.  An
    image 1.03 (a 3% bias) has the raw error sqrt(0.03^2 + s^2), the corrected one 0.03
    exactly; its per-pixel tail is (0.03 + s) / (1 - s + 0.02) where u = -1 (half the
    pixels), the reference's own s / (1 - s + 0.02).  Raising 0.2% of the pixels to 3 puts
    the 99.9th percentile at their error; 0.05% of them stay below it."""
    rng = np.random.default_rng(0)
    h = w = 200
    s = 0.1
    u = np.where((np.arange(h)[:, None] + np.arange(w)) % 2, 1.0, -1.0)[..., None]
    v = rng.choice([-1.0, 1.0], (h, w, 1))
    a, b = 1 + s * u + s * v + np.zeros(3), 1 + s * u - s * v + np.zeros(3)
    r = (a + b) / 2
    x = np.full((h, w, 3), 1.03)
    e = image_error(x, r, reference_halves=(a, b))
    assert e["raw"] == pytest.approx(np.hypot(0.03, s), rel=1e-9)
    assert e["reference_noise"] == pytest.approx(s, rel=1e-9)
    assert e["error"] == pytest.approx(0.03, rel=1e-6)
    assert e["mean_ratio"] == pytest.approx(1.03, rel=1e-9)
    assert e["p99_9"] == pytest.approx((0.03 + s) / (1 - s + TAIL_FLOOR), rel=1e-9)
    assert e["reference_p99_9"] == pytest.approx(s / (1 - s + TAIL_FLOOR), rel=1e-9)

    r = np.ones((h, w, 3))
    flat = x.reshape(-1, 3).copy()
    spots = rng.choice(h * w, int(0.002 * h * w), replace=False)
    flat[spots] = 3.0
    assert image_error(flat.reshape(h, w, 3), r)["p99_9"] == pytest.approx(2.0 / (1 + TAIL_FLOOR), rel=1e-9)
    flat = x.reshape(-1, 3).copy()
    flat[spots[: int(0.0005 * h * w)]] = 3.0
    assert image_error(flat.reshape(h, w, 3), r)["p99_9"] < 0.1


def test_excluded_pixels_do_not_count_and_bad_input_is_refused():
    r = np.ones((10, 10, 3))
    x = r.copy()
    x[:2] = 100.0                         # a lamp's pixels, excluded
    mask = np.zeros((10, 10), bool)
    mask[:2] = True
    got = image_error(x, r, exclude=mask)
    assert got["error"] == 0.0 and got["pixels"] == 80 and got["mean_ratio"] == 1.0
    with pytest.raises(ValueError, match="shape"):
        image_error(x[:5], r)
    with pytest.raises(ValueError, match="black"):
        image_error(x, np.zeros_like(r))


def test_an_error_splits_into_the_bias_more_time_keeps_and_the_noise_it_removes():
    """An image 10% too bright with a per-pixel noise of 20% of the mean, rendered twice: the
    split reads bias 0.10 and noise 0.20 (their sum in quadrature is the error), whatever
    the reference's own noise (halves of sd 0.05 each); a region grid's shares add up to the
    whole and find the one block that is wrong."""
    rng = np.random.default_rng(3)
    shape = (120, 90, 3)
    truth = np.ones(shape)
    a, b = truth + rng.normal(0, 0.05, shape), truth + rng.normal(0, 0.05, shape)
    ref = 0.5 * (a + b)
    x1, x2 = 1.1 + rng.normal(0, 0.2, shape), 1.1 + rng.normal(0, 0.2, shape)
    s = bias_and_noise(x1, x2, ref, (a, b))
    # the noise^2 estimate from 32,400 pixel-channels has a relative sd of sqrt(2 / N) < 1%
    assert abs(s["noise"] - 0.2) < 0.004 and abs(s["bias"] - 0.1) < 0.01, s
    assert s["error"] == pytest.approx(np.hypot(s["bias"], s["noise"]))
    y = truth.copy()
    y[80:, 60:] *= 1.3                                   # the bottom-right block of a 3 x 3 grid
    blocks = region_errors(y, truth)
    assert sum(g["share"] for g in blocks) == pytest.approx(1.0)
    worst = max(blocks, key=lambda g: g["share"])
    assert (worst["row"], worst["column"], worst["share"]) == (2, 2, pytest.approx(1.0))
    assert worst["mean_ratio"] == pytest.approx(1.3) and worst["error"] == pytest.approx(0.3)


def test_pixel_errors_are_the_image_error_pixel_by_pixel():
    """The per-pixel squared errors (what the tools rank pixels and regions by) sum, over the
    kept pixels and relative to the reference's mean, to the noise-corrected error squared."""
    rng = np.random.default_rng(4)
    truth = rng.random((20, 30, 3)) + 0.5
    a, b = truth * (1 + 0.02 * rng.standard_normal((2, 20, 30, 3)))
    ref = 0.5 * (a + b)
    img = ref * (1 + 0.1 * rng.standard_normal(ref.shape))
    exclude = np.zeros((20, 30), bool)
    exclude[3:6, 4:9] = True
    d2 = pixel_errors(img, ref, (a, b))
    got = d2[~exclude].mean() / ref[~exclude].mean() ** 2
    want = image_error(img, ref, (a, b), exclude)["error"] ** 2
    assert want > 0.05 ** 2 and got == pytest.approx(want, rel=1e-12)
    assert np.allclose(pixel_errors(img, ref), ((img - ref) ** 2).mean(axis=-1))


def test_the_overlap_mask_marks_the_pixels_that_see_two_objects_in_one_plane():
    """An orthographic 16 x 16 camera 1 m above a 1 x 1 m floor (1/16 m a pixel) on which a
    second object's strip x in [0, 0.25] lies in the floor's plane: the pixels wholly over the
    strip are marked, those wholly off it are not (the strip's edge pixels: either); a third
    object, a lamp 1 cm above the floor, overlaps nothing, and one object overlaps nothing."""
    from raybundle.app.metrics import overlap_mask
    from raybundle.scene.build import build_scene
    from raybundle.scene.camera import Camera
    from raybundle.scene.materials import MaterialTable

    def quad(x0, x1, y0, y1, z):
        return [[x0, y0, z], [x1, y0, z], [x1, y1, z], [x0, y1, z]]

    v = np.array(quad(-0.5, 0.5, -0.5, 0.5, 0) + quad(0, 0.25, -0.5, 0.5, 0) + quad(-0.4, -0.2, -0.4, -0.2, 0.01),
                 float)
    t = np.array([[k, k + 1, k + 2] for k in (0, 4, 8)] + [[k, k + 2, k + 3] for k in (0, 4, 8)])
    mats = MaterialTable.from_list([dict(name="clay", diffuse=(0.8,) * 3), dict(name="lamp", emission=(1,) * 3)])
    m = np.eye(4)
    m[2, 3] = 1.0
    cam = Camera(16, 16, 16.0, 16.0, 8.0, 8.0, m, orthographic=True)
    sc = build_scene(v, t, [0, 0, 1, 0, 0, 1], mats, camera=cam)
    groups = np.array([0, 1, 2, 0, 1, 2])[sc.triangle_source]
    mask = overlap_mask(sc, groups, samples=8)
    x = (np.arange(16) + 0.5) / 16 - 0.5                     # pixel centres, columns left to right
    over = (x - 1 / 32 > 0) & (x + 1 / 32 < 0.25)
    off = (x + 1 / 32 < 0) | (x - 1 / 32 > 0.25)
    assert mask[:, over].all() and not mask[:, off].any()
    assert not overlap_mask(sc, np.zeros(6, int)[sc.triangle_source], samples=8).any()
