"""Fit the two noise-model effects (`drift`, `coloured_noise`) on the estimation
residual and score them by one-step-ahead prediction on the validation residual."""

import threading
from collections.abc import Iterable

import equinox as eqx
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from .effects.coloured_noise import ar1_errors, fit_ar1
from .effects.drift import fit_local_level, local_level_errors
from .layout import bucket


class NoiseFit(eqx.Module):
    """Fitted noise models and their validation one-step-ahead errors."""

    ar1_pole: Float[Array, ""]
    ar1_errors: Float[Array, " L"]
    level_alpha: Float[Array, ""]
    level_errors: Float[Array, " L"]


@eqx.filter_jit
def fit_noise_models(
    r_est: Float[Array, " L"],
    m_est: Float[Array, " L"],
    r_val: Float[Array, " L"],
) -> NoiseFit:
    """AR(1) and local-level predictors fitted on `r_est`, applied to `r_val`."""
    a = fit_ar1(r_est, m_est)
    alpha = fit_local_level(r_est, m_est)
    return NoiseFit(
        a,
        ar1_errors(r_val, a),
        alpha,
        local_level_errors(r_val, alpha),
    )


def noise_fit_numpy(r_est: np.ndarray, r_val: np.ndarray) -> dict:
    """Convenience wrapper on unpadded NumPy residuals (padded to the diagnosis's
    record buckets, so records of many lengths share a few compilations)."""
    n = bucket(max(r_est.shape[0], r_val.shape[0]))
    pe = np.zeros(n)
    pe[: r_est.shape[0]] = r_est
    me = np.zeros(n)
    me[: r_est.shape[0]] = 1.0
    pv = np.zeros(n)
    pv[: r_val.shape[0]] = r_val
    f = fit_noise_models(jnp.asarray(pe), jnp.asarray(me), jnp.asarray(pv))
    k = r_val.shape[0]
    return {
        "coloured_noise": (float(f.ar1_pole), np.asarray(f.ar1_errors)[:k]),
        "drift": (float(f.level_alpha), np.asarray(f.level_errors)[:k]),
    }


def compile_in_background(lengths: Iterable[int]) -> threading.Thread:
    """Compile `fit_noise_models` for the records of these lengths on a thread.

    The candidate fits compile meanwhile (XLA releases the GIL while compiling), so
    the noise models, needed once the first case is fitted, are ready by then.
    """

    def run() -> None:
        for n in sorted({bucket(k) for k in lengths}):
            z = jnp.zeros(n)
            try:
                fit_noise_models(z, z, z)
            except Exception:  # noqa: BLE001 - a real call raises it where it matters
                return

    thread = threading.Thread(target=run, name="hamjax-noise-compile", daemon=True)
    thread.start()
    return thread
