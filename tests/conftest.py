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


def pytest_addoption(parser):
    parser.addoption(
        "--seeds",
        type=int,
        default=1,
        metavar="N",
        help="run every test that uses `getkey` under N seeds: HAMJAX_TEST_SEED "
        "(default 0) + 0..N-1. The default, 1, draws one random seed per test "
        "(or takes HAMJAX_TEST_SEED) and prints it.",
    )


def pytest_configure(config):
    config.addinivalue_line(
        "markers",
        "randomised: draws from the `getkey` fixture (added automatically); "
        "select with -m randomised for a seed sweep",
    )
    if config.getoption("seeds") < 1:
        raise pytest.UsageError("--seeds must be at least 1")


def pytest_generate_tests(metafunc):
    """With ``--seeds N`` (N > 1), parametrise every `getkey` user over N seeds.

    The seeds are deterministic (HAMJAX_TEST_SEED, default 0, plus 0..N-1), so a
    sweep is reproducible and a failure's node id (``[seed=17]``) names the seed
    to replay with ``HAMJAX_TEST_SEED=17``.
    """
    if "_getkey_seed" not in metafunc.fixturenames:
        return
    n = metafunc.config.getoption("seeds")
    if n > 1:
        base = int(os.environ.get("HAMJAX_TEST_SEED", 0))
        seeds = [base + i for i in range(n)]
        metafunc.parametrize("_getkey_seed", seeds, ids=[f"seed={s}" for s in seeds])


# The longest single test (a whole pytest in a subprocess): collected first, so that
# under pytest-xdist (`-n`, pyproject's addopts) it runs beside the other files
# instead of alone at the end (2 cores: 17.3 min with it last).
FIRST = "test_seed_sweep.py"


def pytest_collection_modifyitems(items):
    for item in items:
        if "_getkey_seed" in getattr(item, "fixturenames", ()):
            item.add_marker(pytest.mark.randomised)
    items.sort(key=lambda item: item.path.name != FIRST)


@pytest.fixture
def _getkey_seed():
    """The seed of `getkey`: HAMJAX_TEST_SEED, else random (see ``--seeds``)."""
    return int(os.environ.get("HAMJAX_TEST_SEED", random.randrange(2**31)))


@pytest.fixture
def getkey(_getkey_seed):
    """A fresh key per call; the seed is printed so a failure can be replayed."""
    seed = _getkey_seed
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


@pytest.fixture(autouse=True, scope="module")
def _fresh_compiled_programs():
    """Each test module leaves no compiled programs behind: late in the full suite
    XLA's CPU compiler crashed (SIGSEGV in backend_compile_and_load) on programs
    that compile fine in a shorter run, so the suite no longer accumulates them."""
    yield
    import gc

    from hamjax.diagnosis import fit

    fit.clear_compiled()
    jax.clear_caches()
    gc.collect()
