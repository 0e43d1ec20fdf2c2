"""`probabilities` of a diagnosis: the contract's shape, the named effect on top,
the calibration's monotonicity, and the evidence it reads (`diagnose._tried`)."""

import dataclasses
import math

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from hamjax.diagnosis.attribute import Attribution, Candidate
from hamjax.diagnosis.diagnose import _tried
from hamjax.diagnosis.probabilities import CLASSES, named_confidence, probabilities


CANDIDATES = [c for c in CLASSES if c != "unexplained"]


def _mse(values):
    return dict(zip(CANDIDATES, values, strict=True))


@settings(max_examples=200, deadline=None, derandomize=True)
@given(
    values=st.lists(
        st.floats(1e-8, 1e2, allow_nan=False),
        min_size=len(CANDIDATES),
        max_size=len(CANDIDATES),
    ),
    named=st.sampled_from(CANDIDATES + ["unexplained"]),
    n=st.integers(50, 8000),
    shrink=st.floats(-2.0, 1.5, allow_nan=False),
)
def test_every_class_sums_to_one_and_the_named_effect_is_on_top(
    values, named, n, shrink
):
    # derandomized: the same 200 examples every run
    p = probabilities(named, _mse(values), n, shrink)
    assert set(p) == set(CLASSES)
    assert all(v >= 0 for v in p.values())
    assert math.isclose(sum(p.values()), 1.0, rel_tol=1e-12)
    assert p[named] >= max(v for k, v in p.items() if k != named) - 1e-12
    assert len(CLASSES) == len(set(CLASSES))  # every class once (none tried twice)


def test_more_evidence_for_the_named_effect_means_more_confidence():
    base = _mse([1.0] * len(CANDIDATES))
    conf = []
    for ratio in (1.0, 1.01, 1.1, 2.0, 10.0):
        mse = dict(base, saturation=1.0 / ratio)
        conf.append(named_confidence("saturation", mse, 1000))
    assert conf == sorted(conf) and conf[-1] > conf[0]


def test_a_named_effect_that_is_not_the_best_fit_is_less_sure():
    mse = _mse([1.0] * len(CANDIDATES))
    better = dict(mse, saturation=0.9)
    worse = dict(mse, saturation=1.1)
    assert named_confidence("saturation", better, 1000) > named_confidence(
        "saturation", worse, 1000
    )


def test_what_the_named_effect_leaves_above_the_floor_is_unexplained():
    mse = _mse([1.0] * len(CANDIDATES))
    full = probabilities("saturation", dict(mse, saturation=0.5), 1000, 1.0)
    half = probabilities("saturation", dict(mse, saturation=0.5), 1000, 0.5)
    assert full["unexplained"] == pytest.approx(0.0, abs=1e-15)
    assert half["unexplained"] > 0 and half["saturation"] == pytest.approx(
        full["saturation"]
    )


def test_an_unexplained_gap_is_as_sure_as_the_share_the_best_fit_leaves():
    # named `unexplained` where the best candidate closes 30 % of the gap: its
    # probability is the 70 % left, the candidates share the other 30 %
    mse = dict(_mse([1.0] * len(CANDIDATES)), saturation=0.5)
    p = probabilities("unexplained", mse, 1000, 0.3)
    assert p["unexplained"] == pytest.approx(0.7, rel=1e-12)
    assert sum(v for k, v in p.items() if k != "unexplained") == pytest.approx(0.3)
    assert p["saturation"] == max(v for k, v in p.items() if k != "unexplained")
    # a shrink at or below 0 leaves it all unexplained
    assert probabilities("unexplained", mse, 1000, -0.2)["unexplained"] == 1.0


def _level_errors(r, gain):
    """One-step errors of the local level, written out: l_0 = 0, e_k = r_k - l_k,
    l_{k+1} = l_k + gain e_k."""
    level, out = 0.0, np.empty_like(r)
    for k, rk in enumerate(r):
        out[k] = rk - level
        level += gain * out[k]
    return out


def _rms(x):
    return float(np.sqrt(np.mean(np.square(x))))


def test_a_noise_verdict_is_weighed_like_for_like():
    # Named `drift`, a deterministic rival's evidence is its validation residual
    # through the named predictor (one-step errors), not its simulation residual;
    # `none` keeps the white-noise predictor. Named the rival, nothing changes.
    # The reference: the local level's recursion written out (`_level_errors`).
    rng = np.random.default_rng(0)
    n, gain = 400, 0.3
    r_nominal = 0.05 * np.cumsum(rng.normal(size=n)) + rng.normal(size=n)
    r_effect = r_nominal - 0.5 * np.sin(np.arange(n) / 10)
    e_drift = _level_errors(r_nominal, gain)
    drift = Candidate(
        "drift",
        -1,
        _rms(e_drift),
        e_drift,
        None,
        params={"level_gain": {"value": gain, "std": 0.0}},
        measure="one_step_prediction",
        predictor=("level_gain", gain),
    )
    sat = Candidate("saturation", 3, _rms(r_effect), r_effect, np.zeros(n))
    att = Attribution(
        effect="drift",
        gap_before=_rms(r_nominal),
        gap_after=_rms(e_drift),
        noise_floor=1.0,
        shrink=1.0,
        candidates=[drift, sat],
        chosen=drift,
        tests={},
        r_before=r_nominal,
        y_nominal=np.zeros(n),
    )
    mse = {k: v[0] for k, v in _tried(att).items()}
    assert mse["saturation"] == pytest.approx(
        np.mean(_level_errors(r_effect, gain) ** 2), rel=1e-12
    )
    assert mse["saturation"] < _rms(r_effect) ** 2  # the predictor took the drift
    assert mse["none"] == pytest.approx(_rms(r_nominal) ** 2, rel=1e-12)
    assert mse["drift"] == pytest.approx(_rms(e_drift) ** 2, rel=1e-12)
    # where the class was re-fitted by prediction error, that fit is what is seen
    r_pe = r_nominal - 0.6 * np.sin(np.arange(n) / 10)
    sat_pe = dataclasses.replace(sat, residual=r_pe)
    with_pe = dataclasses.replace(att, whitened={"saturation": sat_pe})
    assert _tried(with_pe)["saturation"][0] == pytest.approx(
        np.mean(_level_errors(r_pe, gain) ** 2), rel=1e-12
    )
    named_sat = dataclasses.replace(with_pe, effect="saturation", chosen=sat)
    mse = {k: v[0] for k, v in _tried(named_sat).items()}
    assert mse["saturation"] == pytest.approx(_rms(r_effect) ** 2, rel=1e-12)
