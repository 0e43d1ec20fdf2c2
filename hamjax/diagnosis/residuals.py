"""Residual statistics: noise floor, held-out improvement tests, whiteness,
input cross-correlation and the Billings-Voon higher-order correlation tests.

NumPy on purpose: these run once per case on concrete records, after the fits.
"""

import math

import numpy as np


Z_95 = 1.959963984540054


def noise_floor_hf(r: np.ndarray) -> float:
    """RMS of white measurement noise estimated from the upper half band of `r`.

    The plants are low-pass, so a model error passed through $G$ leaves little
    power above half the Nyquist frequency, while white noise has a flat
    spectrum: the mean periodogram over $[\\pi/2, \\pi]$ estimates $\\sigma^2$. It
    over-estimates (never under-estimates) when the model error is broadband.
    """
    r = np.asarray(r, float) - np.mean(r)
    n = r.shape[0]
    P = np.abs(np.fft.rfft(r)) ** 2 / n
    k = np.arange(P.shape[0])
    upper = (k >= n / 4) & (k < n / 2)
    if not upper.any():
        return float(np.std(r))
    return float(np.sqrt(np.mean(P[upper])))


def noise_std_differences(r: np.ndarray) -> float:
    r"""A robust estimate of the std of white noise in `r`: the median absolute
    second difference, $\sigma \approx \mathrm{med}|\Delta^2 r| / (0.6745\sqrt 6)$
    ($\Delta^2 e$ of white Gaussian noise is $N(0, 6\sigma^2)$). A model error that
    is smooth in time has small second differences, and one with kinks or jumps
    (a clip, $|w|$, a stick-slip) has large ones at a few samples only, which the
    median ignores; coloured noise is under-estimated (its second differences
    are smaller than a white noise's of the same std)."""
    d = np.diff(np.asarray(r, float), n=2)
    if d.size == 0:
        return 0.0
    return float(np.median(np.abs(d)) / (0.6744897501960817 * math.sqrt(6.0)))


def batch_means_se(x: np.ndarray, n_blocks: int) -> float:
    """Standard error of the mean of `x` by batch means: the sample std of the means
    of `n_blocks` contiguous blocks (the first `n_blocks * (len // n_blocks)`
    samples) over $\\sqrt{B}$; needs `len(x) >= n_blocks`."""
    n = x.shape[0] // n_blocks * n_blocks
    means = x[:n].reshape(n_blocks, -1).mean(axis=1)
    return np.std(means, ddof=1) / math.sqrt(n_blocks)


def improvement_z(
    r_before: np.ndarray, r_after: np.ndarray, n_blocks: int = 20
) -> float:
    """Held-out improvement $\\bar d / \\mathrm{se}$, $d_k = r_{b,k}^2 - r_{a,k}^2$.

    With $\\delta = r_b - r_a$ (the difference of the two models' predictions, fixed
    by the estimation record), $d = \\delta^2 + 2 r_a \\delta$: the first term is the
    improvement itself, the second the only noise. The standard error is therefore
    that of the mean of $2 r_a \\delta$, by batch means over `n_blocks` contiguous
    blocks (robust to residuals smooth in time: model errors, coloured noise).
    Under "no improvement" the statistic is about Student-t, `n_blocks - 1` dof.
    """
    r_b = np.asarray(r_before, float)
    r_a = np.asarray(r_after, float)
    d = r_b**2 - r_a**2
    s = 2 * r_a * (r_b - r_a)
    if d.shape[0] < n_blocks:
        return 0.0
    se = batch_means_se(s, n_blocks)
    if not np.isfinite(se) or not np.isfinite(np.mean(d)):
        return -np.inf
    if se == 0:
        return 0.0 if np.mean(d) == 0 else math.copysign(np.inf, np.mean(d))
    return float(np.mean(d) / se)


def autocorrelation(x: np.ndarray, max_lag: int) -> np.ndarray:
    """Normalised autocorrelation at lags `0..max_lag`."""
    x = np.asarray(x, float) - np.mean(x)
    den = np.dot(x, x) or 1.0
    return np.array(
        [np.dot(x[: x.shape[0] - k], x[k:]) / den for k in range(max_lag + 1)]
    )


