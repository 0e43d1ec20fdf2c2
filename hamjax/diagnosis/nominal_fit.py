"""The default nominal model when a case has no `model.json`.

Structure (documented in the contract): a static map $F$, piecewise-linear
(seed-001 Fig. 2 form, started at the identity) or the identity, followed by a
discrete $B(q^{-1})/A(q^{-1})$ with $\\deg A = \\deg B = n$ ($b_0$ included,
but 0 on a closed-loop record); the map and $n \\in \\{1, 2, 3\\}$ are selected
by BIC on the estimation record.
Each order is started from the least-squares ARX fit with $F$ = identity and then
refined by output-error least squares over the poles and either the six
piecewise-linear parameters or the gain (the numerator shape stays the ARX one).
Behind the order, a dead time of $d$ samples: $B = q^{-d}(b_0 + \\dots + b_n
q^{-n})$, $d$ chosen per order by the ARX stage (`arx_delay`: the least one-step
SSE over the same samples, the same parameter count for every $d$), as far as
the block keeps within `FITTED_ORDER` lags ($n + d \\le 3$, an integrating block's
numerator one lag more), so a first-order process behind a dead time is that,
not a third-order block imitating it.
The identity map is what an input with only a few levels (two, in a step test)
can determine; a piecewise-linear map there is not identifiable. Fits whose
poles left the unit circle are not candidates.

**Closed-loop records** (`layout.looks_closed_loop`: the output predicts the
input beyond the input's own past) get $b_0 = 0$, one sample of delay at least:
a controller acts within the sample ($v_k$ depends on $y_k$), so a direct term
$b_0 v_k$ in the plant would let a fit explain $y_k$ by the controller's own law
inverted, $y_k \\approx -v_k / K_c$ (the loop is identifiable by the direct
method only with a delay in it: Ljung, *System Identification*, 2nd ed.,
§13.4), and a plant sampled behind a held input has no direct term anyway. The
re-fit of the linear block keeps that $b_0 = 0$ (`layout.prepare`). There the
input is correlated with the noise, so an output-error fit to $y$ is biased;
each structure is fitted instead to `loop_response`, the response of a
high-order ARX model (consistent), and scored on the measured $y$.

Integrating plants (a level loop, a position axis) are candidates too:
$B/(A\\,(1 - q^{-1}))$ with $\\deg A \\in \\{1, 2\\}$, the same map choices, fitted
by the same output-error refinement on the increments $\\Delta y_k = y_k -
y_{k-1}$ ($y_{-1} = 0$: the record starts from rest) with the integrator fixed;
every candidate is then scored by BIC on the simulated $y$ itself, so the
integrating and the stable structures compete on the same error (a stable
candidate's output-error SSE is that error already; only the integrating ones,
and a map whose dead zone had to be clipped, are simulated again).
"""

from collections.abc import Sequence

import jax
import jax.tree_util as jtu
import numpy as np

from .._filters import lfilter_numpy
from ..io.model_json import integrators
from ..models import DiscreteTransferFunction, Hammerstein, Identity, PiecewiseLinear
from ..models.nonlinearities.piecewise_linear import PARAMETERS as PL_PARAMETERS
from ..simulation.sharding import effective_chunk
from .augmented import Row, slot_names
from .fit import LAMBDA0, SUCCESSFUL, fit_padded
from .layout import (
    FITTED_ORDER,
    MAX_EFFECT_SLOTS,
    N_MAX,
    ONE_GROUP,
    bucket,
    looks_closed_loop,
    nominal_output,
    prepare,
)


ORDERS = tuple(range(1, FITTED_ORDER + 1))
# orders of the stable part of an integrating structure B/(A (1 - q^-1)): level
# loops and position axes (the whole block stays within the diagnosis's N_MAX)
INTEGRATING_ORDERS = (1, 2)
NOMINAL_STEPS = 100  # Levenberg-Marquardt budget of each nominal fit
NOMINAL_FIRST_PASS = 30  # the steps of the first pass (`_fit_structures`)
# rows per batch of the nominal fits (rounded up to a multiple of the devices:
# each gets a slice): one compiled shape per length
NOMINAL_BATCH = 32
# highest order of `loop_response`'s ARX model (chosen by BIC below it; a cap on
# the cost, with at most a twentieth of the record as its other bound)
HIGH_ORDER = 20


