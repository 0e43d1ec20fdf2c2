r"""Lagrange reparametrisation of seed 001, (3.2)-(3.8), for any order $n$.

With the input restricted to $\{0, V_1, \dots, V_4\}$ the hard nonlinearity $F$
equals the quartic $P(v) = v \sum_j d_j P_j(v)$ of (3.3), and the plant becomes
the linear regression $y(t) = \Phi(t)^T \Theta^* + \eta(t)$ of (3.8).
"""

import equinox as eqx
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float

from ..._checks import concrete
from ..._types import Signal


def lagrange_basis(
    levels: Float[Array, " 4"], v: Float[Array, "*shape"]
) -> Float[Array, "*shape 4"]:
    r"""Eq. (3.3): $P_j(v) = \prod_{i \ne j} (v - V_i) / (V_j - V_i)$, stacked on a
    last axis of size 4, so that $P_j(V_i) = \delta_{ij}$ (3.4)."""
    v = jnp.asarray(v, dtype=float)[..., None]
    columns = []
    for j in range(4):
        p = jnp.ones_like(v[..., 0])
        for i in range(4):
            if i != j:
                p = p * (v[..., 0] - levels[i]) / (levels[j] - levels[i])
        columns.append(p)
    return jnp.stack(columns, axis=-1)


def interpolating_polynomial(
    levels: Float[Array, " 4"], d: Float[Array, " 4"], v: Float[Array, "*shape"]
) -> Float[Array, "*shape"]:
    """Eq. (3.3): $P(v) = v \\sum_j d_j P_j(v)$; $P(0) = 0$, $P(V_j) = d_j V_j$."""
    v = jnp.asarray(v, dtype=float)
    return v * (lagrange_basis(levels, v) @ d)


def lagrange_coefficients(
    levels: Float[Array, " 4"], values: Float[ArrayLike, " 4"]
) -> Float[Array, " 4"]:
    """Eq. (3.5): $d_j = F(V_j) / V_j$ from the values $F(V_j)$."""
    return jnp.asarray(values, dtype=float) / levels


def theta_star(
    a: Float[ArrayLike, " n"], b: Float[ArrayLike, " n"], d: Float[ArrayLike, " 4"]
) -> Float[Array, " p"]:
    r"""Eq. (3.8c): $\Theta^* = [a_1 \dots a_n\ \mu_{11} \dots \mu_{n1} \dots
    \mu_{14} \dots \mu_{n4}]^T$ with $\mu_{ij} = b_i d_j$ (3.7b).

    `a` and `b` are $(a_1..a_n)$ and $(b_1..b_n)$ (no leading 1 or $b_0$); pad the
    shorter one with zeros to the common order $n$.
    """
    a = jnp.asarray(a, dtype=float)
    b = jnp.asarray(b, dtype=float)
    d = jnp.asarray(d, dtype=float)
    if a.ndim != 1 or b.ndim != 1 or a.shape != b.shape:
        raise ValueError(
            f"a and b must be 1-D of the same length n; got {a.shape} and {b.shape}"
        )
    if d.shape != (4,):
        raise ValueError(f"d must have 4 entries d_1..d_4; got shape {d.shape}")
    return jnp.concatenate([a, jnp.outer(b, d).T.reshape(-1)])


def split_theta(
    theta: Float[Array, " p"], order: int
) -> tuple[Float[Array, " n"], Float[Array, "n 4"]]:
    """Split (3.8c)/(4.2a) into $(a_1..a_n)$ and the matrix $M$ of (3.9)/(4.3)."""
    n = int(order)
    if theta.shape[-1] != 5 * n:
        raise ValueError(
            f"theta must have 5n = {5 * n} entries for order n = {n}; "
            f"got {theta.shape[-1]}"
        )
    return theta[:n], theta[n:].reshape(4, n).T


def check_input_in_levels(
    v: Signal, levels: Float[Array, " 4"], *, rtol: float = 1e-9
) -> Signal:
    r"""Check that every $v(t) \in \{0, V_1, \dots, V_4\}$, where $P(v) = F(v)$ (3.2).

    Raises `ValueError` naming the first offending sample when `v` is concrete;
    under `jit` the check is an `eqx.error_if`.
    """
    value, lv = concrete(v), concrete(levels)
    if value is not None and lv is not None:
        allowed = np.r_[0.0, lv]
        distance = np.min(np.abs(value[:, None] - allowed[None, :]), axis=1)
        bad = distance > rtol * np.max(np.abs(lv))
        if bad.any():
            k = int(bad.argmax())
            raise ValueError(
                f"input sample v[{k}] = {float(value[k]):g} is not in {{0, V1..V4}} = "
                f"{{0, {', '.join(f'{x:g}' for x in lv.tolist())}}}; "
                "the reparametrisation (3.6) holds only on these values"
            )
        return v
    allowed = jnp.concatenate([jnp.zeros(1), levels])
    distance = jnp.min(jnp.abs(v[:, None] - allowed[None, :]), axis=1)
    bad = distance > rtol * jnp.max(jnp.abs(levels))
    return eqx.error_if(
        v, jnp.any(bad), "input v has a value outside {0, V1..V4}; (3.6) needs them"
    )


def _lags(x: Signal, order: int) -> Float[Array, "time n"]:
    """Column i is $x(t - 1 - i)$, zero before the start (the plant starts at rest)."""
    padded = jnp.concatenate([jnp.zeros(order, x.dtype), x])
    n_time = x.shape[0]
    return jnp.stack(
        [padded[order - 1 - i : order - 1 - i + n_time] for i in range(order)], axis=1
    )


def regressor(
    v: Signal, y: Signal, *, levels: Float[Array, " 4"], order: int
) -> Float[Array, "time p"]:
    r"""Eq. (3.8b): the rows $\Phi(t)^T = [-y(t-1) \dots -y(t-n)\ v(t-1) P_1(v(t-1))
    \dots v(t-n) P_1(v(t-n)) \dots v(t-n) P_4(v(t-n))]$ for $t = 0..N-1$.

    Samples before $t = 0$ are zero: the experiment starts at rest.

    **Arguments:**

    - `v`, `y`: input and measured output, shape `(time,)`.
    - `levels`: $(V_1..V_4)$, already checked by `check_levels`.
    - `order`: $n \ge 1$ (static).

    **Returns:** $\Phi$, shape `(time, 5n)`, in the order of $\Theta^*$ (3.8c).
    """
    if int(order) != order or order < 1:
        raise ValueError(f"order n must be an integer >= 1; got {order}")
    n = int(order)
    if v.ndim != 1 or y.ndim != 1 or v.shape != y.shape:
        raise ValueError(
            f"v and y must be 1-D of the same length; got {v.shape} and {y.shape}"
        )
    y_lags = _lags(y, n)
    v_lags = _lags(v, n)
    # (time, n, 4) -> (time, 4, n): the mu block is ordered column by column of M.
    g = v_lags[..., None] * lagrange_basis(levels, v_lags)
    g = jnp.swapaxes(g, 1, 2).reshape(v.shape[0], 4 * n)
    return jnp.concatenate([-y_lags, g], axis=1)
