"""The command line end to end, in a subprocess: EXR, stats JSON, Ctrl-C, errors."""
import json
import os
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

from raybundle.util.io import read_exr


def run_cli(*args, **kw):
    return subprocess.run([sys.executable, "-m", "raybundle", *args], capture_output=True, text=True,
                          timeout=300, **kw)


def test_render_furnace_writes_exr_png_and_stats(tmp_path):
    out, stats = tmp_path / "f.exr", tmp_path / "f.json"
    p = run_cli("render", "furnace", "--iterations", "20", "--patches", "200", "--resolution", "24", "24",
                "--seed", "3", "--out", str(out), "--stats", str(stats))
    assert p.returncode == 0, p.stderr
    img = read_exr(out)
    assert img.shape == (24, 24, 3) and np.isfinite(img).all()
    assert (tmp_path / "f.png").exists()
    s = json.loads(stats.read_text())
    for key in ("iterations", "seconds", "rays_traced", "patches", "analytic_radiance", "pixel_relative_rmse"):
        assert key in s
    assert s["iterations"] == 20 and 150 < s["patches"] < 260
    assert np.allclose(s["image_mean"], img.reshape(-1, 3).mean(axis=0), rtol=1e-5)
    assert max(abs(e) for e in s["mean_relative_error"]) < 0.1
    assert "error vs analytic" in p.stderr
    # set-up reports its steps, in order, before the iterations
    steps = [p.stderr.find(t) for t in ("laying out the patches", "building the ray tracer", "first shot and solver")]
    assert -1 not in steps and steps == sorted(steps), p.stderr
    # ... and --stats holds each phase's seconds, the iterations' beside them, in the order shown
    names = [ph["name"] for ph in s["phases"]]
    # (the kernels, compiled or loaded from their cache, first: the layout uses them too)
    first = names[1] if names[0] == "compiling the kernels" else names[0]
    assert first.startswith("laying out the patches") and names[-2:] == ["iterating", "forming the final image"]
    assert all(ph["seconds"] >= 0 and ph["peak_rss_mb"] > 0 for ph in s["phases"])
    assert sum(ph["seconds"] for ph in s["phases"] if ph["name"] == "iterating") >= s["seconds"] * 0.9


def test_ctrl_c_stops_and_still_writes_the_image(tmp_path):
    out = tmp_path / "c.exr"
    env = dict(os.environ, RAYBUNDLE_PROGRESS="1")
    proc = subprocess.Popen([sys.executable, "-m", "raybundle", "render", "cornell", "--time", "120",
                             "--patches", "300", "--resolution", "32", "32", "--out", str(out)],
                            stderr=subprocess.PIPE, text=True, env=env)
    # wait for the first progress line, then interrupt
    buf = ""
    t0 = time.time()
    while "iterations" not in buf and time.time() - t0 < 120:
        buf += proc.stderr.read(1)
    proc.send_signal(signal.SIGINT)
    rest = proc.communicate(timeout=120)[1]
    assert proc.returncode == 130, buf + rest
    assert "stopped early" in rest
    img = read_exr(out)
    assert np.isfinite(img).all() and img.mean() > 0.01


def test_ctrl_c_during_set_up_writes_nothing(tmp_path):
    """Ctrl-C while a 256k-triangle scene is laid out (about 2 s of set-up on 2 cores): the next
    set-up step stops the run, exit 130, no image and no half-written file."""
    from raybundle.patches.clusters import tessellate
    from raybundle.scene.builtin import load_scene

    big = tmp_path / "big.npz"
    tessellate(load_scene("cornell"), 256_000).save_npz(big)
    out = tmp_path / "c.exr"
    proc = subprocess.Popen([sys.executable, "-m", "raybundle", "render", str(big), "--time", "60",
                             "--resolution", "16", "16", "--out", str(out)], stderr=subprocess.PIPE, text=True)
    buf, t0 = "", time.time()
    while "laying out the patches" not in buf and time.time() - t0 < 120 and proc.poll() is None:
        buf += proc.stderr.read(1)
    proc.send_signal(signal.SIGINT)
    rest = proc.communicate(timeout=120)[1]
    assert proc.returncode == 130 and "stopped during set-up" in rest and "nothing written" in rest, buf + rest
    assert "Traceback" not in rest and sorted(os.listdir(tmp_path)) == ["big.npz"]


def test_bad_scene_names_and_files_give_errors(tmp_path):
    p = run_cli("render", "no-such-scene", "--iterations", "1", "--out", str(tmp_path / "x.exr"))
    assert p.returncode == 2 and "unknown scene" in p.stderr and "Traceback" not in p.stderr
    bad = tmp_path / "bad.npz"
    np.savez(bad, something=np.zeros(3))
    p = run_cli("render", str(bad), "--iterations", "1", "--out", str(tmp_path / "x.exr"))
    assert p.returncode == 2 and "not a raybundle scene" in p.stderr
    assert not (tmp_path / "x.exr").exists()



