#!/usr/bin/env python3
"""The extension zip in every Blender release line the manifest admits, one ``bpy`` at a time.

    python tools/blender_versions.py [--versions 4.2.23 4.5.15 5.0.1 5.1.2 5.2.3 5.3.0] [--out out/blender-versions]

For each version: a fresh venv from the Python that Blender version ships (3.11 up to 5.0, 3.13
from 5.1; found by ``tools/find_python``) holding only ``bpy``, the NumPy that Blender ships
(1.26.4 up to 5.0; from 5.1 whatever ``bpy`` asks for, 2.x) and pytest, then
``tests/test_extension.py`` in it: the linux-x64 zip built, installed, enabled, the demo
``.blend`` exported and rendered beside Cycles, uninstalled. ``make test`` runs the two ends
(5.3 in ``.venv``, 4.2 in ``.venv-oldest``); this runs every release line, the ends included.
Prints a table and writes it to ``OUT/versions.md``; exit status 1 if any version failed. About
35 s per version on 2 cores (the ``bpy`` wheels come from pip's cache after the first run).
"""
from __future__ import annotations

import argparse
import os
import pathlib
import subprocess
import sys
import time

ROOT = pathlib.Path(__file__).resolve().parents[1]
DEFAULT_VERSIONS = ["4.2.23", "4.5.15", "5.0.1", "5.1.2", "5.2.3", "5.3.0"]


def python_for(version: str) -> tuple[str, str | None]:
    """(Python version, NumPy pin) of a Blender release: 3.11 with NumPy 1.26 up to 5.0, 3.13 from 5.1."""
    major, minor = (int(x) for x in version.split(".")[:2])
    return ("3.13", None) if (major, minor) >= (5, 1) else ("3.11", "1.26.4")


def run_version(version: str, out: pathlib.Path) -> dict:
    py_version, numpy_pin = python_for(version)
    found = subprocess.run([str(ROOT / "tools" / "find_python"), py_version], capture_output=True, text=True)
    if found.returncode != 0:
        return {"version": version, "python": py_version, "result": f"skipped: no working Python {py_version}"}
    venv = out / f"venv-{version}"
    env = {k: v for k, v in os.environ.items() if k not in {"PYTHONPATH", "VIRTUAL_ENV", "PYTHONHOME"}}
    t0 = time.perf_counter()
    subprocess.run([found.stdout.strip(), "-m", "venv", "--clear", str(venv)], check=True, env=env)
    py = str(venv / "bin" / "python")
    pins = [f"bpy=={version}", "pytest>=8"] + ([f"numpy=={numpy_pin}"] if numpy_pin else [])
    p = subprocess.run([py, "-m", "pip", "install", "--quiet", *pins], capture_output=True, text=True, env=env)
    if p.returncode != 0:
        return {"version": version, "python": py_version, "result": "pip failed: " + p.stderr.strip()[-300:]}
    numpy = subprocess.run([py, "-c", "import numpy; print(numpy.__version__)"], capture_output=True, text=True,
                           env=env).stdout.strip()
    setup = time.perf_counter() - t0
    t0 = time.perf_counter()
    p = subprocess.run([py, "-m", "pytest", "-q", "-p", "no:cacheprovider", str(ROOT / "tests" / "test_extension.py")],
                       capture_output=True, text=True, cwd=ROOT, env=env)
    last = (p.stdout.strip().splitlines() or ["(no output)"])[-1]
    (out / f"pytest-{version}.log").write_text(p.stdout + p.stderr)
    return {"version": version, "python": py_version, "numpy": numpy, "setup_s": round(setup, 1),
            "tests_s": round(time.perf_counter() - t0, 1), "result": ("passed: " if p.returncode == 0 else "FAILED: ")
            + last.strip("= ")}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--versions", nargs="+", default=DEFAULT_VERSIONS, help="bpy versions (default: %(default)s)")
    ap.add_argument("--out", default=str(ROOT / "out" / "blender-versions"), help="venvs, logs and the table")
    a = ap.parse_args(argv)
    out = pathlib.Path(a.out).resolve()
    out.mkdir(parents=True, exist_ok=True)
    rows = []
    for v in a.versions:
        print(f"[blender_versions] bpy {v} ...", flush=True)
        rows.append(run_version(v, out))
        print(f"[blender_versions] {rows[-1]}", flush=True)
    lines = ["| Blender (`bpy`) | Python | NumPy | venv s | tests/test_extension.py |", "|---|---|---|---|---|"]
    lines += [f"| {r['version']} | {r['python']} | {r.get('numpy', '-')} | {r.get('setup_s', '-')} | "
              f"{r['result']} ({r.get('tests_s', '-')} s) |" for r in rows]
    table = "\n".join(lines)
    (out / "versions.md").write_text(table + "\n")
    print(table)
    return 0 if all(r["result"].startswith(("passed", "skipped")) for r in rows) else 1


if __name__ == "__main__":
    sys.exit(main())
