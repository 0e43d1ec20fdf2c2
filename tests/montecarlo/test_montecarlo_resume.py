"""A run killed with SIGKILL mid-way resumes to the uninterrupted results."""

import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import jax
import jax.numpy as jnp
import jax.random as jr
import numpy as np

from hamjax.montecarlo import MonteCarloConfig, run_monte_carlo, runner


REPO = Path(__file__).resolve().parents[2]
R, C = 60, 2


def trial(key):
    x = jr.normal(key, (4,))
    return {"x": x, "norm": jnp.sqrt(jnp.sum(x * x))}


CHILD = textwrap.dedent(
    f"""
    import sys
    import time
    import jax
    jax.config.update("jax_enable_x64", True)
    import jax.numpy as jnp
    import jax.random as jr
    from hamjax.montecarlo import MonteCarloConfig, run_monte_carlo, storage

    def trial(key):
        x = jr.normal(key, (4,))
        return {{"x": x, "norm": jnp.sqrt(jnp.sum(x * x))}}

    write = storage.write_chunk

    def slow_write(*args):  # slow the run down so that it can be killed mid-way
        write(*args)
        time.sleep(0.2)

    storage.write_chunk = slow_write
    run_monte_carlo(
        jr.key(4), trial, MonteCarloConfig(realisations={R}, chunk={C}, name="kill"),
        out=sys.argv[1], quiet=True,
    )
    """
)


def _chunks(out: Path) -> list[Path]:
    folder = out / "chunks"
    return sorted(folder.glob("chunk_*.npz")) if folder.is_dir() else []


def test_sigkill_then_resume_equals_uninterrupted_run(tmp_path, monkeypatch):
    out = tmp_path / "run"
    script = tmp_path / "child.py"
    script.write_text(CHILD)
    env = {**os.environ, "PYTHONPATH": str(REPO), "JAX_PLATFORMS": "cpu"}
    env.pop("XLA_FLAGS", None)
    proc = subprocess.Popen(
        [sys.executable, str(script), str(out)],
        env=env,
        cwd=REPO,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
    )
    try:
        deadline = time.monotonic() + 240
        while len(_chunks(out)) < 3:
            assert proc.poll() is None, proc.stderr.read().decode()[-3000:]
            assert time.monotonic() < deadline, "child made no progress"
            time.sleep(0.05)
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait(timeout=30)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
        proc.stderr.close()
    assert proc.returncode == -signal.SIGKILL
    finished = len(_chunks(out))
    assert 3 <= finished < R // C

    computed = []
    original = runner._run_chunk

    def counting(*args):
        if not isinstance(args[2], jax.core.Tracer):
            computed.append(1)
        return original(*args)

    monkeypatch.setattr(runner, "_run_chunk", counting)
    config = MonteCarloConfig(realisations=R, chunk=C, name="kill")
    resumed = run_monte_carlo(jr.key(4), trial, config, out=out, quiet=True)
    assert len(computed) == R // C - finished  # finished chunks were not recomputed
    monkeypatch.setattr(runner, "_run_chunk", original)
    reference = run_monte_carlo(jr.key(4), trial, config)
    for name in ("x", "norm"):
        np.testing.assert_array_equal(resumed[name], reference[name])
    assert not list((out / "chunks").glob(".*.tmp"))
