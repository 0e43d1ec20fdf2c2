"""The extra pole's starts span the nominal's dominant time constant, so a lag far
slower than the nominal's own is recovered (noise-free, against the closed form
of the simulated truth); its continuous form (`held_lag`) is a continuous lag's
exact response to an input linear between samples (scipy's `lsim`), and a
sub-sample sensor lag on a continuous plant is named `extra_pole` in that form."""

import jax.random as jr
import numpy as np
import pytest
import scipy.signal as ss
from scipy.signal import lfilter

from hamjax.diagnosis.augmented import n_max_of, slot_names
from hamjax.diagnosis.diagnose import diagnose_many
from hamjax.diagnosis.effects import StartContext
from hamjax.diagnosis.effects.extra_pole import (
    ExtraPoleEffect,
    lag_factor,
    lag_pole,
)
from hamjax.diagnosis.effects.time_delay import dominant_time_constant
from hamjax.diagnosis.layout import prepare
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
    starts = ExtraPoleEffect().starts(_ctx(t_dom))
    poles = [s["pole"] for s in starts if "pole" in s]
    lags = -1 / np.log(poles)
    # a start at or below a quarter of T_d and one at or above four times it
    assert lags.min() <= t_dom / 4 * (1 + 1e-12)
    assert lags.max() >= 4 * t_dom * (1 - 1e-12)
    assert poles == sorted(poles)
    # beyond the slot's usable range the slowest start is capped, still < 1
    assert lag_pole(1e9) < 1.0
    # without a stable nominal time constant: the fixed starts
    starts = ExtraPoleEffect().starts(_ctx(float("inf")))
    assert [s["pole"] for s in starts if "pole" in s] == [0.3, 0.85]
    # the continuous form starts once, at the sub-sample lag
    assert [s for s in starts if "lag_pole" in s] == [{"lag_pole": 0.3}]


@pytest.mark.parametrize("t_lag", [0.3, 1.0, 7.0])
def test_the_continuous_form_is_a_lag_behind_a_linearly_held_input(t_lag):
    # scipy's lsim interpolates its input linearly between samples and solves
    # the lag exactly over each: the same response to rounding, from rest (the
    # input starts at 0, as the filter's zero state assumes)
    u = np.concatenate([[0.0], np.asarray(jr.normal(jr.key(3), (299,)))])
    t = np.arange(300) * DT
    _, ref, _ = ss.lsim(([1.0], [t_lag * DT, 1.0]), u, t)
    p = np.exp(-1 / t_lag)
    num, den = lag_factor(np.float64(0.0), p)  # slot `lag_pole` alone
    ours = lfilter(np.asarray(num), np.asarray(den), u)
    np.testing.assert_allclose(ours, ref, rtol=0, atol=1e-10)
    # unit static gain; slot `pole` alone is the contract's (1 - p)/(1 - p q^-1)
    assert float(np.sum(num) / np.sum(den)) == pytest.approx(1.0, rel=1e-12)
    num, den = lag_factor(p, np.float64(0.0))
    np.testing.assert_array_equal(np.asarray(num), [1 - p, 0.0])
    np.testing.assert_array_equal(np.asarray(den), [1.0, -p])
    # the identity at 0, 0
    num, den = lag_factor(np.float64(0.0), np.float64(0.0))
    assert list(np.asarray(num)) == [1.0, 0.0] and list(np.asarray(den)) == [1.0, 0.0]


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


@pytest.mark.slow
def test_a_sensor_lag_on_a_continuous_plant_is_named_in_its_continuous_form():
    # a continuous first-order plant (time constant 4 samples) behind a held
    # input, its output read through a sensor lag of 0.4 samples: the cascade
    # discretised exactly (zero-order hold of v; scipy). The nominal is the
    # plant alone. The lag is a pole and a zero in discrete time, which the
    # discrete form (a pole) lacks and a fractional delay (a zero) half has;
    # noise 1e-4: named extra_pole, continuous form, its time constant within
    # 10 % (the output of the plant is not linear between samples: the fit is
    # 5.3 % short here: the bias of the hold, not noise). Beside it the same
    # plant's samples through the continuous form itself: recovered exactly
    # (within 4 standard errors), the gap closed to the noise
    t_plant, t_lag = T_NOMINAL * DT, 0.4 * DT
    cascade = ss.cont2discrete(
        ([1.0], np.polymul([t_plant, 1.0], [t_lag, 1.0])), DT, method="zoh"
    )
    p = float(np.exp(-DT / t_lag))
    num, den = (np.asarray(x) for x in lag_factor(np.float64(0.0), np.float64(p)))
    truths = (
        lambda v: lfilter(*(np.ravel(x) for x in cascade[:2]), v),
        lambda v: lfilter(num, den, lfilter([0.0, 1 - A], [1.0, -A], v)),
    )
    items = []
    for j, truth in enumerate(truths):
        recs = []
        for i in range(2):
            v = staircase(jr.key(60 + i), 1200, hold=7)
            e = 1e-4 * np.asarray(jr.normal(jr.key(70 + 2 * j + i), (1200,)))
            recs.append({"t": np.arange(1200) * DT, "v": v, "y": truth(v) + e})
        items.append((PLANT, DT, *recs))
    physical, exact = diagnose_many(items)
    for d in (physical, exact):
        assert d.effect == "extra_pole", (d.effect, d.tests)
        assert d.ranking[0]["params"]["form"]["value"] == "continuous"
    tc = physical.ranking[0]["params"]["time_constant_seconds"]["value"]
    assert tc == pytest.approx(t_lag, rel=0.1)
    fitted = exact.ranking[0]["params"]["lag_pole"]
    assert abs(fitted["value"] - p) < 4 * fitted["std"] + 1e-6, (p, fitted)
    assert exact.gap_after < 1.1e-4


@pytest.mark.parametrize("fitted", [False, True])
def test_no_row_frees_both_forms_of_the_lag(fitted):
    # `lag_factor` is exact only where at most one of `pole` and `lag_pole` is
    # away from its neutral 0: every candidate row of a case, given or fitted
    # nominal (the starts that re-fit the linear block included), frees one of
    # them at most, and the extra pole's own rows free exactly one
    recs = []
    for i in range(2):
        v = staircase(jr.key(80 + i), 600, hold=20)
        y = lfilter([0.0, 1 - A], [1.0, -A], v)
        recs.append({"t": np.arange(600) * DT, "v": v, "y": y})
    prep = prepare(PLANT, DT, *recs, fitted_nominal=fitted)
    names = slot_names(n_max_of(prep.arrays.anchor.shape[0]))
    cols = [names.index("pole"), names.index("lag_pole")]
    freed = [(name, int(np.sum(np.asarray(row.free)[cols]))) for name, row in prep.rows]
    assert max(k for _, k in freed) <= 1, freed
    own = [k for name, k in freed if name == "extra_pole"]
    assert own and all(k == 1 for k in own), freed
