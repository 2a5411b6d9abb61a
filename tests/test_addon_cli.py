"""The headless command line ``raybundle-blender SCENE.blend --out out.exr`` as installed,
run from a temporary folder (subprocesses with the real ``bpy`` module; the .blend is built
in the test session)."""
import os
import signal
import subprocess
import tempfile
import time

import numpy as np
import pytest
from addon_helpers import addon, blender_cli_command, bpy  # noqa: F401

from raybundle.util.io import read_exr, read_exr_header


@pytest.fixture(scope="module")
def cornell_blend(tmp_path_factory, addon):  # noqa: F811
    import make_demo_scenes as mds

    path = tmp_path_factory.mktemp("blend") / "cornell_box.blend"
    mds.reset()
    mds.build_cornell(resolution=(48, 48))
    bpy.context.scene.raybundle.time_limit = 60.0
    mds.save(str(path))
    return str(path)


def cli(*args, env=None, **kw):
    e = dict(os.environ, BLENDER_USER_RESOURCES=os.environ.get("BLENDER_USER_RESOURCES", ""), **(env or {}))
    return subprocess.run(blender_cli_command(*args), cwd=tempfile.mkdtemp(prefix="rb-cli-"), env=e,
                          capture_output=True, text=True, timeout=120, **kw)


def test_cli_renders_an_exr_and_saves_the_scene(cornell_blend, tmp_path):
    out, npz = tmp_path / "out.exr", tmp_path / "scene.npz"
    r = cli(cornell_blend, "--out", out, "--iterations", 30, "--seed", 3, "--patches", 800, "--save-npz", npz)
    assert r.returncode == 0, r.stderr[-2000:]
    img = read_exr(out)
    assert img.shape == (48, 48, 3) and np.isfinite(img).all() and img.mean() > 0.05
    assert (tmp_path / "out.png").exists()
    assert read_exr_header(out)["raybundle_iterations"] == "30"
    assert "done: 30 iterations" in r.stderr and "Traceback" not in r.stderr
    from raybundle.scene.npz import load_npz

    sc = load_npz(npz)                            # the core CLI's exchange format, two-sided
    assert sc.triangle_two_sided.all() and len(sc.triangles) == 2 * (6 + 5 + 5)


@pytest.mark.parametrize("args,message", [
    (["--iterations", "-3"], "--iterations"),
    (["--time", "abc"], "--time"),
    (["--seed", "1.5"], "--seed"),
    (["--resolution-percentage", "0"], "--resolution-percentage"),
    (["--out", "x.png"], "must end in .exr"),
    (["--out", "/proc/nope/o.exr"], "cannot write there"),
    (["--out", "o.exr", "--save-npz", "/proc/nope/s.npz"], "--save-npz"),
    (["--bogus"], "unrecognized"),
])
def test_cli_bad_arguments_exit_2_with_one_line(cornell_blend, tmp_path, args, message):
    a = ["--out", str(tmp_path / "o.exr")] + args if "--out" not in args else args
    r = cli(cornell_blend, *a)
    assert r.returncode == 2, (r.returncode, r.stderr)
    err = r.stderr.strip()
    assert message in err and "Traceback" not in err and len(err.splitlines()) == 1, err


def test_cli_missing_file_and_unrenderable_scene(tmp_path, addon):  # noqa: F811
    r = cli(tmp_path / "nope.blend", "--out", tmp_path / "o.exr")
    assert r.returncode == 2 and "no such file" in r.stderr and "Traceback" not in r.stderr
    bpy.ops.wm.read_factory_settings(use_empty=True)                  # a camera and nothing else
    cam = bpy.data.objects.new("cam", bpy.data.cameras.new("cam"))
    bpy.context.scene.collection.objects.link(cam)
    bpy.context.scene.camera = cam
    empty = tmp_path / "empty.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(empty))
    r = cli(empty, "--out", tmp_path / "o.exr", "--iterations", 5)
    assert r.returncode == 2 and "no visible mesh" in r.stderr and "Traceback" not in r.stderr, r.stderr
    assert not (tmp_path / "o.exr").exists()


