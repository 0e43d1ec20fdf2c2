"""Study `simulation-throughput`: how fast does hamjax simulate a backlash plant?

Each realisation drives a Hammerstein plant (backlash of width `--width`, then
the second-order discrete block of seed 001 Section V.C, $A = 1 - 1.5 q^{-1} +
0.56 q^{-2}$, $B = q^{-1} - 2 q^{-2}$) with its own white Gaussian input of
`--samples` samples and keeps the mean, RMS and peak of the output. Reports the
spread of the output RMS across realisations (with MCSE) and the throughput in
realisation-samples per second.

The input of realisation $r$ is `hamjax.montecarlo.random.normal_blocks` of its key
`fold_in(key, r)`; the engine draws it block by block inside the time-major scan
(`output_summary_drawn`), so the chunk's inputs are never stored.
"""

import json
import time
from pathlib import Path

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float, PRNGKeyArray

from ...._argtypes import positive_float, positive_int
from ....models import Backlash, DiscreteTransferFunction, Hammerstein
from ....montecarlo.config import MonteCarloConfig
from ....montecarlo.random import (
    BLOCK,
    GENERATOR,
    normal_block_time_major,
    normal_blocks,
)
from ....montecarlo.registry import StudyOption, option_values
from ....montecarlo.runner import run_monte_carlo
from ....montecarlo.statistics import summarise
from ....montecarlo.storage import atomic_write_bytes
from ....simulation.time_major import output_summary, output_summary_drawn


NAME = "simulation-throughput"
DESCRIPTION = (
    "simulate a backlash + 2nd-order Hammerstein plant over R random inputs; "
    "output-RMS spread and realisation-samples/s"
)
DEFAULT_REALISATIONS = 1000
DEFAULT_CHUNK = 256
SPLIT_CPU = True  # `hamjax study` exposes each core as a device first


class BacklashPlantTrial(eqx.Module):
    """One realisation: white Gaussian input of std `input_std` -> plant -> summaries.

    The backlash width is static (a Python float, part of the compiled program), so
    that the traced trial keeps concrete straight borders and the time-major scan
    steps them as the play operator (`hamjax.simulation.time_major.is_play_operator`,
    equal to `Backlash.step` bit for bit)."""

    linear: DiscreteTransferFunction
    input_std: Float[Array, ""]
    n_samples: int = eqx.field(static=True)
    width: float = eqx.field(static=True, default=0.5)
    unroll: int = eqx.field(static=True, default=1)

    @property
    def plant(self) -> Hammerstein:
        # The borders are computed from the static width at trace time, so that
        # under jit they stay concrete.
        with jax.ensure_compile_time_eval():
            backlash = Backlash.from_width(self.width)
        return Hammerstein(backlash, self.linear)

    def _inputs(self, key: PRNGKeyArray) -> Float[Array, " time"]:
        return self.input_std * normal_blocks(key, self.n_samples)

    def __call__(self, key: PRNGKeyArray) -> dict[str, Float[Array, ""]]:
        return output_summary(self.plant, self._inputs(key), unroll=self.unroll)

    def batched(self, keys: PRNGKeyArray) -> dict[str, Float[Array, " batch"]]:
        # Same inputs as __call__, drawn block by block inside the time-major scan.
        return output_summary_drawn(
            self.plant,
            lambda b: self.input_std * normal_block_time_major(keys, b),
            n_samples=self.n_samples,
            block=BLOCK,
            unroll=self.unroll,
        )


def make_trial(
    *, n_samples: int, width: float = 0.5, input_std: float = 1.0, unroll: int = 1
) -> BacklashPlantTrial:
    """The trial of this study (also used by `benchmarks/benchmark_throughput.py`)."""
    if not width >= 0:
        raise ValueError(f"backlash width must be >= 0; got {width}")
    return BacklashPlantTrial(
        linear=DiscreteTransferFunction([0.0, 1.0, -2.0], [1.0, -1.5, 0.56]),
        input_std=jnp.asarray(input_std, dtype=float),
        n_samples=n_samples,
        width=float(width),
        unroll=unroll,
    )


OPTIONS = (
    StudyOption(
        "samples", 1000, "samples per realisation (default 1000)", positive_int
    ),
    StudyOption("width", 0.5, "backlash width (default 0.5)", positive_float),
)


def run(key, *, realisations: int, chunk: int, out: Path, quiet: bool, args) -> dict:
    opts = option_values(args, OPTIONS)
    n_samples, width = opts.samples, opts.width
    trial = make_trial(n_samples=n_samples, width=width)
    config = MonteCarloConfig(realisations=realisations, chunk=chunk, name=NAME)
    seed = getattr(args, "seed", None)
    # Compile first (same trial and chunk shape: the real run reuses it), so the
    # throughput below is the steady state.
    run_monte_carlo(
        key, trial, MonteCarloConfig(realisations=1, chunk=chunk), quiet=True
    )
    start = time.perf_counter()
    results = run_monte_carlo(
        key,
        trial,
        config,
        out=Path(out) / "realisations",
        quiet=quiet,
        metadata={
            "seed": seed,
            "samples": n_samples,
            "width": width,
            "inputs": GENERATOR,
        },
    )
    elapsed = time.perf_counter() - start
    rms = summarise(results["rms"], 0.0)
    summary = {
        "study": NAME,
        "seed": seed,
        "realisations": realisations,
        "chunk": chunk,
        "samples": n_samples,
        "width": width,
        "output_rms": {
            "mean": float(rms.mean),
            "mean_mcse": float(rms.mean_mcse),
            "mean_ci": np.asarray(rms.mean_ci).tolist(),
            "std": float(rms.std),
            "std_mcse": float(rms.std_mcse),
        },
        # Excludes compilation; includes chunks read back from a resumed folder.
        "elapsed_s": elapsed,
        "realisation_samples_per_s": realisations * n_samples / elapsed,
    }
    summary["headline"] = (
        f"output RMS {rms.mean:.4g} +- {rms.mean_mcse:.2g} (MCSE); "
        f"{summary['realisation_samples_per_s']:.3g} realisation-samples/s"
    )
    atomic_write_bytes(
        Path(out) / "summary.json", (json.dumps(summary, indent=2) + "\n").encode()
    )
    _figure(results["rms"], Path(out) / "output_rms.png")
    return summary


def _figure(rms: np.ndarray, path: Path) -> None:
    # TODO(lead): move to hamjax.plotting when it has a Monte Carlo histogram helper.
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(5, 3.5))
    ax.hist(rms, bins=min(50, max(5, rms.shape[0] // 10)))
    ax.set_xlabel("output RMS of one realisation")
    ax.set_ylabel("realisations")
    ax.set_title(NAME)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
