"""The ``auto`` method (:mod:`raybundle.app.auto`): it decides from what it measures in a scene.

The rule comes from the methods bench (docs/benchmarks.md); these tests check that the figures it reads
are right (against hand computations on the built-in boxes), that the choice follows them on
rooms no test or bench tuned it on (seeded random layouts), and that the CLI prints the choice
and writes it to ``--stats``.
"""
import json
import subprocess
import sys

import numpy as np
import pytest

from raybundle.app import auto
from raybundle.scene import builtin as scenes


def test_figures_of_the_cornell_boxes_match_hand_computations():
    """cornell: nothing glossy, one small emitter (the 130 x 105 mm lamp, 0.69% of the area);
    cornell-glossy: the glossy share equals the area-weighted glossy albedos over all albedos,
    computed here from the material table by hand."""
    f = auto.inspect(scenes.load_scene("cornell"))
    assert f.glossy_share == 0 and f.small_emitters == 1 and f.lights == 0 and not f.environment
    assert f.emitting_share == pytest.approx(0.130 * 0.105 / f.area, rel=1e-6)
    sc = scenes.load_scene("cornell-glossy")
    mats, area = sc.materials, sc.triangle_area
    glossy = reflected = 0.0
    for m in range(len(mats)):
        a = area[sc.triangle_material == m].sum()
        glossy += a * mats.albedo([m], [0.7], diffuse=False).mean()
        reflected += a * mats.albedo([m], [0.7]).mean()
    assert auto.inspect(sc).glossy_share == pytest.approx(glossy / reflected, rel=1e-9)
    assert auto.inspect(scenes.load_scene("near-mirror")).near_mirror_share == 1.0


@pytest.mark.parametrize("seed", [11, 12, 13])
def test_unseen_rooms_get_the_method_their_figures_call_for(seed):
    """Random rooms: the Lambertian one takes the bundle iteration's view-independent path; the
    glossy one, most of its reflection glossy but lit by small ceiling lamps, takes the bundle
    iteration with its first shot (measured on glossy-room-11 at 30 s: 6.5% against path
    tracing's 8.3%); the same glossy room with glowing walls (most of the area emits) takes
    path tracing, and with its glossy lobes weakened below the limit the iteration again: the
    decision moves with the measured figures, and the reason names them."""
    diffuse, glossy = auto.choose(scenes.random_room(seed)), auto.choose(scenes.random_room(seed, glossy=True))
    assert diffuse.method == "stochastic-iteration" and diffuse.figures.glossy_share == 0
    assert diffuse.figures.small_emitters == 1
    assert glossy.figures.glossy_share > auto.GLOSSY_SHARE_LIMIT and glossy.figures.small_emitters == 2
    assert glossy.method == "stochastic-iteration" and f"{100 * glossy.figures.glossy_share:.0f}%" in glossy.reason
    sc = scenes.random_room(seed, glossy=True)
    sc.materials.emission[sc.materials.names.index("walls")] = 0.3
    glowing = auto.choose(sc)
    assert glowing.figures.emitting_share > auto.EMITTING_SHARE_LIMIT and glowing.method == "path-tracing"
    assert f"{100 * glowing.figures.emitting_share:.0f}% of the area emits" in glowing.reason
    sc.materials.glossy_weight = np.minimum(sc.materials.glossy_weight, 0.1)
    weak = auto.choose(sc)
    assert weak.figures.glossy_share <= auto.GLOSSY_SHARE_LIMIT and weak.method == "stochastic-iteration"


def test_cli_auto_prints_and_records_its_choice(tmp_path):
    out, stats = tmp_path / "auto.exr", tmp_path / "auto.json"
    p = subprocess.run([sys.executable, "-m", "raybundle", "render", "furnace-glossy", "--method", "auto",
                        "--iterations", "2", "--resolution", "16", "16", "--out", str(out), "--stats", str(stats)],
                       capture_output=True, text=True)
    assert p.returncode == 0, p.stderr
    assert "auto: path-tracing" in p.stderr and "glossy lobes carry 91%" in p.stderr
    st = json.loads(stats.read_text())
    assert st["solver"] == "path-tracing" and st["auto"]["method"] == "path-tracing"
    assert st["auto"]["sequence"] == "halton" and st["sampler"] == "halton"      # the QMC walk
    assert st["auto"]["figures"]["glossy_share"] > 0.5
