import os
import sys

import numpy as np
import pytest

# the benches' harnesses in tools/ (tools/invariance.py) serve the tests too
_TOOLS = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "tools")
if _TOOLS not in sys.path:
    sys.path.insert(0, _TOOLS)


@pytest.fixture
def rng():
    """A seeded generator: every statistical test is reproducible."""
    return np.random.default_rng(12345)


#: the files that take 15 s or more, slowest first (`make test-suite` with ``--durations=0``, summed
#: per file): run first, so that the suite's two processes, which take a file at a time in collection
#: order (``--dist loadfile --no-loadscope-reorder``), end together with the short files
SLOWEST_FIRST = (
    "test_addon_render.py",
    "test_bench_pages.py",
    "test_addon_glass.py",
    "test_solver.py",
    "test_addon_materials.py",
    "test_invariance.py",
    "test_transmission.py",
    "test_bench.py",
    "test_light_tree.py",
    "test_cli.py",
    "test_extension.py",
    "test_clusters.py",
    "test_pathtracing.py",
    "test_stability.py",
    "test_mis.py",
    "test_blender_semantics.py",
    "test_addon_cli.py",
    "test_walk.py",
    "test_lights.py",
    "test_imaging.py",
    "test_gather.py",
    "test_addon_export.py",
    "test_addon_components.py",
    "test_addon_light_settings.py",
    "test_lighttracing.py",
)


def pytest_collection_modifyitems(items):
    rank = {name: k for k, name in enumerate(SLOWEST_FIRST)}
    items.sort(key=lambda item: rank.get(item.path.name, len(rank)))
