"""Measurement-noise models: white Gaussian and AR(1) coloured."""

import abc

import equinox as eqx
import jax.lax as lax
import jax.numpy as jnp
import jax.random as jr
from jaxtyping import Array, Float, PRNGKeyArray

from .._checks import concrete
from .._fields import float_field
from .._types import Signal


class AbstractNoise(eqx.Module):
    """Additive output noise $e$ in $y = w + e$."""

    @abc.abstractmethod
    def sample(self, key: PRNGKeyArray, n: int) -> Signal:
        """`n` samples of the noise."""


class WhiteNoise(AbstractNoise):
    """Zero-mean white Gaussian noise of standard deviation `std`."""

    std: Float[Array, ""] = float_field()

    def __check_init__(self):
        s = concrete(self.std)
        if s is not None and not (s >= 0 and jnp.isfinite(s)):
            raise ValueError(f"noise std must be finite and >= 0; got {float(s)}")

    def sample(self, key: PRNGKeyArray, n: int) -> Signal:
        return self.std * jr.normal(key, (n,))


class AR1Noise(AbstractNoise):
    """Stationary AR(1) noise $e_k = p\\,e_{k-1} + \\varepsilon_k$ of marginal std `std`."""

    std: Float[Array, ""] = float_field()
    pole: Float[Array, ""] = float_field()

    def __check_init__(self):
        p = concrete(self.pole)
        if p is not None and not abs(p) < 1:
            raise ValueError(f"AR(1) pole must satisfy |pole| < 1; got {float(p)}")
        s = concrete(self.std)
        if s is not None and not s >= 0:
            raise ValueError(f"noise std must be >= 0; got {float(s)}")

    def sample(self, key: PRNGKeyArray, n: int) -> Signal:
        innovation_std = self.std * jnp.sqrt(1 - self.pole**2)
        eps = jr.normal(key, (n,))
        # Start in the stationary distribution so every sample has std `std`.
        e0 = self.std * eps[0]

        def step(e, x):
            e = self.pole * e + innovation_std * x
            return e, e

        _, rest = lax.scan(step, e0, eps[1:])
        return jnp.concatenate([e0[None], rest])


def noise_std_for_snr(w: Signal, snr_db: float) -> Float[Array, ""]:
    """The white-noise std giving the signal-to-noise ratio `snr_db` (dB) on `w`.

    SNR is the ratio of the variance of `w` to the noise variance.
    """
    return jnp.std(w) / 10.0 ** (snr_db / 20.0)


def add_noise(key: PRNGKeyArray, w: Signal, noise: AbstractNoise) -> Signal:
    """$y = w + e$ with $e$ drawn from `noise` with `key`."""
    return w + noise.sample(key, w.shape[0])
