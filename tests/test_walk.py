"""Random ray-bundle tracing (:mod:`raybundle.methods.ray_bundle_walk`, thesis 3.2) against the furnaces'
analytic answers, and the failure the thesis predicts for non-CUD sequences.

Tolerances as in :mod:`test_solver`: batch means after a burn-in batch, |mean - exact| <
4.5 SE.  A walk's steps are correlated over its length (1/(1 - q) ~ 3 steps here), far
shorter than a batch.  Measured on the diffuse furnace (300 patches, 8 x 150 steps): the walk's
SE is 1.3% (red), 1.7% (green), 0.2% (blue) against 0.03-0.14% for the stochastic iteration at
the same steps: a walk spends each emission once, and one Russian roulette (q = the largest
channel's albedo, 0.7) serves three channels of albedo 0.3, 0.5, 0.7.
"""
import subprocess
import sys

import numpy as np
import pytest
from test_solver import assert_biased, assert_converged, batch_means

from raybundle.app import pipeline
from raybundle.imaging.settings import RenderSettings
from raybundle.scene import builtin as scenes


def walk_renderer(glossy, sequence, patches=300, seed=0):
    sc = pipeline.prepare(scenes.furnace(glossy=glossy, resolution=(24, 24)), patches=patches)
    return pipeline.make_renderer(sc, RenderSettings(sequence=sequence, seed=seed, resolve_samples=4),
                                  solver="ray-bundle-walk")


@pytest.mark.parametrize("glossy,batches,per_batch", [(False, 8, 100), (True, 8, 30)],
                         ids=["diffuse", "glossy"])
def test_walk_furnace_converges_to_analytic(glossy, batches, per_batch):
    """Patch radiance and image mean within 4.5 SE of Le / (1 - a); the number of walks
    started is binomial: 1 + (steps - 1)(1 - q) within 4.5 sd."""
    r = walk_renderer(glossy, "prng")
    exact = r.scene.analytic_radiance
    patch, img = batch_means(r, batches, per_batch)
    assert_converged(patch, exact, max_se=0.03)
    assert_converged(img, exact, max_se=0.03)
    s = r.solver
    assert 0.25 <= s.q <= 0.95
    n = s.stats.iterations - 1
    assert abs(s.walks - 1 - n * (1 - s.q)) < 4.5 * np.sqrt(n * s.q * (1 - s.q)), (s.walks, n, s.q)
    r.tracer.close()


def test_walk_driven_by_halton_converges_to_a_wrong_answer():
    """Thesis 1.2 for the walk too: Halton directions bias it; the blue channel (albedo 0.7 = q,
    so almost no roulette noise) shows it beyond 4.5 SE (measured: -0.21%, 6.6 SE in 8 x 80
    steps), and the run warns."""
    with pytest.warns(UserWarning, match="Halton.*ray-bundle-walk"):
        r = walk_renderer(False, "halton")
    assert_biased(r, per_batch=80)


def test_cli_walk_on_the_glossy_box_reports_its_walks(tmp_path):
    """``render --method ray-bundle-walk``: a finite image, and the walks and q in --stats."""
    import json

    from raybundle.util.io import read_exr

    out, stats = tmp_path / "walk.exr", tmp_path / "walk.json"
    p = subprocess.run([sys.executable, "-m", "raybundle", "render", "cornell-glossy", "--method", "ray-bundle-walk",
                        "--iterations", "30", "--resolution", "16", "16", "--patches", "600", "--out", str(out),
                        "--stats", str(stats)], capture_output=True, text=True)
    assert p.returncode == 0, p.stderr
    img = read_exr(out)
    assert img.shape == (16, 16, 3) and np.isfinite(img).all() and img.mean() > 0
    st = json.loads(stats.read_text())
    assert st["solver"] == "ray-bundle-walk" and 1 <= st["walks"] <= 30 and 0.25 <= st["continuation_probability"] <= 0.95
