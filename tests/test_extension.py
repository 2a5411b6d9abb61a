"""The installable extension zip, end to end, as a Blender user gets it, in the newest and the
oldest Blender the extension supports.

``tools/build_extension.py`` builds the linux-x64 zip (no Blender binary; the wheel download
cache ``wheels/`` is reused; cp311 and cp313 wheels side by side). A Python that holds only
``bpy`` and NumPy (checked: ``import raybundle``/``embreex``/``OpenEXR`` fail there first, since
an env that already has them hides a broken zip) installs it with
``bpy.ops.extensions.package_install_files`` into an isolated ``BLENDER_USER_RESOURCES``,
enables it, imports the bundled packages, opens ``demo_scenes/cornell_box.blend``, exports it
with the installed add-on, renders it at 64 x 64 with the ``RAYBUNDLE`` engine (300 iterations)
and with Cycles (two seeds of 256 samples), and uninstalls it again.

That Python is the one running the tests when it is such an env (``make test`` runs this file
in ``.venv-oldest``: bpy 4.2 LTS, Python 3.11, NumPy 1.26); otherwise a fresh venv with this
env's ``bpy`` and NumPy and what they require, linked from this env (bpy 5.3, Python 3.13, NumPy 2
in ``.venv``), made in pytest's tmp dir.
"""
import importlib.util
import json
import os
import pathlib
import subprocess
import sys
import textwrap

import numpy as np
import pytest

pytest.importorskip("tomllib", reason="tools/build_extension.py needs Python >= 3.11")
ROOT = pathlib.Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tools"))
import build_extension as bx  # noqa: E402

needs_bpy = pytest.mark.skipif(
    importlib.util.find_spec("bpy") is None,
    reason="needs the bpy module (source of Blender's blender_ext.py and the Blender the zip is installed into)")
DEMO_BLEND = ROOT / "demo_scenes" / "cornell_box.blend"
#: what the demo .blend exports to (the same in every Blender): its objects, triangles, lamp triangles
DEMO_EXPORT = {"objects": ["back", "ceiling", "floor", "green", "light", "red", "short_block", "tall_block"],
               "triangles": 32, "emitting_triangles": 2, "warnings": []}


# ---------------------------------------------------------------- fast checks (no build)
def test_core_runtime_imports_are_bundled_or_shipped_by_blender():
    """Every non-stdlib module the core imports outside try/except ImportError is in the zip (or numpy)."""
    required, _optional = bx.scan_imports(ROOT / "core" / "raybundle")
    third_party = {m: w for m, w in required.items() if m not in sys.stdlib_module_names and m != "__future__"}
    unbundled = {m: w for m, w in third_party.items() if m not in set(bx.PINS) | bx.PROVIDED_BY_BLENDER}
    assert not unbundled, (f"the core imports {unbundled} at run time, which the extension zip does not bundle "
                           f"(bundled: {sorted(bx.PINS)}, from Blender: {sorted(bx.PROVIDED_BY_BLENDER)})")


def test_core_dependencies_match_the_bundled_wheels():
    import tomllib
    bx.check_core_dependencies(tomllib.loads((ROOT / "blender_manifest.toml").read_text()))


def test_manifest_edit_keeps_tables_and_replaces_lists():
    text = 'id = "x"\nwheels = ["./wheels/a.whl",\n  "./wheels/b.whl"]  # old\nplatforms = ["linux-x64"]\n\n' \
           '[permissions]\nfiles = "Read files"\n'
    out = bx.set_root_list(bx.set_root_list(text, "wheels", ["./wheels/c.whl"]), "platforms", ["windows-x64"])
    import tomllib
    doc = tomllib.loads(out)
    assert doc["wheels"] == ["./wheels/c.whl"] and doc["platforms"] == ["windows-x64"]
    assert doc["id"] == "x" and doc["permissions"] == {"files": "Read files"}