def test_cli_ctrl_c_keeps_the_partial_image(cornell_blend, tmp_path):
    out = tmp_path / "partial.exr"
    p = subprocess.Popen(blender_cli_command(cornell_blend, "--out", out, "--time", 60), cwd=tmp_path,
                         env=dict(os.environ, RAYBUNDLE_PROGRESS="1"), stderr=subprocess.PIPE, text=True)
    t0 = time.perf_counter()
    buf = ""
    while "iterations" not in buf and time.perf_counter() - t0 < 60:      # wait for the progress bar
        buf += p.stderr.read(1)
    p.send_signal(signal.SIGINT)
    _, err = p.communicate(timeout=60)
    assert p.returncode == 130, err[-2000:]
    assert time.perf_counter() - t0 < 40 and "stopped early" in err and "Traceback" not in err
    img = read_exr(out)
    assert img.shape == (48, 48, 3) and np.isfinite(img).all() and img.mean() > 0.05


@pytest.mark.parametrize("delay", [0.3, 0.8])
def test_cli_ctrl_c_at_once_is_heard(cornell_blend, tmp_path, delay):
    """Ctrl-C while ``bpy`` is imported or the file opened: exit 130, nothing written, no
    traceback (it was ignored, the render ran on and wrote ``--out``; once it segfaulted);
    if it lands in the render, the image so far is written and the run says so."""
    out = tmp_path / "early.exr"
    p = subprocess.Popen(blender_cli_command(cornell_blend, "--out", out, "--time", 60), cwd=tmp_path,
                         stderr=subprocess.PIPE, text=True)
    time.sleep(delay)
    p.send_signal(signal.SIGINT)
    _, err = p.communicate(timeout=60)
    assert p.returncode == 130 and "Traceback" not in err, err[-2000:]
    assert ("nothing written" in err and not out.exists()) or ("stopped early" in err and out.exists()), err


def test_cli_writes_each_view_layer_as_blender_renders_it(tmp_path, addon):  # noqa: F811
    """A file with two view layers, the second without the tall block (its collection excluded):
    the command writes a multilayer EXR with a ``<view layer>.Combined`` RGBA pass for each, and
    each equals that layer as Blender renders and writes it itself (F12, multilayer EXR) with the
    same seed and iterations (it wrote the last layer alone, as plain RGB)."""
    import make_demo_scenes as mds

    from raybundle.util.io import exr_layers

    mds.reset()
    mds.build_cornell(resolution=(32, 32))
    scene = bpy.context.scene
    blocks = bpy.data.collections.new("blocks")
    scene.collection.children.link(blocks)
    tall = next(ob for ob in scene.objects if "tall" in ob.name.lower())
    for c in tall.users_collection:
        c.objects.unlink(tall)
    blocks.objects.link(tall)
    second = scene.view_layers.new("No Block")
    second.layer_collection.children["blocks"].exclude = True
    first = scene.view_layers[0].name
    rb = scene.raybundle
    rb.iterations, rb.seed, rb.patches = 6, 2, 600
    blend = str(tmp_path / "layers.blend")
    mds.save(blend)
    r = cli(blend, "--out", tmp_path / "cli.exr")
    assert r.returncode == 0, r.stderr[-2000:]
    assert sorted(exr_layers(tmp_path / "cli.exr")) == sorted([first, "No Block"])
    assert (tmp_path / "cli.No Block.png").exists()
    scene.render.engine = "RAYBUNDLE"
    st = scene.render.image_settings
    if hasattr(st, "media_type"):             # Blender 5: the multilayer kind is a media type
        st.media_type = "MULTI_LAYER_IMAGE"
    st.file_format, st.color_depth = "OPEN_EXR_MULTILAYER", "32"
    scene.render.filepath = str(tmp_path / "blender.exr")
    bpy.ops.render.render(write_still=True)
    for name in (first, "No Block"):
        ours, blenders = read_exr(tmp_path / "cli.exr", name), read_exr(tmp_path / "blender.exr", name)
        assert np.array_equal(ours, blenders), (name, np.abs(ours - blenders).max())
    assert not np.allclose(read_exr(tmp_path / "cli.exr", first), read_exr(tmp_path / "cli.exr", "No Block"))
