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
"""

import jax.tree_util as jtu
import numpy as np

from ..models import DiscreteTransferFunction, Hammerstein, Identity, PiecewiseLinear
from .augmented import slot_names
from .fit import fit_rows
from .layout import MAX_EFFECT_SLOTS, N_MAX, prepare


ORDERS = (1, 2, 3)
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


def fit_nominal(dt: float, estimation: dict) -> Hammerstein:
    """Fit the default nominal structure on the estimation record (see module doc)."""
    v, y = estimation["v"], estimation["y"]
    best, best_bic = None, np.inf
    names = slot_names(N_MAX)
    n_params = N_MAX + 6 + MAX_EFFECT_SLOTS  # one row shape: one compilation
    for n in ORDERS:
        b, a = _arx(v, y, n)
        for nl in (PiecewiseLinear(k1=1.0, k2=1.0), Identity()):
            start = Hammerstein(nl, DiscreteTransferFunction(b, a, dt))
            prep = prepare(start, dt, estimation, estimation, n_params=n_params)
            rows = [r for name, r in prep.rows if name == "parameter_mismatch"]
            stacked = jtu.tree_map(lambda *x: np.stack(x), *rows)
            fit = fit_rows(stacked, prep.arrays, NOMINAL_STEPS)
            sse = float(fit.sse_est[0])
            p = np.asarray(fit.params[0])
            pl = isinstance(nl, PiecewiseLinear)
            k = (6 if pl else 1) + n + 1
            bic = v.shape[0] * np.log(max(sse, 1e-300) / v.shape[0]) + k * np.log(
                v.shape[0]
            )
            den = np.r_[1.0, [p[names.index(f"den{j}")] for j in range(1, n + 1)]]
            gain = p[names.index("gain")]  # 1 beside a piecewise-linear map
            if not (
                np.isfinite(bic)
                and bic < best_bic
                and np.all(np.isfinite(den))
                and np.isfinite(gain)
            ):
                continue
            linear = DiscreteTransferFunction(gain * b, den, dt)
            # the output-error fit does not constrain the poles: an unstable
            # nominal fits the estimation record and diverges on any other
            if not linear.is_stable():
                continue
            fitted = Identity()
            if pl:
                vals = {
                    s: float(p[names.index(s)])
                    for s in ("k1", "k2", "d1", "d2", "l1", "l2")
                }
                vals["d1"], vals["d2"] = max(vals["d1"], 0.0), min(vals["d2"], 0.0)
                fitted = PiecewiseLinear(**vals)
            best = Hammerstein(fitted, linear)
            best_bic = bic
    if best is None:
        return Hammerstein(Identity(), DiscreteTransferFunction(*_arx(v, y, 1), dt))
    return best
