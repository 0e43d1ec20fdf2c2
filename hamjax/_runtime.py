"""Process-wide runtime settings applied at the entry points (CLI, tests)."""

import os


_EIGEN_FLAG = "--xla_cpu_multi_thread_eigen=false"


def avoid_eigen_pool_hang() -> None:
    """Run XLA's CPU Eigen kernels single-threaded unless the user chose otherwise.

    With jax 0.10 on CPU, vmapped graphs holding LAPACK calls (batched `eigh`)
    were seen to wedge XLA's Eigen thread pool, with every thread asleep; the same
    has been reported elsewhere for vmap graphs. Single-threaded Eigen avoids it at
    a cost of about 15% on the heaviest paths; XLA still runs independent ops in
    parallel. Must run before the first computation (XLA reads the flags when the
    backend starts); set `XLA_FLAGS=--xla_cpu_multi_thread_eigen=true` to opt out.
    """
    flags = os.environ.get("XLA_FLAGS", "")
    if "xla_cpu_multi_thread_eigen" not in flags:
        os.environ["XLA_FLAGS"] = f"{flags} {_EIGEN_FLAG}".strip()
