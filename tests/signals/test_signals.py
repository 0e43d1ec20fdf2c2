"""Experiment signals: exact sample-level structure of seed 000's (3), (4a-b), (24)
and seed 001's (5.1); FGI period rounding; random staircase, PRBS and multisine."""

import math

import jax
import jax.numpy as jnp
import jax.random as jr
import numpy as np
import pytest

import hamjax as hj


def _levels(n):
    return np.sort(np.linspace(-1.0, 2.0, n) + 0.01 * np.arange(n) ** 2)


@pytest.mark.parametrize("n", [2, 3, 5])
def test_initialisation_step(n):
    # Eq. (3): v_M on [0, T0), v_m on [T0, 2 T0).
    levels = _levels(n)
    t, v = hj.initialisation_step(levels, duration=0.3, dt=0.1)
    np.testing.assert_allclose(t, [0.0, 0.1, 0.2, 0.3, 0.4, 0.5], atol=1e-15)
    np.testing.assert_array_equal(v, [levels[-1]] * 3 + [levels[0]] * 3)


@pytest.mark.parametrize("n", [3, 4, 7])
def test_nbbi_staircase_structure(n):
    # Eq. (4a-b): V_{i+1} on [i N Tr, (i+1) N Tr) for i = 0..2n-3, with
    # V_{n+i} = V_{n-i}: up V1..Vn, then down V_{n-1}..V2.
    levels = _levels(n)
    hold, dt = 0.5, 0.1
    t, v = hj.nbbi_staircase(levels, hold=hold, dt=dt)
    per = 5
    assert v.shape == t.shape == ((2 * n - 2) * per,)
    np.testing.assert_allclose(np.diff(t), dt, atol=1e-14)
    assert t[0] == 0.0
    for i in range(2 * n - 2):
        expected = (
            levels[i] if i <= n - 1 else levels[2 * n - i - 2]
        )  # 0-based V_{2n-i-1}
        np.testing.assert_array_equal(v[i * per : (i + 1) * per], expected)
    np.testing.assert_array_equal(v[per * (n - 1)], levels[-1])  # the top V_n
    np.testing.assert_array_equal(v[-1], levels[1])  # last plateau: V_2


@pytest.mark.parametrize("n", [3, 4, 6])
def test_periodic_staircase_structure(n):
    # Eq. (24): v(t) = V_i for t in [(i-1) tau, i tau), i = 1..2n-2, period T.
    levels = _levels(n)
    m = 2 * n - 2
    tau = 3
    t, v = hj.periodic_staircase(levels, period_samples=m * tau, periods=4, dt=0.2)
    assert v.shape == (4 * m * tau,)
    cycle = np.concatenate([levels, levels[-2:0:-1]])
    np.testing.assert_array_equal(v, np.tile(np.repeat(cycle, tau), 4))
    np.testing.assert_array_equal(v[: m * tau], v[m * tau : 2 * m * tau])  # periodic
    # deterministic: t = arange * dt, one rounding
    np.testing.assert_allclose(t[-1], (v.shape[0] - 1) * 0.2, rtol=1e-14)


@pytest.mark.parametrize("n", [1, 2, 3, 5])
def test_pe_impulse_sequence_structure(n):
    # Eq. (5.1): period T = 7n; v(t_k + 2n) = V1, v(t_k + (2+j) n) = Vj (j = 2..4),
    # v = 0 elsewhere.
    V = np.array([-6.0, -3.0, 3.0, 6.0])
    t, v = hj.pe_impulse_sequence(V, order=n, periods=3, dt=1.0)
    assert v.shape == (21 * n,)
    np.testing.assert_array_equal(t, np.arange(21 * n))
    for k in range(3):
        period = np.asarray(v[7 * n * k : 7 * n * (k + 1)])
        expected = np.zeros(7 * n)
        expected[2 * n] = V[0]
        for j in (2, 3, 4):
            expected[(2 + j) * n] = V[j - 1]
        np.testing.assert_array_equal(period, expected)
    # Every value lies in {0, V1..V4} and each level occurs once per period.
    for level in V:
        assert np.sum(np.asarray(v) == level) == 3


@pytest.mark.parametrize(
    "omega,dt,n", [(1.0, 0.01, 5), (2.0, 0.05, 4), (0.3, 0.1, 3), (7.0, 0.02, 6)]
)
def test_fgi_period_samples_rounding(omega, dt, n):
    period, omega_used = hj.fgi_period_samples(omega, dt, n)
    m = 2 * n - 2
    assert isinstance(period, int) and period % m == 0 and period >= m
    # deterministic: the same expression, at most 1 ulp apart (2.2e-16)
    assert omega_used == pytest.approx(2 * math.pi / (period * dt), rel=1e-15)
    # It is the nearest multiple of 2n-2 to the exact period 2 pi / (omega dt).
    exact = 2 * math.pi / (omega * dt)
    assert abs(period - exact) <= m / 2 + 1e-9


