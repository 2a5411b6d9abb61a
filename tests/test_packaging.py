"""The core is a standalone, pip-installable package that never imports bpy."""
import pathlib
import re
import subprocess
import sys
import zipfile

import numpy as np

ROOT = pathlib.Path(__file__).resolve().parents[1]


def test_core_never_imports_bpy():
    offenders = [str(p) for p in (ROOT / "core").rglob("*.py")
                 if re.search(r"^\s*(import bpy|from bpy)", p.read_text(), re.M)]
    assert offenders == []


def test_core_builds_a_wheel_named_raybundle(tmp_path):
    p = subprocess.run([sys.executable, "-m", "pip", "wheel", "--no-deps", "-q", "-w", str(tmp_path), str(ROOT / "core")],
                       capture_output=True, text=True, timeout=300)
    assert p.returncode == 0, p.stderr
    (wheel,) = tmp_path.glob("raybundle-*.whl")
    names = zipfile.ZipFile(wheel).namelist()
    assert "raybundle/__init__.py" in names and "raybundle/methods/stochastic_iteration.py" in names
    assert not any(n.startswith(("core/", "tests/")) for n in names)


def test_the_readme_library_example_runs(tmp_path, monkeypatch):
    """The README's library example, as printed (one second instead of ten, in a temporary folder)."""
    readme = (ROOT / "README.md").read_text()
    code = readme.split("## Library", 1)[1].split("```python", 1)[1].split("```", 1)[0]
    assert "time_limit=10" in code and "write_exr(" in code
    monkeypatch.chdir(tmp_path)
    exec(compile(code.replace("time_limit=10", "time_limit=1"), "README.md", "exec"), {})
    from raybundle.util.io import read_exr

    assert np.isfinite(read_exr(tmp_path / "out" / "glossy.exr")).all()
