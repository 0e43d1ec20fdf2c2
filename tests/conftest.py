"""Test configuration: float64, strict promotion, a printed-seed key fixture."""

import os
import random
from pathlib import Path

import pytest

from hamjax._runtime import avoid_eigen_pool_hang


avoid_eigen_pool_hang()  # before jax starts its backend; see the docstring
# CLI calls inside tests must not write XLA programs into the user's cache
os.environ.setdefault("HAMJAX_CACHE_DIR", "off")

import jax  # noqa: E402
import jax.random as jr  # noqa: E402


jax.config.update("jax_enable_x64", True)
jax.config.update("jax_numpy_rank_promotion", "raise")

SHARED = Path(__file__).resolve().parents[1].parent / "shared"


@pytest.fixture
def getkey():
    """A fresh key per call; the seed is printed so a failure can be replayed."""
    seed = int(os.environ.get("HAMJAX_TEST_SEED", random.randrange(2**31)))
    print(f"getkey seed: {seed}")
    key = jr.key(seed)

    def _getkey():
        nonlocal key
        key, sub = jr.split(key)
        return sub

    return _getkey


@pytest.fixture
def shared_dir() -> Path:
    """`../shared` beside the repository; tests needing it skip without it."""
    if not SHARED.is_dir():
        pytest.skip("../shared is not beside this clone (needed for seeds/data)")
    return SHARED


@pytest.fixture
def mplcleanup():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    yield
    plt.close("all")
