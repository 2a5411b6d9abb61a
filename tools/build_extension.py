#!/usr/bin/env python3
"""Build the installable Blender extension zip(s) without a Blender binary.

    python tools/build_extension.py                      # every platform in the manifest -> dist/
    python tools/build_extension.py --platforms linux-x64 --out /tmp/x

Steps (see ../shared/docs/blender.md section 1):
1. Check that everything the core and the add-on import at run time is either the
   standard library, something Blender ships (numpy, bpy, mathutils, ...) or one of
   the bundled wheels, and that the core's runtime dependencies (core/pyproject.toml,
   minus numpy) are exactly the pinned wheels below.
2. Build the core wheel (``pip wheel --no-deps core/``, offline once setuptools is in
   the cache) and fetch the ``embreex``/``OpenEXR`` binary wheels for each platform and
   each of Blender's Pythons (cp311: Blender 4.2 - 5.0; cp313: 5.1 - 5.3) into the download
   cache (``wheels/``, gitignored; a second build is offline). One zip per platform holds
   both: Blender installs only the wheels of its own Python (4.2 included).
3. Stage ``raybundle_addon/*`` + the top-level ``blender_manifest.toml`` (with its
   ``wheels``/``platforms`` lists written in) + ``wheels/`` into a clean folder: the
   zip's top level is the add-on package, ``__init__.py`` next to the manifest.
4. Run Blender's own ``blender_ext.py validate`` and ``build --split-platforms`` (found
   inside the installed ``bpy`` package) with plain Python.

Needs Python >= 3.11 (tomllib) and pip; the bpy module only as the source of
blender_ext.py (or pass --blender-ext).
"""
from __future__ import annotations

import argparse
import ast
import importlib.util
import os
import pathlib
import re
import shutil
import subprocess
import sys
import tempfile
import tomllib
import zipfile

ROOT = pathlib.Path(__file__).resolve().parents[1]
MANIFEST = ROOT / "blender_manifest.toml"
ADDON = ROOT / "raybundle_addon"
CORE = ROOT / "core"

# Third-party runtime wheels bundled in the zip, pinned (these two versions were tried
# together with bpy 4.2.23 - 5.3.0, which ship their own libembree4 and libOpenEXR). numpy is
# NOT bundled: Blender ships it. Adding a runtime dependency to core/pyproject.toml
# means adding its pin here.
PINS = {"embreex": "4.4.0.post1", "OpenEXR": "3.5.3", "numba": "0.68.1", "llvmlite": "0.50.0"}
# Numba's compiler, needed by numba and not imported by the core itself
TRANSITIVE = {"llvmlite"}
# Numba 0.68 has no Intel macOS wheels: 0.62.1 (with llvmlite 0.45.1) is the last that has them;
# it supports NumPy 1.22 - 2.3 (0.68.1: 1.22 - 2.5), both cover Blender's NumPy 1.26 and 2.x
PLATFORM_PINS = {"macos-x64": {"numba": "0.62.1", "llvmlite": "0.45.1"}}
PROVIDED_BY_BLENDER = {"numpy"}
# Blender's Pythons: 3.11 in Blender 4.2 - 5.0, 3.13 in 5.1 - 5.3 (blender_version_max is 5.4.0)
PYTHON_VERSIONS = ("3.11", "3.13")
SETUPTOOLS_REQ = "setuptools>=77"  # the core's build-system requirement (SPDX license string)

# Blender platform -> (pip --platform tag, test on one platform tag of a wheel file name)
PLATFORMS = {
    "linux-x64": ("manylinux_2_28_x86_64", lambda t: t.startswith("manylinux") and t.endswith("_x86_64")),
    "windows-x64": ("win_amd64", lambda t: t == "win_amd64"),
    # embreex's macOS wheels are tagged macosx_13_0 (asking for 11_0 finds nothing)
    "macos-arm64": ("macosx_13_0_arm64", lambda t: t.startswith("macosx_") and t.endswith(("_arm64", "_universal2"))),
    "macos-x64": ("macosx_13_0_x86_64", lambda t: t.startswith("macosx_") and t.endswith(("_x86_64", "_universal2"))),
}

