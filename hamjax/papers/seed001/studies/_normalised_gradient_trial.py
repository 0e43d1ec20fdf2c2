r"""The normalised-gradient Monte Carlo trial of seed 001 Section V.C (the
throughput benchmark's workload 2).

Realisation $r$: output $y = w + \sigma e_r$ of the paper's plant driven by the
input (5.1) (noise-free $w$ and input $v$ shared by every realisation), $e_r$ =
`hamjax.montecarlo.random.normal_blocks` of its key `fold_in(key, r)`; the trial's
result is the final estimate of (4.1a-b) from $\hat\theta(0) = 0$ with the radius
$\rho^* = 2\|\Theta^*\|$. The engine's form (`batched`) draws the noise block by
block inside the time-major scan (`normalised_gradient_drawn`), so the chunk's
outputs are never stored; it equals `vmap` of `__call__` (tested).
"""

import math

import equinox as eqx
import jax.numpy as jnp
from jaxtyping import Array, Float, PRNGKeyArray

from ....identification.seed001 import (
    lagrange_coefficients,
    normalised_gradient,
    regressor,
    theta_star,
)
from ....identification.seed001.normalised_gradient_4_1 import (
    normalised_gradient_drawn,
)
from ....montecarlo.random import BLOCK, normal_block_time_major, normal_blocks
from ....signals import pe_impulse_sequence
from ....simulation import simulate
from ..plants import paper_case


class NormalisedGradientTrial(eqx.Module):
    """Realisation r: y = w + noise_std e_r; final estimate of (4.1a-b)."""

    v: Float[Array, " time"]
    w: Float[Array, " time"]
    g: Float[Array, "time q"]
    levels: Float[Array, " 4"]
    noise_std: float = eqx.field(static=True)
    rho: float = eqx.field(static=True)
    unroll: int = eqx.field(static=True, default=4)

    def outputs(self, key: PRNGKeyArray) -> Float[Array, " time"]:
        return self.w + self.noise_std * normal_blocks(key, self.w.shape[0])

    def __call__(self, key: PRNGKeyArray) -> Float[Array, " p"]:
        y = self.outputs(key)
        phi = regressor(self.v, y, levels=self.levels, order=2)
        return normalised_gradient(
            phi, y, theta0=jnp.zeros(phi.shape[1]), rho=self.rho
        )[0]

    def batched(self, keys: PRNGKeyArray) -> Float[Array, "batch p"]:
        # Same outputs as __call__, the noise drawn block by block inside the scan.
        return normalised_gradient_drawn(
            self.w,
            self.g,
            lambda b: self.noise_std * normal_block_time_major(keys, b),
            block=BLOCK,
            order=2,
            theta0=jnp.zeros(2 + self.g.shape[1]),
            rho=self.rho,
            unroll=self.unroll,
        )


def make_gradient_trial(
    *, n_samples: int, noise_std: float = 1.0, unroll: int = 4
) -> tuple[NormalisedGradientTrial, Float[Array, " p"]]:
    """`(trial, theta*)` on the plant of Section V.C, input (5.1) cut to
    `n_samples`, $\\rho^* = 2\\|\\Theta^*\\|$ with $\\Theta^*$ of (3.8c)."""
    case = paper_case()
    levels = case.levels
    _, v = pe_impulse_sequence(levels, order=2, periods=math.ceil(n_samples / 14))
    v = v[:n_samples]
    w = simulate(case.plant(), v)
    g = regressor(v, w, levels=levels, order=2)[:, 2:]  # the same for every y
    d = lagrange_coefficients(levels, case.nonlinearity(levels))
    star = theta_star(case.a, case.b, d)
    rho = 2.0 * float(jnp.linalg.norm(star))
    trial = NormalisedGradientTrial(v, w, g, levels, float(noise_std), rho, unroll)
    return trial, star
