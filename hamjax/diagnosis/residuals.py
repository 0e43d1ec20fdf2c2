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


FEEDBACK_LAGS = 1  # lags 0..1 of the output tested as predictors of the input
FEEDBACK_AR = 20  # order of the input's own autoregression (the null's predictor)
FEEDBACK_ALPHA = 0.01  # false-alarm level of the feedback test on open-loop records
FEEDBACK_BLOCKS = 20  # contiguous blocks of the cluster-robust covariance
# the autoregression reaches back this many of the input's longest hold (chosen on
# family A seed 0's open-loop records; see `feedback_test`)
FEEDBACK_HOLDS = 1.5


def longest_hold(v: np.ndarray) -> int:
    """Length of the longest run of exactly equal consecutive samples of `v`."""
    change = np.flatnonzero(np.diff(np.asarray(v)) != 0)
    edges = np.r_[-1, change, np.asarray(v).shape[0] - 1]
    return int(np.max(np.diff(edges)))


def period_of(v: np.ndarray) -> int | None:
    """Smallest period (samples) of an exactly periodic input with >= 2 periods."""
    n = v.shape[0]
    tol = 1e-9 * (np.ptp(v) or 1.0)
    for p in np.flatnonzero(np.abs(v - v[0]) <= tol):
        if p < 2 or p > n // 2:
            continue
        if np.all(np.abs(v[p:] - v[:-p]) <= tol):
            return int(p)
    return None


