"""`FGIDesign` owns Table 2's period and transient rules (seed 000, Remark 2a)."""

import math

import numpy as np
import pytest

import hamjax as hj
from hamjax.signals import FGIDesign


LEVELS = (-2.0, -0.7, 0.7, 2.0)


@pytest.mark.parametrize("omega, dt, settle", [(0.5, 0.01, 20.0), (1.8, 0.02, 3.3)])
def test_design_follows_the_period_and_transient_rules(omega, dt, settle):
    d = FGIDesign.settling(LEVELS, omega=omega, dt=dt, periods=8, settle=settle)
    m = 2 * len(LEVELS) - 2
    assert d.period_samples % m == 0
    assert d.omega == pytest.approx(2 * math.pi / (d.period_samples * dt), rel=1e-15)
    # the rounded period is the multiple of 2n-2 samples nearest the requested one
    assert abs(d.period_samples - 2 * math.pi / (omega * dt)) <= m / 2
    # the transient is the fewest whole periods lasting at least `settle`
    period = d.period_samples * dt
    assert d.transient_periods * period >= settle > (d.transient_periods - 1) * period
    t, v = d.input()
    assert v.shape[0] == d.period_samples * (d.transient_periods + 8)
    _, ref = hj.periodic_staircase(
        np.asarray(LEVELS),
        period_samples=d.period_samples,
        periods=d.total_periods,
        dt=dt,
    )
    np.testing.assert_array_equal(np.asarray(v), np.asarray(ref))
    kw = d.identify_kwargs(100)
    assert kw == {
        "period_samples": d.period_samples,
        "periods": 8,
        "dt": dt,
        "start": 100 + d.transient_periods * d.period_samples,
    }


def test_a_frequency_too_high_for_the_sampling_is_refused():
    with pytest.raises(ValueError, match="too high"):
        FGIDesign.settling(LEVELS, omega=500.0, dt=0.01, periods=8, settle=1.0)
