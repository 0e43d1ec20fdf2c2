"""Least-squares fit of candidate rows on the estimation record, batched over a flat
list of rows (each with its own case) so that one compilation serves every batch
of a call; `schedule.py` decides which rows go into a batch. The solver is the
fitting layer's (`fitting.least_squares` with `BatchedLevenbergMarquardt`, the
same interface and `RESULTS` as `refine`'s optimistix solvers); this module gives
it the rows' blocked normal equations and the compiled batch programs."""

from collections.abc import Callable

import equinox as eqx
import jax
import jax.lax as lax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Bool, Float, Int

from .._linalg import fixed_order_sum
from .._results import RESULTS
from ..fitting import (
    BatchedLevenbergMarquardt,
    CompiledPrograms,
    GaussianPrior,
    NormalEquations,
    least_squares,
    standard_errors_from_information,
)
from ..fitting.least_squares import LAMBDA0
from .augmented import (
    EFFECT_SLOTS,
    NOMINAL_SLOTS,
    CaseArrays,
    Row,
    filter_coefficients,
    full_parameters,
    linear_part,
    memory_init,
    memory_scan,
    n_max_of,
    output_part,
    output_play_scan,
    simulate_with_filter,
    slot_index,
    static_part,
    switch,
    uses_feedback,
    uses_memory,
    uses_table,
)
from .effects.time_delay import delay


BLOCK = 256  # samples per block of `normal_equations`
SUCCESSFUL = int(RESULTS.successful._value)  # a converged fit's code on the host


class RowFit(eqx.Module):
    """Fitted rows (leading axis: row)."""

    theta: Float[Array, "... P"]
    params: Float[Array, "... S"]  # physical full parameter vector
    sse_est: Float[Array, "..."]
    y_val: Float[Array, "... L"]
    # the fitted row's output on the estimation input (from rest): its estimation
    # residual, on which `attribute` fits a noise model on top of the candidate
    y_est: Float[Array, "... L"]
    result: RESULTS  # successful, or not_converged (stopped at its step budget)
    steps: Int[Array, "..."]  # Levenberg-Marquardt iterations taken
    lam: Float[Array, "..."]  # damping of the last proposed step (to continue)
    # Gauss-Newton information J^T J (scaled output) of `theta`; with the noise
    # filter's parameter fitted jointly, its Schur complement (that parameter
    # profiled out: the information left about `theta`)
    jtj: Float[Array, "... P P"]
    s2: Float[Array, "..."]  # residual variance (scaled output), SSE / dof
    # how far the noise filter's parameter moved in a joint fit (the predictor's
    # pole or gain, `CaseArrays.noise_dfir`, `noise_dar`); 0 with a fixed filter
    noise_shift: Float[Array, "..."]


def nominal_mask(row: Row, case: CaseArrays) -> Bool[Array, " P"]:
    """Which entries of `theta` move the nominal model's own parameters (the
    numerator changes `db..` of a `REFIT_LINEAR` row do not: that row re-fits a
    numerator the nominal's own linear fit could not determine)."""
    first_den = len(NOMINAL_SLOTS) + len(EFFECT_SLOTS)
    n_max = case.b_disc.shape[0] - 1
    return (row.idx < len(NOMINAL_SLOTS)) | (
        (row.idx >= first_den) & (row.idx < first_den + n_max)
    )


def _block_model(p, b, a, state, vb, case, memory, table, feedback):
    """One block of the estimation record through the augmented model, from the
    scans' `state = (memory-scan state, filter state, output play)`
    (`augmented.memory_scan` and `augmented.memory_init`; `augmented.linear_part`:
    the feedback loop or the plain filter; `augmented.output_play_scan`, skipped
    with the memory scan)."""
    mem, z, played = state
    skip = lambda v, s, *_: (s, v)  # noqa: E731
    mem, x = switch(memory, memory_scan, skip, vb, mem, p, case, table)
    u = static_part(x, p, case, table)
    z, w = linear_part(b, a, u, z, p, case, feedback)
    played, w = switch(memory, output_play_scan, skip, w, played, p, case)
    return (mem, z, played), output_part(w, p, case)


def _coefficients(theta, row, case):
    p = full_parameters(theta, row, case)
    return (p, *filter_coefficients(p, case))


