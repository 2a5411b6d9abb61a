"""How `make test` finds its Pythons and what it does when one is missing (tools/find_python,
the Makefile): a name on PATH counts only if it runs; a missing Python is named at the end, and
is an error under CI=true."""
import os
import pathlib
import shutil
import stat
import subprocess
import sys

import pytest

ROOT = pathlib.Path(__file__).resolve().parents[1]
FIND = str(ROOT / "tools" / "find_python")
THIS = f"{sys.version_info[0]}.{sys.version_info[1]}"
#: what find_python prints for this Python, however it is reached: the base interpreter's real file
BASE = os.path.realpath(getattr(sys, "_base_executable", sys.executable))


def _stub(path: pathlib.Path, body: str) -> pathlib.Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text("#!/bin/sh\n" + body + "\n")
    path.chmod(path.stat().st_mode | stat.S_IEXEC)
    return path


def _env(tmp_path, path_dirs):
    """No pyenv on PATH, HOME in tmp_path (so $HOME/.pyenv is the fallback root)."""
    return {"PATH": os.pathsep.join([*map(str, path_dirs), "/usr/bin", "/bin"]), "HOME": str(tmp_path)}


def test_a_failing_stub_on_path_falls_back_to_the_pyenv_versions(tmp_path):
    """`python3.X` on PATH that fails (a pyenv shim with the version not selected) is skipped; the
    newest $(pyenv root)/versions/X.* whose python3 runs is taken (printed as its real file)."""
    bin_dir = tmp_path / "bin"
    _stub(bin_dir / f"python{THIS}", 'echo "pyenv: python{THIS}: command not found" >&2; exit 127')
    versions = tmp_path / ".pyenv" / "versions"
    _stub(versions / f"{THIS}.99" / "bin" / "python3", "exit 1")                     # broken install
    good = versions / f"{THIS}.0" / "bin" / "python3"
    good.parent.mkdir(parents=True)
    good.symlink_to(sys.executable)
    r = subprocess.run([FIND, THIS], capture_output=True, text=True, env=_env(tmp_path, [bin_dir]))
    assert r.returncode == 0 and r.stdout.strip() == BASE, (r.stdout, r.stderr)


def test_a_working_python_on_path_is_taken_and_a_missing_one_is_nothing(tmp_path):
    bin_dir = tmp_path / "bin"
    bin_dir.mkdir()
    (bin_dir / f"python{THIS}").symlink_to(sys.executable)
    r = subprocess.run([FIND, THIS], capture_output=True, text=True, env=_env(tmp_path, [bin_dir]))
    assert r.returncode == 0 and r.stdout.strip() == BASE, r.stderr
    r = subprocess.run([FIND, "3.99"], capture_output=True, text=True, env=_env(tmp_path, [bin_dir]))
    assert r.returncode == 1 and r.stdout == ""


@pytest.mark.skipif(shutil.which("make") is None, reason="needs make")
@pytest.mark.parametrize("missing,ci", [("PY_NEWEST", ""), ("PY_OLDEST", ""), ("PY_NEWEST", "true"),
                                        ("PY_OLDEST", "true")])
def test_make_test_names_a_missing_python_and_fails_under_ci(missing, ci):
    """`make -n test` with one Python taken away: the last line names the skipped environment;
    under CI=true make stops with an error naming the Python."""
    other = {"PY_NEWEST": "PY_OLDEST", "PY_OLDEST": "PY_NEWEST"}[missing]
    args = ["make", "-n", "--no-print-directory", "-C", str(ROOT), "test", f"{missing}=",
            f"{other}={sys.executable}", f"CI={ci}"]
    r = subprocess.run(args, capture_output=True, text=True)
    want = {"PY_NEWEST": "Python 3.13", "PY_OLDEST": "Python 3.11"}[missing]
    if ci:
        assert r.returncode != 0 and "CI=true" in r.stderr and want in r.stderr, (r.stdout, r.stderr)
    else:
        assert r.returncode == 0, r.stderr
        last = r.stdout.strip().splitlines()[-1]
        assert "make test: skipped" in last and want in last, r.stdout
