"""The two noise-model classes, `drift` (a trend plus the white noise) and
`coloured_noise` (no white part), split at the local level's white share
$1 - \\alpha = 1/2$ (`effects/drift.py`), and the flicker (fractional) predictor
of `coloured_noise`, against closed forms."""

import jax.random as jr
import numpy as np
import pytest
from scipy import signal

from hamjax.diagnosis.effects.drift import MAX_DRIFT_GAIN
from hamjax.diagnosis.noise_fit import noise_filter, noise_fit_numpy, predictor_errors


N = 4000


def kalman_gain(q: float) -> float:
    """Steady-state gain of a random-walk level (increment variance q) in unit
    white noise: P^2 = q (P + 1), K = P / (P + 1)."""
    p = 0.5 * (q + np.sqrt(q * q + 4 * q))
    return p / (p + 1)


def level_in_white(key, q: float, n: int = 2 * N) -> np.ndarray:
    k1, k2 = jr.split(key)
    level = np.cumsum(np.sqrt(q) * np.asarray(jr.normal(k1, (n,))))
    return level + np.asarray(jr.normal(k2, (n,)))


def split(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    return x[:N], x[N:]


def test_gain_restrictions_hold():
    # the drift fit never leaves [0, 1/2]; the coloured level never enters it
    x = np.cumsum(np.ones(N))  # a pure ramp: the unrestricted optimum is 1
    fit = noise_fit_numpy(x, x)
    assert fit["drift"][0] <= MAX_DRIFT_GAIN
    assert fit["coloured_noise"][2] == "level_gain"
    assert fit["coloured_noise"][0] > MAX_DRIFT_GAIN


def test_a_slow_random_walk_in_white_noise_is_drift(getkey):
    # q = 0.05: closed-form gain 0.20, white share 0.80. The estimate's spread
    # at N = 4000 (the grid's steps near 0.2 are 0.03) measured over 100 seeds:
    # mean 0.199, std 0.010, range 0.171..0.230; 0.08 is 8 std.
    q = 0.05
    est, val = split(level_in_white(getkey(), q))
    fit = noise_fit_numpy(est, val)
    value, _, name, sse, _ = fit["drift"]
    assert name == "level_gain"
    assert abs(value - kalman_gain(q)) < 0.08, value
    # the estimation likelihood, which picks the class, prefers drift
    assert sse < fit["coloured_noise"][3]


def test_a_random_walk_without_white_part_is_coloured_noise(getkey):
    # the white part absent (white share 1 - K ~ 0.01 at q = 1e4): a level of gain
    # near 1 and an AR(1) of pole near 1 predict it alike (which fits better is
    # chance); either is coloured noise's and beats the drift capped at 1/2
    est, val = split(level_in_white(getkey(), 1e4))
    fit = noise_fit_numpy(est, val)
    value, _, _, sse, _ = fit["coloured_noise"]
    assert value > 0.9
    assert sse < fit["drift"][3]


@pytest.mark.parametrize("pole", [0.7, 0.95])
def test_an_ar1_process_is_coloured_noise_with_its_pole(getkey, pole):
    # AR(1) without a white part: least squares is consistent, se of the pole
    # sqrt((1 - a^2) / N) <= 0.012, checked to 0.05 (over 4 se)
    e = np.asarray(jr.normal(getkey(), (2 * N,)))
    x = np.zeros(2 * N)
    for k in range(1, 2 * N):
        x[k] = pole * x[k - 1] + e[k]
    est, val = split(x)
    fit = noise_fit_numpy(est, val)
    value, err, name, sse, _ = fit["coloured_noise"]
    assert name == "ar1_pole" and abs(value - pole) < 0.05
    assert sse < fit["drift"][3]
    # its validation errors are the innovations, within their sampling spread
    assert abs(np.std(err[1:]) - 1.0) < 0.05


@pytest.mark.parametrize(("name", "value"), [("ar1_pole", 0.8), ("level_gain", 0.3)])
def test_host_predictor_is_the_jax_one(getkey, name, value):
    # the veto's NumPy twin against the scans the fits use, to rounding
    import jax.numpy as jnp

    from hamjax.diagnosis.effects.coloured_noise import ar1_errors
    from hamjax.diagnosis.effects.drift import local_level_errors

    r = np.cumsum(np.asarray(jr.normal(getkey(), (777,))))
    scan = ar1_errors if name == "ar1_pole" else local_level_errors
    want = np.asarray(scan(jnp.asarray(r), jnp.asarray(value)))
    np.testing.assert_allclose(
        predictor_errors(name, value, r), want, rtol=1e-12, atol=1e-12
    )
    with pytest.raises(ValueError, match="unknown noise predictor"):
        predictor_errors("ma_coefficient", 0.1, r)


def flicker(key, beta: float, n: int = 2 * N) -> np.ndarray:
    """1/f^beta noise by shaping white noise's spectrum (no predictor's formula)."""
    spec = np.fft.rfft(np.asarray(jr.normal(key, (n,))))
    f = np.fft.rfftfreq(n)
    spec[1:] /= f[1:] ** (beta / 2)
    spec[0] = 0.0
    x = np.fft.irfft(spec, n)
    return x / np.std(x)


def test_flicker_noise_is_coloured_noise_with_its_fractional_order(getkey):
    # 1/f noise: d = beta / 2 = 0.5 (`effects/coloured_noise.py`). Over 60 seeds
    # at N = 4000: d 0.50..0.60 (mean 0.548, std 0.013: the spectrum 1/f and the
    # model's |2 sin(w/2)|^-1 part at high frequency), the class's SSE 0.90..0.95
    # of the drift's; 0.15 and "below the drift's" leave 7 std and 5 % of margin
    est, val = split(flicker(getkey(), 1.0))
    fit = noise_fit_numpy(est, val)
    value, err, name, sse, stand_in = fit["coloured_noise"]
    assert name == "fractional_d" and abs(value - 0.5) < 0.15, (name, value)
    assert sse < fit["drift"].est_sse
    # its stand-in for a finite filter is one of the low-order predictors
    assert stand_in[0] in ("ar1_pole", "level_gain")
    with pytest.raises(ValueError, match="no finite filter"):
        noise_filter("fractional_d", value)


@pytest.mark.parametrize("d", [0.25, 0.5, 0.9])
def test_the_fractional_predictor_recovers_the_innovations(getkey, d):
    # ARFIMA(0, d, 0) from rest, built by its MA weights psi_k = psi_{k-1} (k-1+d)/k,
    # the inverse series of the predictor's pi weights: the one-step errors are
    # the innovations to rounding (a closed form), on the host and in JAX alike
    import jax.numpy as jnp

    from hamjax.diagnosis.effects.coloured_noise import fractional_errors

    n = 777
    eps = np.asarray(jr.normal(getkey(), (n,)))
    k = np.arange(1, n)
    psi = np.concatenate([[1.0], np.cumprod((k - 1 + d) / k)])
    x = signal.lfilter(psi, [1.0], eps)
    np.testing.assert_allclose(predictor_errors("fractional_d", d, x), eps, atol=1e-9)
    np.testing.assert_allclose(
        np.asarray(fractional_errors(jnp.asarray(x), jnp.asarray(d))), eps, atol=1e-9
    )


def test_the_prediction_error_refits_whiten_by_the_flicker_models_stand_in(getkey):
    # where the flicker model is the case's noise model, `schedule`'s re-fits need
    # a finite filter: `whitening_noise`'s filter is the low-order stand-in,
    # while the judgement through the noise model keeps the fractional predictor
    from hamjax.diagnosis.attribute import Candidate, whitening_noise

    est, val = split(flicker(getkey(), 1.0))
    fit = noise_fit_numpy(est, val)
    cands = {
        effect: Candidate(
            effect,
            -1,
            float(np.sqrt(np.mean(p.errors**2))),
            p.errors,
            None,
            params={p.name: {"value": p.value, "std": 0.0}},
            est_sse=p.est_sse,
            whitening=p.whitening,
        )
        for effect, p in fit.items()
    }
    assert cands["coloured_noise"].params.keys() == {"fractional_d"}
    assert whitening_noise(cands, val).whitening == fit["coloured_noise"].whitening
