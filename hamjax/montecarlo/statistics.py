r"""Monte Carlo summaries with their Monte Carlo standard errors (MCSE).

For estimates $\hat\theta_1, \dots, \hat\theta_R$ of $\theta$ (Morris, White and
Crowther, *Using simulation studies to evaluate statistical methods*, Stat. Med.
2019, Table 6):

- mean $\bar\theta$, MCSE $s/\sqrt{R}$; bias $\bar\theta - \theta$, same MCSE;
- standard deviation $s$ (ddof 1), MCSE by the delta method
  $\sqrt{(m_4 - s^4)/R} / (2 s)$ with $m_4$ the fourth central moment (this does not
  assume normal estimates; for normal ones it is $s/\sqrt{2R}$);
- RMSE $\sqrt{\mathrm{MSE}}$, $\mathrm{MSE} = \frac1R\sum(\hat\theta_r - \theta)^2$, MCSE
  $\mathrm{sd}((\hat\theta_r - \theta)^2)/(2\,\mathrm{RMSE}\sqrt{R})$.

Confidence intervals are Wald intervals, estimate $\pm z_{1-\alpha/2}$ MCSE.
"""

import dataclasses
import functools
import math

import equinox as eqx
import jax
import jax.numpy as jnp
import jax.random as jr
import numpy as np
from jax.scipy.special import betainc, ndtri
from jaxtyping import Array, ArrayLike, Float, PRNGKeyArray


class _Record(eqx.Module):
    """A summary whose `to_dict()` holds its fields in the order declared."""

    def to_dict(self) -> dict:
        """JSON-able dict: arrays as (nested) lists of floats, the rest as is."""
        out = {}
        for field in dataclasses.fields(self):
            value = getattr(self, field.name)
            out[field.name] = (
                np.asarray(value).tolist() if eqx.is_array(value) else value
            )
        return out


class MonteCarloSummary(_Record):
    """Summary of $R$ estimates; every array has the shape of one estimate (the
    intervals a leading axis of 2)."""

    realisations: int = eqx.field(static=True)
    level: float = eqx.field(static=True)
    mean: Float[Array, "..."]
    mean_mcse: Float[Array, "..."]
    mean_ci: Float[Array, "2 ..."]
    bias: Float[Array, "..."]
    bias_mcse: Float[Array, "..."]
    bias_ci: Float[Array, "2 ..."]
    std: Float[Array, "..."]
    std_mcse: Float[Array, "..."]
    std_ci: Float[Array, "2 ..."]
    rmse: Float[Array, "..."]
    rmse_mcse: Float[Array, "..."]
    rmse_ci: Float[Array, "2 ..."]


class LogLogSlope(_Record):
    r"""Fit $\log e = c + p \log N$: slope $p$, its standard error and CI."""

    slope: Float[Array, ""]
    intercept: Float[Array, ""]
    stderr: Float[Array, ""]
    ci: Float[Array, "2"]
    level: float = eqx.field(static=True)
    method: str = eqx.field(static=True)


def summarise(
    estimates: Float[ArrayLike, "realisations ..."],
    truth: Float[ArrayLike, "..."],
    *,
    level: float = 0.95,
) -> MonteCarloSummary:
    """Mean, bias, standard deviation and RMSE of `estimates`, with MCSE and CIs.

    **Arguments:**

    - `estimates`: shape `(R, ...)`, realisations along axis 0 (as returned by
      `run_monte_carlo`); other axes are summarised elementwise.
    - `truth`: the true value, broadcastable to `estimates[0]`.
    - `level`: confidence level of the intervals.

    **Returns:** a `MonteCarloSummary`.

    **Raises:** `ValueError` for fewer than 2 realisations or a bad `level`.
    """
    x = jnp.asarray(estimates, dtype=float)
    if x.ndim < 1 or x.shape[0] < 2:
        raise ValueError(f"need at least 2 realisations along axis 0; got {x.shape}")
    if not 0 < level < 1:
        raise ValueError(f"level must be in (0, 1); got {level}")
    truth = jnp.broadcast_to(jnp.asarray(truth, dtype=float), x.shape[1:])
    R = x.shape[0]
    z = _z(level)
    sqrt_r = math.sqrt(R)
    mean = jnp.mean(x, axis=0)
    centred = x - mean[None]
    var = jnp.sum(centred**2, axis=0) / (R - 1)
    std = jnp.sqrt(var)
    mean_mcse = std / sqrt_r
    # Delta method on s^2 (whose variance is (m4 - sigma^4)/R) without normality.
    m4 = jnp.mean(centred**4, axis=0)
    std_mcse = jnp.sqrt(jnp.maximum(m4 - var**2, 0.0) / R) / (2 * std)
    sq_err = (x - truth[None]) ** 2
    mse = jnp.mean(sq_err, axis=0)
    rmse = jnp.sqrt(mse)
    mse_mcse = jnp.std(sq_err, axis=0, ddof=1) / sqrt_r
    rmse_mcse = mse_mcse / (2 * rmse)
    bias = mean - truth

    def ci(value, se):
        return jnp.stack([value - z * se, value + z * se])

    return MonteCarloSummary(
        mean=mean,
        bias=bias,
        std=std,
        rmse=rmse,
        mean_mcse=mean_mcse,
        bias_mcse=mean_mcse,
        std_mcse=std_mcse,
        rmse_mcse=rmse_mcse,
        mean_ci=ci(mean, mean_mcse),
        bias_ci=ci(bias, mean_mcse),
        std_ci=ci(std, std_mcse),
        rmse_ci=ci(rmse, rmse_mcse),
        realisations=R,
        level=level,
    )