def _arx_lstsq(
    v: np.ndarray,
    y: np.ndarray,
    n: int,
    *,
    direct: bool = True,
    delay: int = 0,
    skip: int = 0,
) -> tuple[np.ndarray, np.ndarray, float]:
    """Least-squares ARX fit of order `n` behind `delay` samples of dead time:
    `(b, a, sse)`, `b` of length `n + delay + 1` (one-step errors on samples
    `n + delay + skip..`), $b_0$ fitted if `direct` and there is no delay, else
    exactly 0 (strictly proper)."""
    first = (0 if direct else 1) + delay
    last = n + delay  # the numerator's lags: first..last
    m = last + skip
    N = v.shape[0]
    cols = [-y[m - i : N - i] for i in range(1, n + 1)]
    cols += [v[m - i : N - i] for i in range(first, last + 1)]
    X = np.column_stack(cols)
    theta, *_ = np.linalg.lstsq(X, y[m:], rcond=None)
    sse = float(np.sum(np.square(y[m:] - X @ theta)))
    return np.r_[np.zeros(first), theta[n:]], np.r_[1.0, theta[:n]], sse


def arx_delay(
    v: np.ndarray, y: np.ndarray, n: int, *, direct: bool, max_delay: int
) -> int:
    """The dead time, 0 to `max_delay` samples, of the order-`n` ARX model of
    least one-step SSE over the same samples for every delay (the same number of
    parameters each: the lowest SSE is the highest likelihood)."""
    sse = [
        _arx_lstsq(v, y, n, direct=direct, delay=d, skip=max_delay - d)[2]
        for d in range(max_delay + 1)
    ]
    return int(np.argmin(sse))


def _arx(
    v: np.ndarray, y: np.ndarray, n: int, *, direct: bool = True, delay: int = 0
) -> tuple[np.ndarray, np.ndarray]:
    """`_arx_lstsq`'s `(b, a)`, its unstable roots reflected (a start)."""
    b, a, _ = _arx_lstsq(v, y, n, direct=direct, delay=delay)
    # keep the start stable: reflect unstable roots inside the unit circle
    roots = np.roots(a)
    big = np.abs(roots) >= 0.999  # (a root at 0 is not divided by)
    roots[big] = 0.98 / np.conj(roots[big])
    return b, np.real(np.poly(roots))


def _prepare_structure(dt, record, nl, b, a, n_params, length=None):
    """The re-fit row (`parameter_mismatch`) of `nl` then `B/A` on `record`, and
    its prepared case (`layout.prepare`, padded to `length`)."""
    start = Hammerstein(nl, DiscreteTransferFunction(b, a, dt))
    prep = prepare(start, dt, record, record, length, n_params, screens=False)
    row = next(r for name, r in prep.rows if name == "parameter_mismatch")
    return prep, row


def _read_structure(prep, p, sse, record, nl, b, a):
    """The fitted static map, the discrete block, the parameter count, and the
    fit's SSE on `record` when it is that of the returned model (None where the
    map's dead zone was clipped to d1 >= 0 >= d2, or the fit did not see every
    sample), from the fitted physical parameters `p` and SSE `sse`."""
    names = slot_names(N_MAX)
    p = np.asarray(p)
    n = a.shape[0] - 1
    den = np.r_[1.0, [p[names.index(f"den{j}")] for j in range(1, n + 1)]]
    gain = p[names.index("gain")]  # 1 beside a piecewise-linear map
    fitted = Identity()
    sse = float(sse)
    exact = np.isfinite(sse) and np.sum(prep.arrays.m_est) == record["v"].shape[0]
    if isinstance(nl, PiecewiseLinear):
        vals = {s: float(p[names.index(s)]) for s in PL_PARAMETERS}
        exact = exact and vals["d1"] >= 0.0 >= vals["d2"]
        vals["d1"], vals["d2"] = max(vals["d1"], 0.0), min(vals["d2"], 0.0)
        fitted = PiecewiseLinear(**vals)
    k = (6 if isinstance(nl, PiecewiseLinear) else 1) + n + 1
    return fitted, gain * b, den, k, (sse if exact else None)


def _simulated_sse(plant: Hammerstein, record: dict, dt: float) -> float:
    return float(
        np.sum(np.square(record["y"] - nominal_output(plant, record["v"], dt)))
    )