# ---------------------------------------------------------------- the zip in a clean bpy
@pytest.fixture(scope="module")
def linux_zip(tmp_path_factory):
    d = tmp_path_factory.mktemp("ext")
    p = subprocess.run([sys.executable, str(ROOT / "tools" / "build_extension.py"), "--platforms", "linux-x64",
                        "--out", str(d / "dist"), "--build-dir", str(d / "build")],
                       capture_output=True, text=True, timeout=600)
    assert p.returncode == 0, f"tools/build_extension.py failed:\n{p.stdout}\n{p.stderr}"
    (z,) = (d / "dist").glob("raybundle-*-linux_x64.zip")
    return z


@needs_bpy
def test_zip_holds_the_wheels_of_both_blender_pythons(linux_zip):
    """cp311 wheels for Blender 4.2 - 5.0 and cp313 ones for 5.1 - 5.3 in one zip per platform."""
    import tomllib
    import zipfile

    with zipfile.ZipFile(linux_zip) as z:
        wheels = [n.split("/")[-1] for n in z.namelist() if n.endswith(".whl")]
        manifest = tomllib.loads(z.read("blender_manifest.toml").decode())
    for dist in ("embreex", "openexr", "numba", "llvmlite"):
        assert sorted(w.split("-")[2] for w in wheels if w.lower().startswith(dist)) == ["cp311", "cp313"], wheels
    assert (manifest["blender_version_min"], manifest["blender_version_max"]) == ("4.2.0", "5.4.0")


@needs_bpy
def test_every_demo_blend_opens_in_this_blender():
    """The demo files are saved by the oldest supported Blender (`make demo-scenes`): Blender 4.2
    cannot read a file that 5.0 wrote ("not a blend file")."""
    code = ("import sys, bpy\n"
            "for f in sys.argv[1:]:\n"
            "    bpy.ops.wm.open_mainfile(filepath=f)\n"
            "    print(f.rsplit('/', 1)[-1], *bpy.data.version[:2], len(bpy.context.scene.objects))\n")
    files = sorted(str(f) for f in (ROOT / "demo_scenes").glob("*.blend"))
    r = subprocess.run([sys.executable, "-c", code, *files], capture_output=True, text=True, timeout=300,
                       env=_clean_env())
    assert r.returncode == 0, r.stdout[-2000:] + r.stderr[-2000:]
    opened = [ln.split() for ln in r.stdout.splitlines() if ln.endswith(tuple("0123456789")) and ".blend" in ln]
    assert len(opened) == len(files) >= 5, r.stdout
    assert all((int(v0), int(v1)) == (4, 2) and int(n) > 0 for _, v0, v1, n in opened), opened


def _clean_env(**extra):
    env = {k: v for k, v in os.environ.items()
           if k not in {"PYTHONPATH", "PYTHONHOME", "VIRTUAL_ENV", "BLENDER_USER_RESOURCES"}}
    env.update(PYTHONNOUSERSITE="1", **extra)
    return env


def _imports_ours(python) -> list[str]:
    code = ("import importlib.util as u, json; "
            "print(json.dumps([m for m in ('raybundle', 'embreex', 'OpenEXR', 'numba') if u.find_spec(m)]))")
    r = subprocess.run([str(python), "-c", code], capture_output=True, text=True, env=_clean_env(), check=True)
    return json.loads(r.stdout)


def _distribution_closure(names):
    """The installed distributions ``names`` need, themselves included (their Requires-Dist,
    extras left out)."""
    from importlib.metadata import distribution
    from packaging.requirements import Requirement

    seen, todo = {}, list(names)
    while todo:
        dist = distribution(todo.pop())
        key = dist.metadata["Name"].lower().replace("_", "-")
        if key in seen:
            continue
        seen[key] = dist
        for spec in dist.requires or ():
            req = Requirement(spec)
            if req.marker is None or req.marker.evaluate({"extra": ""}):
                todo.append(req.name)
    return list(seen.values())