def normal_equations(
    theta: Float[Array, " P"],
    row: Row,
    case: CaseArrays,
    memory: bool | Bool[Array, ""] = True,
    table: bool | Bool[Array, ""] = True,
    feedback: bool | Bool[Array, ""] = True,
    whiten: bool | Bool[Array, ""] = True,
) -> tuple[Float[Array, ""], Float[Array, "P P"], Float[Array, " P"]]:
    """The record part of the least-squares problem at `theta`: `(r^T r, J^T J,
    J^T r)` of the scaled output residual `r = (y_model - y) m / y_scale` and its
    Jacobian `J`.

    Accumulated over blocks of `BLOCK` samples up to the record's own length (the
    scans carry their state, and their tangents, from block to block), so padding
    costs nothing and `J` (`[L, P]`) is never stored: the cost follows each
    record's length while one compiled program serves every length up to `L`.
    The Jacobian is forward mode, one tangent per entry of `theta`; the
    parameter-to-coefficient map (matrix exponential included) runs once per
    call, not per block. A non-finite residual sample counts as `1e3` with a zero
    Jacobian row, so a diverging trial step is rejected. `memory`, `table`,
    `feedback`: as in `augmented.simulate_with_filter`.

    With the case's noise filter $A(q)$ (`case.noise_fir`, `case.noise_ar`) not
    the identity, `r` and `J` are those of the one-step-ahead prediction errors
    $A(q) r$ of the output with that noise model, from rest
    (`schedule.whitening_items`): the prediction-error fit. `whiten=False`: the
    filter is skipped (output error; the case's filter must be the identity).
    Here the filter is held fixed; `fit_row` frees its parameter too (the
    Box-Jenkins fit, `_normal_equations`).
    """
    flags = (memory, table, feedback, whiten)
    theta_ext = jnp.concatenate([theta, jnp.zeros(1, theta.dtype)])
    (sse, H, g), _ = _normal_equations(theta_ext, row, case, flags)
    return sse, H[:-1, :-1], g[:-1]


def _noise_block(x, state, fir, g):
    """One block of the noise filter $A(q) = (f_0 + f_1 q^{-1} + f_2 q^{-2}) /
    (1 + g q^{-1})$ on the rows of `x` (`[Q, BLOCK]`, each row a signal), carrying
    `state = (last two inputs, last output)` across blocks; the recursion
    $e_k = -g\\,e_{k-1} + f_k$ as an associative scan of affine maps."""
    x_prev, e_prev = state
    ext = jnp.concatenate([x_prev, x], axis=1)
    f = fir[0] * ext[:, 2:] + fir[1] * ext[:, 1:-1] + fir[2] * ext[:, :-2]
    f = f.at[:, 0].add(-g * e_prev)
    a = jnp.broadcast_to(-g, f.shape)

    def compose(left, right):
        (a1, b1), (a2, b2) = left, right
        return a1 * a2, a2 * b1 + b2

    _, e = lax.associative_scan(compose, (a, f), axis=1)
    return (x[:, -2:], e[:, -1]), e


