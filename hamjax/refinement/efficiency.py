"""Monte Carlo summaries of an estimator against the Cramér-Rao bound."""

import numpy as np


def efficiency_summary(
    estimates: np.ndarray, truth: np.ndarray, crlb_var: np.ndarray, ok: np.ndarray
) -> dict:
    """Bias, std, RMSE, efficiency $\\text{CRLB}/\\text{MSE}$ per parameter.

    **Arguments:**

    - `estimates`: shape `(R, p)`.
    - `truth`: shape `(p,)`.
    - `crlb_var`: the bound's diagonal, shape `(p,)`.
    - `ok`: shape `(R,)`, the realisations kept (successful estimates).

    **Returns:** a JSON-able dict of lists. `efficiency_se` is the Monte Carlo
    standard error of the efficiency by the delta method,
    $\\text{se}(\\hat e) = \\hat e\\,\\text{se}(\\widehat{\\text{MSE}})/\\widehat{\\text{MSE}}$
    with $\\text{se}(\\widehat{\\text{MSE}})$ the sample std of the squared errors over
    $\\sqrt R$ (about $\\hat e\\sqrt{2/R}$ for Gaussian errors); `efficiency_ci` is the
    95% interval $\\text{CRLB}/(\\widehat{\\text{MSE}} \\pm 1.96\\,\\text{se})$.
    """
    e = np.asarray(estimates)[np.asarray(ok)] - np.asarray(truth)[None, :]
    R = e.shape[0]
    if R < 2:
        nan = [float("nan")] * np.asarray(truth).shape[0]
        return {
            "kept": int(R),
            "bias": nan,
            "std": nan,
            "rmse": nan,
            "efficiency": nan,
            "efficiency_se": nan,
            "efficiency_ci": [nan, nan],
            "crlb_std": nan,
        }
    mse = np.mean(e**2, axis=0)
    mse_se = np.std(e**2, axis=0, ddof=1) / np.sqrt(R)
    eff = crlb_var / mse
    lo = crlb_var / (mse + 1.96 * mse_se)
    hi = crlb_var / np.maximum(mse - 1.96 * mse_se, 1e-300)
    return {
        "kept": int(R),
        "bias": np.mean(e, axis=0).tolist(),
        "std": np.std(e, axis=0, ddof=1).tolist(),
        "rmse": np.sqrt(mse).tolist(),
        "rmse_mcse": (mse_se / (2 * np.sqrt(mse))).tolist(),
        "crlb_std": np.sqrt(crlb_var).tolist(),
        "efficiency": eff.tolist(),
        "efficiency_se": (eff * mse_se / mse).tolist(),
        "efficiency_ci": [lo.tolist(), hi.tolist()],
    }
