#!/usr/bin/env python3
"""Golden hashes: the renders a refactoring must not change, bit for bit.

    python tools/golden.py              # render every case, compare with tests/golden_hashes.json
    python tools/golden.py --record     # (re)write this environment's hashes (`make golden`)
    python tools/golden.py --only cornell:stochastic-iteration ...

Each case is a command line, run in-process through a front door a user has:

- ``raybundle render`` (``raybundle.app.cli.main``): the built-in scenes with ``--iterations 4
  --seed 3`` at 24 x 24 pixels and 300 patches; every method on the Cornell box;
  ``--gather-rays 64`` (the final gather at a fixed count); and chains by iterations
  (``--workers 2``). Its hash is the SHA-256 of the EXR's float32 pixels read back, with the
  iteration count and the rays traced from ``--stats``;
- ``raybundle-blender`` (``raybundle_addon.__main__.main``, the real ``bpy``) on
  ``demo_scenes/cornell_box.blend`` with the same iterations, seed and patches at 10%: the
  render's pixels (``blend:render``), and the exported scene it saves (``blend:npz``: every array
  of the ``.npz``, by name, dtype, shape and bytes).

Floating-point results can depend on the machine (SIMD paths, core count) and the libraries,
so the file keeps one set of hashes per environment: Python, NumPy, embreex and bpy versions, the CPU
model, its vector instruction sets and the core count. An environment the file does not know is reported, not failed:
record it with ``make golden`` on the commit before a refactoring.
"""
from __future__ import annotations

import argparse
import contextlib
import hashlib
import io
import json
import os
import pathlib
import platform
import sys
import tempfile
from importlib.metadata import version

ROOT = pathlib.Path(__file__).resolve().parents[1]
GOLDEN = ROOT / "tests" / "golden_hashes.json"
COMMON = ["--iterations", "4", "--seed", "3", "--resolution", "24", "24", "--patches", "300"]
SCENES = ["cornell", "cornell-glossy", "furnace", "furnace-glossy", "small-light", "near-mirror", "room-1",
          "glossy-room-1"]
METHODS = ["ray-bundle-walk", "radiosity", "point-collocation", "path-tracing", "single-ray-iteration", "auto"]


BLEND = ROOT / "demo_scenes" / "cornell_box.blend"
BLEND_ARGS = ["--iterations", "4", "--seed", "3", "--patches", "300", "--resolution-percentage", "10"]


def cases() -> dict[str, list[str]]:
    """name -> the ``render`` arguments after the scene's name and before --out/--stats; the
    ``blend:`` cases -> [] (their command is fixed: :func:`blend_hashes`)."""
    out = {"blend:render": [], "blend:npz": []}
    out.update({f"{s}:stochastic-iteration": [s] for s in SCENES})
    out.update({f"cornell:{m}": ["cornell", "--method", m] for m in METHODS})
    out.update({f"{s}:gather-64": [s, "--gather-rays", "64"] for s in ("cornell", "cornell-glossy")})
    out.update({f"{s}:chains-2": [s, "--workers", "2"] for s in ("cornell", "furnace-glossy")})
    return out


def environment() -> str:
    """The key of this environment's hashes: versions, CPU model, its vector instruction sets
    (NumPy and Embree choose their code paths by them; a digest) and the core count."""
    cpu, simd = platform.processor() or platform.machine(), ""
    try:
        info = pathlib.Path("/proc/cpuinfo").read_text().splitlines()
        cpu = next((ln.split(":", 1)[1].strip() for ln in info if ln.startswith("model name")), cpu)
        flags = next((ln.split(":", 1)[1].split() for ln in info if ln.startswith("flags")), [])
        vector = sorted(f for f in flags if f.startswith(("sse", "ssse", "avx", "fma", "f16c", "amx")))
        simd = f", simd {hashlib.sha256(' '.join(vector).encode()).hexdigest()[:8]}"
    except OSError:
        pass
    return (f"python {sys.version_info[0]}.{sys.version_info[1]}, numpy {version('numpy')}, "
            f"embreex {version('embreex')}, bpy {version('bpy')}, {cpu}{simd}, {os.cpu_count()} cores")