def _normal_equations(theta_ext, row, case, flags):
    """`normal_equations` of `theta_ext = (theta, eta)`, and the physical
    parameters and filter at `theta`; `flags = (memory, table, feedback, whiten)`.

    `eta` moves the noise filter along its direction (`case.noise_dfir`,
    `case.noise_dar`: the one-step predictor's parameter, the AR(1) pole or the
    local level's gain), so that the deterministic part and the noise model are
    fitted jointly by prediction error (Box-Jenkins; Ljung, *System
    Identification*, 1999, sec. 7.2): the last row and column of `J^T J` and the
    last entry of `J^T r` are those of `eta`, whose column is the derivative of
    the filtered residual $e = F(q) r / (1 + g q^{-1})$, from
    $(1 + g q^{-1})\\, \\partial e = \\partial F(q)\\, r - \\partial g\\, q^{-1} e$
    (one signal, a sequential scan carried from block to block: a second
    associative scan cost the fit programs 0.7 s more compilation in a cold
    one-case diagnosis, this one 0.1 s). A zero direction, or `whiten=False`,
    leaves that column zero (the filter fixed)."""
    memory, table, feedback, whiten = flags
    theta, eta = theta_ext[:-1], theta_ext[-1]
    P, L = theta.shape[0], case.v_est.shape[0]
    pad = -L % BLOCK
    vd = jnp.pad(delay(case.v_est, row.tau), (0, pad), mode="edge")
    y, m = (jnp.pad(x, (0, pad)) for x in (case.y_est, case.m_est))
    n_blocks = (jnp.sum(case.m_est).astype(jnp.int32) + BLOCK - 1) // BLOCK

    basis = jnp.eye(P, dtype=theta.dtype)
    (p, b, a), (dp, db, da) = jax.vmap(
        lambda t: jax.jvp(lambda th: _coefficients(th, row, case), (theta,), (t,)),
        out_axes=(None, 0),
    )(basis)
    # the memory scan's state at rest at vd[0] (`memory_init`; the nominal
    # backlash's in_scale tangents with it), the filter at rest
    init = lambda p: memory_init(vd[0], p, case)  # noqa: E731
    mem0, dmem0 = jax.vmap(lambda t: jax.jvp(init, (p,), (t,)), out_axes=(None, 0))(dp)
    filt0 = jnp.zeros(a.shape[0] - 1, theta.dtype)
    # the output play at rest at 0 (`augmented.output_memory`)
    state0 = (mem0, filt0, jnp.zeros((), theta.dtype))
    dstate0 = (
        dmem0,
        jnp.zeros((P, *filt0.shape), filt0.dtype),
        jnp.zeros(P, theta.dtype),
    )
    # the noise filter A(q) on the residual and its Jacobian (P + 1 signals),
    # and the residual's derivative in eta (its state: its last sample)
    zeros = lambda *s: jnp.zeros(s, theta.dtype)  # noqa: E731
    noise0 = ((zeros(P + 1, 2), zeros(P + 1)), zeros(1))
    fir = case.noise_fir + eta * case.noise_dfir
    ar = case.noise_ar + eta * case.noise_dar

    def noise(x, ns, mb):
        state, de_prev = ns
        new_state, e = _noise_block(x, state, fir, ar)
        # e = F r / (1 + g q^-1) in eta: (1 + g q^-1) de = dF r - dg q^-1 e
        r = jnp.concatenate([state[0][0], x[0]])  # r_{k-2}, r_{k-1}, r_k, ...
        e_lag = jnp.concatenate([state[1][:1], e[0, :-1]])
        df = case.noise_dfir
        z = df[0] * r[2:] + df[1] * r[1:-1] + df[2] * r[:-2] - case.noise_dar * e_lag

        def step(prev, zk):
            out = zk - ar * prev
            return out, out

        last, de = lax.scan(step, de_prev[0], z)
        de_prev, de = last[None], de[None]
        # nothing past the record's end
        return (new_state, de_prev), jnp.concatenate([e, de]) * mb[None]

    def skip(x, ns, mb):
        return ns, jnp.concatenate([x, jnp.zeros_like(x[:1])])

    def body(carry):
        k, state, dstate, ns, sse, H, g = carry
        take = lambda x: lax.dynamic_slice_in_dim(x, k * BLOCK, BLOCK)  # noqa: E731
        vb, yb, mb = take(vd), take(y), take(m)
        f = lambda p, b, a, s: _block_model(  # noqa: E731
            p, b, a, s, vb, case, memory, table, feedback
        )
        (state, yhat), (dstate, dy) = jax.vmap(
            lambda *t: jax.jvp(f, (p, b, a, state), t), out_axes=(None, 0)
        )(dp, db, da, dstate)
        r = (yhat - yb) * mb / case.y_scale
        ok = jnp.isfinite(r)
        r = jnp.where(ok, r, 1e3)
        J = jnp.where(ok[None], dy * (mb / case.y_scale)[None], 0.0)  # [P, BLOCK]
        ns, x = switch(whiten, noise, skip, jnp.concatenate([r[None], J]), ns, mb)
        r, J = x[0], x[1:]  # J: [P + 1, BLOCK], eta's row last
        sse = sse + fixed_order_sum(r * r)
        H = H + fixed_order_sum(J[:, None] * J[None])
        return k + 1, state, dstate, ns, sse, H, g + fixed_order_sum(J * r[None])

    carry = (
        jnp.asarray(0, jnp.int32),
        state0,
        dstate0,
        noise0,
        jnp.zeros((), theta.dtype),
        jnp.zeros((P + 1, P + 1), theta.dtype),
        jnp.zeros(P + 1, theta.dtype),
    )
    *_, sse, H, g = lax.while_loop(lambda c: c[0] < n_blocks, body, carry)
    return (sse, H, g), (p, b, a)


