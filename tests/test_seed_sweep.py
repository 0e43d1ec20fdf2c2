"""The randomised tests pass for every seed, not just the one a run happens to draw.

Every test that takes the `getkey` fixture draws a random seed per run (printed,
replayable with HAMJAX_TEST_SEED). `--seeds N` (tests/conftest.py) runs each of them
under the N deterministic seeds HAMJAX_TEST_SEED (default 0) + 0..N-1; this test
runs the fast ones that way in a fresh pytest, so a tolerance that only holds for
lucky draws fails here rather than at random in CI. A longer sweep by hand:

    python -m pytest tests -m "randomised and not slow" --seeds 200 -q
"""

import os
import subprocess
import sys
from pathlib import Path

import pytest


ROOT = Path(__file__).resolve().parents[1]
# About 60 s of compilation for the first seed and about 15 s per further seed on 2
# CPU cores when it was written (5 seeds: 135 s); with the diagnosis's later rows
# 5 seeds took 302 s of a 28-min CI (2026-12-03), so 3: a tolerance that holds for
# only some draws still fails here with probability 1 - (1 - p)^3 per run, and the
# one random seed of every other run adds to it. Issue 23's sweep passed 200 seeds
# (16 for the blocked normal equations).
SEEDS = 3


@pytest.mark.slow
def test_fast_randomised_tests_pass_for_many_seeds():
    env = {k: v for k, v in os.environ.items() if k != "HAMJAX_TEST_SEED"}
    env["PYTHONPATH"] = os.pathsep.join(
        [str(ROOT), *filter(None, [os.environ.get("PYTHONPATH")])]
    )
    cmd = [
        sys.executable,
        "-m",
        "pytest",
        "tests",
        "-m",
        "randomised and not slow",
        "--seeds",
        str(SEEDS),
        "-q",
        "-p",
        "no:cacheprovider",
    ]
    out = subprocess.run(
        cmd, cwd=ROOT, env=env, capture_output=True, text=True, timeout=900
    )
    tail = out.stdout[-4000:] + out.stderr[-2000:]
    assert out.returncode == 0, tail
    # every randomised test ran once per seed (none silently deselected or skipped
    # for all seeds): at least one test, and a count divisible by SEEDS
    summary = out.stdout.strip().splitlines()[-1]
    passed = int(summary.split(" passed")[0].split()[-1])
    assert passed > 0 and passed % SEEDS == 0, summary