def cross_correlation(a: np.ndarray, b: np.ndarray, lags: np.ndarray) -> np.ndarray:
    """Normalised $\\phi_{ab}(\\tau) = \\sum_k a_k b_{k+\\tau} / \\sqrt{\\sum a^2 \\sum b^2}$."""
    a = np.asarray(a, float) - np.mean(a)
    b = np.asarray(b, float) - np.mean(b)
    den = math.sqrt(np.dot(a, a) * np.dot(b, b)) or 1.0
    n = a.shape[0]
    out = []
    for tau in lags:
        if tau >= 0:
            out.append(np.dot(a[: n - tau], b[tau:]))
        else:
            out.append(np.dot(a[-tau:], b[: n + tau]))
    return np.array(out) / den


def ljung_box(r: np.ndarray, max_lag: int = 20) -> dict:
    """Ljung-Box whiteness statistic $Q$ and its chi-square p-value."""
    n = r.shape[0]
    rho = autocorrelation(r, max_lag)[1:]
    q = float(n * (n + 2) * np.sum(rho**2 / (n - np.arange(1, max_lag + 1))))
    # chi-square survival function via the regularised upper incomplete gamma
    p = _chi2_sf(q, max_lag)
    return {"Q": q, "dof": max_lag, "p_value": p, "white": p > 0.01}


def _chi2_sf(x: float, k: int) -> float:
    """Survival function of chi-square with `k` dof (series/continued fraction)."""
    a, x2 = k / 2.0, x / 2.0
    if x2 <= 0:
        return 1.0
    if x2 < a + 1:  # series for the lower incomplete gamma
        term = total = 1.0 / a
        n = 1
        while abs(term) > 1e-15 * abs(total) and n < 1000:
            term *= x2 / (a + n)
            total += term
            n += 1
        lower = total * math.exp(-x2 + a * math.log(x2) - math.lgamma(a))
        return max(0.0, 1.0 - lower)
    # continued fraction (Lentz) for the upper incomplete gamma
    b, c, d = x2 + 1 - a, 1e300, 1 / (x2 + 1 - a)
    h = d
    for i in range(1, 1000):
        an = -i * (i - a)
        b += 2
        d = an * d + b
        d = 1e-300 if abs(d) < 1e-300 else d
        c = b + an / c
        c = 1e-300 if abs(c) < 1e-300 else c
        d = 1 / d
        delta = d * c
        h *= delta
        if abs(delta - 1) < 1e-15:
            break
    return float(math.exp(-x2 + a * math.log(x2) - math.lgamma(a)) * h)


def billings_voon(r: np.ndarray, v: np.ndarray, max_lag: int = 20) -> dict:
    """Billings-Voon correlation tests of a residual $\\xi$ against the input $u$.

    For an adequate model all of these stay inside $\\pm 1.96/\\sqrt N$:
    $\\phi_{\\xi\\xi}(\\tau \\ne 0)$, $\\phi_{u\\xi}(\\tau)$, $\\phi_{u^{2\\prime}\\xi}(\\tau)$,
    $\\phi_{u^{2\\prime}\\xi^2}(\\tau)$ and $\\phi_{\\xi(\\xi u)}(\\tau \\ge 1)$, where
    $u^{2\\prime} = u^2 - \\overline{u^2}$. The last three see unmodelled
    nonlinearity that the linear tests miss.

    **Returns:** per test the largest |correlation|, the band and whether it is
    exceeded (with a Bonferroni factor over the lags tried).
    """
    n = r.shape[0]
    lags = np.arange(0, max_lag + 1)
    u = np.asarray(v, float) - np.mean(v)
    xi = np.asarray(r, float) - np.mean(r)
    u2 = u**2 - np.mean(u**2)
    tests = {
        "phi_xi_xi": autocorrelation(xi, max_lag)[1:],
        "phi_u_xi": cross_correlation(u, xi, lags),
        "phi_u2_xi": cross_correlation(u2, xi, lags),
        "phi_u2_xi2": cross_correlation(u2, xi**2 - np.mean(xi**2), lags),
        "phi_xi_xiu": cross_correlation(xi, xi * u, lags[1:]),
    }
    z = _bonferroni_z(0.05, max_lag + 1)
    band = z / math.sqrt(n)
    return {
        name: {
            "max_abs": float(np.max(np.abs(c))),
            "at_lag": int(np.argmax(np.abs(c))),
            "band": band,
            "exceeded": bool(np.max(np.abs(c)) > band),
        }
        for name, c in tests.items()
    }