@pytest.fixture(scope="module")
def bpy_only_python(tmp_path_factory):
    """This Python if it holds none of our packages, else a fresh venv holding only this env's
    ``bpy`` and NumPy and what they require, linked from this env's site-packages (the same
    files as a ``pip install`` of the same versions, without its 15 s of unpacking)."""
    if not _imports_ours(sys.executable):
        return pathlib.Path(sys.executable)
    venv = tmp_path_factory.mktemp("venv-bpy-only")
    subprocess.run([sys.executable, "-m", "venv", "--clear", "--without-pip", str(venv)], check=True, timeout=120)
    py = venv / "bin" / "python"
    site = pathlib.Path(subprocess.run([str(py), "-c", "import sysconfig; print(sysconfig.get_path('purelib'))"],
                                       capture_output=True, text=True, check=True).stdout.strip())
    for dist in _distribution_closure(["bpy", "numpy"]):
        for top in {f.parts[0] for f in dist.files if not f.parts[0].startswith("..")} - {"__pycache__"}:
            src = pathlib.Path(dist.locate_file(top))
            if src.exists() and not (site / top).exists():
                (site / top).symlink_to(src)
    assert not _imports_ours(py), "the bpy-only venv can already import our packages: it would hide a broken zip"
    return py


DRIVER = textwrap.dedent(r'''
    """Runs in the bpy-only venv: install the zip, enable, import, render, uninstall."""
    import json, os, sys, traceback
    zip_path, demo_blend, tools, out_dir, report = sys.argv[1:6]
    res = {}

    def dump():
        with open(report, "w") as f:
            json.dump(res, f, indent=1)

    import bpy, addon_utils
    import numpy as np
    res["imports_before"] = {}
    for m in ("raybundle", "embreex", "OpenEXR", "numba"):
        try:
            __import__(m)
            res["imports_before"][m] = True
        except ImportError:
            res["imports_before"][m] = False
    dump()

    # -- install + enable
    try:
        r = bpy.ops.extensions.package_install_files(filepath=zip_path, repo="user_default", enable_on_install=True)
        res["install_result"] = sorted(r)
    except Exception as e:                           # e.g. the add-on's register() failed while enabling
        res["install_result"] = f"{type(e).__name__}: {e}"
    mod = "bl_ext.user_default.raybundle"
    res["enabled"] = mod in bpy.context.preferences.addons and addon_utils.check(mod)[1]
    user = os.environ["BLENDER_USER_RESOURCES"]
    res["imports_after"] = {}
    for m in ("raybundle", "embreex", "OpenEXR", "numba"):
        try:
            f = __import__(m).__file__
            res["imports_after"][m] = {"ok": True, "file": f, "from_user_dir": os.path.realpath(f).startswith(
                os.path.realpath(user))}
        except Exception as e:
            res["imports_after"][m] = {"ok": False, "error": f"{type(e).__name__}: {e}"}
    dump()

    # -- the demo .blend through the installed extension: export, then the engine beside Cycles
    try:
        engines = {getattr(c, "bl_idname", c.__name__) for c in bpy.types.RenderEngine.__subclasses__()}
        res["engines"] = sorted(engines)
        if "RAYBUNDLE" not in engines:
            raise RuntimeError("no RenderEngine with bl_idname 'RAYBUNDLE' is registered after enabling the "
                               "add-on (raybundle_addon still a stub?)")
        bpy.ops.wm.open_mainfile(filepath=demo_blend)
        import importlib
        export = importlib.import_module(mod + ".translation.export")
        ex = export.export_scene(bpy.context.evaluated_depsgraph_get())
        res["export"] = {"objects": sorted(o.name for o in ex.objects), "triangles": int(len(ex.scene.triangles)),
                         "emitting_triangles": int((ex.scene.materials.emission[ex.scene.triangle_material]
                                                    .max(axis=1) > 0).sum()),
                         "warnings": list(ex.warnings)}
        folder = importlib.import_module(mod + ".translation.bake_cache").cache_folder()
        res["bake_cache"] = [folder, bool(folder) and os.path.isdir(folder)]
        dump()
        sys.path.insert(0, tools)
        from cycles_reference import cycles_settings, exr_output
        import OpenEXR
        from raybundle.util.io import read_exr           # the bundled core and OpenEXR read the EXRs
        sc = bpy.context.scene
        sc.render.resolution_x = sc.render.resolution_y = 64
        sc.render.resolution_percentage = 100
        images = {}
        for name, seed in (("cycles-a", 1), ("cycles-b", 2), ("raybundle", 3)):
            if name == "raybundle":
                sc.render.engine = "RAYBUNDLE"
                sc.raybundle.iterations, sc.raybundle.seed = 300, seed
            else:
                cycles_settings(256, seed, world_strength=None)
            path = os.path.join(out_dir, name + ".exr")
            exr_output(path)
            r = bpy.ops.render.render(write_still=True)
            if not os.path.exists(path):
                raise RuntimeError(f"{name}: render returned {sorted(r)} but wrote no {path}")
            images[name] = read_exr(path).astype(np.float64)
        with OpenEXR.File(os.path.join(out_dir, "raybundle.exr")) as f:
            px = next(iter(f.channels().values())).pixels
        res["exr"] = {"dtype": str(px.dtype), "shape": list(images["raybundle"].shape),
                      "finite": bool(np.isfinite(images["raybundle"]).all()),
                      "min": float(images["raybundle"].min())}
        # the image and its quadrants against Cycles: (H/2, 2, W/2, 2, 3) block means
        quad = {k: im.reshape(2, 32, 2, 32, 3).mean(axis=(1, 3)).reshape(4, 3) for k, im in images.items()}
        full = {k: im.reshape(-1, 3).mean(axis=0) for k, im in images.items()}
        res["means"] = {k: np.vstack([full[k], quad[k]]).tolist() for k in images}
        from raybundle.util import compiled               # the render compiled its kernels into the user folder
        kernels = compiled.cache_folder()
        res["kernels"] = dict(enabled=compiled.ENABLED, reason=compiled.REASON, folder=kernels,
                              pending=compiled.pending(),
                              cached=sorted(n for _, _, fs in os.walk(kernels) for n in fs if n.endswith(".nbi")))
        res["render_ok"] = True
    except Exception as e:
        res["render_ok"] = False
        res["render_error"] = "".join(traceback.format_exception(e))[-3000:]
    dump()

    # -- uninstall
    try:
        repos = bpy.context.preferences.extensions.repos
        idx = next(i for i, rp in enumerate(repos) if rp.module == "user_default")
        pkg_dir = os.path.join(repos[idx].directory, "raybundle")
        existed = os.path.isdir(pkg_dir)
        r = bpy.ops.extensions.package_uninstall(repo_index=idx, pkg_id="raybundle")
        res["uninstall"] = {"result": sorted(r), "existed": existed, "dir_gone": not os.path.exists(pkg_dir),
                            "wheels_gone": not any(os.path.exists(m["file"]) for m in res["imports_after"].values()
                                                   if m.get("ok") and m.get("from_user_dir")),
                            "disabled": mod not in bpy.context.preferences.addons}
    except Exception as e:
        res["uninstall"] = {"error": f"{type(e).__name__}: {e}"}
    dump()
''')