@pytest.mark.parametrize("args", [["--iterations", "-3"], ["--resolution", "0", "10"], ["--time", "nan"],
                                  ["--time", "-1"], ["--patches", "many"], ["--threads", "0"],
                                  ["--bundle-resolution", "99999"], ["--sequence", "niederreiter"], ["--bogus"],
                                  ["--gather-rays", "-2"]])
def test_bad_arguments_get_one_line_and_exit_2(tmp_path, args):
    p = run_cli("render", "cornell", *args, "--out", str(tmp_path / "x.exr"))
    assert p.returncode == 2, p.stderr
    assert len(p.stderr.strip().splitlines()) == 1 and "error" in p.stderr and "Traceback" not in p.stderr
    assert not (tmp_path / "x.exr").exists()


def test_gather_rays_fixes_the_final_gather_of_a_run_of_given_iterations(tmp_path):
    """--iterations alone has no final gather (reproducible); --gather-rays 64 gathers 64 rays."""
    import json

    stats = {}
    for n in (None, 64):
        out = tmp_path / f"g{n}.exr"
        p = run_cli("render", "cornell", "--iterations", "3", "--resolution", "16", "16", "--patches", "300",
                    *(["--gather-rays", str(n)] if n else []), "--out", str(out), "--stats", str(tmp_path / "s.json"))
        assert p.returncode == 0, p.stderr
        stats[n] = json.loads((tmp_path / "s.json").read_text())
    assert stats[None]["gather_rays_per_pixel"] == 0 and stats[64]["gather_rays_per_pixel"] == 64, stats


@pytest.mark.parametrize("out,stats,message", [
    ("x.png", None, "must end in .exr"),                 # the PNG preview would overwrite it
    ("folder", None, "must end in .exr"),
    ("folder.exr", None, "is a folder"),
    ("file.txt/x.exr", None, "cannot write there"),       # a folder that cannot be made
    ("x.exr", "file.txt/s.json", "cannot write there"),
])
def test_outputs_are_checked_before_the_work(tmp_path, out, stats, message):
    (tmp_path / "folder").mkdir()
    (tmp_path / "folder.exr").mkdir()
    (tmp_path / "file.txt").write_text("not a folder")
    args = ["render", "cornell", "--iterations", "5", "--out", str(tmp_path / out)]
    p = run_cli(*args, *(["--stats", str(tmp_path / stats)] if stats else []))
    assert p.returncode == 2 and message in p.stderr, p.stderr
    assert len(p.stderr.strip().splitlines()) == 1 and "laying out" not in p.stderr     # no work done
    assert not (tmp_path / "x.exr").exists()


@pytest.mark.parametrize("content", [b"", b"PK\x03\x04 truncated", None])
def test_empty_truncated_and_malformed_scene_files_get_one_line(tmp_path, content):
    bad = tmp_path / "bad.npz"
    if content is None:                # readable, but the arrays do not fit together
        np.savez(bad, vertices=np.zeros((3, 3)), triangles=np.array([[0, 1, 7]]), triangle_material=[0],
                 material_names=np.array(["a"]), material_diffuse=np.zeros((1, 2)), material_glossy=[0],
                 material_roughness=[0], material_glossy_weight=[0], material_emission=[[1, 1, 1]])
    else:
        bad.write_bytes(content)
    p = run_cli("render", str(bad), "--iterations", "1", "--out", str(tmp_path / "x.exr"))
    assert p.returncode == 2 and "Traceback" not in p.stderr, p.stderr
    assert len(p.stderr.strip().splitlines()) == 1 and str(bad) in p.stderr


def test_time_is_the_whole_run_and_a_short_budget_still_iterates_and_says_so(tmp_path):
    """``--time`` counts from the command's start; a budget the set-up eats still gets
    MIN_ITERATIONS (8) iterations, a warning and ``budget_note`` in the stats; the phases
    add up: set-up + iterations + final image = the run's total."""
    stats = tmp_path / "s.json"
    p = run_cli("render", "cornell", "--time", "0", "--patches", "300", "--resolution", "16", "16",
                "--out", str(tmp_path / "x.exr"), "--stats", str(stats))
    assert p.returncode == 0, p.stderr
    s = json.loads(stats.read_text())
    assert s["iterations"] == 8 and "too short" in s["budget_note"] and "too short" in p.stderr
    assert s["setup_seconds"] > 0
    parts = s["setup_seconds"] + s["seconds"]
    assert parts <= s["total_seconds"] + 1e-3 and s["total_seconds"] - parts < 0.1 + 0.1 * s["total_seconds"], s
    p = run_cli("render", "cornell", "--iterations", "3", "--patches", "300", "--resolution", "16", "16",
                "--out", str(tmp_path / "y.exr"), "--stats", str(stats))
    s = json.loads(stats.read_text())
    assert s["iterations"] == 3 and "budget_note" not in s          # given iterations are given