def _row_problem(theta, args):
    """The row's normal equations, for `fitting.least_squares`; `args = (row,
    case, (memory, table, feedback, whiten))`."""
    row, case, flags = args
    return _normal_equations(theta, row, case, flags)


def _solve_row(row, case, flags, max_steps, lam0, resume=False):
    """`fitting.BatchedLevenbergMarquardt` on the row's normal equations plus a
    Gaussian prior at the nominal parameters, of weight `case.prior_weight`
    (`layout.prior_weight`: the user's stated nominal uncertainty, so the cost is
    the negative log posterior times the noise variance): a re-fit explains only
    what the stated uncertainty makes plausible, and where the estimation record
    leaves a direction of the re-fit undetermined (the gain against the slopes of
    a piecewise-linear map, an unexcited segment) every start ends at the same
    point instead of wherever its path stopped. The last entry of the solved
    vector is the noise filter's parameter (`_normal_equations`), from 0 (the
    case's filter), without a prior."""
    theta0 = jnp.concatenate([row.theta0, jnp.zeros(1, row.theta0.dtype)])
    mask = jnp.concatenate([nominal_mask(row, case), jnp.zeros(1, bool)])
    return least_squares(
        NormalEquations(_row_problem),
        BatchedLevenbergMarquardt(lam0=lam0, resume=resume),
        theta0,
        (row, case, flags),
        max_steps=max_steps,
        prior=GaussianPrior(case.prior_weight, mask),
        throw=False,
    )


def _profile_noise(H: Float[Array, "Q Q"]) -> Float[Array, "P P"]:
    """The information about `theta` left when the noise filter's parameter (the
    last of `H`'s `Q = P + 1`) is fitted too: the Schur complement
    $H_{\\theta\\theta} - H_{\\theta\\eta} H_{\\eta\\eta}^{-1} H_{\\eta\\theta}$
    ($H_{\\theta\\theta}$ itself where that parameter is fixed, $H_{\\eta\\eta} = 0$)."""
    h = H[-1, -1]
    c = H[:-1, -1]
    inv = jnp.where(h > 0, 1.0 / jnp.where(h > 0, h, 1.0), 0.0)
    return H[:-1, :-1] - inv * jnp.outer(c, c)


def fit_row(
    row: Row,
    case: CaseArrays,
    max_steps=30,
    lam0: float | Array = LAMBDA0,
    memory: bool | Bool[Array, ""] = True,
    table: bool | Bool[Array, ""] = True,
    feedback: bool | Bool[Array, ""] = True,
    whiten: bool | Bool[Array, ""] = True,
    *,
    resume: bool | Bool[Array, ""] = False,
) -> RowFit:
    """Fit one row from `row.theta0` (the nominal slots start at nominal).
    `memory`, `table`, `feedback`: as in `simulate_augmented` and `static_part`
    (False only if the row frees neither the rate limit nor the backlash and the
    case's map is not a backlash, if the map reads no table (`uses_table`), and if
    the row frees no feedback slot). `whiten`: False only if the case's noise
    filter is the identity (an output-error fit; `normal_equations`); with a
    filter, `sse_est` and `s2` are those of the prediction errors, and where the
    filter has a direction (`CaseArrays.noise_dfir`, `noise_dar`) its parameter
    is fitted jointly (`noise_shift`). `resume`: `row.theta0` and `lam0` are a
    stopped fit's `theta` and `lam`, continued exactly
    (`fitting.BatchedLevenbergMarquardt`; a joint fit's filter moved by its
    `noise_shift` first)."""
    flags = (memory, table, feedback, whiten)
    sol = _solve_row(row, case, flags, max_steps, lam0, resume)
    (p, b, a), sse = sol.aux, sol.stats["sse"]
    theta, shift = sol.value[:-1], sol.value[-1]
    n = jnp.sum(case.m_est)
    used = row.idx < case.anchor.shape[0]
    joint = jnp.any(case.noise_dfir != 0) | (case.noise_dar != 0)
    dof = jnp.maximum(n - jnp.sum(used) - joint, 1.0)
    y_val = simulate_with_filter(p, b, a, row.tau, case.v_val, case, *flags[:3])
    y_est = simulate_with_filter(p, b, a, row.tau, case.v_est, case, *flags[:3])
    sse_est = sse * case.y_scale**2
    return RowFit(
        theta=theta,
        params=p,
        sse_est=jnp.where(jnp.isfinite(sse_est), sse_est, jnp.inf),
        y_val=y_val,
        y_est=y_est,
        result=sol.result,
        steps=sol.stats["num_steps"],
        lam=sol.stats["damping"],
        jtj=_profile_noise(sol.stats["jtj"]),
        s2=sse / dof,
        noise_shift=shift,
    )


