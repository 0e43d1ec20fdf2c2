"""One least-squares interface for both of hamjax's solvers.

`least_squares(fn, solver, theta0, args, ...)` minimises $\\|r(\\theta)\\|^2$ (plus
an optional Gaussian prior) with either an optimistix least-squares solver
(`optx.LevenbergMarquardt`, `optx.GaussNewton`, `optx.BFGS`: what `refine`
uses) or `BatchedLevenbergMarquardt`, and returns a `LeastSquaresSolution` whose
`result` is a `hamjax.RESULTS` code in both cases (failures are values under
`vmap`; `throw=True` raises instead). `fn` is a residual function
`fn(theta, args) -> r` (or `(r, aux)` with `has_aux=True`), which both solvers
accept, or a `NormalEquations`, which only the batched solver accepts: a problem
that accumulates $(r^\\top r, J^\\top J, J^\\top r)$ itself, block by block,
without ever storing $J$ (the diagnosis's `fit.normal_equations`).
"""

from collections.abc import Callable
from typing import Any

import equinox as eqx
import jax
import jax.lax as lax
import jax.numpy as jnp
import optimistix as optx
from jaxtyping import Array, ArrayLike, Bool, Float, Int

from .._linalg import cholesky_solve, fixed_order_sum
from .._results import RESULTS


LAMBDA0 = 1e-3  # initial Levenberg-Marquardt damping
LAMBDA_CONVERGED = 1e-2  # largest damping at which a small decrease is convergence


class NormalEquations(eqx.Module):
    """A least-squares problem given by its normal equations:
    `fn(theta, args) -> ((r^T r, J^T J, J^T r), aux)` at `theta`."""

    fn: Callable = eqx.field(static=True)

    def __call__(self, theta, args):
        return self.fn(theta, args)


def _from_residuals(fn: Callable, has_aux: bool) -> NormalEquations:
    """The normal equations of a residual function (forward-mode Jacobian)."""

    def normal(theta, args):
        out = fn(theta, args)
        r, aux = out if has_aux else (out, None)
        J = jax.jacfwd(lambda t: fn(t, args)[0] if has_aux else fn(t, args))(theta)
        return (r @ r, J.T @ J, J.T @ r), aux

    return NormalEquations(normal)


class GaussianPrior(eqx.Module):
    """A zero-mean Gaussian prior on the entries `mask` of `theta`: the cost gains
    `weight * sum(theta[mask]**2)` (the negative log posterior times the noise
    variance when `weight` = noise variance / prior variance)."""

    weight: Float[ArrayLike, ""]
    mask: Bool[ArrayLike, " P"]


class BatchedLevenbergMarquardt(eqx.Module):
    """Levenberg-Marquardt with Marquardt's diagonal scaling on the normal equations.

    Written for `vmap` over many small problems (the diagnosis fits ~20 candidate
    rows per case, each its own model): under `vmap` over the rows
    `optx.LevenbergMarquardt` cost 17 s per case (and 80 s to compile) against
    ~3 s for this solver, for the same damped Gauss-Newton iteration. What makes
    it cheap: one call site of the problem per iteration (it evaluates the trial
    point, accepts it if the cost fell, then proposes the next trial from the
    accepted point), the step by `_linalg.cholesky_solve` (plain `jax.numpy`
    loops, no LAPACK custom call: those were seen to hang with two devices), and
    a problem that may give its normal equations directly (`NormalEquations`).
    The step budget, `lam0` and `resume` may be traced (a different budget does
    not recompile). The first iteration accepts `theta0` and divides `lam0` by 3;
    with `resume=True` it keeps `lam0`, so a fit stopped at its budget with
    damping `lam` (`stats["damping"]`, that of its pending step) and continued
    from its `value` with `lam0 = lam`, `resume=True` and one step more than it
    has left (the first re-evaluates `value`) takes exactly the steps it would
    have taken without stopping.

    Stops as `successful` when a nearly undamped step (`lam <= lam_converged`)
    lowers the cost by at most `rtol` relative (under heavy damping a step is
    short, so its decrease is small whatever the distance to the minimum: seen
    stopping fits halfway along a valley), when the damping exceeds `lam_max`, or
    when the step is below `atol`; as `not_converged` at its step budget.
    """

    lam0: Float[ArrayLike, ""] = LAMBDA0
    resume: Bool[ArrayLike, ""] = False
    rtol: float = eqx.field(static=True, default=1e-10)
    atol: float = eqx.field(static=True, default=1e-12)
    lam_converged: float = eqx.field(static=True, default=LAMBDA_CONVERGED)
    lam_max: float = eqx.field(static=True, default=1e10)


class LeastSquaresSolution(eqx.Module):
    """Outcome of `least_squares`.

    - `value`: the parameters at the solution; `result`: a `hamjax.RESULTS` code.
    - `aux`: the problem's auxiliary output at `value` (None without).
    - `stats`: `num_steps`; from `BatchedLevenbergMarquardt` also `sse` and `jtj`
      ($r^\\top r$ and $J^\\top J$ at `value`, without the prior) and `damping` (of
      the last proposed step, to continue); from optimistix `solver_result`
      (its own code).
    """

    value: Float[Array, " P"]
    result: RESULTS
    aux: Any
    stats: dict[str, Any]