def feedback_test(
    s: np.ndarray,
    v: np.ndarray,
    *,
    max_lag: int = FEEDBACK_LAGS,
    order: int = FEEDBACK_AR,
    alpha: float = FEEDBACK_ALPHA,
    n_blocks: int = FEEDBACK_BLOCKS,
) -> dict:
    r"""Does the record look closed-loop? A Granger test for feedback (Ljung,
    *System Identification*, 2nd ed., §13.4, §16.6; Granger 1969): regress the
    input on its own past and on the output,
    $v_k = \sum_{i=1}^{p} \alpha_i v_{k-i} + \sum_{j=0}^{q} \beta_j s_{k-j} +
    \varepsilon_k$, and test $\beta = 0$. In open loop $v$ does not depend on the
    noise, and $s$ (the measured output, or $y$ minus any model's response to
    *past* inputs) is a function of past inputs plus noise independent of them:
    it adds nothing to the prediction of $v_k$, whatever the model error, so the
    test's level does not depend on a nominal model being right (a test on a
    residual's correlation with future inputs does: a wrong $G$ leaves $G'v$,
    correlated with the input's own serial structure). A controller makes $v_k$
    a function of $s_k, s_{k-1}, \dots$ ($j = 0$: it acts within the sample,
    the usual case; this assumes no direct feedthrough, a sampled plant with a
    held input, so pass $y$ itself or the residual of a strictly proper model).

    The covariance of $\hat\beta$ is the cluster-robust sandwich over
    `n_blocks` contiguous blocks (valid for heteroscedastic and serially
    correlated $\varepsilon$ within blocks: a staircase input's AR residual is
    both); its Wald statistic $W$ gives $F = W (B - m)/(m (B - 1))$, about
    $F(m, B - m)$ under open loop ($m = q + 1$ tested lags; the Hotelling
    small-sample reference for $B$ clusters), and feedback is reported when
    $F$ exceeds its $1 - \alpha$ quantile (false-alarm rate $\alpha$).

    A staircase input with (nearly) fixed holds breaks the null for a short
    autoregression: the time since its last step predicts the next, and a slow
    plant's output still shows that step when the input's last $p$ samples do
    not. The order is therefore at least `FEEDBACK_HOLDS` times the longest
    hold (`longest_hold`; at most a twentieth of the record). Not
    applicable to an exactly periodic input (`period_of`: its future is its
    past, so the output's past adds nothing to an exact predictor), a constant
    input, or a record too short for the regression (fewer than $4(p + m)$ or
    $2B$ regression rows)."""
    from scipy import stats

    s = np.asarray(s, float) - np.mean(s)
    v = np.asarray(v, float) - np.mean(v)
    n = v.shape[0]
    m = max_lag + 1
    order = max(order, min(math.ceil(FEEDBACK_HOLDS * longest_hold(v)), n // 20))
    start = max(order, max_lag)
    if n - start < 4 * (order + m) or n - start < 2 * n_blocks or np.ptp(v) == 0:
        return {"applicable": False, "why": "record too short or input constant"}
    if period_of(v) is not None:
        return {"applicable": False, "why": "periodic input"}
    if not (np.all(np.isfinite(s)) and np.all(np.isfinite(v))):
        return {"applicable": False, "why": "the output or the input is not finite"}
    k = np.arange(start, n)
    X = np.column_stack(
        [s[k - j] for j in range(m)] + [v[k - i] for i in range(1, order + 1)]
    )
    target = v[k]
    XtX_inv = np.linalg.pinv(X.T @ X)
    beta = XtX_inv @ (X.T @ target)
    eps = target - X @ beta
    nb = (k.shape[0] // n_blocks) * n_blocks
    scores = (X[:nb] * eps[:nb, None]).reshape(n_blocks, -1, X.shape[1]).sum(axis=1)
    meat = scores.T @ scores
    cov = (XtX_inv @ meat @ XtX_inv)[:m, :m]
    b = beta[:m]
    wald = float(b @ np.linalg.pinv(cov) @ b) if np.all(np.isfinite(cov)) else 0.0
    f = wald * (n_blocks - m) / (m * (n_blocks - 1))
    threshold = float(stats.f.isf(alpha, m, n_blocks - m))
    t = np.abs(b) / np.sqrt(np.maximum(np.diag(cov), 1e-300))
    return {
        "applicable": True,
        "z": f,
        "threshold": threshold,
        "p_value": float(stats.f.sf(f, m, n_blocks - m)),
        "lag": int(np.argmax(t)),
        "closed_loop": bool(f > threshold),
    }


INPUT_LAGS = 25  # lags 0..24 of the input: the standard residual analysis's count
INPUT_ALPHA = 0.01  # false-alarm level: a noise model falsified that is the truth


def input_dependence(
    e: np.ndarray,
    v: np.ndarray,
    *,
    lags: int = INPUT_LAGS,
    order: int = FEEDBACK_AR,
    alpha: float = INPUT_ALPHA,
    material: float = 0.0,
) -> dict:
    r"""Do a model's one-step-ahead errors `e` depend on the input `v`? The
    residual-input independence test of residual analysis (Ljung, *System
    Identification*, 2nd ed., §16.6: the errors' cross-correlation with the
    input over `lags` lags, as MATLAB's `resid`), with the centred square of
    the input beside the input itself (Billings and Voon 1986,
    $\phi_{u^{2\prime}\varepsilon}$: an even unmodelled nonlinearity leaves
    no linear correlation). The errors are regressed on a constant and
    $u_{k-i}$, $u^{2\prime}_{k-i}$ for $i = 0 \dots$ `lags` $- 1$
    ($u = v - \bar v$, $u^{2\prime} = u^2 - \overline{u^2}$), all three
    prewhitened by the errors' own autoregression of order `order` (least
    squares, as the null's predictor of `feedback_test`; `order=0`: none), and
    $F = (R^2 / m) / ((1 - R^2) / (N - m - 1))$, $m$ the regressors' rank less
    the constant's (at most $2\,$`lags`: a held input repeats itself over its
    lags, a binary one has a constant square).

    *Level.* Where the noise does not depend on the input (an open-loop record)
    and the model with its noise predictor is adequate, the errors are
    independent of every input sample; the prewhitening leaves them white
    where the predictor did not quite (a regression of a coloured series on
    smooth regressors is spuriously significant: Granger and Newbold 1974), so
    with Gaussian errors $F$ is about $F(m, N - m - 1)$ and dependence is
    reported when it exceeds its $1 - \alpha$ quantile (false-alarm rate
    `alpha`). `material`: the variance the input explains must also exceed
    this multiple of the variance it leaves (`explained`, the unbiased
    estimate $(F - 1)\,m / n$, $n$ the regression's rows), as every step of
    the diagnosis's rule asks an improvement to exceed a share of the noise.
    In closed loop the input is a function of past noise and the test does
    not apply. Not applicable to a record shorter than $8\,$`lags` samples
    after the prewhitening, or with a constant input."""
    from scipy import signal, stats

    e = np.asarray(e, float) - np.mean(e)
    u = np.asarray(v, float) - np.mean(v)
    n = e.shape[0]
    if n - order - lags < 8 * lags or np.ptp(u) == 0:
        return {"applicable": False, "why": "record too short or input constant"}
    if not (np.all(np.isfinite(e)) and np.all(np.isfinite(u))):
        return {"applicable": False, "why": "the errors or the input are not finite"}
    a = np.zeros(0)
    if order > 0:
        past = np.column_stack([e[order - i : n - i] for i in range(1, order + 1)])
        a = np.linalg.lstsq(past, e[order:], rcond=None)[0]
    white = lambda x: signal.lfilter(np.r_[1.0, -a], 1.0, x)[order:]  # noqa: E731
    e, u2, u = white(e), white(u**2 - np.mean(u**2)), white(u)
    k = np.arange(lags - 1, e.shape[0])
    X = np.column_stack(
        [np.ones(k.shape[0])] + [x[k - i] for x in (u, u2) for i in range(lags)]
    )
    target = e[k]
    beta, _, rank, _ = np.linalg.lstsq(X, target, rcond=None)
    m = int(rank) - 1  # the regressors' own count (docstring)
    if m < 1:
        return {"applicable": False, "why": "the input's lags span nothing"}
    rss = float(np.sum((target - X @ beta) ** 2))
    tss = float(np.sum((target - np.mean(target)) ** 2))
    dof = k.shape[0] - m - 1
    f = ((tss - rss) / m) / (rss / dof) if rss > 0 else math.inf
    threshold = float(stats.f.isf(alpha, m, dof))
    explained = (f - 1.0) * m / k.shape[0]
    return {
        "applicable": True,
        "F": float(f),
        "threshold": threshold,
        "p_value": float(stats.f.sf(f, m, dof)),
        "explained": float(explained),
        "dependent": bool(f > threshold and explained > material),
    }
