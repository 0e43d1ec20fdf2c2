"""The extra pole's starts span the nominal's dominant time constant, so a lag far
slower than the nominal's own is recovered (noise-free, against the closed form
of the simulated truth)."""

import jax.random as jr
import numpy as np
import pytest
from scipy.signal import lfilter

from hamjax.diagnosis.diagnose import diagnose_many
from hamjax.diagnosis.effects import StartContext
from hamjax.diagnosis.effects.extra_pole import ExtraPoleEffect, lag_pole
from hamjax.diagnosis.effects.time_delay import dominant_time_constant
from hamjax.models import DiscreteTransferFunction, Hammerstein, Identity
from hamjax.papers.gap.demo_cases import staircase


DT = 0.1
T_NOMINAL = 4.0  # samples: the nominal lag's time constant
A = float(np.exp(-1 / T_NOMINAL))
PLANT = Hammerstein(Identity(), DiscreteTransferFunction([0.0, 1 - A], [1.0, -A], DT))


def _ctx(t_dom: float) -> StartContext:
    q = {0.02: -1.0, 0.98: 1.0}
    return StartContext(-1.0, 1.0, 1.0, 0.5, DT, q, 0.5, q, 1.0, t_dom=t_dom)


def test_the_starts_bracket_the_dominant_time_constant():
    t_dom = dominant_time_constant(np.array([1.0, -A]), False, DT)
    assert t_dom == pytest.approx(T_NOMINAL, rel=1e-12)
    poles = [s["pole"] for s in ExtraPoleEffect().starts(_ctx(t_dom))]
    lags = -1 / np.log(poles)
    # a start at or below a quarter of T_d and one at or above four times it
    assert lags.min() <= t_dom / 4 * (1 + 1e-12)
    assert lags.max() >= 4 * t_dom * (1 - 1e-12)
    assert poles == sorted(poles)
    # beyond the slot's usable range the slowest start is capped, still < 1
    assert lag_pole(1e9) < 1.0
    # without a stable nominal time constant: the fixed starts
    fixed = [s["pole"] for s in ExtraPoleEffect().starts(_ctx(float("inf")))]
    assert fixed == [0.3, 0.85]


@pytest.mark.slow
def test_a_lag_slower_than_the_nominal_is_recovered():
    # lags of 2 and 60 samples behind a nominal of 4: the slow one is 15 times
    # the nominal's (the fixed starts 0.3 / 0.85 named rate_limit for it); noise
    # 1e-4 on outputs of order 1: named extra_pole, gap closed to the noise (the
    # validation RMS of white noise of std s over 1200 samples is s within 5 %)
    items, poles = [], []
    for T in (2.0, 60.0):
        p = float(np.exp(-1 / T))
        recs = []
        for i in range(2):
            v = staircase(jr.key(40 + i), 1200, hold=150)
            w = lfilter([1 - p], [1.0, -p], lfilter([0.0, 1 - A], [1.0, -A], v))
            y = w + 1e-4 * np.asarray(jr.normal(jr.key(50 + i), (1200,)))
            recs.append({"t": np.arange(1200) * DT, "v": v, "y": y})
        items.append((PLANT, DT, *recs))
        poles.append(p)
    for p, d in zip(poles, diagnose_many(items), strict=True):
        assert d.effect == "extra_pole", (p, d.effect)
        assert d.gap_after < 1.1e-4
        fitted = d.ranking[0]["params"]["pole"]
        assert abs(fitted["value"] - p) < 4 * fitted["std"] + 1e-6, (p, fitted)
