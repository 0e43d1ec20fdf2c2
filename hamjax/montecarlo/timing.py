"""Wall-clock cost of a batched computation, for the studies' cost ratios."""

import time

import jax


def time_per_call(fn, keys) -> float:
    """Seconds per key of `jax.jit(jax.vmap(fn))(keys)`, compilation excluded
    (one warm-up call, then one timed call)."""
    batched = jax.jit(jax.vmap(fn))
    jax.block_until_ready(batched(keys))
    start = time.perf_counter()
    jax.block_until_ready(batched(keys))
    return (time.perf_counter() - start) / keys.shape[0]