def theta_std(
    jtj: Float[np.ndarray, "P P"], s2: float, used: np.ndarray
) -> Float[np.ndarray, " P"]:
    """Gauss-Newton standard errors of `theta` over the used slots (unused: 0):
    `fitting.standard_errors_from_information` of $J^T J$ with variance $s^2$ on
    the host, an unidentifiable direction infinite (`singular="infinite"`)."""
    return standard_errors_from_information(
        np.asarray(jtj, dtype=float),
        variance=float(s2),
        used=np.asarray(used, dtype=bool),
        singular="infinite",
    )


@eqx.filter_jit
def fit_rows(rows: Row, case: CaseArrays, max_steps=30) -> RowFit:
    """All rows (stacked along axis 0) of one case."""
    return jax.vmap(lambda r: fit_row(r, case, max_steps))(rows)


def _fit_flat(
    rows: Row,
    cases: CaseArrays,
    max_steps,
    lam0,
    resume,
    memory=None,
    table=None,
    feedback=None,
    whiten=None,
) -> RowFit:
    # `memory`, `table`: True or False for a whole call (static: the other branch
    # is not even compiled, -20 % of the program), or None to decide per
    # (per-device) batch at run time, a flag not mapped over: a batch in which
    # no row frees the rate limit or the backlash skips the input-memory scan
    # (measured -8 % per screening batch), one without a tabulated map skips the
    # table look-up (-28 %); `schedule` and `diagnose_many` order the rows so
    # that most batches are alike. `feedback` likewise: a batch in which no row
    # frees a `friction` or `feedback_nonlinearity` slot runs the plain filter.
    if memory is None:
        memory = jnp.any(uses_memory(rows.free, cases.nl_kind))
    if table is None:
        table = jnp.any(uses_table(cases.nl_kind))
    if feedback is None:
        feedback = jnp.any(uses_feedback(rows.free))
    if whiten is None:  # any case of the batch with a noise filter
        whiten = jnp.any(cases.noise_ar != 0) | jnp.any(cases.noise_fir[:, 1:] != 0)

    def fit(r, c, k, lam, res):
        return fit_row(r, c, k, lam, memory, table, feedback, whiten, resume=res)

    return jax.vmap(fit)(rows, cases, max_steps, lam0, resume)


# XLA's CPU back end compiles this program (~300 fusions, most of them small loop
# bodies) about 40 % faster with its older loop emitters than with the fusion
# emitters, and the batches run as fast (measured in
# `benchmarks/diagnosis_compile_options.py`). An XLA without the option compiles
# with its defaults.
COMPILER_OPTIONS = {"xla_cpu_use_fusion_emitters": False}
PROGRAMS = CompiledPrograms(
    {
        "one": jax.jit(
            _fit_flat, static_argnames=("memory", "table", "feedback", "whiten")
        )
    },
    compiler_options=COMPILER_OPTIONS,
)


def clear_compiled() -> None:
    """Drop the compiled fit programs (`fit_batch` compiles again on next use)."""
    PROGRAMS.clear()


