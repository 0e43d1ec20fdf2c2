"""Test configuration: float64, strict promotion, a printed-seed key fixture."""

import atexit
import os
import random
import shutil
import tempfile
from pathlib import Path

import pytest

from hamjax._runtime import avoid_eigen_pool_hang, same_rounding_in_every_lane


avoid_eigen_pool_hang()  # before jax starts its backend; see the docstring
same_rounding_in_every_lane()  # likewise
# One folder of compiled XLA programs for the whole test session, shared by the
# xdist workers (they inherit this environment) and the `hamjax` children that the
# CLI tests start (`HAMJAX_CACHE_DIR`, `_runtime.use_compilation_cache`), never the
# user's own cache: each module drops its compiled programs when it ends (see
# `_fresh_compiled_programs`) and the children start cold, so the same programs
# were compiled again and again. Results do not depend on it (XLA's cache returns
# the program it compiled). Removed when the process that made it exits.
if "HAMJAX_TEST_XLA_CACHE" not in os.environ:
    os.environ["HAMJAX_TEST_XLA_CACHE"] = tempfile.mkdtemp(prefix="hamjax-xla-")
    atexit.register(shutil.rmtree, os.environ["HAMJAX_TEST_XLA_CACHE"], True)
os.environ["HAMJAX_CACHE_DIR"] = os.environ["HAMJAX_TEST_XLA_CACHE"]

import jax  # noqa: E402
import jax.random as jr  # noqa: E402


jax.config.update("jax_enable_x64", True)
jax.config.update("jax_numpy_rank_promotion", "raise")
jax.config.update("jax_compilation_cache_dir", os.environ["HAMJAX_CACHE_DIR"])
# programs that compile faster than this are not worth a file
jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.2)

SHARED = Path(__file__).resolve().parents[1].parent / "shared"


# Every fast test that draws from `getkey` runs under one random seed and under the
# SWEEP deterministic seeds 0..SWEEP-1 (ids `[random]`, `[seed=0]`, ...), so that a
# tolerance that only holds for lucky draws fails in every run rather than at
# random: it fails at least one of the fixed seeds with probability
# 1 - (1 - p)^SWEEP, and the random seed explores further in every run. This was a
# separate test running the fast randomised tests again in a fresh pytest (348 s
# of a 38-min CI on 2 cores, almost all of it compiling again what this session
# has compiled); here the extra seeds reuse the module's compiled programs. Tests
# marked slow run once, under a random seed. A longer sweep by hand:
#
#     python -m pytest tests -m "randomised and not slow" --seeds 200 -q
SWEEP = 3


def pytest_addoption(parser):
    parser.addoption(
        "--seeds",
        type=int,
        default=0,
        metavar="N",
        help="run every test that uses `getkey` under N seeds: HAMJAX_TEST_SEED "
        "(default 0) + 0..N-1. Default: a fast test under one random seed and "
        f"seeds 0..{SWEEP - 1}, a slow one under one random seed; with "
        "HAMJAX_TEST_SEED set, every test under that seed only (a replay).",
    )


def pytest_configure(config):
    config.addinivalue_line(
        "markers",
        "randomised: draws from the `getkey` fixture (added automatically); "
        "select with -m randomised for a seed sweep",
    )
    if config.getoption("seeds") < 0:
        raise pytest.UsageError("--seeds must not be negative")


def pytest_generate_tests(metafunc):
    """Parametrise every `getkey` user over its seeds (see `SWEEP`). With
    ``--seeds N`` the seeds are HAMJAX_TEST_SEED (default 0) plus 0..N-1, so a
    sweep is reproducible and a failure's node id (``[seed=17]``) names the seed
    to replay with ``HAMJAX_TEST_SEED=17``; a ``[random]`` test prints its seed.
    """
    if "_getkey_seed" not in metafunc.fixturenames:
        return
    n = metafunc.config.getoption("seeds")
    if n > 0:
        base = int(os.environ.get("HAMJAX_TEST_SEED", 0))
        seeds = [base + i for i in range(n)]
        ids = [f"seed={s}" for s in seeds]
    elif "HAMJAX_TEST_SEED" in os.environ:
        return  # a replay: the fixture takes the seed
    elif metafunc.definition.get_closest_marker("slow") is not None:
        return  # one random seed
    else:
        seeds = [None, *range(SWEEP)]  # None: random (the same ids in every worker)
        ids = ["random", *(f"seed={s}" for s in range(SWEEP))]
    metafunc.parametrize("_getkey_seed", seeds, ids=ids, indirect=True)


# The longest single tests (2-process runs in subprocesses): collected first, so
# that under pytest-xdist (`-n`, pyproject's addopts) they run beside the other
# files instead of alone at the end (2 cores: 17.3 min with the longest last).
FIRST = "test_diagnose_distributed.py"


def pytest_collection_modifyitems(items):
    for item in items:
        if "_getkey_seed" in getattr(item, "fixturenames", ()):
            item.add_marker(pytest.mark.randomised)
    items.sort(key=lambda item: item.path.name != FIRST)


@pytest.fixture
def _getkey_seed(request):
    """The seed of `getkey`: the test's parameter (see `pytest_generate_tests`),
    else HAMJAX_TEST_SEED, else random."""
    seed = getattr(request, "param", None)
    if seed is not None:
        return seed
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
