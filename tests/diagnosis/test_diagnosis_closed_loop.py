"""Ljung's test for feedback (`residuals.feedback_test`): its false-alarm rate on
open-loop records and its power on a PI loop."""

import numpy as np
from scipy import signal, stats

from hamjax.diagnosis.residuals import FEEDBACK_ALPHA, feedback_test


def _open_loop(i: int, n: int = 2000):
    rng = np.random.default_rng([11, i])
    v = signal.lfilter([1.0], [1.0, -0.8], rng.standard_normal(n))
    noise = signal.lfilter([1.0], [1.0, -0.9], 0.3 * rng.standard_normal(n))
    y = signal.lfilter([0.0, 0.5], [1.0, -0.7], v) + noise
    # the nominal's gain is 10 % off: the residual holds a model error of past v
    return y - signal.lfilter([0.0, 0.45], [1.0, -0.7], v), v


def _pi_loop(i: int, n: int = 2000):
    """A first-order plant under PI control acting within the sample, setpoint
    steps every 200 samples, a coloured output disturbance."""
    rng = np.random.default_rng([12, i])
    sp = np.repeat(rng.uniform(-1, 1, n // 200 + 1), 200)[:n]
    d = signal.lfilter([1.0], [1.0, -0.95], 0.1 * rng.standard_normal(n))
    v, y = np.zeros(n), np.zeros(n)
    v_prev = e_prev = 0.0
    for k in range(n):
        y[k] = 0.8 * y[k - 1] + 0.2 * v[k - 1] if k else 0.0
        e = sp[k] - (y[k] + d[k])
        v[k] = v_prev + 0.8 * (e - e_prev) + 0.3 * e
        v_prev, e_prev = v[k], e
    return y + d - signal.lfilter([0.0, 0.2], [1.0, -0.8], v), v


def test_false_alarm_rate_on_open_loop_records_is_the_stated_level():
    m = 200
    alarms = sum(feedback_test(*_open_loop(i))["closed_loop"] for i in range(m))
    # Bonferroni makes the level at most FEEDBACK_ALPHA; the count of m independent
    # records exceeds the binomial 99.5 % quantile at that level with prob. < 0.5 %
    assert alarms <= stats.binom.ppf(0.995, m, FEEDBACK_ALPHA)


def test_a_pi_loop_is_seen_closed():
    results = [feedback_test(*_pi_loop(i)) for i in range(20)]
    assert all(r["applicable"] and r["closed_loop"] for r in results)
    # the controller acts within the sample: the strongest lag is 0
    assert all(r["lag"] == 0 for r in results)


def test_short_or_constant_inputs_are_not_tested():
    assert not feedback_test(np.ones(50), np.arange(50.0))["applicable"]
    assert not feedback_test(np.ones(500), np.ones(500))["applicable"]