def fit_padded(
    rows: Row,
    cases: CaseArrays,
    budgets: Int[np.ndarray, " M"],
    lam0: Float[np.ndarray, " M"],
    width: int,
    while_compiling: Callable[[], None] | None = None,
    *,
    resume: Bool[np.ndarray, " M"] | None = None,
    **flags: bool | None,
) -> RowFit:
    """`fit_batch` of `M <= width` rows (row `i` on case `i`, as gathered by the
    caller) padded to `width` with copies of the first at a zero budget (one
    compiled shape per width, whatever `M`); the first `M` fits, on the host.
    `flags`: `fit_batch`'s `memory`, `table`, `feedback`, `whiten`."""
    m = int(np.shape(budgets)[0])
    if not 0 < m <= width:
        raise ValueError(f"{m} rows for a batch of {width}")
    pad = np.r_[np.arange(m), np.zeros(width - m, int)]
    resume = np.zeros(m, bool) if resume is None else np.asarray(resume, bool)
    # a full batch is its rows as gathered: no second copy of the cases' records
    gather = (lambda x: np.asarray(x)) if m == width else (lambda x: np.asarray(x)[pad])
    fit = fit_batch(
        jax.tree.map(gather, rows),
        jax.tree.map(gather, cases),
        np.where(np.arange(width) < m, np.asarray(budgets)[pad], 0),
        np.asarray(lam0, float)[pad],
        while_compiling,
        resume=resume[pad],
        **flags,
    )
    return jax.tree.map(lambda x: np.asarray(x)[:m], jax.device_get(fit))


def fit_batch(
    rows: Row,
    cases: CaseArrays,
    max_steps: Int[np.ndarray, " N"],
    lam0: Float[np.ndarray, " N"],
    while_compiling: Callable[[], None] | None = None,
    *,
    resume: Bool[np.ndarray, " N"] | None = None,
    memory: bool | None = None,
    table: bool | None = None,
    feedback: bool | None = None,
    whiten: bool | None = None,
) -> RowFit:
    """Fit `N` rows, row `i` on case `i` (both stacked along axis 0), each with its
    own step budget and initial damping.

    With several devices (e.g. `XLA_FLAGS=--xla_force_host_platform_device_count=2`
    on a 2-core CPU, as `hamjax diagnose` sets) and `N` a multiple of their number,
    the rows are split over them in equal shares, each share run by the same
    one-device program (one compilation per device) and all at once: a row's fit
    is bitwise the same on any number of devices (`_run_on_devices`). Budgets
    and dampings are traced, so changing them does not recompile; the cost of a
    batch is that of its longest-running row. `while_compiling` is called once the
    program for these shapes is traced, if it has to be compiled (work to overlap
    with it).
    `resume[i]`: row `i` continues a stopped fit exactly (its `theta0` and `lam0`
    the stopped fit's `theta` and `lam`, its budget one step more than it has
    left; `fitting.BatchedLevenbergMarquardt`); None: no row does.
    `memory`, `table`, `feedback`: whether the rows need the input-memory scan,
    the table look-up and the feedback loop, when that is known for every batch
    of a call (a smaller program); None (default) decides per batch at run time.
    `whiten` likewise, for the cases' noise filters (`normal_equations`).
    """
    args = (
        rows,
        cases,
        np.asarray(max_steps, dtype=np.int32),
        np.asarray(lam0, dtype=float),
        np.zeros(len(lam0), bool) if resume is None else np.asarray(resume, bool),
    )
    flags = {"memory": memory, "table": table, "feedback": feedback, "whiten": whiten}
    devices = jax.local_devices()  # this process's: cases split over processes
    if len(devices) == 1 or len(lam0) % len(devices):
        return PROGRAMS.get("one", args, flags, while_compiling)(*args)
    return _run_on_devices(args, flags, devices, while_compiling)


