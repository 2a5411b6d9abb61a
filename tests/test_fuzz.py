"""Fuzzing the command line (Hypothesis, derandomised: the same examples every run).

The contract for any argument list and any ``.npz`` file: exit status 0 with a finite EXR,
or exit status 2 with one line on stderr; never a traceback, a hang or a NaN.  Every
generated command is capped to a few iterations of a tiny image.
"""
import contextlib
import io

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from raybundle.app.cli import main
from raybundle.methods.registry import SOLVERS
from raybundle.tracing.sampling import SEQUENCES
from raybundle.util.io import read_exr

FUZZ = settings(derandomize=True, max_examples=80, deadline=None, database=None,
                suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow])


def run(argv):
    """(status, stderr) of ``raybundle`` in this process."""
    err = io.StringIO()
    with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
        try:
            status = main(argv)
        except SystemExit as e:            # argparse
            status = e.code
    return status, err.getvalue()


def check_contract(status, err, out):
    assert "Traceback" not in err, err
    if status == 0:
        img = read_exr(out)
        assert np.isfinite(img).all()
    else:            # one line says what is wrong (progress lines and warnings may come before it)
        assert status == 2, (status, err)
        assert len([x for x in err.splitlines() if "error:" in x]) == 1, err
    STATUS.append(status)


#: the statuses seen, so the harness can show it exercises both outcomes
STATUS = []


numbers = st.one_of(st.integers(-3, 400).map(str), st.sampled_from(["nan", "inf", "-0", "1e9", "x", "", "0.5"]))
options = st.lists(st.one_of(
    st.tuples(st.just("--iterations"), st.integers(-1, 3).map(str)),
    st.tuples(st.just("--patches"), numbers),
    st.tuples(st.just("--seed"), numbers),
    st.tuples(st.just("--bundle-resolution"), numbers),
    st.tuples(st.just("--method"), st.sampled_from(sorted(SOLVERS) + ["auto", "bogus"])),
    st.tuples(st.just("--sequence"), st.sampled_from(sorted(SEQUENCES) + ["bogus"])),
    st.tuples(st.just("--threads"), numbers),
), max_size=4)


@FUZZ
@given(scene=st.sampled_from(["furnace", "cornell", "cornell-glossy", "room-3", "nope", "x.npz"]), opts=options,
       res=st.tuples(st.integers(0, 12), st.integers(1, 12)))
def test_any_command_line_exits_0_with_an_image_or_2_with_one_line(tmp_path, scene, opts, res):
    out = tmp_path / "f.exr"
    out.unlink(missing_ok=True)
    argv = ["render", scene, "--resolution", *map(str, res), "--out", str(out)]
    for k, v in opts:
        argv += [k, v]
    if not any(k == "--iterations" for k, _ in opts):
        argv += ["--iterations", "2"]
    if not any(k == "--patches" for k, _ in opts):
        argv += ["--patches", "200"]
    status, err = run(argv)
    check_contract(status, err, out)


def _scene_arrays(draw):
    """A small scene's arrays, each perhaps broken (shapes, indices, NaN, albedo > 1, camera)."""
    n_v = draw(st.integers(0, 8))
    v = np.array(draw(st.lists(st.tuples(*[st.floats(-2, 2)] * 3), min_size=n_v, max_size=n_v)), float).reshape(-1, 3)
    n_t = draw(st.integers(0, 6))
    t = np.array(draw(st.lists(st.tuples(*[st.integers(-1, 9)] * 3), min_size=n_t, max_size=n_t)),
                 np.int64).reshape(-1, 3)
    d = {"vertices": v, "triangles": t, "triangle_material": np.zeros(len(t) + draw(st.integers(-1, 1)), np.int64),
         "material_names": np.array(["m"]), "material_diffuse": np.array([[0.5, 0.5, draw(st.sampled_from([0.5, 1.5]))]]),
         "material_glossy": np.zeros((1, 3)), "material_roughness": np.array([0.3]),
         "material_glossy_weight": np.zeros(1),
         "material_emission": np.array([[draw(st.sampled_from([0.0, 1.0, np.nan]))] * 3])}
    if draw(st.booleans()):
        d["camera_intrinsics"] = np.array([draw(st.sampled_from([0, 8])), 8, draw(st.sampled_from([0.0, 10.0])),
                                           10.0, 4, 4], float)
        d["camera_matrix_world"] = np.eye(4) * draw(st.sampled_from([0.0, 1.0]))
    for k in list(d):
        if draw(st.integers(0, 12)) == 0:
            del d[k]
    return d


@FUZZ
@given(data=st.data())
def test_any_scene_file_exits_0_with_an_image_or_2_with_one_line(tmp_path, data):
    path, out = tmp_path / "s.npz", tmp_path / "s.exr"
    out.unlink(missing_ok=True)
    np.savez(path, **_scene_arrays(data.draw))
    status, err = run(["render", str(path), "--iterations", "1", "--patches", "50", "--out", str(out)])
    check_contract(status, err, out)


@pytest.mark.parametrize("content", [b"", b"PK\x03\x04", b"\x93NUMPY garbage"])
def test_files_that_are_not_scenes(tmp_path, content):
    path = tmp_path / "s.npz"
    path.write_bytes(content)
    status, err = run(["render", str(path), "--iterations", "1", "--out", str(tmp_path / "x.exr")])
    check_contract(status, err, tmp_path / "x.exr")


def test_the_fuzzing_reached_both_outcomes():
    """Run after the fuzz tests: both renders and refusals were generated."""
    assert STATUS.count(0) >= 5 and STATUS.count(2) >= 5, (STATUS.count(0), STATUS.count(2))
