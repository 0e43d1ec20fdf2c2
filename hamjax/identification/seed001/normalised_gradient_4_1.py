"""Normalised gradient with projection on a ball, (4.1a-b) of seed 001."""

from collections.abc import Callable

import jax.lax as lax
import jax.numpy as jnp
from jaxtyping import Array, Float, Int, UInt

from ..._types import Signal
from ...simulation.time_major import check_unroll, scan_blocks
from .reparametrisation_3_2_to_3_8 import regressor


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
    return projected_update(theta, phi_t, e, phi_t @ phi_t, rho)


def projected_update(
    theta: Float[Array, " p *batch"],
    phi: Float[Array, " p *batch"],
    e: Float[Array, " *batch"],
    phi_norm2: Float[Array, " *batch"],
    rho: Float[Array, ""],
) -> Float[Array, " p *batch"]:
    r"""(4.1a) from the error $e(t)$ of (4.1b) and $\Phi(t)^T\Phi(t)$: the step
    $\theta' = \hat\theta + \Phi e / (1 + \Phi^T\Phi)$ projected on the ball of
    radius $\rho^*$. The parameter axis is the first; a trailing batch axis (the
    time-major form) is carried along."""
    candidate = theta + phi * (e / (1.0 + phi_norm2))[None]  # Eq. (4.1a)
    norm = jnp.sqrt(jnp.sum(candidate * candidate, axis=0))
    # Projection on the ball of radius rho*; inside it the step is unchanged
    # (the where also avoids 0/0 when the candidate is exactly zero).
    scale = jnp.where(norm > rho, rho / jnp.where(norm > 0, norm, 1.0), 1.0)
    return candidate * scale[None]  # Eq. (4.1a), second line


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
    the number of samples after which $\max_k |\hat\theta_k(t) - \theta^{ref}_k|
    \le$ tol for good (`time` + 1 if still above at the end).

    Memory is $O(p)$ instead of $O(\text{time} \cdot p)$: for Monte Carlo studies.
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


def normalised_gradient_time_major(
    y: Float[Array, "time batch"],
    g: Float[Array, "time q"],
    *,
    order: int,
    theta0: Float[Array, " p"],
    rho: float,
    unroll: int = 1,
) -> Float[Array, "batch p"]:
    r"""Final estimates of seed 001's (4.1a-b) for a batch of outputs, time-major.

    The regressor (3.8b) is $\Phi(t) = [-y(t-1) \dots -y(t-n),\ g(t)]$ where the
    input part $g(t)$ (the $v(t-i) P_j(v(t-i))$ columns, shape `(time, 4n)`) is the
    same for every realisation (a fixed excitation), so it is passed once. Equals
    `normalised_gradient(regressor(v, y_r), y_r, ...)[0]` for each column `y_r`.
    """
    if y.ndim != 2 or g.ndim != 2 or g.shape[0] != y.shape[0]:
        raise ValueError(f"need y (time, batch), g (time, q); got {y.shape}, {g.shape}")
    check_unroll(unroll)
    n = _check_order(order, theta0, g)
    theta, lags = _time_major_init(theta0, n, y.shape[1], y.dtype)
    step = _time_major_step(n, rho)
    xs = (y, g, jnp.sum(g * g, axis=1))
    (theta, _), _ = lax.scan(step, (theta, lags), xs, unroll=unroll)
    return theta.T


