"""From $\\hat\\Theta$ back to $(a, b)$ and the nonlinearity: (3.9)-(3.18), (4.2)-(4.10).

Giri, Rochdi, Chaoui, Sections III.B and IV.B. The four points $(V_j, F(V_j))$
cannot tell a dead zone from a preload, so the rule of (3.18a), (3.18b) or
(3.18c) is chosen by the caller, who knows the structure.
"""

import equinox as eqx
import jax.numpy as jnp
from jaxtyping import Array, Bool, Float

from .rank_one_prop3_1 import rank_one_decomposition
from .reparametrisation_3_2_to_3_8 import split_theta


STRUCTURES = ("dead-zone", "preload", "symmetric")


class RecursivePLEstimate(eqx.Module):
    """Plant parameters recovered from one $\\hat\\Theta$, in the normalisation (3.10).

    `b` has $\\sum_i b_i^2 = 1$ and its first largest-magnitude entry positive;
    `d`, `points`, `k1, k2, h1, h2` and `l1, l2` carry the matching scale (the
    dead zones `d1, d2` are scale-free). `d1, d2, l1, l2` are NaN when no
    structure is named, and `consistent` says whether the named structure fits.
    """

    a: Float[Array, " n"]
    b: Float[Array, " n"]
    d: Float[Array, " 4"]
    points: Float[Array, " 4"]
    k1: Float[Array, ""]
    k2: Float[Array, ""]
    h1: Float[Array, ""]
    h2: Float[Array, ""]
    d1: Float[Array, ""]
    d2: Float[Array, ""]
    l1: Float[Array, ""]
    l2: Float[Array, ""]
    consistent: Bool[Array, ""]
    singular_values: Float[Array, " k"]


def points_from_d(
    levels: Float[Array, " 4"], d: Float[Array, " 4"]
) -> Float[Array, " 4"]:
    """Eq. (3.14)/(4.7): $F(V_j) = d_j V_j$."""
    return d * levels


def slopes_and_offsets(
    levels: Float[Array, " 4"], points: Float[Array, " 4"]
) -> tuple[Float[Array, ""], Float[Array, ""], Float[Array, ""], Float[Array, ""]]:
    """Eqs. (3.16)-(3.17): $(K_1, K_2, H_1, H_2)$ of the two lines (3.15)."""
    v1, v2, v3, v4 = levels
    f1, f2, f3, f4 = points
    k1 = (f3 - f4) / (v3 - v4)  # Eq. (3.16)
    k2 = (f1 - f2) / (v1 - v2)
    h1 = (v3 * f4 - v4 * f3) / (v3 - v4)  # Eq. (3.17)
    h2 = (v1 * f2 - v2 * f1) / (v1 - v2)
    return k1, k2, h1, h2


def dead_zone_rule(k1, k2, h1, h2):
    """Eq. (3.18a), $L_1 = L_2 = 0$: $D_i = -H_i / K_i$. Returns `(d1, d2, l1, l2)`."""
    zero = jnp.zeros_like(h1)
    return -h1 / k1, -h2 / k2, zero, zero


def preload_rule(k1, k2, h1, h2):
    """Eq. (3.18b), $D_1 = D_2 = 0$: $L_i = H_i$. Returns `(d1, d2, l1, l2)`."""
    zero = jnp.zeros_like(h1)
    return zero, zero, h1, h2


def symmetric_rule(k1, k2, h1, h2):
    """Eq. (3.18c), $D_1 = -D_2 = D$, $L_1 = -L_2 = L$, $K_1 \\ne K_2$:
    $D = (H_1 + H_2)/(K_2 - K_1)$, $L = K_1 D + H_1$. Returns `(d1, d2, l1, l2)`."""
    dz = (h1 + h2) / (k2 - k1)
    load = k1 * dz + h1
    return dz, -dz, load, -load


_RULES = {
    "dead-zone": dead_zone_rule,
    "preload": preload_rule,
    "symmetric": symmetric_rule,
}


