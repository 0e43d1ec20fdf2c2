"""Noise models: moments of WhiteNoise and AR1Noise against their theory, the SNR
helper and `add_noise`.

Statistical tests use fixed keys; each statistic is normalised by its standard
error and compared with Z = norm.ppf(1 - P/2), P = 1e-3, so a test with k such
checks has a false-failure rate of at most k * 1e-3 over keys (deterministic for
the fixed key used here)."""

import jax
import jax.numpy as jnp
import jax.random as jr
import numpy as np
import pytest
from scipy.stats import norm

import hamjax as hj


P = 1e-3
Z = norm.ppf(1 - P / 2)  # 3.29


def _lag1(e):
    e = e - e.mean()
    return np.sum(e[1:] * e[:-1]) / np.sum(e * e)


@pytest.mark.statistical
def test_white_noise_moments():
    # 4 checks: false-failure rate <= 4e-3.
    n, std = 20_000, 0.7
    e = np.asarray(hj.WhiteNoise(std).sample(jr.key(11), n))
    assert e.shape == (n,)
    assert abs(e.mean()) < Z * std / np.sqrt(n)
    # Var of the sample variance of Gaussian data: 2 sigma^4 / (n - 1).
    assert abs(e.var(ddof=1) - std**2) < Z * std**2 * np.sqrt(2 / (n - 1))
    assert abs(_lag1(e)) < Z / np.sqrt(n)  # white: r1 ~ N(0, 1/n)
    # Gaussian: the fraction beyond 2 std is 2 * (1 - Phi(2)), a binomial count.
    p2 = 2 * norm.sf(2.0)
    frac = np.mean(np.abs(e) > 2 * std)
    assert abs(frac - p2) < Z * np.sqrt(p2 * (1 - p2) / n)


@pytest.mark.statistical
@pytest.mark.parametrize("pole", [0.8, -0.5])
def test_ar1_noise_moments(pole):
    # 3 checks per pole: false-failure rate <= 6e-3 for the two cases.
    n, std = 40_000, 0.5
    e = np.asarray(hj.AR1Noise(std, pole).sample(jr.key(12), n))
    rho = pole
    # Large-sample variances for a Gaussian AR(1) (Bartlett's formulas).
    se_mean = std * np.sqrt((1 + rho) / (1 - rho) / n)
    se_var = std**2 * np.sqrt(2 * (1 + rho**2) / (1 - rho**2) / n)
    se_r1 = np.sqrt((1 - rho**2) / n)
    assert abs(e.mean()) < Z * se_mean
    assert abs(e.var() - std**2) < Z * se_var
    assert abs(_lag1(e) - rho) < Z * se_r1


@pytest.mark.statistical
def test_ar1_noise_is_stationary_from_the_first_sample():
    # Across R independent realisations (per-realisation keys by fold_in), the
    # first and the last sample both have variance std^2: 2 checks, <= 2e-3.
    R, n, std = 4000, 50, 1.3
    keys = jax.vmap(lambda r: jr.fold_in(jr.key(13), r))(jnp.arange(R))
    e = np.asarray(jax.vmap(lambda k: hj.AR1Noise(std, 0.9).sample(k, n))(keys))
    for col in (e[:, 0], e[:, -1]):
        assert abs(col.var(ddof=1) - std**2) < Z * std**2 * np.sqrt(2 / (R - 1))


def test_noise_vmap_equals_loop():
    keys = jr.split(jr.key(3), 4)
    noise = hj.AR1Noise(0.3, 0.6)
    batched = jax.vmap(lambda k: noise.sample(k, 30))(keys)
    loop = np.stack([noise.sample(k, 30) for k in keys])
    # Fixed key 3 (same draws each run); vmap and the loop do the same AR(1) steps,
    # |e| <~ 1.5 here, so 1e-15 is a few ulp of the values.
    np.testing.assert_allclose(batched, loop, rtol=1e-14, atol=1e-15)


def test_add_noise_is_signal_plus_sample():
    w = jnp.sin(jnp.linspace(0.0, 5.0, 100))
    key = jr.key(5)
    for noise in (hj.WhiteNoise(0.2), hj.AR1Noise(0.2, 0.5)):
        y = hj.add_noise(key, w, noise)
        np.testing.assert_allclose(y - w, noise.sample(key, 100), rtol=0, atol=1e-15)
    np.testing.assert_array_equal(hj.add_noise(key, w, hj.WhiteNoise(0.0)), w)


def test_noise_std_for_snr_definition():
    w = 3.0 * jnp.sin(jnp.linspace(0.0, 20.0, 500)) + 1.0
    for snr_db in (0.0, 10.0, 23.5):
        s = hj.noise_std_for_snr(w, snr_db)
        # SNR = var(w) / var(e) in dB (documented).
        np.testing.assert_allclose(10 * np.log10(np.var(w) / s**2), snr_db, atol=1e-12)


@pytest.mark.statistical
def test_noise_std_for_snr_achieved():
    # The realised SNR of add_noise: 10 log10(var w / var e) has standard error
    # (10 / ln 10) sqrt(2 / n) from the sample variance of e. 1 check: 1e-3.
    n, snr_db = 20_000, 15.0
    w = jnp.sin(0.01 * jnp.arange(n)) + 0.3 * jnp.sin(0.07 * jnp.arange(n))
    y = hj.add_noise(jr.key(21), w, hj.WhiteNoise(hj.noise_std_for_snr(w, snr_db)))
    e = np.asarray(y - w)
    achieved = 10 * np.log10(np.var(np.asarray(w)) / np.var(e, ddof=1))
    assert abs(achieved - snr_db) < Z * 10 / np.log(10) * np.sqrt(2 / (n - 1))