# Modules that exist inside Blender's Python besides the standard library and
# scripts/{modules,startup,addons_core} (C modules built into the Blender binary).
BLENDER_BUILTIN_MODULES = {"bpy", "mathutils", "bmesh", "gpu", "gpu_extras", "aud", "bl_math", "blf", "bgl",
                           "imbuf", "idprop", "freestyle", "bpy_extras", "bl_ui", "addon_utils", "_bpy"}


class BuildError(Exception):
    pass


def log(msg: str) -> None:
    print(f"[build_extension] {msg}", flush=True)


def norm(name: str) -> str:
    return re.sub(r"[-_.]+", "_", name).lower()


# ---------------------------------------------------------------- import scan
def _catches_import_error(handler: ast.ExceptHandler) -> bool:
    t = handler.type
    names = [t] if not isinstance(t, ast.Tuple) else list(t.elts)
    return t is None or any(isinstance(n, ast.Name) and n.id in {"ImportError", "ModuleNotFoundError", "Exception"}
                            for n in names)


def scan_imports(pkg_dir: pathlib.Path) -> tuple[dict[str, list[str]], dict[str, list[str]]]:
    """Top-level absolute imports of every .py under pkg_dir: (required, optional).

    An import is optional when it sits in a ``try`` whose handler catches ImportError.
    Each maps module name -> ["file:line", ...].
    """
    required: dict[str, list[str]] = {}
    optional: dict[str, list[str]] = {}

    def visit(node: ast.AST, guarded: bool, where: str) -> None:
        if isinstance(node, ast.Try):
            g = guarded or any(_catches_import_error(h) for h in node.handlers)
            for child in node.body:
                visit(child, g, where)
            for child in node.handlers + node.orelse + node.finalbody:
                visit(child, guarded, where)
            return
        mods: list[str] = []
        if isinstance(node, ast.Import):
            mods = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            mods = [node.module]
        for m in mods:
            top = m.split(".")[0]
            (optional if guarded else required).setdefault(top, []).append(f"{where}:{node.lineno}")
        for child in ast.iter_child_nodes(node):
            visit(child, guarded, where)

    for py in sorted(pkg_dir.rglob("*.py")):
        if "__pycache__" in py.parts:
            continue
        visit(ast.parse(py.read_text(encoding="utf-8"), str(py)), False, str(py.relative_to(pkg_dir.parent)))
    return required, optional


def wheel_import_names(wheel: pathlib.Path) -> set[str]:
    """Top-level importable names a wheel installs (packages and extension modules)."""
    names = set()
    for n in zipfile.ZipFile(wheel).namelist():
        top = n.split("/")[0]
        if top.endswith((".dist-info", ".data", ".libs")) or top.startswith("."):
            continue
        if "/" in n:
            names.add(top)
        elif top.endswith((".py", ".so", ".pyd")):
            names.add(top.split(".")[0])
    return names


def wheel_requires(wheel: pathlib.Path) -> set[str]:
    """Distribution names the wheel needs at run time (Requires-Dist without an extra)."""
    zf = zipfile.ZipFile(wheel)
    meta = next(n for n in zf.namelist() if n.endswith(".dist-info/METADATA") and n.count("/") == 1)
    out = set()
    for line in zf.read(meta).decode("utf-8").splitlines():
        if line.startswith("Requires-Dist:"):
            spec = line.split(":", 1)[1]
            if "extra ==" in spec or "extra==" in spec:
                continue
            out.add(norm(re.match(r"\s*([A-Za-z0-9._-]+)", spec).group(1)))
    return out


def blender_script_modules(blender_ext: pathlib.Path) -> set[str]:
    scripts = blender_ext.parents[3]          # .../5.0/scripts
    names = set(BLENDER_BUILTIN_MODULES)
    for sub in ("modules", "startup", "addons_core"):
        d = scripts / sub
        if d.is_dir():
            names |= {p.stem if p.suffix == ".py" else p.name for p in d.iterdir()}
    return names


