"""The default nominal model when a case has no `model.json`.

Structure (documented in the contract): a static map $F$, piecewise-linear
(seed-001 Fig. 2 form, started at the identity) or the identity, followed by a
discrete $B(q^{-1})/A(q^{-1})$ with $\\deg A = \\deg B = n$ ($b_0$ included);
the map and $n \\in \\{1, 2, 3\\}$ are selected by BIC on the estimation record.
Each order is started from the least-squares ARX fit with $F$ = identity and then
refined by output-error least squares over the poles and either the six
piecewise-linear parameters or the gain (the numerator shape stays the ARX one).
The identity map is what an input with only a few levels (two, in a step test)
can determine; a piecewise-linear map there is not identifiable. Fits whose
poles left the unit circle are not candidates.

Integrating plants (a level loop, a position axis) are candidates too:
$B/(A\\,(1 - q^{-1}))$ with $\\deg A \\in \\{1, 2\\}$, the same map choices, fitted
by the same output-error refinement on the increments $\\Delta y_k = y_k -
y_{k-1}$ ($y_{-1} = 0$: the record starts from rest) with the integrator fixed;
every candidate is then scored by BIC on the simulated $y$ itself, so the
integrating and the stable structures compete on the same error (a stable
candidate's output-error SSE is that error already; only the integrating ones,
and a map whose dead zone had to be clipped, are simulated again).
"""

import jax.tree_util as jtu
import numpy as np

from ..models import DiscreteTransferFunction, Hammerstein, Identity, PiecewiseLinear
from .augmented import slot_names
from .fit import fit_rows
from .layout import (
    FITTED_ORDER,
    MAX_EFFECT_SLOTS,
    N_MAX,
    nominal_output,
    prepare,
)


ORDERS = tuple(range(1, FITTED_ORDER + 1))
# orders of the stable part of an integrating structure B/(A (1 - q^-1)): level
# loops and position axes (the whole block stays within the diagnosis's N_MAX)
INTEGRATING_ORDERS = (1, 2)
NOMINAL_STEPS = 100  # Levenberg-Marquardt budget of each nominal fit


def _arx(v: np.ndarray, y: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray]:
    rows = []
    for k in range(n, v.shape[0]):
        rows.append(np.r_[-y[k - n : k][::-1], v[k - n : k + 1][::-1]])
    X = np.asarray(rows)
    theta, *_ = np.linalg.lstsq(X, y[n:], rcond=None)
    a = np.r_[1.0, theta[:n]]
    b = theta[n:]
    # keep the start stable: reflect unstable roots inside the unit circle
    roots = np.roots(a)
    roots = np.where(np.abs(roots) >= 0.999, 0.98 / np.conj(roots), roots)
    return b, np.real(np.poly(roots))


def _fit_structure(dt, record, nl, b, a, n_params):
    """Output-error fit of `nl` then `B/A` (started at `b, a`) on `record`: the
    fitted static map, the discrete block, the parameter count, and the fit's SSE
    on `record` when it is that of the returned model (None where the map's
    dead zone was clipped to d1 >= 0 >= d2, or the fit did not see every sample)."""
    names = slot_names(N_MAX)
    start = Hammerstein(nl, DiscreteTransferFunction(b, a, dt))
    prep = prepare(start, dt, record, record, n_params=n_params)
    rows = [r for name, r in prep.rows if name == "parameter_mismatch"]
    stacked = jtu.tree_map(lambda *x: np.stack(x), *rows)
    fit = fit_rows(stacked, prep.arrays, NOMINAL_STEPS)
    p = np.asarray(fit.params[0])
    n = a.shape[0] - 1
    den = np.r_[1.0, [p[names.index(f"den{j}")] for j in range(1, n + 1)]]
    gain = p[names.index("gain")]  # 1 beside a piecewise-linear map
    fitted = Identity()
    sse = float(fit.sse_est[0])
    exact = np.isfinite(sse) and np.sum(prep.arrays.m_est) == record["v"].shape[0]
    if isinstance(nl, PiecewiseLinear):
        vals = {
            s: float(p[names.index(s)]) for s in ("k1", "k2", "d1", "d2", "l1", "l2")
        }
        exact = exact and vals["d1"] >= 0.0 >= vals["d2"]
        vals["d1"], vals["d2"] = max(vals["d1"], 0.0), min(vals["d2"], 0.0)
        fitted = PiecewiseLinear(**vals)
    k = (6 if isinstance(nl, PiecewiseLinear) else 1) + n + 1
    return fitted, gain * b, den, k, (sse if exact else None)


def _simulated_sse(plant: Hammerstein, record: dict, dt: float) -> float:
    return float(
        np.sum(np.square(record["y"] - nominal_output(plant, record["v"], dt)))
    )


def fit_nominal(dt: float, estimation: dict) -> Hammerstein:
    """Fit the default nominal structure on the estimation record (see module doc)."""
    v, y = estimation["v"], estimation["y"]
    n_samples = v.shape[0]
    best, best_bic = None, np.inf
    n_params = N_MAX + 6 + MAX_EFFECT_SLOTS  # one row shape: one compilation
    # the increments of y (from rest: y[-1] = 0) for the integrating structures
    increments = {**estimation, "y": np.diff(y, prepend=0.0)}
    for integrating, orders in ((False, ORDERS), (True, INTEGRATING_ORDERS)):
        record = increments if integrating else estimation
        for n in orders:
            b, a = _arx(v, record["y"], n)
            for nl in (PiecewiseLinear(k1=1.0, k2=1.0), Identity()):
                fitted, b_fit, den, k, sse = _fit_structure(
                    dt, record, nl, b, a, n_params
                )
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
                # fitted on the increments, so it is simulated on y here
                if integrating or sse is None:
                    sse = _simulated_sse(plant, estimation, dt)
                bic = n_samples * np.log(max(sse, 1e-300) / n_samples) + k * np.log(
                    n_samples
                )
                if np.isfinite(bic) and bic < best_bic:
                    best, best_bic = plant, bic
    if best is None:
        return Hammerstein(Identity(), DiscreteTransferFunction(*_arx(v, y, 1), dt))
    return best