@pytest.fixture(scope="module")
def installed(linux_zip, bpy_only_python, tmp_path_factory):
    d = tmp_path_factory.mktemp("bpy-run")
    (d / "driver.py").write_text(DRIVER)
    report = d / "report.json"
    p = subprocess.run([str(bpy_only_python), str(d / "driver.py"), str(linux_zip), str(DEMO_BLEND), str(ROOT / "tools"),
                        str(d), str(report)], capture_output=True, text=True, timeout=600, cwd=d,
                       env=_clean_env(BLENDER_USER_RESOURCES=str(d / "blender-user")))
    res = json.loads(report.read_text()) if report.exists() else {}
    res["_log"] = f"exit status {p.returncode}\n--- stdout\n{p.stdout[-4000:]}\n--- stderr\n{p.stderr[-4000:]}"
    return res


@needs_bpy
def test_zip_installs_and_enables_in_a_bpy_only_env(installed):
    assert installed.get("imports_before") == {"raybundle": False, "embreex": False, "OpenEXR": False,
                                               "numba": False}, \
        installed["_log"]
    r = installed.get("install_result")
    hint = ("\nraybundle_addon/__init__.py must define register() and unregister(); Blender removes an "
            "extension whose register() fails") if "register" in str(r) else ""
    assert r == ["FINISHED"], f"package_install_files: {r}{hint}\n{installed['_log']}"
    assert installed.get("enabled"), "installed but the add-on is not enabled\n" + installed["_log"]