def _batched_lm(normal, solver, theta0, args, max_steps, prior):
    P = theta0.shape[0]

    def cond(state):
        return (state[-2] < max_steps) & ~state[-1]

    def body(state):
        theta, trial, sse, H, g, aux, cost, lam, k, _ = state
        (sse_n, H_n, g_n), aux_n = normal(trial, args)
        if prior is None:
            cost_n = sse_n
        else:
            w, mask = prior.weight, prior.mask
            cost_n = sse_n + w * fixed_order_sum(jnp.where(mask, trial, 0.0) ** 2)
        better = cost_n < cost
        small = ((cost - cost_n) <= solver.rtol * cost_n) & (
            lam <= solver.lam_converged
        )
        theta, sse, H, g, aux = jax.tree.map(
            lambda a, b: jnp.where(better, a, b),
            (trial, sse_n, H_n, g_n, aux_n),
            (theta, sse, H, g, aux),
        )
        cost_new = jnp.where(better, cost_n, cost)
        keep = (k == 0) & solver.resume  # a resumed fit's pending step as it was
        lam = jnp.where(better, jnp.where(keep, lam, lam / 3), lam * 4)
        if prior is None:
            Hp, gp = H, g
        else:
            Hp = H + w * jnp.diag(mask.astype(theta.dtype))
            gp = g + w * jnp.where(mask, theta, 0.0)
        d = jnp.diag(Hp) + 1e-12
        step = -cholesky_solve(Hp + lam * jnp.diag(d), gp)
        done = (
            (better & small)
            | (lam > solver.lam_max)
            | (jnp.max(jnp.abs(step)) < solver.atol)
        )
        return theta, theta + step, sse, H, g, aux, cost_new, lam, k + 1, done

    shapes = jax.eval_shape(normal, theta0, args)[1]
    state = (
        theta0,
        theta0,
        jnp.zeros((), theta0.dtype),
        jnp.zeros((P, P), theta0.dtype),
        jnp.zeros(P, theta0.dtype),
        jax.tree.map(lambda s: jnp.zeros(s.shape, s.dtype), shapes),
        jnp.asarray(jnp.inf),
        jnp.asarray(solver.lam0, dtype=theta0.dtype),
        jnp.asarray(0, dtype=jnp.int32),
        jnp.asarray(False),
    )
    theta, _, sse, H, _, aux, _, lam, k, done = lax.while_loop(cond, body, state)
    result = RESULTS.where(done, RESULTS.successful, RESULTS.not_converged)
    stats = {"num_steps": k, "sse": sse, "jtj": H, "damping": lam}
    return theta, result, aux, stats


def _optimistix(fn, solver, theta0, args, max_steps, has_aux, prior):
    if isinstance(fn, NormalEquations):
        raise TypeError(
            "an optimistix solver needs a residual function, not NormalEquations "
            "(use BatchedLevenbergMarquardt)"
        )
    if prior is not None:  # the prior as extra residuals sqrt(w) theta[mask]

        def fn(theta, args, _fn=fn):
            out = _fn(theta, args)
            r, aux = out if has_aux else (out, None)
            extra = jnp.sqrt(prior.weight) * jnp.where(prior.mask, theta, 0.0)
            r = jnp.concatenate([r, extra])
            return (r, aux) if has_aux else r

    sol = optx.least_squares(
        fn,
        solver,
        theta0,
        args=args,
        has_aux=has_aux,
        max_steps=max_steps,
        throw=False,
    )
    ok = sol.result == optx.RESULTS.successful
    result = RESULTS.where(ok, RESULTS.successful, RESULTS.not_converged)
    stats = {"num_steps": sol.stats["num_steps"], "solver_result": sol.result}
    return sol.value, result, sol.aux, stats


def least_squares(
    fn: Callable | NormalEquations,
    solver: BatchedLevenbergMarquardt | optx.AbstractLeastSquaresSolver,
    theta0: Float[ArrayLike, " P"],
    args: Any = None,
    *,
    max_steps: int | Int[ArrayLike, ""] = 256,
    has_aux: bool = False,
    prior: GaussianPrior | None = None,
    throw: bool = True,
) -> LeastSquaresSolution:
    """Minimise $\\|r(\\theta)\\|^2$ (+ the `prior`'s term) from `theta0`.

    `fn`: residuals `fn(theta, args)` (`(r, aux)` with `has_aux`), or a
    `NormalEquations` (`BatchedLevenbergMarquardt` only). `solver`: either kind;
    `max_steps` must be a Python int for an optimistix solver and may be traced
    for the batched one. A non-finite value is `RESULTS.nonfinite`. `throw`:
    raise on failure (pass False under `vmap` and read `result`).
    """
    theta0 = jnp.asarray(theta0)
    if isinstance(solver, BatchedLevenbergMarquardt):
        normal = fn if isinstance(fn, NormalEquations) else _from_residuals(fn, has_aux)
        value, result, aux, stats = _batched_lm(
            normal, solver, theta0, args, max_steps, prior
        )
    else:
        value, result, aux, stats = _optimistix(
            fn, solver, theta0, args, max_steps, has_aux, prior
        )
    finite = jnp.all(jnp.isfinite(value))
    result = RESULTS.where(finite, result, RESULTS.nonfinite)
    if throw:
        value = result.error_if(value, result != RESULTS.successful)
    return LeastSquaresSolution(value=value, result=result, aux=aux, stats=stats)