def _run_on_devices(args, flags, devices, while_compiling) -> RowFit:
    """`_fit_flat` of equal shares of the rows, share `i` on `devices[i]`, each
    by the one-device program compiled for its device, dispatched together (they
    run at once) and gathered on the host.

    Not one program partitioned over the devices (`jax.shard_map`): XLA compiles
    that with other fusions (519 against 513 for one fit program), and even
    without fused multiply-adds (`_runtime.same_rounding_in_every_lane`) a row's
    simulated output came out 1 ulp apart on one device and on two. The
    one-device program's lanes round alike at every batch width (the reductions
    are `_linalg.fixed_order_sum`), so the split decides nothing.
    The programs of the devices compile at the same time
    (`CompiledPrograms.get_each`): one case cold (`HAMJAX_CACHE_DIR=off hamjax
    diagnose`, 2 cores) took 8.5-8.9 s against 7.7-7.8 s with the partitioned
    program, 10.6-11.2 s with the two compiled one after the other.
    """
    share = len(args[3]) // len(devices)
    parts = [
        jax.device_put(
            jax.tree.map(
                lambda x, i=i: np.asarray(x)[i * share : (i + 1) * share], args
            ),
            device,
        )
        for i, device in enumerate(devices)
    ]
    programs = PROGRAMS.get_each("one", parts, flags, while_compiling, devices)
    runs = [program(*part) for program, part in zip(programs, parts, strict=True)]
    return jax.tree.map(lambda *x: np.concatenate([np.asarray(y) for y in x]), *runs)


# starts of the valve tried on the validation record, in each of
# `VALIDATION_STAGES` searches, each within a step of the last one's best
VALIDATION_STARTS = 32
VALIDATION_STAGES = 3


def _starts_on_validation(
    p: Float[Array, " S"], tau: Int[Array, ""], case: CaseArrays
) -> Float[Array, " L"]:
    """`simulate_with_filter` on the validation record at `p`, the valve started
    at each of `VALIDATION_STARTS` points within the play's width $c$ of $v_0$
    (`valve_start` from $-c$ to $c$), then at as many within a step of the
    best, `VALIDATION_STAGES` times (an integrating process makes the start a
    needle): the output whose masked SSE is least."""
    n_max = n_max_of(p.shape[0])
    start, width = slot_index("valve_start", n_max), p[slot_index("backlash", n_max)]
    b, a = filter_coefficients(p, case)
    grid = jnp.linspace(-1.0, 1.0, VALIDATION_STARTS)

    def best(deltas):
        runs = jax.vmap(
            lambda d: simulate_with_filter(
                p.at[start].set(d), b, a, tau, case.v_val, case, True, True, True
            )
        )(deltas)
        sse = fixed_order_sum(case.m_val[None] * (runs - case.y_val[None]) ** 2)
        k = jnp.argmin(jnp.where(jnp.isfinite(sse), sse, jnp.inf))
        return deltas[k], runs[k]

    d, span = jnp.zeros(()), jnp.abs(width)
    for _ in range(VALIDATION_STAGES):
        d, y = best(d + grid * span)
        span = 2.0 * span / (VALIDATION_STARTS - 1)  # a step of this search
    return y


_starts_on_validations = jax.jit(jax.vmap(_starts_on_validation, (0, 0, None)))


def validation_start(
    params: np.ndarray, rows: list, case: CaseArrays, *, batch: int = 1
) -> np.ndarray:
    """The validation outputs `(R, L)` of rows that fit the valve's start
    (`layout.frees_valve_start`) at their fitted `params` `(R, S)`, each with the
    validation record's own start: as the estimation record's, that is an
    initial state (where the valve was stuck when the record began), estimated
    there by the least simulation SSE over `VALIDATION_STARTS` starts within
    the play's width of $v_0$, then as many within a step of the best, and so
    on (`_starts_on_validation`, the rows in one call). One parameter; the
    other rows start from rest, as the contract's simulations do.

    The rows are padded (the last repeated) to a multiple of `batch`, so that
    calls with up to `batch` rows share one compiled program per record length
    (each row is simulated on its own: the padding changes no row's output)."""
    if batch < 1:
        raise ValueError(f"batch must be a positive number of rows, not {batch}")
    R = len(rows)
    if R == 0:
        return np.zeros((0, case.v_val.shape[0]))
    pad = -R % batch
    taus = np.array([int(r.tau) for r in rows] + [int(rows[-1].tau)] * pad)
    params = np.concatenate([params, np.repeat(params[-1:], pad, axis=0)])
    out = _starts_on_validations(jnp.asarray(params), jnp.asarray(taus), case)
    return np.asarray(out)[:R]