def loop_response(v: np.ndarray, y: np.ndarray) -> np.ndarray | None:
    """Stage 1 of a closed-loop nominal: the noise-free response to `v`, from
    rest, of the strictly proper ARX model of the order (1 to `HIGH_ORDER`, at
    most a twentieth of the record) of least BIC on its one-step errors, $N \\ln
    (S/N) + 2 n \\ln N$; None where no order is stable.

    In closed loop the input is correlated with the noise: an output-error fit
    (a white noise model) is biased there, while a prediction-error fit whose
    noise model can be right is not (Ljung, *System Identification*, 2nd ed.,
    §13.4). ARX's noise model is $1/A$, so a high order makes it flexible enough
    and its $B/A$ consistent; the low-order nominal is then fitted by output
    error to this response (the model reduction of Zhu's asymptotic method, Zhu
    1998), not to the measured output."""
    N = v.shape[0]
    best, best_bic = None, np.inf
    for n in range(1, min(HIGH_ORDER, N // 20) + 1):
        b, a, sse = _arx_lstsq(v, y, n, direct=False)
        m = N - n
        bic = m * np.log(max(sse, 1e-300) / m) + 2 * n * np.log(m)
        stable = np.all(np.abs(np.roots(a)) < 1.0)
        if stable and np.isfinite(bic) and bic < best_bic:
            best, best_bic = (b, a), bic
    if best is None:
        return None
    return lfilter_numpy(*best, np.asarray(v, float))


def _structures(dt: float, estimation: dict):
    """Every candidate structure of a record: `(integrating, record, nl, b, a)`,
    started from the ARX fit of its order (`direct` per `looks_closed_loop`); on
    a closed-loop record each is fitted to `loop_response` instead of $y$."""
    v, y = estimation["v"], estimation["y"]
    direct = not looks_closed_loop(np.asarray(y), np.asarray(v))
    if not direct:
        target = loop_response(np.asarray(v, float), np.asarray(y, float))
        if target is not None:
            estimation = {**estimation, "y": target}
            y = target
    # the increments of y (from rest: y[-1] = 0) for the integrating structures
    increments = {**estimation, "y": np.diff(y, prepend=0.0)}
    out = []
    for integrating, orders in ((False, ORDERS), (True, INTEGRATING_ORDERS)):
        record = increments if integrating else estimation
        for n in orders:
            # the dead time that keeps the block within FITTED_ORDER lags (an
            # integrating block's numerator gains one)
            most = FITTED_ORDER - n - int(integrating)
            d = arx_delay(v, record["y"], n, direct=direct, max_delay=max(most, 0))
            b, a = _arx(v, record["y"], n, direct=direct, delay=d)
            for nl in (PiecewiseLinear(k1=1.0, k2=1.0), Identity()):
                out.append((integrating, record, nl, b, a))
    return out, direct


def _select(dt, estimation, structures, fitted_structures, direct) -> Hammerstein:
    """The candidate of least BIC on the simulated estimation output."""
    v, y = estimation["v"], estimation["y"]
    n_samples = v.shape[0]
    best, best_bic = None, np.inf
    for (integrating, *_), got in zip(structures, fitted_structures, strict=True):
        fitted, b_fit, den, k, sse = got
        if not (np.all(np.isfinite(den)) and np.all(np.isfinite(b_fit))):
            continue
        # the output-error fit does not constrain the poles: an unstable
        # block fits the estimation record and diverges on any other
        if not DiscreteTransferFunction(b_fit, den, dt).is_stable():
            continue
        if integrating:  # the integrator 1/(1 - q^-1), fixed
            den = np.convolve(den, [1.0, -1.0])
            b_fit = np.r_[b_fit, 0.0]
        plant = Hammerstein(fitted, DiscreteTransferFunction(b_fit, den, dt))
        # a stable candidate's fit SSE is already its simulated SSE on
        # y (same model, same record, from rest); an integrating one was
        # fitted on the increments, and a closed loop's on `loop_response`,
        # so they are simulated on the measured y here
        if integrating or sse is None or not direct:
            sse = _simulated_sse(plant, estimation, dt)
        bic = n_samples * np.log(max(sse, 1e-300) / n_samples) + k * np.log(n_samples)
        if np.isfinite(bic) and bic < best_bic:
            best, best_bic = plant, bic
    if best is None:
        b, a = _arx(v, y, 1, direct=direct)
        return Hammerstein(Identity(), DiscreteTransferFunction(b, a, dt))
    return best


N_PARAMS = N_MAX + 6 + MAX_EFFECT_SLOTS  # one row shape: one compilation


def _fit_structures(jobs: list, length: int) -> list:
    """Output-error fits of `jobs`, `(dt, record, nl, b, a)` each (`nl` then
    `B/A` started at `b, a` on `record`), all padded to `length`: `_read_structure`'s
    tuple for each.

    The fits run in batches of `NOMINAL_BATCH` rows (`fit.fit_padded`, split over
    the devices; one compiled shape per length): every row first gets
    `NOMINAL_FIRST_PASS` steps, then the rows still moving resume exactly where
    they stopped (`fit_batch`'s `resume`) with the rest of their
    `NOMINAL_STEPS`, together. A batch costs as much as its slowest row, and about
    half of the rows converge within the first pass: they no longer wait for the
    others' whole budget (one batch of all rows before). A row's fit is the same
    in either form, up to rounding (the 80 control loops of `hamjax blind make
    --family loops --seed 1`, 2 cores: 55 s -> 41 s, every nominal within 2e-8
    relative)."""
    prepared = [
        _prepare_structure(dt, record, nl, b, a, N_PARAMS, length)
        for dt, record, nl, b, a in jobs
    ]
    rows = jtu.tree_map(lambda *x: np.stack(x), *(row for _, row in prepared))
    arrays = jtu.tree_map(lambda *x: np.stack(x), *(p.arrays for p, _ in prepared))
    n = len(prepared)
    theta, lam = np.array(rows.theta0), np.full(n, LAMBDA0)
    params, sse, moving = None, np.empty(n), np.zeros(n, bool)
    first = min(NOMINAL_FIRST_PASS, NOMINAL_STEPS)
    todo, budget, resume = np.arange(n), first, False
    width = effective_chunk(NOMINAL_BATCH, jax.local_device_count())  # rows a batch
    while todo.shape[0]:
        for i in range(0, todo.shape[0], width):
            take = todo[i : i + width]
            m = take.shape[0]
            batch = Row(
                idx=rows.idx[take],
                theta0=theta[take],
                tau=rows.tau[take],
                free=rows.free[take],
                held=rows.held[take],
            )
            fit = fit_padded(  # padded to `width` rows: one shape per length
                batch,
                jtu.tree_map(lambda x, take=take: x[take], arrays),
                np.full(m, budget),
                lam[take],
                width,
                resume=np.full(m, resume),
            )
            if params is None:
                params = np.empty((n, fit.params.shape[1]))
            params[take], sse[take] = fit.params, fit.sse_est
            theta[take], lam[take] = fit.theta, fit.lam
            code = np.asarray(fit.result._value)
            moving[take] = (code != SUCCESSFUL) & (np.asarray(fit.steps) >= budget)
        if resume or first == NOMINAL_STEPS:
            break
        # the rows stopped at the first pass's budget: the rest of theirs, with
        # the pending step re-evaluated (`fit_batch`'s `resume`)
        todo, budget, resume = np.flatnonzero(moving), NOMINAL_STEPS - first + 1, True
    return [
        _read_structure(prep, params[j], sse[j], record, nl, b, a)
        for j, ((prep, _), (_, record, nl, b, a)) in enumerate(
            zip(prepared, jobs, strict=True)
        )
    ]


def fit_nominal_many(cases: Sequence[tuple[float, dict]]) -> list[Hammerstein]:
    """`fit_nominal` of each `(dt, estimation)`: every candidate structure of the
    cases whose records share a padded length fitted in one batch
    (`_fit_structures`; padding changes only rounding), so a call with many
    cases compiles once per length and runs the fits side by side. Records up to
    `layout.ONE_GROUP` samples are padded to that length, longer ones to their
    `layout.bucket` (a case's padding is its own, whatever the others); the
    fits follow each record's own length, so the padding costs no time
    (seed-1 control loops, 80 records of 1000-4100 samples in five buckets:
    one compilation instead of five, the nominal fits 34 -> 25 s on 2 cores,
    every nominal's structure the same). Within a length, the cases go in
    order of their records' lengths, so that a batch holds records alike."""
    per_case = [_structures(dt, est) for dt, est in cases]
    fitted: dict[int, list] = {}
    n = [est["v"].shape[0] for _, est in cases]
    lengths = [max(bucket(k), ONE_GROUP) for k in n]
    for length in sorted(set(lengths)):
        members = sorted(
            (c for c, k in enumerate(lengths) if k == length), key=n.__getitem__
        )
        jobs = [
            (cases[c][0], *structure[1:])
            for c in members
            for structure in per_case[c][0]
        ]
        got = iter(_fit_structures(jobs, length))
        for c in members:
            fitted[c] = [next(got) for _ in per_case[c][0]]
    return [
        _select(dt, est, per_case[c][0], fitted[c], per_case[c][1])
        for c, (dt, est) in enumerate(cases)
    ]


def describe_structure(plant: Hammerstein) -> str:
    """The structure the selection chose for a fitted nominal, in words: the map,
    the order of the block (an integrator apart), its dead time (the lag of its
    first nonzero numerator coefficient, the closed loop's sample included)."""
    b = np.asarray(plant.linear.b, float)
    n_int = integrators(plant.linear)
    order = np.asarray(plant.linear.a).shape[0] - 1 - n_int
    nonzero = np.flatnonzero(b)
    delay = int(nonzero[0]) if nonzero.size else 0
    kind = (
        "piecewise-linear map"
        if isinstance(plant.nonlinearity, PiecewiseLinear)
        else "identity map"
    )
    block = f"order {order}" + {0: "", 1: " with an integrator"}.get(
        n_int, f" with {n_int} integrators"
    )
    return f"{kind}, {block}, dead time {delay} sample(s)"


def fit_nominal(dt: float, estimation: dict) -> Hammerstein:
    """Fit the default nominal structure on the estimation record (see module doc)."""
    return fit_nominal_many([(dt, estimation)])[0]
