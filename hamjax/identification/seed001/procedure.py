"""Recursive identification of a Hammerstein plant with a two-segment
piecewise-linear nonlinearity with preload and dead zone.

Giri, Rochdi, Chaoui, *Recursive identification of systems with hard input
nonlinearities of known structure*: regression (3.8), normalised gradient with
projection (4.1), rank-1 SVD (4.5) and recovery of $F$ (4.7)-(4.10), (3.18).
"""

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

from ..._results import RESULTS
from .batch_ls_3_8a import batch_least_squares
from .excitation_prop5_1 import excitation_level
from .levels_3_1 import check_levels
from .normalised_gradient_4_1 import normalised_gradient
from .recovery_3_9_to_3_18 import STRUCTURES, RecursivePLEstimate, recover_parameters
from .reparametrisation_3_2_to_3_8 import check_input_in_levels, regressor


ESTIMATORS = ("gradient", "batch")

# Below this relative smallest eigenvalue the regressors span less than all of
# Theta*: round-off in float64 sits near 1e-16, a PE sequence (5.1) well above 1e-6.
_EXCITATION_FLOOR = 1e-12


class RecursivePLResult(eqx.Module):
    """Outcome of `identify_recursive_pl`.

    - `estimate`: the recovered parameters (`RecursivePLEstimate`) from `theta`.
    - `theta`: the final $\\hat\\Theta$, order of (3.8c).
    - `history`: every $\\hat\\Theta(t)$, shape `(time, 5n)` (gradient only, else
      `None`); recover parameters along it with `recover_history`.
    - `levels`, `order`, `structure`: the settings used.
    - `result`: a `RESULTS` code (`inconsistent_structure` when the named
      structure does not fit the estimates).
    - `stats`: `excitation` (relative smallest eigenvalue of the information
      matrix) and `residual_rms` (of $y - \\Phi \\hat\\Theta$).
    """

    estimate: RecursivePLEstimate
    theta: Float[Array, " p"]
    history: Float[Array, "time p"] | None
    levels: Float[Array, " 4"]
    order: int = eqx.field(static=True)
    structure: str | None = eqx.field(static=True)
    result: RESULTS
    stats: dict[str, Array]


def identify_recursive_pl(
    v: Float[ArrayLike, " time"],
    y: Float[ArrayLike, " time"],
    *,
    levels: Float[ArrayLike, " 4"],
    order: int,
    structure: str | None = None,
    rho: float = 1e6,
    theta0: Float[ArrayLike, " p"] | None = None,
    estimator: str = "gradient",
    d_max: float | None = None,
    keep_history: bool = True,
    rtol: float = 1e-6,
    throw: bool = True,
) -> RecursivePLResult:
    r"""Identify $A$, $B$ and the piecewise-linear $F$ of seed 001 from $(v, y)$.

    **Arguments:**

    - `v`: plant input, shape `(time,)`, with values in $\{0, V_1..V_4\}$ (e.g.
      `hamjax.pe_impulse_sequence`, (5.1)); the plant starts at rest at $t = 0$.
    - `y`: measured output, shape `(time,)`.
    - `levels`: $(V_1..V_4)$ satisfying (3.1).
    - `order`: the known bound $n$ of assumption A1 (static).
    - `structure`: `"dead-zone"`, `"preload"`, `"symmetric"` or `None`: which rule
      of (3.18) gives $(D_i, L_i)$.
    - `rho`: projection radius $\rho^* \ge \|\Theta^*\|$ of (4.1a).
    - `theta0`: initial estimate $\hat\theta(0)$ (default zero).
    - `estimator`: `"gradient"` (4.1) or `"batch"` (least squares on (3.8)).
    - `d_max`: $D_M$ of A4, to check (3.1) fully (optional).
    - `keep_history`: keep every $\hat\Theta(t)$ (memory `time * 5n`).
    - `rtol`: relative tolerance of the structure check.
    - `throw`: raise if the result is not `RESULTS.successful`; with `False` the
      code is returned (for `vmap`).

    **Returns:** a `RecursivePLResult`.

    **Raises:** `ValueError` for levels violating (3.1), a bad order, structure
    or estimator, mismatched or too-short data, or an input outside
    $\{0, V_1..V_4\}$.
    """
    levels = check_levels(levels, d_max=d_max)
    if int(order) != order or order < 1:
        raise ValueError(f"order n must be an integer >= 1; got {order}")
    n = int(order)
    if structure is not None and structure not in STRUCTURES:
        raise ValueError(
            f"structure must be one of {', '.join(STRUCTURES)} or None; got {structure!r}"
        )
    if estimator not in ESTIMATORS:
        raise ValueError(f"estimator must be one of {ESTIMATORS}; got {estimator!r}")
    if not rho > 0:
        raise ValueError(f"projection radius rho* must be > 0; got {rho}")
    v = jnp.asarray(v, dtype=float)
    y = jnp.asarray(y, dtype=float)
    if v.ndim != 1 or v.shape != y.shape:
        raise ValueError(
            f"v and y must be 1-D of equal length; got {v.shape}, {y.shape}"
        )
    if v.shape[0] < 7 * n:
        raise ValueError(
            f"the data hold {v.shape[0]} samples, fewer than one period T = 7n = "
            f"{7 * n} of (5.1) for order n = {n}: too short to identify 5n = "
            f"{5 * n} parameters"
        )
    v = check_input_in_levels(v, levels)
    p = 5 * n
    theta0 = jnp.zeros(p) if theta0 is None else jnp.asarray(theta0, dtype=float)
    if theta0.shape != (p,):
        raise ValueError(f"theta0 must have 5n = {p} entries; got shape {theta0.shape}")
    theta, history, estimate, result, stats = _identify(
        v,
        y,
        theta0,
        levels,
        jnp.asarray(rho, dtype=float),
        n,
        structure,
        estimator,
        keep_history,
        rtol,
    )
    if throw:
        theta = result.error_if(theta, result != RESULTS.successful)
    return RecursivePLResult(
        estimate=estimate,
        theta=theta,
        history=history,
        levels=levels,
        order=n,
        structure=structure,
        result=result,
        stats=stats,
    )


