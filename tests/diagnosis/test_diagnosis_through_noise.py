"""The deterministic gap judged through the noise predictor (`attribute`, *the gap
through the noise predictor*): under a strongly coloured disturbance the plain
simulation comparison has no power, the whitened one keeps its level. Residuals are
built directly (no fit), so the statistic itself is tested: fixed keys."""

from types import SimpleNamespace

import jax.random as jr
import numpy as np
import scipy.signal
import scipy.stats

from hamjax.diagnosis.attribute import (
    Z_STAR,
    Candidate,
    _gap_through_noise,
    _lr_through_noise,
    _nested_lr,
    rms,
    significant,
)
from hamjax.diagnosis.layout import LR_ALPHA
from hamjax.diagnosis.noise_fit import predictor_errors


POLE = 0.95
N = 600
NAMES = ("parameter_mismatch", "saturation", "backlash", "time_delay")


def _ar1(key, n=N):
    e = np.asarray(jr.normal(key, (n,)))
    return scipy.signal.lfilter([1.0], [1.0, -POLE], e)


def _square(n=N, period=37, phase=0):
    k = np.arange(n) + phase
    return np.where((k // (period // 2)) % 2 == 0, 1.0, -1.0)


def _noise_candidate(r_nom):
    err = predictor_errors("ar1_pole", POLE, r_nom)
    params = {"ar1_pole": {"value": POLE, "std": 0.0}}
    return Candidate(
        "coloured_noise", -1, rms(err), err, None, params, "one_step_prediction"
    )


def _decide(residuals: dict, r_nom):
    det = [
        Candidate(n, i, rms(r), r, None) for i, (n, r) in enumerate(residuals.items())
    ]
    tests = {}
    named = _gap_through_noise(
        _noise_candidate(r_nom), {c.effect: c for c in det}, det, significant, tests
    )
    return (None if named is None else named.effect), tests


def test_an_effect_under_a_coloured_disturbance_is_named_through_the_filter():
    named = []
    plain = []
    for k in range(20):
        n = _ar1(jr.key(k))
        s = 1.2 * _square()
        r_nom = n + s
        residuals = {
            "parameter_mismatch": n + 0.7 * s,  # a re-fit takes part of it
            "saturation": n,  # the effect explains it
            "backlash": n + 0.5 * s,
            "time_delay": n + 0.9 * s,
        }
        plain.append(significant(r_nom, residuals["saturation"], 1.0)[0])
        effect, tests = _decide(residuals, r_nom)
        named.append(effect)
        assert tests["gap_through_noise"]["best"] == "saturation", tests
    # the simulation comparison misses most of them (the disturbance's variance,
    # 1 / (1 - 0.95^2) = 10 innovations' worth, swamps an effect of 1.2; z 1-3 mostly); the
    # whitened one finds the effect's corners against unit innovations
    assert sum(plain) <= 5, plain
    assert named.count("saturation") >= 18, named


def test_no_effect_keeps_the_stated_level():
    # Under "the gap is noise" each candidate's residual is the disturbance minus
    # a fixed difference of predictions (fitted on the other record), so d has
    # mean <= 0: a name is given with probability at most the one-sided t_19 tail
    # at z* per candidate (Bonferroni over the 4 here): p <= 4 * 1.2e-3. Over 300
    # fixed keys the count is then Binomial(300, <= 0.005): more than 6 has
    # probability < 1e-3 at the bound.
    p_one = scipy.stats.t.sf(Z_STAR, 19)
    assert p_one < 1.5e-3
    count = 0
    for k in range(300):
        n = _ar1(jr.key(1000 + k))
        deltas = {name: 0.3 * _square(phase=7 * i) for i, name in enumerate(NAMES)}
        residuals = {name: n - d for name, d in deltas.items()}
        effect, _ = _decide(residuals, n)
        count += effect is not None
    assert count <= 6, count


def _nested_prep(n: int, p_refit, p_effect):
    """A stand-in for `layout.Prepared` with what the nested test reads: row 0
    the re-fit, row 1 the effect's; each given as a number of fitted slots (the
    first ones) or as the fitted slots themselves."""
    sets = [
        set(range(p)) if isinstance(p, int) else set(p) for p in (p_refit, p_effect)
    ]
    slots = max(max(s, default=-1) for s in sets) + 1
    pad = slots + 1  # an index past the slots: padding, not fitted

    def row(fitted):
        idx = sorted(fitted) + [pad] * (slots - len(fitted))
        return SimpleNamespace(idx=np.asarray(idx), free=np.isin(np.arange(slots), idx))

    rows = [("parameter_mismatch", row(sets[0])), ("backlash", row(sets[1]))]
    return SimpleNamespace(
        rows=rows, arrays=SimpleNamespace(anchor=np.zeros(slots)), n_est=n
    )


def _candidates():
    empty = np.zeros(1)
    return (
        Candidate("parameter_mismatch", 0, 0.0, empty, None),
        Candidate("backlash", 1, 0.0, empty, None),
    )


def test_the_likelihood_ratio_through_the_noise_model_is_chi2_under_no_effect():
    # Regression stand-ins for the two prediction-error fits: y = X b + AR(1)
    # noise, the re-fit on X (3 columns), the "effect" on X plus one regressor
    # that is absent; both fitted with the noise filter A fixed (least squares
    # on A-filtered data, which is what a prediction-error fit with A held
    # does). Their one-step-error SSEs go through `_lr_through_noise`: its
    # statistic must then be chi^2_1 (KS test over 400 fixed keys, rejected
    # below p = 1e-3: a false failure once in a thousand). The same sums
    # without the filter (an output-error fit's) give a ratio several times
    # larger: what makes the plain likelihood ratio unusable under a coloured
    # disturbance.
    n, pole = 500, POLE
    prep = _nested_prep(n, 3, 4)
    pm, best = _candidates()
    fit_of = lambda s_pm, s_d: {  # noqa: E731
        "whitened": {"sse_est": np.array([s_pm, s_d]), "rows": [0, 1]}
    }
    white, plain = [], []
    for k in range(400):
        key = jr.key(5000 + k)
        x = np.array(jr.normal(key, (n, 4)))
        x[:, 3] = scipy.signal.lfilter([1.0], [1.0, -0.9], x[:, 3])  # slow
        y = x[:, :3] @ np.array([1.0, -0.5, 0.3]) + _ar1(jr.fold_in(key, 1), n)
        filt = lambda z: scipy.signal.lfilter([1.0, -pole], [1.0], z, axis=0)  # noqa: E731
        for out, f in ((white, filt), (plain, lambda z: z)):
            fy, fx = f(y), f(x)
            s = [
                np.sum((fy - fx[:, :m] @ np.linalg.lstsq(fx[:, :m], fy)[0]) ** 2)
                for m in (3, 4)
            ]
            test = _lr_through_noise(prep, fit_of(*s), pm, best, 1, z=3.0)
            out.append(test["lr"])
    assert scipy.stats.kstest(white, scipy.stats.chi2(1).cdf).pvalue > 1e-3
    assert np.median(plain) > 3 * scipy.stats.chi2(1).median(), np.median(plain)


def test_the_likelihood_ratio_through_the_noise_model_needs_nested_whitened_fits():
    pm, best = _candidates()
    fit = {"whitened": {"sse_est": np.array([10.0, 5.0]), "rows": [0, 1]}}
    # nested, both fitted by prediction error: a test (significant: far over
    # the chi^2 threshold, validation z over Z_CONFIRM)
    test = _lr_through_noise(_nested_prep(100, 3, 4), fit, pm, best, 4, z=3.0)
    assert test is not None and test["significant"], test
    assert not _lr_through_noise(_nested_prep(100, 3, 4), fit, pm, best, 4, z=1.0)[
        "significant"
    ]
    # the effect's row kept its output-error fit: no test
    half = {"whitened": {"sse_est": fit["whitened"]["sse_est"], "rows": [0]}}
    assert _lr_through_noise(_nested_prep(100, 3, 4), half, pm, best, 4, z=3.0) is None
    assert _lr_through_noise(_nested_prep(100, 3, 4), {}, pm, best, 4, z=3.0) is None
    # as many parameters as the re-fit and all of them the re-fit's: nested in
    # it, no test
    assert _lr_through_noise(_nested_prep(100, 4, 4), fit, pm, best, 4, z=3.0) is None


def test_the_nested_test_counts_the_slots_beyond_the_refit():
    # A profile start that re-fits the numerator with the map held at identity
    # frees as many slots as a re-fit of the map and the poles, not the same
    # ones: the model freeing both nests each, and the test is that model's,
    # with k the slots beyond the re-fit's (here 2: the chi^2_2 bound), the
    # residual variance on n - (p_refit + k) degrees of freedom.
    pm, best = _candidates()
    refit, effect = {0, 1, 2, 3}, {0, 1, 4, 5}
    fit = {"whitened": {"sse_est": np.array([10.0, 5.0]), "rows": [0, 1]}}
    prep = _nested_prep(100, refit, effect)
    test = _lr_through_noise(prep, fit, pm, best, 4, z=3.0)
    assert test is not None and test["significant"], test
    assert np.isclose(test["lr"], (10.0 - 5.0) / (5.0 / (100 - 6)))
    assert np.isclose(test["threshold"], 2 * np.log(4 / LR_ALPHA))
    # five slots beyond the re-fit's: the chi^2_5 quantile at alpha / m
    prep = _nested_prep(100, refit, {0, *range(4, 9)})
    test = _nested_lr(prep, fit["whitened"]["sse_est"], pm, best, 4, z=3.0)
    assert np.isclose(test["threshold"], scipy.stats.chi2.isf(LR_ALPHA / 4, 5))
    assert np.isclose(test["lr"], 5.0 / (5.0 / (100 - 9)))
    # every slot of the candidate is the re-fit's: nested in it, never significant
    prep = _nested_prep(100, refit, {0, 1})
    test = _nested_lr(prep, fit["whitened"]["sse_est"], pm, best, 4, z=3.0)
    assert not test["significant"], test