def structure_consistent(
    structure: str,
    levels: Float[Array, " 4"],
    k1,
    k2,
    h1,
    h2,
    d1,
    d2,
    l1,
    l2,
    *,
    rtol: float = 1e-6,
) -> Bool[Array, ""]:
    r"""Whether the recovered $(D_i, L_i)$ fit the named structure of Fig. 2.

    Common to all: both slopes have the same sign (the normalisation (3.10) may
    flip both), $D_2 \le 0 \le D_1$ and the break points lie inside
    $(V_2, V_3)$ so that the interpolation points sit on the two lines (3.1);
    the jumps $L_i$ point away from zero ($L_1 \operatorname{sign} K_1 \ge 0 \ge
    L_2 \operatorname{sign} K_2$). The symmetric rule also needs $K_1 \ne K_2$.
    Tolerances are `rtol` times the scale of the levels or of the values.
    """
    v_scale = jnp.max(jnp.abs(levels))
    f_scale = jnp.maximum(jnp.max(jnp.abs(jnp.stack([k1, k2]))) * v_scale, 1e-300)
    tol_v = rtol * v_scale
    tol_f = rtol * f_scale
    s1, s2 = jnp.sign(k1), jnp.sign(k2)
    ok = (k1 * k2 > 0) & jnp.isfinite(jnp.stack([d1, d2, l1, l2])).all()
    ok &= (d1 >= -tol_v) & (d2 <= tol_v) & (d1 < levels[2]) & (d2 > levels[1])
    ok &= (l1 * s1 >= -tol_f) & (l2 * s2 <= tol_f)
    if structure == "symmetric":
        ok &= jnp.abs(k2 - k1) > rtol * jnp.maximum(jnp.abs(k1), jnp.abs(k2))
    return ok


def recover_parameters(
    theta: Float[Array, " p"],
    *,
    levels: Float[Array, " 4"],
    order: int,
    structure: str | None = None,
    rtol: float = 1e-6,
) -> RecursivePLEstimate:
    r"""All plant parameters from one estimate $\hat\Theta$ (4.2a)-(4.10), (3.18).

    **Arguments:**

    - `theta`: $\hat\Theta$ in the order of (3.8c), shape `(5n,)`.
    - `levels`: $(V_1..V_4)$.
    - `order`: $n$.
    - `structure`: `"dead-zone"` (3.18a), `"preload"` (3.18b), `"symmetric"`
      (3.18c) or `None` (then `d1, d2, l1, l2` are NaN).
    - `rtol`: relative tolerance of the consistency check.

    **Returns:** a `RecursivePLEstimate`. Vectorise over a history with `jax.vmap`.
    """
    if structure is not None and structure not in _RULES:
        raise ValueError(
            f"structure must be one of {', '.join(STRUCTURES)} or None; got {structure!r}"
        )
    a, m = split_theta(theta, order)  # Eq. (4.2a)-(4.3)
    b, d, sigma = rank_one_decomposition(m)  # Eq. (4.5a-c)
    points = points_from_d(levels, d)  # Eq. (4.7)
    k1, k2, h1, h2 = slopes_and_offsets(levels, points)  # Eqs. (4.9)-(4.10)
    if structure is None:
        nan = jnp.full_like(k1, jnp.nan)
        d1 = d2 = l1 = l2 = nan
        consistent = jnp.array(True)
    else:
        d1, d2, l1, l2 = _RULES[structure](k1, k2, h1, h2)  # Eq. (3.18)
        consistent = structure_consistent(
            structure, levels, k1, k2, h1, h2, d1, d2, l1, l2, rtol=rtol
        )
    return RecursivePLEstimate(
        a=a,
        b=b,
        d=d,
        points=points,
        k1=k1,
        k2=k2,
        h1=h1,
        h2=h2,
        d1=d1,
        d2=d2,
        l1=l1,
        l2=l2,
        consistent=consistent,
        singular_values=sigma,
    )