def check_runtime_imports(bundled_wheels: list[pathlib.Path], blender_ext: pathlib.Path,
                          allow: frozenset[str] = frozenset(), addon: pathlib.Path = ADDON) -> None:
    stdlib = set(sys.stdlib_module_names) | {"__future__"}
    bundled = set()
    for w in bundled_wheels:
        bundled |= wheel_import_names(w)
    problems = []
    # the bundled wheels' own runtime dependencies
    bundled_dists = {norm(w.name.split("-")[0]) for w in bundled_wheels}
    for w in bundled_wheels:
        missing = wheel_requires(w) - bundled_dists - {norm(n) for n in PROVIDED_BY_BLENDER}
        if missing:
            problems.append(f"{w.name} requires {sorted(missing)}, which is neither bundled nor shipped by Blender")
    # the core: stdlib + numpy + the bundled wheels
    req, opt = scan_imports(CORE / "raybundle")
    allowed = stdlib | PROVIDED_BY_BLENDER | bundled | set(allow)
    for mod, where in sorted(req.items()):
        if mod not in allowed:
            problems.append(f"core imports {mod!r} at run time ({', '.join(where)}) but the extension does not "
                            f"bundle it; bundle it (core/pyproject.toml + PINS in tools/build_extension.py) "
                            f"or drop the import")
    if opt:
        log("optional core imports (try/except ImportError, not bundled): " + ", ".join(sorted(opt)))
    # the add-on: additionally everything Blender's Python has
    req, _ = scan_imports(addon)
    allowed |= blender_script_modules(blender_ext) | {addon.name}
    for mod, where in sorted(req.items()):
        if mod not in allowed:
            problems.append(f"the add-on imports {mod!r} ({', '.join(where)}), which is neither in Blender "
                            f"nor bundled")
    if problems:
        raise BuildError("run-time imports not covered by the zip:\n  " + "\n  ".join(problems))
    log(f"run-time imports covered: stdlib + {sorted(PROVIDED_BY_BLENDER)} (Blender) + {sorted(bundled)} (bundled)")


def check_core_dependencies(manifest: dict) -> None:
    core = tomllib.loads((CORE / "pyproject.toml").read_text())["project"]
    deps = {norm(re.match(r"\s*([A-Za-z0-9._-]+)", d).group(1)) for d in core.get("dependencies", [])
            if "extra ==" not in d}
    want = {norm(n) for n in set(PINS) - TRANSITIVE} | {norm(n) for n in PROVIDED_BY_BLENDER}
    if deps != want:
        raise BuildError(f"core/pyproject.toml runtime dependencies {sorted(deps)} differ from what the extension "
                         f"bundles {sorted(norm(n) for n in PINS)} plus {sorted(PROVIDED_BY_BLENDER)} from Blender; "
                         f"update PINS in tools/build_extension.py")
    if core["version"] != manifest["version"]:
        raise BuildError(f"core version {core['version']} != extension version {manifest['version']} "
                         f"(blender_manifest.toml); bump both")


# ---------------------------------------------------------------- wheels
def _wheel_tags(fname: str) -> tuple[str, str, list[str]]:
    parts = fname[:-4].split("-")
    return parts[-3], parts[-2], parts[-1].split(".")


def _wheel_fits(fname: str, dist: str, version: str, platform: str, python: str) -> bool:
    if not fname.endswith(".whl") or not norm(fname).startswith(f"{norm(dist)}_{norm(version)}_"):
        return False
    if fname[:-4].split("-")[1] != version:
        return False
    py, abi, plats = _wheel_tags(fname)
    cp = "cp" + python.replace(".", "")
    return cp in py.split(".") and any(PLATFORMS[platform][1](t) for t in plats)


def fetch_wheel(dist: str, version: str, platform: str, python: str, cache: pathlib.Path,
                offline: bool) -> pathlib.Path:
    def cached():
        return sorted(p for p in cache.glob("*.whl") if _wheel_fits(p.name, dist, version, platform, python))
    hits = cached()
    if not hits:
        what = f"{dist}=={version} for {platform}, Python {python}"
        if offline:
            raise BuildError(f"--offline: no cached wheel of {what} in {cache}")
        log(f"downloading {what}")
        cmd = [sys.executable, "-m", "pip", "download", "--no-deps", "--only-binary=:all:", "--quiet",
               "--python-version", python, "--implementation", "cp", "--platform", PLATFORMS[platform][0],
               "-d", str(cache), f"{dist}=={version}"]
        p = subprocess.run(cmd, capture_output=True, text=True)
        hits = cached()
        if p.returncode != 0 or not hits:
            raise BuildError(f"pip download of {what} failed:\n{p.stderr[-2000:]}")
    return hits[-1]


