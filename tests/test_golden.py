"""Renders keep their golden hashes (tools/golden.py): a refactoring changes no pixel.

Skipped where tests/golden_hashes.json has no hashes for this environment (Python, NumPy, bpy,
embreex, CPU model and vector instruction sets, core count): floating-point results can differ
between machines. `make golden` records them; an intended change of results re-records them
and says which cases changed.
"""
import json

import golden
import pytest


def test_renders_keep_their_golden_hashes():
    table = json.loads(golden.GOLDEN.read_text()) if golden.GOLDEN.exists() else {}
    env = golden.environment()
    if env not in table:
        pytest.skip(f"no golden hashes for this environment ({env}): `make golden` records them")
    want = table[env]
    assert set(want) == set(golden.cases()), "tests/golden_hashes.json and tools/golden.py list other cases"
    got = golden.run()
    assert got == want, {k: (want[k], v) for k, v in got.items() if want[k] != v}
