"""Normalised gradient with projection on a ball, (4.1a-b) of seed 001."""

import jax.lax as lax
import jax.numpy as jnp
from jaxtyping import Array, Float, Int

from ..._types import Signal


def normalised_gradient(
    phi: Float[Array, "time p"],
    y: Signal,
    *,
    theta0: Float[Array, " p"],
    rho: float | Float[Array, ""],
) -> tuple[Float[Array, " p"], Float[Array, "time p"]]:
    r"""Run (4.1a-b) over the whole record as one `lax.scan`:

    $$e(t) = y(t) - \Phi(t)^T \hat\theta(t-1),\quad
    \theta'(t) = \hat\theta(t-1) + \frac{\Phi(t) e(t)}{1 + \Phi(t)^T \Phi(t)},\quad
    \hat\theta(t) = \min(\rho^*, \|\theta'(t)\|) \frac{\theta'(t)}{\|\theta'(t)\|}.$$

    **Arguments:**

    - `phi`: regressors $\Phi(t)$ of (3.8b), shape `(time, p)`.
    - `y`: outputs, shape `(time,)`.
    - `theta0`: the arbitrary initial estimate $\hat\theta(0)$ (call it $t=-1$).
    - `rho`: the projection radius $\rho^* > 0$, an upper bound on $\|\Theta^*\|$.

    **Returns:** `(theta, history)`: the last estimate and every $\hat\theta(t)$,
    `history[t]` being the estimate after sample `t`, shape `(time, p)`.
    """
    if phi.ndim != 2 or y.shape != phi.shape[:1] or theta0.shape != phi.shape[1:]:
        raise ValueError(
            f"need phi (time, p), y (time,), theta0 (p,); got {phi.shape}, "
            f"{y.shape}, {theta0.shape}"
        )
    rho = jnp.asarray(rho, dtype=phi.dtype)

    def step(theta, row):
        theta = gradient_step(theta, row[0], row[1], rho)
        return theta, theta

    theta, history = lax.scan(step, theta0.astype(phi.dtype), (phi, y))
    return theta, history


def gradient_step(
    theta: Float[Array, " p"],
    phi_t: Float[Array, " p"],
    y_t: Float[Array, ""],
    rho: Float[Array, ""],
) -> Float[Array, " p"]:
    r"""One step of (4.1a-b): $\hat\theta(t-1) \mapsto \hat\theta(t)$."""
    e = y_t - phi_t @ theta  # Eq. (4.1b)
    candidate = theta + phi_t * e / (1.0 + phi_t @ phi_t)  # Eq. (4.1a)
    norm = jnp.linalg.norm(candidate)
    # Projection on the ball of radius rho*; inside it the step is unchanged
    # (the where also avoids 0/0 when the candidate is exactly zero).
    scale = jnp.where(norm > rho, rho / jnp.where(norm > 0, norm, 1.0), 1.0)
    return scale * candidate  # Eq. (4.1a), second line


def normalised_gradient_convergence(
    phi: Float[Array, "time p"],
    y: Signal,
    *,
    theta0: Float[Array, " p"],
    rho: float | Float[Array, ""],
    theta_ref: Float[Array, " p"],
    tolerances: Float[Array, " k"],
) -> tuple[Float[Array, " p"], Int[Array, " k"]]:
    r"""(4.1a-b) without the history: the last estimate and, for each tolerance,
    the number of samples after which $\max_k |\hat	heta_k(t) - 	heta^{ref}_k|
    \le$ tol for good (`time` + 1 if still above at the end).

    Memory is $O(p)$ instead of $O(	ext{time} \cdot p)$: for Monte Carlo studies.
    """
    rho = jnp.asarray(rho, dtype=phi.dtype)
    n_time = phi.shape[0]

    def step(carry, row):
        theta, last = carry
        phi_t, y_t, t = row
        theta = gradient_step(theta, phi_t, y_t, rho)
        err = jnp.max(jnp.abs(theta - theta_ref))
        last = jnp.where(err > tolerances, t + 1, last)
        return (theta, last), None

    init = (theta0.astype(phi.dtype), jnp.zeros(tolerances.shape, int))
    (theta, last), _ = lax.scan(step, init, (phi, y, jnp.arange(n_time)))
    # `last` = index after the last exceedance; still above at the end -> time + 1.
    return theta, jnp.where(last == n_time, n_time + 1, last)
