"""The one set-up path (:mod:`raybundle.app.plan`): what ``auto`` decides, what the user keeps,
and what cannot run, for every front-end alike."""
import pytest

from raybundle.app.plan import DEFAULT_TIME_LIMIT, RunOptions, check, plan
from raybundle.patches.clusters import DEFAULT_PATCHES
from raybundle.scene import builtin as scenes
from raybundle.tracing.sampling import DEFAULT_SEQUENCE


def test_defaults_and_the_budget():
    p = plan(scenes.cornell(), RunOptions())
    assert (p.method, p.patches, p.iterations, p.time_limit) == ("stochastic-iteration", DEFAULT_PATCHES, None,
                                                              DEFAULT_TIME_LIMIT)
    assert p.settings.sequence == DEFAULT_SEQUENCE and p.settings.first_shot == "auto" and p.describe() is None
    p = plan(scenes.cornell(), RunOptions(iterations=5, first_shot=False, gather_rays=64, seed=7))
    assert (p.iterations, p.time_limit, p.settings.first_shot, p.settings.gather_rays, p.settings.seed) == (
        5, None, "none", 64, 7)


def test_auto_decides_what_the_user_left_open():
    glossy = scenes.furnace(glossy=True)            # glossy lobes carry most of it and most of it glows
    p = plan(glossy, RunOptions(method="auto"))
    assert p.method == "path-tracing" and p.settings.sequence == "halton" and p.choice is not None
    assert p.describe().startswith("auto: path-tracing")
    kept = plan(glossy, RunOptions(method="auto", sequence="prng", patches=123))
    assert kept.settings.sequence == "prng" and kept.patches == 123


@pytest.mark.parametrize("what", ["bake", "chains"])
def test_bakes_and_chains_take_a_patch_method_where_auto_picks_an_image_method(what):
    p = plan(scenes.furnace(glossy=True), RunOptions(method="auto"), **{what: True})
    assert p.method == "stochastic-iteration" and p.settings.sequence == DEFAULT_SEQUENCE
    assert "patch solution" in p.describe()


@pytest.mark.parametrize("options,kw,message", [
    (RunOptions(method="nope"), {}, "unknown method"),
    (RunOptions(iterations=3, time_limit=2.0), {}, "not both"),
    (RunOptions(time_limit=float("nan")), {}, "time limit"),
    (RunOptions(patches=-1), {}, "patch count"),
    (RunOptions(bundle_resolution=5000), {}, "bundle_resolution"),
    (RunOptions(method="path-tracing"), {"bake": True}, "renders images only"),
    (RunOptions(method="single-ray-iteration"), {"chains": True}, "no patch solution to merge"),
    (RunOptions(method="point-collocation"), {"chains": True}, "cannot run as merged chains"),
])
def test_what_cannot_run_is_one_line_before_the_scene_is_read(options, kw, message):
    with pytest.raises(ValueError, match=message):
        check(options, **kw)