def build_core_wheel(out: pathlib.Path, cache: pathlib.Path, offline: bool) -> pathlib.Path:
    """``pip wheel --no-deps core/``; the isolated build env takes setuptools from the cache."""
    if not any(cache.glob("setuptools-*.whl")):
        if offline:
            raise BuildError(f"--offline: no setuptools wheel in {cache}")
        log("downloading setuptools (build backend of the core) into the cache")
        subprocess.run([sys.executable, "-m", "pip", "download", "--no-deps", "--only-binary=:all:", "--quiet",
                        "-d", str(cache), SETUPTOOLS_REQ], check=True)
    with tempfile.TemporaryDirectory() as tmp:
        # build from a copy: setuptools writes build/ and *.egg-info next to the sources
        src = pathlib.Path(tmp) / "core"
        shutil.copytree(CORE, src, ignore=shutil.ignore_patterns("__pycache__", "*.pyc", "*.egg-info", "build"))
        cmd = [sys.executable, "-m", "pip", "wheel", "--no-deps", "--quiet", "--no-index", "--find-links", str(cache),
               "-w", str(out), str(src)]
        p = subprocess.run(cmd, capture_output=True, text=True)
        if p.returncode != 0:
            raise BuildError(f"building the core wheel failed:\n{p.stdout[-2000:]}{p.stderr[-3000:]}")
    (wheel,) = out.glob("raybundle-*.whl")
    return wheel


# ---------------------------------------------------------------- manifest edit
def set_root_list(text: str, key: str, values: list[str]) -> str:
    """Set ``key = [...]`` in the root table of a TOML text (replacing any existing one)."""
    head, sep, tail = text.partition("\n[")          # root table = everything before the first [table]
    head = re.sub(rf"(?ms)^{key}\s*=\s*\[.*?\]\s*(#[^\n]*)?\n?", "", head + "\n")
    body = ",\n".join(f'    "{v}"' for v in values)
    head = head.rstrip("\n") + f"\n{key} = [\n{body},\n]\n"
    out = head + ("\n[" + tail if sep else "")
    assert tomllib.loads(out)[key] == values
    return out


# ---------------------------------------------------------------- build
def find_blender_ext(explicit: str | None) -> pathlib.Path:
    if explicit:
        return pathlib.Path(explicit)
    spec = importlib.util.find_spec("bpy")
    if spec is None or not spec.submodule_search_locations:
        raise BuildError("the bpy module is not installed in this Python (it carries Blender's blender_ext.py); "
                         "run through `make extension` or pass --blender-ext PATH/TO/blender_ext.py")
    for loc in spec.submodule_search_locations:
        hits = sorted(pathlib.Path(loc).glob("*/scripts/addons_core/bl_pkg/cli/blender_ext.py"))
        if hits:
            return hits[-1]
    raise BuildError("blender_ext.py not found inside the bpy package")


def run_blender_ext(blender_ext: pathlib.Path, *args: str) -> str:
    p = subprocess.run([sys.executable, str(blender_ext), *args], capture_output=True, text=True)
    out = (p.stdout + p.stderr).strip()
    if p.returncode != 0 or "FATAL_ERROR" in out or "Error:" in out:
        raise BuildError(f"blender_ext.py {args[0]} failed:\n{out}")
    return out


