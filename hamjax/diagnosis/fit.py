"""Least-squares fit of candidate rows on the estimation record (Levenberg-Marquardt),
batched over a flat list of rows (each with its own case) so that one compilation
serves every batch of a call; `schedule.py` decides which rows go into a batch."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jax.sharding import Mesh, PartitionSpec
from jaxtyping import Array, Bool, Float, Int

from .._linalg import cholesky_solve
from .augmented import (
    EFFECT_SLOTS,
    NOMINAL_SLOTS,
    CaseArrays,
    Row,
    full_parameters,
    simulate_row,
    uses_memory,
)


LAMBDA0 = 1e-3  # initial Levenberg-Marquardt damping
PRIOR = 1e-6  # weight of the prior at nominal on the scaled re-fit parameters
LAMBDA_CONVERGED = 1e-2  # largest damping at which a small decrease is convergence


class RowFit(eqx.Module):
    """Fitted rows (leading axis: row)."""

    theta: Float[Array, "... P"]
    params: Float[Array, "... S"]  # physical full parameter vector
    sse_est: Float[Array, "..."]
    y_val: Float[Array, "... L"]
    result: Int[Array, "..."]  # 0 converged, 1 stopped at its step budget
    steps: Int[Array, "..."]  # Levenberg-Marquardt iterations taken
    lam: Float[Array, "..."]  # damping of the last proposed step (to continue)
    jtj: Float[Array, "... P P"]  # Gauss-Newton information J^T J (scaled output)
    s2: Float[Array, "..."]  # residual variance (scaled output), SSE / dof


def nominal_mask(row: Row, case: CaseArrays) -> Bool[Array, " P"]:
    """Which entries of `theta` move the nominal model's own parameters."""
    first_den = len(NOMINAL_SLOTS) + len(EFFECT_SLOTS)
    return (row.idx < len(NOMINAL_SLOTS)) | (
        (row.idx >= first_den) & (row.idx < case.anchor.shape[0])
    )


def _residuals(theta, args):
    row, case, memory = args
    y = simulate_row(theta, row, case.v_est, case, memory)
    r = (y - case.y_est) * case.m_est / case.y_scale
    # A diverging trial step must not poison the Jacobian: a large finite value
    # makes Levenberg-Marquardt reject the step instead.
    r = jnp.where(jnp.isfinite(r), r, 1e3)
    # A weak prior at the nominal parameters (a fit of `theta` with prior std
    # ~ 1/sqrt(PRIOR) per unit of scaled output noise): where the estimation record
    # leaves a direction of the re-fit undetermined (the gain against the slopes of
    # a piecewise-linear map, an unexcited segment), every start then ends at the
    # same point instead of wherever its path stopped.
    prior = jnp.sqrt(PRIOR) * jnp.where(nominal_mask(row, case), theta, 0.0)
    return jnp.concatenate([r, prior])


def _value_and_jacobian(theta, args):
    r, J = jax.vmap(
        lambda t: jax.jvp(lambda th: _residuals(th, args), (theta,), (t,)),
        out_axes=(None, 1),
    )(jnp.eye(theta.shape[0], dtype=theta.dtype))
    return r, J


def levenberg_marquardt(theta0, lam0, args, max_steps):
    """Levenberg-Marquardt with Marquardt's diagonal scaling, forward-mode Jacobian.

    Hand-rolled rather than `optx.LevenbergMarquardt`: under `vmap` over ~20
    candidate rows the optimistix solver cost 17 s per case (and 80 s to
    compile) against ~3 s here, for the same damped Gauss-Newton iteration. One
    call site of the Jacobian keeps the compilation small: each iteration
    evaluates the trial point, accepts it if the cost fell, then proposes the
    next trial from the accepted point. The first iteration accepts `theta0` and
    divides `lam0` by 3, so a fit stopped with damping `lam` continues seamlessly
    from `lam0 = 3 lam`. Returns `(theta, r, J, converged, lam, steps)`.
    """
    P = theta0.shape[0]
    n = args[1].v_est.shape[0] + P  # record and prior residuals

    def cond(state):
        return (state[-2] < max_steps) & ~state[-1]

    def body(state):
        theta, trial, r, J, cost, lam, k, _ = state
        r_n, J_n = _value_and_jacobian(trial, args)
        cost_n = jnp.sum(r_n**2)
        better = cost_n < cost
        # A small decrease counts as convergence only for a nearly undamped step:
        # under heavy damping the step is short, so the decrease is small whatever
        # the distance to the minimum (seen stopping fits halfway along a valley).
        small = ((cost - cost_n) <= 1e-10 * cost_n) & (lam <= LAMBDA_CONVERGED)
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
        jnp.asarray(lam0, dtype=theta0.dtype),
        jnp.asarray(0, dtype=jnp.int32),
        jnp.asarray(False),
    )
    theta, _, r, J, _, lam, k, done = jax.lax.while_loop(cond, body, state)
    return theta, r, J, done, lam, k