@eqx.filter_jit
def _identify(v, y, theta0, levels, rho, n, structure, estimator, keep_history, rtol):
    """The traced part of `identify_recursive_pl` (arguments already checked)."""
    phi = regressor(v, y, levels=levels, order=n)  # Eq. (3.8b)
    if estimator == "gradient":
        theta, history = normalised_gradient(phi, y, theta0=theta0, rho=rho)
        if not keep_history:
            history = None
    else:
        theta, history = batch_least_squares(phi, y), None
    estimate = recover_parameters(
        theta, levels=levels, order=n, structure=structure, rtol=rtol
    )
    excitation = excitation_level(phi)
    residual_rms = jnp.sqrt(jnp.mean((y - phi @ theta) ** 2))
    finite = jnp.all(jnp.isfinite(theta)) & jnp.all(jnp.isfinite(estimate.points))
    # A constant output (to rounding) holds no response: every Theta with B = 0
    # and A(1) y = y explains it. A gradient estimate on the ball of (4.1a) is
    # held there by the projection: Theta* lies outside, the fixed point is not it.
    spread = jnp.max(y) - jnp.min(y)
    constant = spread <= 64 * jnp.finfo(y.dtype).eps * jnp.max(jnp.abs(y))
    on_ball = (estimator == "gradient") & (jnp.linalg.norm(theta) >= rho * (1 - 1e-9))
    cases = (
        (excitation <= _EXCITATION_FLOOR, RESULTS.not_exciting),
        (constant, RESULTS.degenerate),
        (~finite, RESULTS.nonfinite),
        (on_ball, RESULTS.constrained),
        (~estimate.consistent, RESULTS.inconsistent_structure),
    )
    result = RESULTS.successful
    for failed, code in reversed(cases):  # the first failing check wins
        result = RESULTS.where(failed, code, result)
    stats = {"excitation": excitation, "residual_rms": residual_rms}
    return theta, history, estimate, result, stats


def recover_history(
    result: RecursivePLResult, *, every: int = 1
) -> RecursivePLEstimate:
    """Parameters recovered from every `every`-th $\\hat\\Theta(t)$ of the history
    (the Fig. 3b curves); fields gain a leading time axis."""
    if result.history is None:
        raise ValueError("this result has no history (gradient with keep_history=True)")
    history = result.history[every - 1 :: every]
    return eqx.filter_jit(jax.vmap)(
        lambda th: recover_parameters(
            th, levels=result.levels, order=result.order, structure=result.structure
        )
    )(history)