def _bonferroni_z(alpha: float, m: int) -> float:
    """Two-sided normal quantile for `alpha / m` (Acklam-style rational approx.)."""
    p = alpha / (2 * m)
    # inverse of the upper normal tail by Newton on erfc
    z = math.sqrt(-2 * math.log(p))
    for _ in range(50):
        f = 0.5 * math.erfc(z / math.sqrt(2)) - p
        df = -math.exp(-z * z / 2) / math.sqrt(2 * math.pi)
        z -= f / df
    return z


FEEDBACK_LAGS = 20  # future-input lags tested
FEEDBACK_AR = 10  # order of the input's prewhitening AR model
FEEDBACK_ALPHA = 0.01  # false-alarm level of the feedback test on open-loop records


def feedback_test(
    r: np.ndarray,
    v: np.ndarray,
    *,
    max_lag: int = FEEDBACK_LAGS,
    order: int = FEEDBACK_AR,
    alpha: float = FEEDBACK_ALPHA,
) -> dict:
    r"""Does the record look closed-loop? The test for feedback of Ljung
    (*System Identification*, 2nd ed., §16.6): in open loop the output error $r$
    is a function of past inputs and of noise independent of them, so it cannot
    predict present or future inputs; a controller closing the loop makes
    $v_{k+j}$, $j \ge 0$, react to $r_k$ (at $j = 0$ already for a controller
    acting within the sample, the usual case). Lag 0 assumes no direct
    feedthrough within a sample (a sampled physical plant, held input: $y_k$ is
    measured before $v_k$ acts).

    The input is prewhitened by a least-squares AR(`order`) model
    $A(q)v = \varepsilon$ and $r$ is filtered by the same $A(q)$, which leaves a
    model error $G'(q)v$ as $G'(q)\varepsilon$ (past and present $\varepsilon$
    only); then $\rho_j = \mathrm{corr}(A r_k, \varepsilon_{k+j})$, $j = 1..$
    `max_lag`, is about $N(0, 1/N)$ under open loop, and feedback is reported
    when $\max_j |\rho_j|\sqrt{N}$ exceeds the two-sided Bonferroni quantile at
    `alpha` over the lags (false-alarm rate $\le$ `alpha`). Not applicable to an
    exactly periodic input (its future is its past): `applicable` is then False.
    """
    r = np.asarray(r, float) - np.mean(r)
    v = np.asarray(v, float) - np.mean(v)
    n = v.shape[0]
    if n < 4 * (order + max_lag) or np.ptp(v) == 0:
        return {"applicable": False, "why": "record too short or input constant"}
    X = np.column_stack([v[order - i - 1 : n - i - 1] for i in range(order)])
    coef, *_ = np.linalg.lstsq(X, v[order:], rcond=None)
    eps = v[order:] - X @ coef
    R = np.column_stack([r[order - i - 1 : n - i - 1] for i in range(order)])
    rf = r[order:] - R @ coef
    lags = np.arange(0, max_lag + 1)
    rho = cross_correlation(rf, eps, lags)
    z = float(np.max(np.abs(rho)) * math.sqrt(eps.shape[0]))
    threshold = _bonferroni_z(alpha, lags.shape[0])
    return {
        "applicable": True,
        "z": z,
        "threshold": threshold,
        "lag": int(lags[np.argmax(np.abs(rho))]),
        "closed_loop": bool(z > threshold),
    }
