"""Output-error (maximum-likelihood under white Gaussian noise) refinement.

Starts from a closed-form estimate (seed 000's NBBI/FGI, seed 001's least
squares (3.8)) and minimises $\\sum_k (y_k - \\hat w_k(\\theta))^2$ through the
differentiable simulator with a least-squares solver (`fitting.least_squares`:
an optimistix one by default, or the diagnosis's batched Levenberg-Marquardt).
"""

import equinox as eqx
import jax.numpy as jnp
import optimistix as optx
from jaxtyping import Array, ArrayLike, Float, Int

from .._results import RESULTS
from .._types import Params
from ..fitting import least_squares
from ._parametrisation import AbstractParametrisation
from .options import RefinementOptions


class RefinementResult(eqx.Module):
    """Outcome of `refine`.

    - `estimate`: the reported parameters, `parametrisation.to_physical(theta)`.
    - `theta`: the free parameters at the solution.
    - `result`: a `hamjax.RESULTS` code: `successful` only if the solver converged
      to a finite, admissible model; `not_converged` if the step budget ran out or
      the end point is inadmissible (`parametrisation.is_valid`, e.g. an unstable
      linear block); `nonfinite` if the fit diverged.
    - `solver_result`: the solver's own code (optimistix's, or the
      `hamjax.RESULTS` of `fitting.BatchedLevenbergMarquardt`).
    - `steps`: solver steps taken (summed over annealing stages).
    - `rss`: residual sum of squares at the solution; `initial_rss` at the start.
    - `noise_variance`: $\\hat\\sigma^2 = \\text{rss}/(N - p)$.
    """

    estimate: Float[Array, " n_physical"]
    theta: Params
    result: RESULTS
    solver_result: optx.RESULTS | RESULTS
    steps: Int[Array, ""]
    rss: Float[Array, ""]
    initial_rss: Float[Array, ""]
    noise_variance: Float[Array, ""]


def _residuals(theta, args):
    parametrisation, v, y = args
    r = y - parametrisation.predict(theta, v)
    # An unstable trial model may overflow: make it a large finite misfit so the
    # trust region rejects the step instead of the whole fit turning NaN.
    return jnp.where(jnp.isfinite(r), r, 1e150)


def _solve(parametrisation, theta0, v, y, options):
    return least_squares(
        _residuals,
        options.make_solver(),
        theta0,
        (parametrisation, v, y),
        max_steps=options.max_steps,
        throw=False,
    )


def _classify(solver_result, theta, parametrisation, rss) -> RESULTS:
    finite = jnp.all(jnp.isfinite(theta)) & jnp.isfinite(rss) & (rss < 1e200)
    # An inadmissible end point (unstable A or G, d2 > 0 ...) is a fit that did
    # not converge to a model of the class.
    converged = (solver_result == RESULTS.successful) & parametrisation.is_valid(theta)
    result = RESULTS.where(converged, RESULTS.successful, RESULTS.not_converged)
    return RESULTS.where(finite, result, RESULTS.nonfinite)


@eqx.filter_jit
def refine(
    parametrisation: AbstractParametrisation,
    theta0: Float[ArrayLike, " n_params"],
    v: Float[ArrayLike, " time"],
    y: Float[ArrayLike, " time"],
    *,
    options: RefinementOptions | None = None,
    throw: bool = True,
) -> RefinementResult:
    """Output-error fit of `parametrisation` to the record `(v, y)` from `theta0`.

    For parametrisations with a `with_smoothing(width)` method (a map that is not
    differentiable at its breakpoints), the fit is run with each width of
    `options.annealing` in turn, each started from the previous admissible
    solution (`is_valid`), and finally with the exact map; the reported optimum is the exact map's. Where the
    parametrisation has `place_breakpoints(theta, v, y)`, it places the breakpoints
    in their gaps between input values before the exact stage.

    **Arguments:**

    - `parametrisation`: the model structure (e.g. `ImpulseTableParametrisation`).
    - `theta0`: initial free parameters (`parametrisation.from_physical(...)` of a
      closed-form estimate).
    - `v`, `y`: input and measured output, shape `(time,)`.
    - `options`: solver and tolerances (default `RefinementOptions()`).
    - `throw`: raise if the refinement fails; pass `False` under `vmap` and count
      `result != RESULTS.successful` instead.

    **Returns:** a `RefinementResult`.

    **Raises:** `ValueError` for mismatched shapes; an `EquinoxRuntimeError` on
    failure when `throw=True`.
    """
    options = RefinementOptions() if options is None else options
    theta0 = jnp.asarray(theta0, dtype=float)
    v = jnp.asarray(v, dtype=float)
    y = jnp.asarray(y, dtype=float)
    if v.ndim != 1 or v.shape != y.shape:
        raise ValueError(
            f"v and y must be 1-D of the same length; got {v.shape} and {y.shape}"
        )
    if theta0.ndim != 1:
        raise ValueError(f"theta0 must be 1-D; got shape {theta0.shape}")
    if v.shape[0] <= theta0.shape[0]:
        raise ValueError(
            f"record of {v.shape[0]} samples is too short for {theta0.shape[0]} "
            "parameters"
        )
    initial_rss = jnp.sum(_residuals(theta0, (parametrisation, v, y)) ** 2)
    theta, steps = theta0, jnp.array(0)
    stages = []
    if hasattr(parametrisation, "with_smoothing"):
        scale = jnp.max(v) - jnp.min(v)
        stages = [parametrisation.with_smoothing(w * scale) for w in options.annealing]
    for stage in stages:
        sol = _solve(stage, theta, v, y, options)
        # A failed smoothed stage is not fatal: the next one starts from the last
        # admissible point and the exact stage decides. An inadmissible end point
        # (e.g. crossed breakpoints d1 < 0 < d2, which the smoothed map can fit
        # and Fig. 2's cannot) is not a model of the class: it is dropped too.
        keep = jnp.all(jnp.isfinite(sol.value)) & stage.is_valid(sol.value)
        theta = jnp.where(keep, sol.value, theta)
        steps = steps + sol.stats["num_steps"]
    if hasattr(parametrisation, "place_breakpoints"):
        theta = parametrisation.place_breakpoints(theta, v, y)
    sol = _solve(parametrisation, theta, v, y, options)
    theta = sol.value
    steps = steps + sol.stats["num_steps"]
    rss = jnp.sum(_residuals(theta, (parametrisation, v, y)) ** 2)
    result = _classify(sol.result, theta, parametrisation, rss)
    if throw:
        theta = result.error_if(theta, result != RESULTS.successful)
    dof = v.shape[0] - theta.shape[0]
    return RefinementResult(
        estimate=parametrisation.to_physical(theta),
        theta=theta,
        result=result,
        solver_result=sol.stats.get("solver_result", sol.result),
        steps=steps,
        rss=rss,
        initial_rss=initial_rss,
        noise_variance=rss / dof,
    )