def loglog_slope(
    ns: Float[ArrayLike, " n"],
    errors: Float[ArrayLike, " n"] | Float[ArrayLike, "realisations n"],
    *,
    level: float = 0.95,
    key: PRNGKeyArray | None = None,
    bootstrap: int = 1000,
) -> LogLogSlope:
    r"""Slope of error against sample size on log-log axes (rate claims like $N^{-1/2}$).

    Two forms:

    - `errors` of shape `(n,)` (say, an RMSE per $N$): ordinary least squares of
      $\log e$ on $\log N$; the CI is $p \pm t_{n-2}$ times the regression standard
      error (it assumes independent, homoscedastic scatter of $\log e$ about the line;
      needs $n \ge 3$).
    - `errors` of shape `(R, n)` (per-realisation errors, e.g. $|\hat\theta - \theta|$
      for realisation $r$ at each $N$): the slope of $\log \mathrm{RMSE}(N)$, with
      $\mathrm{RMSE}(N)=\sqrt{\mathrm{mean}_r\, e_{r}(N)^2}$, and a percentile bootstrap CI
      resampling realisations (`bootstrap` resamples drawn with `key`, required). The
      reported `stderr` is the bootstrap standard deviation.

    **Raises:** `ValueError` for mismatched shapes, non-positive values, fewer than
    3 sample sizes in the regression form, or a missing `key` in the bootstrap form.
    """
    ns = jnp.asarray(ns, dtype=float)
    errors = jnp.asarray(errors, dtype=float)
    if ns.ndim != 1 or ns.shape[0] < 2:
        raise ValueError(f"ns must be 1-D with at least 2 sizes; got shape {ns.shape}")
    if errors.ndim not in (1, 2) or errors.shape[-1] != ns.shape[0]:
        raise ValueError(
            f"errors must have shape (n,) or (realisations, n) with n = {ns.shape[0]}; "
            f"got {errors.shape}"
        )
    if not 0 < level < 1:
        raise ValueError(f"level must be in (0, 1); got {level}")
    if not bool(jnp.all(ns > 0)):
        raise ValueError("sample sizes ns must be > 0 for a log-log fit")
    log_n = jnp.log(ns)
    if errors.ndim == 1:
        if ns.shape[0] < 3:
            raise ValueError("the regression CI needs at least 3 sample sizes")
        if not bool(jnp.all(errors > 0)):
            raise ValueError("errors must be > 0 for a log-log fit")
        slope, intercept, stderr = _ols(log_n, jnp.log(errors))
        half = _t_ppf(0.5 + level / 2, ns.shape[0] - 2) * stderr
        return LogLogSlope(
            slope=slope,
            intercept=intercept,
            stderr=stderr,
            ci=jnp.stack([slope - half, slope + half]),
            level=level,
            method="ols-t",
        )
    if key is None:
        raise ValueError("per-realisation errors need `key` for the bootstrap CI")
    R = errors.shape[0]
    if R < 2:
        raise ValueError(f"need at least 2 realisations; got {R}")

    sq = errors**2
    if not bool(jnp.all(jnp.mean(sq, axis=0) > 0)):
        raise ValueError("the RMSE is 0 at some sample size; cannot take its log")
    slope, intercept = _rmse_fit(log_n, sq)
    if bootstrap < 2:
        raise ValueError(f"bootstrap must be >= 2 resamples; got {bootstrap}")
    boot = _bootstrap_slopes(key, log_n, sq, bootstrap)
    lo, hi = jnp.quantile(boot, jnp.array([0.5 - level / 2, 0.5 + level / 2]))
    return LogLogSlope(
        slope=slope,
        intercept=intercept,
        stderr=jnp.std(boot, ddof=1),
        ci=jnp.stack([lo, hi]),
        level=level,
        method="bootstrap-percentile",
    )


def _rmse_fit(log_n, sq_err):
    return _ols(log_n, 0.5 * jnp.log(jnp.mean(sq_err, axis=0)))[:2]


@functools.partial(jax.jit, static_argnums=3)
def _bootstrap_slopes(key, log_n, sq_err, n_resamples: int):
    """Slopes of `_rmse_fit` on resamples of the realisations (rows)."""
    R = sq_err.shape[0]
    idx = jr.randint(key, (n_resamples, R), 0, R)
    return jax.vmap(lambda i: _rmse_fit(log_n, sq_err[i])[0])(idx)


def _ols(x, y):
    """Slope, intercept and slope standard error of the least-squares line."""
    n = x.shape[0]
    xm, ym = jnp.mean(x), jnp.mean(y)
    sxx = jnp.sum((x - xm) ** 2)
    slope = jnp.sum((x - xm) * (y - ym)) / sxx
    intercept = ym - slope * xm
    resid = y - (intercept + slope * x)
    dof = max(n - 2, 1)
    stderr = jnp.sqrt(jnp.sum(resid**2) / dof / sxx)
    return slope, intercept, stderr


def _z(level: float) -> float:
    return float(ndtri(0.5 + level / 2))


@functools.lru_cache(maxsize=64)
def _t_ppf(p: float, df: int) -> float:
    """Quantile of Student's t (bisection on its CDF, written via `betainc`)."""

    def cdf(t: float) -> float:
        x = df / (df + t * t)
        tail = 0.5 * float(betainc(df / 2, 0.5, x))
        return 1 - tail if t > 0 else tail

    lo, hi = -1e3, 1e3
    for _ in range(80):
        mid = (lo + hi) / 2
        if cdf(mid) < p:
            lo = mid
        else:
            hi = mid
    return (lo + hi) / 2
