"""The path tracer (:mod:`raybundle.methods.path_tracing`): unbiased against closed forms and against Cycles.

Statistical tolerances: fixed seeds; pixels are independent (one PRNG stream, or for the
quasi-Monte Carlo walk one random shift per pixel), so the standard error of a region's
mean is estimated from the pixels themselves (two independent renders A and B: the
variance of their average is mean((A - B)^2) / 4 per pixel), and bounds are 4.5 of those
SEs plus the stated model difference.
"""
import os
import subprocess
import sys

import numpy as np
import pytest

from raybundle.app import pipeline
from raybundle.imaging.settings import RenderSettings
from raybundle.scene import builtin as scenes
from raybundle.util.io import read_exr


def small(name, res=24):
    sc = scenes.load_scene(name)
    sc.camera = sc.camera.with_resolution(res, res)
    return sc


def path_traced(sc, seed, spp, sequence="prng"):
    return pipeline.render(sc, RenderSettings(seed=seed, sequence=sequence), iterations=spp,
                           solver="path-tracing")


@pytest.mark.parametrize("sequence", ["prng", "halton"])
@pytest.mark.parametrize("name", ["furnace", "furnace-glossy"])
def test_furnaces_converge_to_the_analytic_radiance(name, sequence):
    """Closed furnaces (diffuse walls that emit Le and reflect a; glossy GGX walls whose
    emission makes up their albedo): every pixel's expectation is the analytic radiance.
    The image mean lies within 4.5 SE of it (SE from the pixels' spread)."""
    sc = small(name)
    out = path_traced(sc, 3, 48, sequence)
    img = out.image.reshape(-1, 3).astype(float)
    exact = np.broadcast_to(np.asarray(sc.analytic_radiance, float), (3,))
    se = img.std(axis=0, ddof=1) / np.sqrt(len(img))
    assert np.isfinite(img).all() and out.stats["samples_per_pixel"] == 48
    assert np.all(np.abs(img.mean(axis=0) - exact) < 4.5 * se), (img.mean(axis=0), exact, se)
    assert out.stats["sampler"] == ("halton" if sequence == "halton" else "prng")


def region_means(a, b, regions):
    """Mean luminance sum of each region of the average of renders ``a`` and ``b`` and its SE."""
    out = []
    for sel in regions:
        x, y = a[sel].sum(-1), b[sel].sum(-1)
        out.append((0.5 * (x + y).mean(), np.sqrt(np.mean((x - y) ** 2) / 4 / x.size)))
    return out


@pytest.mark.parametrize("name", ["cornell", "cornell-glossy"])
def test_cornell_boxes_match_cycles_region_by_region(tmp_path, name):
    """The Cornell boxes at 32 x 32 against Cycles (2 x 512 spp, through ``bpy``), the whole
    image and its four quadrants: the glossy box checks that a lamp reflected in a glossy
    lobe is counted once (light sample and lobe ray, MIS-weighted), the diffuse one the
    next-event estimation and the walk.  Bound: 4.5 combined SE + 0.5% (the materials
    agree with Cycles' within 0.2%, ``test_cycles``).  Measured: within 1.5 SE."""
    sys.path.insert(0, os.path.join(os.path.dirname(__file__), "..", "tools"))
    import cycles_reference as cr

    sc = small(name, 32)
    cyc = [cr.render_scene(sc, 512, str(tmp_path / f"c{k}.exr"), seed=k) for k in (1, 2)]
    ours = [path_traced(sc, k, 128).image for k in (1, 2)]
    regions = [np.s_[:, :], np.s_[:16, :16], np.s_[:16, 16:], np.s_[16:, :16], np.s_[16:, 16:]]
    for (mc, sc_), (mo, so), r in zip(region_means(*cyc, regions), region_means(*ours, regions), regions):
        assert abs(mo - mc) < 4.5 * np.hypot(sc_, so) + 0.005 * mc, (name, r, mo, mc, sc_, so)


@pytest.mark.parametrize("method,refused", [("path-tracing", "sobol"), ("single-ray-iteration", "halton")])
def test_cli_image_only_methods_write_the_image_without_patches(tmp_path, method, refused):
    """``render --method path-tracing`` or ``single-ray-iteration`` (light tracing,
    ``test_lighttracing``): no patch layout (a set-up step they do not need), the image and
    stats written; bakes, chains and a sequence they do not draw from are refused with
    one-line errors."""
    out = tmp_path / "pt.exr"
    p = subprocess.run([sys.executable, "-m", "raybundle", "render", "furnace", "--method", method,
                        "--iterations", "4", "--resolution", "16", "16", "--out", str(out)],
                       capture_output=True, text=True)
    assert p.returncode == 0, p.stderr
    assert "laying out the patches" not in p.stderr and "4 iterations" in p.stderr
    img = read_exr(out)
    assert img.shape == (16, 16, 3) and np.isfinite(img).all() and img.mean() > 0
    p = subprocess.run([sys.executable, "-m", "raybundle", "render", "furnace", "--method", method,
                        "--workers", "2", "--iterations", "4", "--out", str(tmp_path / "x.exr")],
                       capture_output=True, text=True)
    assert p.returncode == 2 and "no patch solution to merge" in p.stderr and "Traceback" not in p.stderr
    with pytest.raises(ValueError, match="renders images only"):
        pipeline.make_solver(scenes.load_scene("furnace"), solver=method)
    p = subprocess.run([sys.executable, "-m", "raybundle", "render", "furnace", "--method", method,
                        "--sequence", refused, "--iterations", "1", "--out", str(tmp_path / "y.exr")],
                       capture_output=True, text=True)
    assert p.returncode == 2 and f"not '{refused}'" in p.stderr and "Traceback" not in p.stderr
