"""Running past one machine: `jax.distributed` for the engine's processes.

Every process runs the same program; `run_monte_carlo` then shards the realisation
axis over every device of every process. Process 0 alone reads and writes the
output folder and tells the others which chunks are finished (so only its machine
needs the folder); the others write their study outputs into a scratch folder.
"""

import os

import jax


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
