"""The one-likelihood rule (`decide`): each noise model recovered on noise-only
records, and its false-alarm rate on noise-only cases against the derived bound."""

import jax.random as jr
import numpy as np
import pytest
import scipy.signal
import scipy.stats

from hamjax.diagnosis import decide
from hamjax.diagnosis.diagnose import RULES, diagnose_many
from hamjax.diagnosis.noise_fit import MA_GRID, NOISE_MODELS, noise_family_numpy
from hamjax.papers.gap.demo_cases import coloured_case, tiny_case


N = 20000  # samples per record
SIGMA = 0.3  # innovation std


def _noise(key, b, a, n=2 * N):
    e = SIGMA * np.asarray(jr.normal(key, (n,)))
    return scipy.signal.lfilter(b, a, e)


def _fit(r):
    params, e_est, e_val = noise_family_numpy(r[None, :N], r[None, N:])
    return {m: params[m][0] for m in NOISE_MODELS}, e_est[0], e_val[0]


@pytest.mark.statistical
def test_each_noise_model_recovered_on_noise_only_records():
    # Tolerances: 5 asymptotic standard errors of the least-squares / prediction-
    # error estimates at n = N (AR(p): sqrt((1 - a_p^2) / n) per coefficient, an
    # upper bound for both AR(2) coefficients here; ARMA(1,1):
    # (1 + a c) sqrt((1 - x^2) / n) / |a + c| for x = a, c), plus half a grid step
    # for the gridded c; so each bound fails with probability < 1e-6. The
    # innovation variance: 5 sd of a mean of squares, SIGMA^2 sqrt(2 / n).
    tol_var = 5 * SIGMA**2 * np.sqrt(2 / N)
    ar1, e_est, e_val = _fit(_noise(jr.key(1), [1.0], [1.0, -0.8]))
    assert abs(ar1["ar1"][0] - 0.8) < 5 * np.sqrt((1 - 0.8**2) / N)
    j = NOISE_MODELS.index("ar1")
    assert abs(np.mean(e_est[j] ** 2) - SIGMA**2) < tol_var
    assert abs(np.mean(e_val[j] ** 2) - SIGMA**2) < tol_var

    ar2, e_est, _ = _fit(_noise(jr.key(2), [1.0], [1.0, -1.2, 0.5]))
    np.testing.assert_allclose(ar2["ar2"], [1.2, -0.5], atol=5 * np.sqrt(0.75 / N))
    assert abs(np.mean(e_est[NOISE_MODELS.index("ar2")] ** 2) - SIGMA**2) < tol_var

    a, c = 0.7, 0.5
    arma, e_est, _ = _fit(_noise(jr.key(3), [1.0, c], [1.0, -a]))
    se = (1 + a * c) * np.sqrt((1 - min(a, c) ** 2) / N) / abs(a + c)
    step = 1.9 / (MA_GRID - 1)
    assert abs(arma["arma11"][1] - c) < 5 * se + step / 2
    # a given c off by up to half a step: a moves by about as much
    assert abs(arma["arma11"][0] - a) < 5 * se + step / 2
    assert abs(np.mean(e_est[NOISE_MODELS.index("arma11")] ** 2) - SIGMA**2) < (
        tol_var + SIGMA**2 * (step / 2) ** 2
    )

    # random-walk level plus white noise, q = var(eta) / var(e): the predictor's
    # steady-state Kalman gain is P / (P + 1), P = (q + sqrt(q^2 + 4 q)) / 2
    q = 0.05
    k1, k2 = jr.split(jr.key(4))
    level = np.cumsum(np.sqrt(q) * SIGMA * np.asarray(jr.normal(k1, (2 * N,))))
    r = level + SIGMA * np.asarray(jr.normal(k2, (2 * N,)))
    lev, e_est, _ = _fit(r)
    p = (q + np.sqrt(q**2 + 4 * q)) / 2
    alpha = p / (p + 1)
    # the grid of `effects.drift` steps by a factor 10^(3/47) ~ 1.16; the
    # prediction-error curve is flat near its optimum, so 25 % in the gain
    assert abs(np.log(lev["level"][0] / alpha)) < np.log(1.25)
    innovation = SIGMA**2 * (p + 1)  # the innovation variance of the level model
    assert abs(np.mean(e_est[NOISE_MODELS.index("level")] ** 2) / innovation - 1) < (
        0.05
    )