@needs_bpy
def test_bundled_wheels_import_from_the_installed_extension(installed):
    after = installed.get("imports_after", {})
    for m in ("raybundle", "embreex", "OpenEXR", "numba"):
        assert after.get(m, {}).get("ok"), f"import {m} failed after install: {after.get(m)}\n{installed['_log']}"
        assert after[m]["from_user_dir"], f"{m} was imported from {after[m]['file']}, not the extension's wheels"


@needs_bpy
def test_installed_add_on_exports_the_demo_blend(installed):
    ex = installed.get("export")
    assert ex, f"no export: {installed.get('render_error')}\n{installed['_log']}"
    assert ex == DEMO_EXPORT, ex
    cache, made = installed.get("bake_cache") or ("", False)     # the extension's user folder keeps the bakes
    assert made and cache.replace(os.sep, "/").endswith("extensions/.user/user_default/raybundle/graph-bakes"), cache


@needs_bpy
def test_installed_engine_renders_with_its_compiled_kernels(installed):
    """Numba from the zip's wheels compiles the kernels in this Blender (4.2's Python 3.11 and
    NumPy 1.26, 5.3's 3.13 and 2.x), cached in the extension's user folder."""
    k = installed.get("kernels")
    assert k, f"no render: {installed.get('render_error')}\n{installed['_log']}"
    assert k["enabled"] and not k["pending"], k
    assert k["folder"].replace(os.sep, "/").endswith("extensions/.user/user_default/raybundle/kernels"), k
    assert k["cached"], k


@needs_bpy
def test_installed_engine_renders_the_demo_blend_like_cycles(installed):
    """The 64 x 64 image and each quadrant: every channel's mean within 1.5% of Cycles' (plus 4.5
    times Cycles' noise from its two seeds). Measured: within 0.4% in Blender 4.2 and in 5.3 (the
    region-by-region test of the same scene, tests/test_addon_render.py, allows 3% per region)."""
    assert installed.get("render_ok"), ("rendering the demo .blend with engine RAYBUNDLE from the installed zip "
                                        f"failed:\n{installed.get('render_error')}\n{installed['_log']}")
    exr = installed["exr"]
    assert exr["shape"] == [64, 64, 3] and exr["dtype"] == "float32" and exr["finite"] and exr["min"] >= 0, exr
    m = {k: np.array(v) for k, v in installed["means"].items()}
    cyc = 0.5 * (m["cycles-a"] + m["cycles-b"])
    se = np.abs(m["cycles-a"] - m["cycles-b"]) / 2 / cyc
    rel = m["raybundle"] / cyc - 1
    assert np.all(np.abs(rel) < 0.015 + 4.5 * se), f"(image, quadrants) x RGB relative to Cycles:\n{np.round(rel, 4)}"


@needs_bpy
def test_uninstall_removes_the_extension(installed):
    u = installed.get("uninstall", {})
    assert u.get("existed"), f"nothing to uninstall: the install step failed\n{u}\n{installed['_log']}"
    assert u.get("result") == ["FINISHED"] and u["dir_gone"] and u["disabled"] and u["wheels_gone"], \
        f"{u}\n{installed['_log']}"