def render_hash(args: list[str], workdir: pathlib.Path) -> str:
    """Run ``raybundle render ARGS`` in-process; the hash of its pixels, iterations and rays."""
    from raybundle.app.cli import main
    from raybundle.util.io import read_exr

    out, stats = workdir / "golden.exr", workdir / "golden.json"
    err = io.StringIO()
    with contextlib.redirect_stderr(err):
        status = main(["render", *args, *COMMON, "--out", str(out), "--stats", str(stats)])
    if status != 0:
        raise RuntimeError(f"render {' '.join(args)} exited {status}: {err.getvalue().strip()[-500:]}")
    st = json.loads(stats.read_text())
    h = hashlib.sha256(read_exr(out).astype("<f4").tobytes())
    h.update(f"{st['iterations']} {st.get('rays_traced', 0)}".encode())
    return h.hexdigest()[:16]


def blend_hashes(workdir: pathlib.Path) -> dict[str, str]:
    """Run ``raybundle-blender`` on :data:`BLEND` in-process; the hashes of its image's pixels
    (``blend:render``) and of the exported scene it saved (``blend:npz``)."""
    import numpy as np

    from raybundle.util.io import read_exr
    from raybundle_addon.__main__ import main

    out, npz = workdir / "blend.exr", workdir / "blend.npz"
    err = io.StringIO()
    with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
        status = main([str(BLEND), *BLEND_ARGS, "--out", str(out), "--save-npz", str(npz)])
    if status != 0:
        raise RuntimeError(f"raybundle-blender exited {status}: {err.getvalue().strip()[-500:]}")
    image = hashlib.sha256(read_exr(out).astype("<f4").tobytes())
    scene = hashlib.sha256()
    with np.load(npz, allow_pickle=False) as arrays:
        for name in sorted(arrays.files):
            a = arrays[name]
            scene.update(f"{name} {a.dtype.str} {a.shape}".encode())
            scene.update(np.ascontiguousarray(a).tobytes())
    return {"blend:render": image.hexdigest()[:16], "blend:npz": scene.hexdigest()[:16]}


def run(names: list[str] | None = None) -> dict[str, str]:
    todo = cases()
    names = list(names or todo)
    with tempfile.TemporaryDirectory() as tmp:
        got = blend_hashes(pathlib.Path(tmp)) if any(n.startswith("blend:") for n in names) else {}
        got.update({name: render_hash(todo[name], pathlib.Path(tmp)) for name in names if name not in got})
        return {name: got[name] for name in names}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--record", action="store_true", help="write this environment's hashes")
    ap.add_argument("--only", nargs="+", choices=sorted(cases()), metavar="CASE", help="some cases only")
    a = ap.parse_args(argv)
    env = environment()
    golden = json.loads(GOLDEN.read_text()) if GOLDEN.exists() else {}
    if not a.record and env not in golden:
        print(f"golden: no hashes for this environment ({env}); record them with `make golden`")
        return 0
    got = run(a.only)
    if a.record:
        golden[env] = dict(sorted({**golden.get(env, {}), **got}.items()))
        GOLDEN.write_text(json.dumps(golden, indent=1, sort_keys=True) + "\n")
        print(f"golden: recorded {len(got)} hashes for {env} in {GOLDEN.relative_to(ROOT)}")
        return 0
    changed = {k: (golden[env].get(k), v) for k, v in got.items() if golden[env].get(k) != v}
    for k, (old, new) in changed.items():
        print(f"golden: {k}: {old} -> {new}")
    print(f"golden: {len(got) - len(changed)} of {len(got)} cases unchanged ({env})")
    return 1 if changed else 0


if __name__ == "__main__":
    sys.exit(main())
