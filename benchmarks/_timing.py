"""What the benchmarks share: a median wall time."""

import statistics
import time

import jax


def median_time(f, repeats: int) -> float:
    """Median wall time of `f()` over `repeats` calls, each waited for (JAX
    arrays until ready; anything else as returned)."""
    walls = []
    for _ in range(repeats):
        start = time.perf_counter()
        jax.block_until_ready(f())
        walls.append(time.perf_counter() - start)
    return statistics.median(walls)