def fit_row(
    row: Row,
    case: CaseArrays,
    max_steps=30,
    lam0: float | Array = LAMBDA0,
    memory: bool | Bool[Array, ""] = True,
) -> RowFit:
    """Fit one row from `row.theta0` (the nominal slots start at nominal).
    `memory`: as in `simulate_augmented` (False only if the row frees neither
    the rate limit nor the backlash)."""
    theta, r, J, done, lam, k = levenberg_marquardt(
        row.theta0, lam0, (row, case, memory), max_steps
    )
    L = case.v_est.shape[0]
    r, J = r[:L], J[:L]  # the record's part (the prior's is not data)
    sse = jnp.sum(r**2) * case.y_scale**2
    n = jnp.sum(case.m_est)
    used = row.idx < case.anchor.shape[0]
    dof = jnp.maximum(n - jnp.sum(used), 1.0)
    y_val = simulate_row(theta, row, case.v_val, case, memory)
    bad = ~jnp.isfinite(sse)
    return RowFit(
        theta=theta,
        params=full_parameters(theta, row, case),
        sse_est=jnp.where(bad, jnp.inf, sse),
        y_val=y_val,
        result=jnp.where(done, 0, 1),
        steps=k,
        lam=lam,
        jtj=J.T @ J,
        s2=jnp.sum(r**2) / dof,
    )


def theta_std(
    jtj: Float[np.ndarray, "P P"], s2: float, used: np.ndarray
) -> Float[np.ndarray, " P"]:
    """Gauss-Newton standard errors of `theta` (NumPy, on the host): the square
    roots of the diagonal of $s^2 (J^T J)^{-1}$ over the used slots. An
    unidentifiable direction (a singular or indefinite information matrix, a pivot
    lost to rounding) gets an infinite std; unused slots get 0."""
    jtj = np.asarray(jtj, dtype=float)
    used = np.asarray(used, dtype=bool)
    reg = np.where(used, 1e-12 * (1.0 + np.diag(jtj)), 1.0)
    try:
        factor = np.linalg.cholesky(jtj + np.diag(reg))
        inv = np.linalg.inv(factor)
        var = np.sum(inv**2, axis=0) * s2
    except np.linalg.LinAlgError:
        var = np.full(jtj.shape[0], np.nan)
    std = np.where(var >= 0, np.sqrt(np.abs(var)), np.inf)
    return np.where(used, std, 0.0)


@eqx.filter_jit
def fit_rows(rows: Row, case: CaseArrays, max_steps=30) -> RowFit:
    """All rows (stacked along axis 0) of one case."""
    return jax.vmap(lambda r: fit_row(r, case, max_steps))(rows)


def _fit_flat(rows: Row, cases: CaseArrays, max_steps, lam0) -> RowFit:
    # One flag for the whole (per-device) batch, not mapped over: a batch in which
    # no row frees the rate limit or the backlash skips the input-memory scan
    # (measured -8 % per screening batch); `schedule` queues those rows together.
    memory = jnp.any(uses_memory(rows.free))
    fit = lambda r, c, k, lam: fit_row(r, c, k, lam, memory)  # noqa: E731
    return jax.vmap(fit)(rows, cases, max_steps, lam0)


@eqx.filter_jit
def _fit_flat_jit(rows, cases, max_steps, lam0):
    return _fit_flat(rows, cases, max_steps, lam0)


@eqx.filter_jit
def _fit_flat_sharded(rows, cases, max_steps, lam0):
    mesh = Mesh(np.asarray(jax.devices()), ("d",))
    spec = PartitionSpec("d")
    # `check_vma=False`: the per-device bodies are independent (no collectives);
    # each device runs its own Levenberg-Marquardt loop to its own convergence.
    fn = jax.shard_map(
        _fit_flat,
        mesh=mesh,
        in_specs=(spec, spec, spec, spec),
        out_specs=spec,
        check_vma=False,
    )
    return fn(rows, cases, max_steps, lam0)


def fit_batch(
    rows: Row,
    cases: CaseArrays,
    max_steps: Int[np.ndarray, " N"],
    lam0: Float[np.ndarray, " N"],
) -> RowFit:
    """Fit `N` rows, row `i` on case `i` (both stacked along axis 0), each with its
    own step budget and initial damping.

    With several devices (e.g. `XLA_FLAGS=--xla_force_host_platform_device_count=2`
    on a 2-core CPU, as `hamjax diagnose` sets) and `N` a multiple of their number,
    the rows are split over them; the split changes only rounding. Budgets and
    dampings are traced, so changing them does not recompile; the cost of a batch is
    that of its longest-running row.
    """
    steps = jnp.asarray(max_steps, dtype=jnp.int32)
    lam0 = jnp.asarray(lam0, dtype=float)
    n_dev = jax.device_count()
    if n_dev > 1 and rows.theta0.shape[0] % n_dev == 0:
        return _fit_flat_sharded(rows, cases, steps, lam0)
    return _fit_flat_jit(rows, cases, steps, lam0)
