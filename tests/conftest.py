"""Strict test settings: floating-point errors raise, a seeded rng, a slow marker (pyproject)."""

import numpy as np
import pytest


@pytest.fixture(autouse=True)
def _strict_floats():
    old = np.seterr(all="raise")
    yield
    np.seterr(**old)


@pytest.fixture
def rng():
    return np.random.default_rng(20261122)
