r"""Fast Gaussian draws for Monte Carlo inputs, in blocks that a time-major scan
can generate as it goes.

`jax.random.normal` in float64 spends most of its time in `erfinv` (about 20 ns a
sample on one CPU core, against 1-4 ns for the bits). `normal` here is the
Box-Muller transform of 64 random bits per sample, with the sine and cosine of
$2\pi t$ reduced exactly to $[-\pi/4, \pi/4]$ and evaluated by their Taylor
polynomials (error below $10^{-15}$): exact in distribution up to rounding, for
any key implementation (`jax.random.key(seed, impl=...)`).

`normal_blocks` defines the input of realisation $r$ block by block: samples
$[bK, (b+1)K)$ are `normal(fold_in(key_r, b), (K,))` with $K$ = `BLOCK`. A
realisation so depends only on its key (the seed and $r$), never on the chunk
size or the device count, and the time-major form (`normal_block_time_major`)
draws block $b$ of every realisation of a chunk inside the scan, so the
`(time, chunk)` input is never stored.
"""

import math

import jax
import jax.numpy as jnp
import jax.random as jr
import numpy as np
from jaxtyping import Array, Float, PRNGKeyArray, UInt


# Samples per draw: large enough for the bits to vectorise, small enough that a
# block of a chunk, (BLOCK, chunk / devices), stays in cache.
BLOCK = 50
# Name of this input generator, recorded in a study's manifest (a change of the
# definition must change it, so that a resumed folder is refused).
GENERATOR = f"hamjax.montecarlo.random.normal_blocks/box-muller-64/{BLOCK}"

_SIN = [(-1.0) ** k / math.factorial(2 * k + 1) for k in range(9)]
_COS = [(-1.0) ** k / math.factorial(2 * k) for k in range(10)]


def _horner(coefficients, x):
    acc = jnp.full_like(x, coefficients[-1])
    for c in coefficients[-2::-1]:
        acc = acc * x + c
    return acc


def _sincos_2pi(t: Float[Array, "*s"]) -> tuple[Array, Array]:
    """$\\sin 2\\pi t$, $\\cos 2\\pi t$ for $t \\in [0, 1)$."""
    k = jnp.round(4.0 * t)  # quadrant; t - k/4 is exact in floating point
    b = (2.0 * np.pi) * (t - 0.25 * k)  # in [-pi/4, pi/4]
    b2 = b * b
    s = b * _horner(_SIN, b2)
    c = _horner(_COS, b2)
    q = k.astype(jnp.int32) % 4
    sin = jnp.select([q == 0, q == 1, q == 2], [s, c, -s], -c)
    cos = jnp.select([q == 0, q == 1, q == 2], [c, -s, -c], s)
    return sin, cos


def normal(key: PRNGKeyArray, shape: tuple[int, ...]) -> Float[Array, "*shape"]:
    """Standard normal float64 samples of `shape` (Box-Muller, 64 bits each)."""
    n = math.prod(shape)
    m = (n + 1) // 2
    bits = jr.bits(key, (2, m), jnp.uint64)
    scale = 2.0**-53
    u1 = ((bits[0] >> 11).astype(jnp.float64) + 1.0) * scale  # (0, 1]
    t = (bits[1] >> 11).astype(jnp.float64) * scale  # [0, 1)
    radius = jnp.sqrt(-2.0 * jnp.log(u1))
    sin, cos = _sincos_2pi(t)
    return jnp.concatenate([radius * cos, radius * sin])[:n].reshape(shape)


def normal_block_time_major(
    keys: PRNGKeyArray, block: UInt[Array, ""] | int, *, size: int = BLOCK
) -> Float[Array, "size batch"]:
    """Block `block` of `normal_blocks` for each of `keys`, time-major."""
    block = jnp.asarray(block, jnp.uint32)
    return jax.vmap(lambda k: normal(jr.fold_in(k, block), (size,)))(keys).T


def normal_blocks(
    key: PRNGKeyArray, n_samples: int, *, size: int = BLOCK
) -> Float[Array, " n_samples"]:
    """`n_samples` standard normal samples, block `b` drawn from `fold_in(key, b)`.

    The definition of a realisation's input; equals the blocks that
    `normal_block_time_major` draws inside a time-major scan.
    """
    n_blocks = -(-n_samples // size)
    blocks = jax.vmap(lambda b: normal(jr.fold_in(key, b), (size,)))(
        jnp.arange(n_blocks, dtype=jnp.uint32)
    )
    return blocks.reshape(-1)[:n_samples]


def key_impl_name(key) -> str:
    """The name of the PRNG implementation of `key` (a raw uint32 key: threefry)."""
    if jnp.issubdtype(key.dtype, jax.dtypes.prng_key):
        return str(jr.key_impl(key))
    return "threefry2x32"
