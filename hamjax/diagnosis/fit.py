"""Least-squares fit of every candidate row on the estimation record (Levenberg-Marquardt),
batched over rows and cases so that one compilation serves a whole call."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jax.sharding import Mesh, PartitionSpec
from jaxtyping import Array, Float, Int

from .._linalg import cholesky_solve
from .augmented import CaseArrays, Row, full_parameters, simulate_row


class RowFit(eqx.Module):
    """Fitted rows of one or more cases (leading axes: `[case,] row`)."""

    theta: Float[Array, "... P"]
    params: Float[Array, "... S"]  # physical full parameter vector
    sse_est: Float[Array, "..."]
    y_est: Float[Array, "... L"]
    y_val: Float[Array, "... L"]
    result: Int[Array, "..."]  # 0 converged, 1 stopped at max_steps
    theta_std: Float[Array, "... P"]  # Gauss-Newton standard errors of theta


def _residuals(theta, args):
    row, case = args
    y = simulate_row(theta, row, case.v_est, case)
    r = (y - case.y_est) * case.m_est / case.y_scale
    # A diverging trial step must not poison the Jacobian: a large finite value
    # makes Levenberg-Marquardt reject the step instead.
    return jnp.where(jnp.isfinite(r), r, 1e3)


def _value_and_jacobian(theta, args):
    r, J = jax.vmap(
        lambda t: jax.jvp(lambda th: _residuals(th, args), (theta,), (t,)),
        out_axes=(None, 1),
    )(jnp.eye(theta.shape[0], dtype=theta.dtype))
    return r, J


def levenberg_marquardt(theta0, args, max_steps: int):
    """Levenberg-Marquardt with Marquardt's diagonal scaling, forward-mode Jacobian.

    Hand-rolled rather than `optx.LevenbergMarquardt`: under `vmap` over ~20
    candidate rows the optimistix solver cost 17 s per case (and 80 s to
    compile) against ~3 s here, for the same damped Gauss-Newton iteration. One
    call site of the Jacobian keeps the compilation small: each iteration
    evaluates the trial point, accepts it if the cost fell, then proposes the
    next trial from the accepted point. Returns `(theta, r, J, converged)`.
    """
    P = theta0.shape[0]
    n = args[1].v_est.shape[0]
    max_steps = jnp.asarray(max_steps)

    def cond(state):
        return (state[-2] < max_steps) & ~state[-1]

    def body(state):
        theta, trial, r, J, cost, lam, k, _ = state
        r_n, J_n = _value_and_jacobian(trial, args)
        cost_n = jnp.sum(r_n**2)
        better = cost_n < cost
        small = (cost - cost_n) <= 1e-10 * cost_n
        theta, r, J = jax.tree.map(
            lambda a, b: jnp.where(better, a, b), (trial, r_n, J_n), (theta, r, J)
        )
        cost_new = jnp.where(better, cost_n, cost)
        lam = jnp.where(better, lam / 3, lam * 4)
        H = J.T @ J
        d = jnp.diag(H) + 1e-12
        step = -cholesky_solve(H + lam * jnp.diag(d), J.T @ r)
        done = (better & small) | (lam > 1e10) | (jnp.max(jnp.abs(step)) < 1e-12)
        return theta, theta + step, r, J, cost_new, lam, k + 1, done

    state = (
        theta0,
        theta0,
        jnp.zeros(n),
        jnp.zeros((n, P)),
        jnp.asarray(jnp.inf),
        jnp.asarray(1e-3),
        0,
        jnp.asarray(False),
    )
    theta, _, r, J, _, _, _, done = jax.lax.while_loop(cond, body, state)
    return theta, r, J, done


def fit_row(row: Row, case: CaseArrays, max_steps=30) -> RowFit:
    """Fit one row from `row.theta0` (the nominal slots start at nominal)."""
    theta, r, J, done = levenberg_marquardt(row.theta0, (row, case), max_steps)
    sse = jnp.sum(r**2) * case.y_scale**2
    n = jnp.sum(case.m_est)
    used = row.idx < case.anchor.shape[0]
    dof = jnp.maximum(n - jnp.sum(used), 1.0)
    JtJ = J.T @ J
    JtJ = JtJ + jnp.diag(jnp.where(used, 1e-12 * (1.0 + jnp.diag(JtJ)), 1.0))
    cov = cholesky_solve(JtJ, jnp.eye(JtJ.shape[0])) * (jnp.sum(r**2) / dof)
    var = jnp.diag(cov)
    # an unidentifiable direction (a pivot lost to rounding) gets an infinite std
    theta_std = jnp.where(used, jnp.where(var >= 0, jnp.sqrt(var), jnp.inf), 0.0)
    params = full_parameters(theta, row, case)
    y_est = case.y_est + r * case.y_scale
    y_val = simulate_row(theta, row, case.v_val, case)
    bad = ~jnp.isfinite(sse)
    return RowFit(
        theta=theta,
        params=params,
        sse_est=jnp.where(bad, jnp.inf, sse),
        y_est=y_est,
        y_val=y_val,
        result=jnp.where(done, 0, 1),
        theta_std=theta_std,
    )


@eqx.filter_jit
def fit_rows(rows: Row, case: CaseArrays, max_steps=30) -> RowFit:
    """All rows (stacked along axis 0) of one case."""
    return jax.vmap(lambda r: fit_row(r, case, max_steps))(rows)


def _fit_grid(rows: Row, cases: CaseArrays, max_steps) -> RowFit:
    return jax.vmap(lambda rs, c: jax.vmap(lambda r: fit_row(r, c, max_steps))(rs))(
        rows, cases
    )


@eqx.filter_jit
def _fit_grid_jit(rows, cases, max_steps):
    return _fit_grid(rows, cases, max_steps)


@eqx.filter_jit
def _fit_grid_sharded(rows, cases, max_steps, axis: int):
    devices = np.asarray(jax.devices())
    mesh = Mesh(devices, ("d",))
    spec_rows = PartitionSpec("d") if axis == 0 else PartitionSpec(None, "d")
    spec_cases = PartitionSpec("d") if axis == 0 else PartitionSpec()
    # `check_vma=False`: the per-device bodies are independent (no collectives);
    # each device runs its own Levenberg-Marquardt loop to its own convergence.
    fn = jax.shard_map(
        lambda r, c, m: _fit_grid(r, c, m),
        mesh=mesh,
        in_specs=(spec_rows, spec_cases, PartitionSpec()),
        out_specs=spec_rows,
        check_vma=False,
    )
    return fn(rows, cases, max_steps)


def fit_cases(rows: Row, cases: CaseArrays, max_steps: int = 30) -> RowFit:
    """All rows of several cases (both stacked along axis 0: `[case, row]`, `[case]`).

    With several devices (e.g. `XLA_FLAGS=--xla_force_host_platform_device_count=2`
    on a 2-core CPU, as `hamjax diagnose` sets) the cases, or failing that the rows,
    are split over them; the split changes only rounding.
    `max_steps` is traced, so changing it does not recompile.
    """
    steps = jnp.asarray(max_steps, dtype=jnp.int32)
    n_dev = jax.device_count()
    n_cases, n_rows = rows.theta0.shape[:2]
    if n_dev > 1 and n_cases % n_dev == 0:
        return _fit_grid_sharded(rows, cases, steps, 0)
    if n_dev > 1 and n_rows % n_dev == 0:
        return _fit_grid_sharded(rows, cases, steps, 1)
    return _fit_grid_jit(rows, cases, steps)
