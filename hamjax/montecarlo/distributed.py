"""Running past one machine: `jax.distributed` for the engine's processes.

Every process runs the same program; `run_monte_carlo` then shards the realisation
axis over every device of every process. Process 0 alone reads and writes the
output folder and tells the others which chunks are finished (so only its machine
needs the folder); the others write their study outputs into a scratch folder.
`hamjax diagnose` splits its cases over the processes instead (each writes the
cases it owns); `allgather_ints` and `fingerprint` are its start and end checks.
"""

import hashlib
import os
from collections.abc import Sequence

import jax
import numpy as np
from jax.experimental import multihost_utils
from jaxtyping import Int


def initialize(
    *,
    coordinator: str | None = None,
    num_processes: int | None = None,
    process_id: int | None = None,
    auto: bool = False,
) -> bool:
    """Start `jax.distributed` before any computation; return whether it started.

    With `coordinator` (`HOST:PORT` of process 0), `num_processes` and `process_id`
    as in `jax.distributed.initialize`. With `auto=True` and no coordinator, JAX
    detects the cluster (SLURM, Open MPI, MPICH, Kubernetes, Cloud TPU). With
    neither, nothing is done (one process). On CPU the cross-process collectives
    use gloo unless `JAX_CPU_COLLECTIVES_IMPLEMENTATION` says otherwise.
    """
    if coordinator is None and not auto:
        if num_processes not in (None, 1) or process_id not in (None, 0):
            raise ValueError(
                "--num-processes/--process-id need --coordinator HOST:PORT "
                "(or --distributed to detect the cluster)"
            )
        return False
    if coordinator is not None:
        host, _, port = coordinator.rpartition(":")
        if not host or not port.isdigit():
            raise ValueError(f"--coordinator must be HOST:PORT; got {coordinator!r}")
        if num_processes is None or process_id is None:
            raise ValueError("--coordinator needs --num-processes and --process-id")
        if not 0 <= process_id < num_processes:
            raise ValueError(
                f"--process-id must be in 0..{num_processes - 1}; got {process_id}"
            )
    if "JAX_CPU_COLLECTIVES_IMPLEMENTATION" not in os.environ:
        jax.config.update("jax_cpu_collectives_implementation", "gloo")
    jax.distributed.initialize(
        coordinator_address=coordinator,
        num_processes=num_processes,
        process_id=process_id,
    )
    return True


def allgather_ints(values: Sequence[int]) -> Int[np.ndarray, "processes k"]:
    """Every process's `values` (the same length on each), row `p` from process
    `p`: a collective that every process must call (one process: just `values`)."""
    row = np.asarray(values, dtype=np.int64)[None]
    if jax.process_count() == 1:
        return row
    return np.asarray(multihost_utils.process_allgather(row[0])).reshape(
        jax.process_count(), -1
    )


def fingerprint(parts: Sequence[str]) -> int:
    """A 62-bit hash of `parts` (SHA-256), to check with `allgather_ints` that
    every process was given the same work."""
    digest = hashlib.sha256("\0".join(parts).encode()).digest()
    return int.from_bytes(digest[:8], "little") >> 2