def build(platforms: list[str] | None, out_dir: pathlib.Path, cache: pathlib.Path, build_dir: pathlib.Path,
          blender_ext_path: str | None = None, offline: bool = False,
          allow_imports: frozenset[str] = frozenset(), addon: pathlib.Path = ADDON) -> list[pathlib.Path]:
    manifest_text = MANIFEST.read_text(encoding="utf-8")
    manifest = tomllib.loads(manifest_text)
    ext_id, version = manifest["id"], manifest["version"]
    platforms = platforms or manifest["platforms"]
    unknown = set(platforms) - set(manifest["platforms"]) or set(platforms) - set(PLATFORMS)
    if unknown:
        raise BuildError(f"platforms {sorted(unknown)} not in the manifest {manifest['platforms']} "
                         f"or without a wheel recipe {sorted(PLATFORMS)}")
    if not (addon / "__init__.py").is_file():
        raise BuildError(f"{addon}/__init__.py is missing")
    blender_ext = find_blender_ext(blender_ext_path)
    check_core_dependencies(manifest)
    cache.mkdir(parents=True, exist_ok=True)

    # stage: build_dir/<id>/ = raybundle_addon/* + manifest + wheels/
    stage = build_dir / ext_id
    if stage.exists():
        shutil.rmtree(stage)
    shutil.copytree(addon, stage, ignore=shutil.ignore_patterns("__pycache__", "*.pyc", "*.pyo", ".*", "wheels",
                                                                "*.blend[1-9]", "*.zip"))
    wheel_dir = stage / "wheels"
    wheel_dir.mkdir()
    core_wheel = build_core_wheel(wheel_dir, cache, offline)
    per_platform = {pf: [fetch_wheel(dist, ver, pf, py, cache, offline)
                         for dist, ver in {**PINS, **PLATFORM_PINS.get(pf, {})}.items()
                         for py in PYTHON_VERSIONS] for pf in platforms}
    check_runtime_imports([core_wheel] + per_platform[platforms[0]], blender_ext, allow_imports, addon)
    for src in {w for ws in per_platform.values() for w in ws}:
        shutil.copy2(src, wheel_dir / src.name)
    wheels = sorted(wheel_dir.glob("*.whl"))

    text = set_root_list(manifest_text, "platforms", list(platforms))
    text = set_root_list(text, "wheels", [f"./wheels/{w.name}" for w in wheels])
    (stage / "blender_manifest.toml").write_text(text, encoding="utf-8")

    log(run_blender_ext(blender_ext, "validate", "--valid-tags=", str(stage)).splitlines()[-1])
    out_dir.mkdir(parents=True, exist_ok=True)
    for old in out_dir.glob(f"{ext_id}-{version}-*.zip"):
        old.unlink()
    run_blender_ext(blender_ext, "build", "--valid-tags=", "--split-platforms",
                    "--source-dir", str(stage), "--output-dir", str(out_dir))
    zips = sorted(out_dir.glob(f"{ext_id}-{version}-*.zip"))
    if len(zips) != len(platforms):
        raise BuildError(f"expected {len(platforms)} zips in {out_dir}, found {[z.name for z in zips]}")
    for z in zips:
        names = zipfile.ZipFile(z).namelist()
        in_zip = sorted(n.split("/")[-1] for n in names if n.endswith(".whl"))
        if ("__init__.py" not in names or "blender_manifest.toml" not in names
                or len(in_zip) != 1 + len(PINS) * len(PYTHON_VERSIONS)):
            raise BuildError(f"{z.name}: unexpected contents {names}")
        log(f"{z.relative_to(ROOT) if z.is_relative_to(ROOT) else z}: {z.stat().st_size / 2**20:.1f} MiB "
            f"({', '.join(in_zip)})")
    return zips


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--platforms", help="comma-separated Blender platforms (default: all in the manifest)")
    ap.add_argument("--out", default=str(ROOT / "dist"), help="output folder for the zips (default dist/)")
    ap.add_argument("--cache", default=str(ROOT / "wheels"), help="download cache for wheels (default wheels/)")
    ap.add_argument("--build-dir", default=str(ROOT / "build" / "extension"), help="staging folder")
    ap.add_argument("--blender-ext", help="path to Blender's bl_pkg/cli/blender_ext.py (default: from bpy)")
    ap.add_argument("--addon-dir", default=str(ADDON), help="add-on package to stage (default raybundle_addon/)")
    ap.add_argument("--offline", action="store_true", help="fail instead of downloading")
    ap.add_argument("--allow-import", action="append", default=[], metavar="MODULE",
                    help="escape hatch: accept an unbundled run-time import (the zip breaks where it runs)")
    a = ap.parse_args(argv)
    try:
        build(a.platforms.split(",") if a.platforms else None, pathlib.Path(a.out).resolve(),
              pathlib.Path(a.cache).resolve(), pathlib.Path(a.build_dir).resolve(), a.blender_ext, a.offline,
              frozenset(a.allow_import), pathlib.Path(a.addon_dir).resolve())
    except BuildError as e:
        print(f"build_extension: error: {e}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
