"""Which matrix exponential should the zero-order hold use? (`hamjax._filters.expm`)

Times, in one process on this machine, the fixed Taylor series with squaring
(`hamjax._filters.expm`) against `jax.scipy.linalg.expm` (Padé with a
branch on the norm) in the two places the zero-order hold runs:

1. the diagnosis: `jit(vmap(jvp(expm)))` over a batch of 5x5 matrices (the
   augmented model's order `N_MAX + 1`), compile time and median run time;
2. an eager `ContinuousTransferFunction.discretise`-sized call (3x3), median time.

    python benchmarks/expm_choice.py [--batch 512] [--repeats 20]

Prints one line per case and the largest relative difference of the two.
"""

import argparse
import time

import jax
import jax.numpy as jnp
import jax.scipy.linalg as jsl
import numpy as np
from _timing import median_time

import hamjax
from hamjax._filters import expm_taylor as taylor_expm


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--batch", type=int, default=512)
    parser.add_argument("--repeats", type=int, default=20)
    args = parser.parse_args(argv)
    hamjax.enable_x64()
    rng = np.random.default_rng([0, 0])
    # |p| dt up to ~3: the range of the diagnosis's continuous blocks
    M = jnp.asarray(rng.normal(size=(args.batch, 5, 5)))
    dM = jnp.asarray(rng.normal(size=(args.batch, 5, 5)))
    small = jnp.asarray(rng.normal(size=(3, 3)))
    for name, fn in (("taylor", taylor_expm), ("jax.scipy", jsl.expm)):
        batched = jax.jit(jax.vmap(lambda m, t, fn=fn: jax.jvp(fn, (m,), (t,))))
        start = time.perf_counter()
        compiled = batched.lower(M, dM).compile()
        compile_s = time.perf_counter() - start
        run_s = median_time(lambda c=compiled: c(M, dM), args.repeats)
        eager_s = median_time(lambda fn=fn: fn(small), args.repeats)
        print(
            f"{name:10s} vmap-jvp batch {args.batch}: compile {compile_s:.3f} s, "
            f"run {run_s * 1e3:.3f} ms; eager 3x3: {eager_s * 1e3:.3f} ms"
        )
    diff = jnp.max(
        jnp.abs(jax.vmap(taylor_expm)(M) - jax.vmap(jsl.expm)(M))
        / jnp.max(jnp.abs(jax.vmap(jsl.expm)(M)))
    )
    print(f"largest relative difference: {float(diff):.2e}")


if __name__ == "__main__":
    main()