@pytest.mark.statistical
def test_the_flicker_model_recovered_on_a_fractional_record():
    # ARFIMA(0, d, 0) built from its MA(infinity) weights psi_k = psi_{k-1}
    # (k - 1 + d) / k (`effects/coloured_noise.py` inverts them: no shared
    # formula), d = 0.4. Tolerance: 5 asymptotic standard errors of d,
    # sqrt(6 / (pi^2 n)) (Whittle), plus half the fitted grid's step of 1/20;
    # the innovation variance as above, plus the truncation of the weights at
    # the record's start, which the variance test's 5 sd covers at n = N
    d, n = 0.4, 2 * N
    k = np.arange(1, n)
    psi = np.concatenate([[1.0], np.cumprod((k - 1 + d) / k)])
    e = SIGMA * np.asarray(jr.normal(jr.key(5), (n,)))
    r = scipy.signal.oaconvolve(e, psi)[:n]
    fitted, e_est, e_val = _fit(r)
    assert abs(fitted["fractional"][0] - d) < 5 * np.sqrt(6 / (np.pi**2 * N)) + 0.025
    j = NOISE_MODELS.index("fractional")
    tol_var = 5 * SIGMA**2 * np.sqrt(2 / N)
    assert abs(np.mean(e_est[j] ** 2) - SIGMA**2) < tol_var
    assert abs(np.mean(e_val[j] ** 2) - SIGMA**2) < tol_var
    # and of the one-parameter models it leaves the least SSE (AR(1) and the
    # level follow a power-law memory only in part)
    for m in ("ar1", "level"):
        assert np.mean(e_est[j] ** 2) < np.mean(e_est[NOISE_MODELS.index(m)] ** 2), m


def _random_walk_case(key, n=400, std=0.003):
    case = tiny_case(key, "none", n=n, noise=0.01)
    for i, rec in enumerate(case[2:]):
        steps = std * np.asarray(jr.normal(jr.fold_in(key, 7 + i), (n,)))
        rec["y"] = rec["y"] + np.cumsum(steps)
    return case


@pytest.mark.slow
@pytest.mark.statistical
def test_false_alarm_rate_on_noise_only_cases():
    # Noise-only cases with fixed keys and the correct nominal: white noise (any
    # name but `none` is an alarm), AR(1) and random-walk noise (a deterministic
    # name is an alarm: the noise classes are right there). The rule bounds the
    # rate of each by ALPHA (`decide` docstring); with M cases per kind, more
    # alarms than the binomial(M, ALPHA) 0.999 quantile has probability < 1e-3
    # under that bound: the false-failure rate of each count.
    m = 16
    kinds = {
        "white": [tiny_case(jr.key(2000 + i), "none", noise=0.01) for i in range(m)],
        "ar1": [
            coloured_case(jr.key(3000 + i), n=400, pole=0.8, std=0.01) for i in range(m)
        ],
        "random_walk": [_random_walk_case(jr.key(4000 + i)) for i in range(m)],
    }
    items = [c for cases in kinds.values() for c in cases]
    out = diagnose_many(items, rule="likelihood")
    bound = scipy.stats.binom.ppf(0.999, m, decide.ALPHA)
    noise_names = {"none", "coloured_noise", "drift"}
    for k, name in enumerate(kinds):
        named = [d.effect for d in out[k * m : (k + 1) * m]]
        ok = {"none"} if name == "white" else noise_names
        alarms = sum(e not in ok for e in named)
        assert alarms <= bound, (name, named)
    # the noise is seen where it is strong: most AR(1) and random-walk cases get
    # their noise class (a power check, not a derived bound)
    assert sum(d.effect == "coloured_noise" for d in out[m : 2 * m]) > m // 2
    assert sum(d.effect == "drift" for d in out[2 * m :]) > m // 2


def test_threshold_bonferroni_and_rule_switch():
    # the threshold is the t_{B-1} quantile at 1 - alpha / K (scipy), growing in K
    t = [decide.threshold(k) for k in (1, 10, 100)]
    assert np.isclose(t[1], scipy.stats.t.ppf(1 - decide.ALPHA / 10, 19))
    assert t[0] < t[1] < t[2]
    assert set(RULES) == {"cascade", "likelihood"}
    with pytest.raises(ValueError, match="unknown rule"):
        diagnose_many([tiny_case(jr.key(0), "none")], rule="bayes")


def test_cli_rule_option_offers_the_rules():
    from hamjax.cli.main import build_parser

    parser = build_parser(["diagnose"])
    args = parser.parse_args(["diagnose", "c", "--out", "o", "--rule", "likelihood"])
    assert args.rule == "likelihood"
    assert parser.parse_args(["diagnose", "c", "--out", "o"]).rule == "cascade"
    for rule in RULES:
        assert parser.parse_args(["diagnose", "c", "--out", "o", "--rule", rule])
    with pytest.raises(SystemExit):
        parser.parse_args(["diagnose", "c", "--out", "o", "--rule", "bayes"])