def normalised_gradient_drawn(
    w: Float[Array, " time"],
    g: Float[Array, "time q"],
    noise: Callable[[UInt[Array, ""]], Float[Array, "block batch"]],
    *,
    block: int,
    order: int,
    theta0: Float[Array, " p"],
    rho: float,
    unroll: int = 1,
) -> Float[Array, "batch p"]:
    r"""`normalised_gradient_time_major` of the outputs $y = w + e$ whose noise
    samples $[bK, (b+1)K)$ are `noise(b)` ($K$ = `block`, shape `(block, batch)`),
    drawn block by block inside the time scan: the `(time, batch)` outputs are
    never stored (memory $O$(`block` x batch)). `w` is the common noise-free
    output, `g` the common input part of the regressor (3.8b)."""
    if w.ndim != 1 or g.ndim != 2 or g.shape[0] != w.shape[0]:
        raise ValueError(f"need w (time,), g (time, q); got {w.shape}, {g.shape}")
    n = _check_order(order, theta0, g)
    n_samples = w.shape[0]
    # Padded to whole blocks, so that every block is a full-size dynamic slice.
    pad = -n_samples % block
    common = (
        jnp.pad(w, (0, pad)),
        jnp.pad(g, ((0, pad), (0, 0))),
        jnp.pad(jnp.sum(g * g, axis=1), (0, pad)),
    )

    def block_xs(b):
        w_b, g_b, gg_b = (
            lax.dynamic_slice_in_dim(x, b * block, block, axis=0) for x in common
        )
        return w_b[:, None] + noise(b), g_b, gg_b

    def init(xs0):
        return _time_major_init(theta0, n, xs0[0].shape[1], xs0[0].dtype)

    theta, _ = scan_blocks(
        _time_major_step(n, rho),
        init,
        block_xs,
        n_samples=n_samples,
        block=block,
        unroll=unroll,
    )
    return theta.T


def _check_order(order: int, theta0, g) -> int:
    n = int(order)
    if theta0.shape != (n + g.shape[1],):
        raise ValueError(
            f"theta0 must have {n + g.shape[1]} entries; got {theta0.shape}"
        )
    return n


def _time_major_init(theta0, n: int, batch: int, dtype):
    theta = jnp.broadcast_to(theta0[:, None], (theta0.shape[0], batch)).astype(dtype)
    return theta, jnp.zeros((n, batch), dtype)


def _time_major_step(n: int, rho: float):
    """One sample of (4.1a-b) for a batch: carry `(theta (p, batch), lags (n,
    batch))`, row `(y_t (batch,), g_t (q,), g_t^T g_t)`."""

    def step(carry, row):
        theta, lags = carry
        y_t, g_t, gg = row
        batch = y_t.shape[0]
        phi_y = -lags  # -y(t-1) .. -y(t-n), Eq. (3.8b)
        e = y_t - jnp.sum(phi_y * theta[:n], axis=0) - g_t @ theta[n:]  # Eq. (4.1b)
        phi = jnp.concatenate(
            [phi_y, jnp.broadcast_to(g_t[:, None], (g_t.shape[0], batch))], axis=0
        )
        theta = projected_update(
            theta, phi, e, jnp.sum(phi_y * phi_y, axis=0) + gg, rho
        )  # Eq. (4.1a)
        lags = jnp.concatenate([y_t[None], lags[:-1]], axis=0)
        return (theta, lags), None

    return step


def normalised_gradient_batch(
    v: Signal,
    Y: Float[Array, "batch time"],
    *,
    levels: Float[Array, " 4"],
    order: int,
    theta0: Float[Array, " p"],
    rho: float,
    unroll: int = 4,
) -> Float[Array, "batch p"]:
    r"""Final estimates of (4.1a-b) for many output records of one input `v`.

    Equals `normalised_gradient(regressor(v, y, ...), y, ...)[0]` for each row `y`
    of `Y` (tested), computed by `normalised_gradient_time_major`: the input part of
    the regressor (3.8b) is built once and every step updates the whole batch.

    **Arguments:** `v`, the common input `(time,)`; `Y`, the outputs
    `(batch, time)`; `levels`, `order`, `theta0`, `rho` as in `normalised_gradient`
    and `regressor`; `unroll`, the static unroll of the time scan.
    """
    Y = jnp.asarray(Y, dtype=float)
    if Y.ndim != 2 or Y.shape[1:] != jnp.shape(v):
        raise ValueError(
            f"need Y (batch, time) with time = len(v); got {Y.shape}, {jnp.shape(v)}"
        )
    n = int(order)
    g = regressor(v, jnp.zeros_like(v), levels=levels, order=n)[:, n:]
    return normalised_gradient_time_major(
        Y.T, g, order=n, theta0=jnp.asarray(theta0), rho=rho, unroll=unroll
    )
