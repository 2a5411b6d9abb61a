import numpy as np
import pytest


def pytest_configure(config):
    config.addinivalue_line("markers", "slow: long statistical or Blender runs (make test-all)")


@pytest.fixture
def rng():
    """A seeded generator: every statistical test is reproducible."""
    return np.random.default_rng(12345)
