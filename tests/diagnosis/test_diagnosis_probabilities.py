"""`probabilities` of a diagnosis: the contract's shape, the named effect on top,
and the calibration's monotonicity."""

import math

import pytest
from hypothesis import given, settings, strategies as st

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