def test_fgi_period_rejects_too_high_omega():
    # T/dt = 2 pi / (100 * 0.1) = 0.63 samples: fewer than 2n-2 = 4.
    with pytest.raises(ValueError, match="too high"):
        hj.fgi_period_samples(100.0, 0.1, 3)
    with pytest.raises(ValueError, match="omega must be finite and > 0"):
        hj.fgi_period_samples(-1.0, 0.1, 3)


def test_fgi_period_feeds_periodic_staircase():
    period, _ = hj.fgi_period_samples(1.0, 0.01, 5)
    _, v = hj.periodic_staircase(_levels(5), period_samples=period, periods=2, dt=0.01)
    assert v.shape == (2 * period,)


def test_random_staircase_holds_levels(getkey):
    # Any draw: exact checks; 11 distinct uniform levels fail only if two of 11
    # doubles coincide (probability ~ 55 * 2^-52).
    key = getkey()
    t, v = hj.random_staircase(key, n_samples=103, hold=10, low=-2.0, high=3.0, dt=0.5)
    assert v.shape == t.shape == (103,)
    np.testing.assert_allclose(t, 0.5 * np.arange(103), atol=1e-14)
    blocks = np.asarray(v[:100]).reshape(10, 10)
    assert np.all(blocks == blocks[:, :1])
    np.testing.assert_array_equal(v[100:], v[100])  # a truncated last level
    assert np.all((np.asarray(v) >= -2.0) & (np.asarray(v) <= 3.0))
    assert len(np.unique(np.asarray(v))) == 11
    np.testing.assert_array_equal(
        hj.random_staircase(key, n_samples=103, hold=10, low=-2.0, high=3.0, dt=0.5)[1],
        v,
    )


def test_prbs_levels_and_hold(getkey):
    _, v = hj.prbs(getkey(), n_samples=400, hold=4, amplitude=0.7)
    values = np.asarray(v)
    assert set(np.unique(values)) == {-0.7, 0.7}
    blocks = values.reshape(100, 4)
    assert np.all(blocks == blocks[:, :1])
    # 99 fair bit changes: 0 or 99 switches have probability 2^-98 for any seed
    switches = np.sum(blocks[1:, 0] != blocks[:-1, 0])
    assert 0 < switches < 99


def test_multisine_periodic_rms_and_spectrum(getkey):
    n, harmonics = 256, 20
    _, v = hj.multisine(getkey(), n_samples=n, harmonics=harmonics, rms=1.7)
    v = np.asarray(v)
    # Any phases: the rms of 256 squares (positive terms) has relative error
    # <= 256 u = 2.8e-14. The FFT bins are n A / 2 ~ 70 whatever the phases, so the
    # FFT's ~1e-14 relative error is far below rtol 1e-10 / atol 1e-10.
    np.testing.assert_allclose(np.sqrt(np.mean(v**2)), 1.7, rtol=1e-12)
    spectrum = np.abs(np.fft.rfft(v))
    # Equal amplitudes on harmonics 1..H, nothing elsewhere: periodic in n samples.
    np.testing.assert_allclose(spectrum[1 : harmonics + 1], spectrum[1], rtol=1e-10)
    np.testing.assert_allclose(spectrum[0], 0.0, atol=1e-10)
    np.testing.assert_allclose(spectrum[harmonics + 1 :], 0.0, atol=1e-10)


def test_signals_accept_traced_levels():
    # Levels may be traced (vmap over level sets); value checks then are skipped.
    levels = jnp.array([[0.0, 1.0, 2.0, 3.0], [-1.0, 0.0, 0.5, 4.0]])
    out = jax.vmap(lambda lv: hj.nbbi_staircase(lv, hold=1.0, dt=0.5)[1])(levels)
    for row, lv in zip(out, levels, strict=True):
        np.testing.assert_array_equal(row, hj.nbbi_staircase(lv, hold=1.0, dt=0.5)[1])
    pe = jax.vmap(lambda lv: hj.pe_impulse_sequence(lv, order=2, periods=1)[1])(levels)
    np.testing.assert_array_equal(
        pe[1], hj.pe_impulse_sequence(levels[1], order=2, periods=1)[1]
    )


def test_random_signals_differ_by_key():
    _, a = hj.random_staircase(jr.key(0), n_samples=50, hold=5, low=0.0, high=1.0)
    _, b = hj.random_staircase(jr.key(1), n_samples=50, hold=5, low=0.0, high=1.0)
    assert not np.array_equal(a, b)
