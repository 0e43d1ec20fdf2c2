"""`locate`'s input levels, its direction test on a residual without variance, and
what the report says of a two-level record."""

from types import SimpleNamespace

import numpy as np

from hamjax.diagnosis.locate import LEVELS_COUNTED, by_direction, input_levels, locate
from hamjax.diagnosis.report import report_markdown


def test_input_levels_counts_distinct_values_to_rounding():
    rng = np.random.default_rng(3)
    prbs = np.repeat(rng.choice([-1.7, 1.7], 50), 7)
    assert input_levels(prbs) == 2
    # rounding far below the range (a CSV's last digit) is one level
    assert input_levels(prbs + 1e-13 * rng.standard_normal(prbs.shape)) == 2
    assert input_levels(np.full(40, 0.3)) == 1
    assert input_levels(np.repeat([0.0, 1.0, 2.0], 10)) == 3
    multisine = np.sin(0.1 * np.arange(500)) + 0.5 * np.sin(0.37 * np.arange(500))
    assert input_levels(multisine) == LEVELS_COUNTED


def test_direction_test_of_a_residual_without_variance():
    # an exact noise-free fit leaves a constant (here zero) residual: no
    # autocorrelation to estimate (np.corrcoef would divide 0 by 0), no difference
    v = np.repeat([0.0, 1.0, -1.0, 0.5], 25)
    for r in (np.zeros(100), np.full(100, 0.25)):  # exact means
        out = by_direction(r, v, floor=0.1)
        assert out["difference"] == 0.0 and out["z"] == 0.0
        assert not out["significant"]
    # and a residual that differs by direction still gives its z
    r = 0.25 * (v > 0) + 0.01 * np.random.default_rng(0).standard_normal(100)
    assert by_direction(r, v, floor=0.1)["z"] > 0.0


def _diagnosis(v_est, v_val):
    rng = np.random.default_rng(4)
    n = v_val.shape[0]
    r = 0.1 * rng.standard_normal(n)
    t = np.arange(n) * 0.01
    where = locate(t, v_val, r, r, v_val, 0.1, 0.01, v_est=v_est)
    return SimpleNamespace(
        effect="saturation",
        probabilities={"saturation": 0.6, "parameter_mismatch": 0.4},
        tests={},
        where=where,
        gap_before=0.3,
        gap_after=0.1,
        noise_floor=0.1,
        shrink=1.0,
        gap_definition="simulation error",
        ranking=[
            {
                "effect": "saturation",
                "gap_after": 0.1,
                "measure": "simulation",
                "params": {},
            }
        ],
    )


def test_the_report_says_when_a_record_has_two_input_levels():
    rng = np.random.default_rng(5)
    prbs = np.repeat(rng.choice([-1.0, 1.0], 80), 5)
    noise = rng.standard_normal(400)
    d = _diagnosis(prbs, noise)
    assert d.where["input_levels"] == {"estimation": 2, "validation": LEVELS_COUNTED}
    text = report_markdown(d)
    assert "the estimation record's input takes at most two levels" in text
    assert "on that record a static effect on the input" in text
    assert "cannot be told apart from a gain mismatch" in text
    one = report_markdown(_diagnosis(noise, prbs))
    assert "the validation record's input takes at most two levels" in one
    both = report_markdown(_diagnosis(prbs, prbs))
    assert "the inputs of both records take at most two levels" in both
    assert "on those records a static effect" in both
    assert "seen there at two points" in both
    # a constant input is one level: the map is seen at one point
    flat = report_markdown(_diagnosis(np.full(400, 0.5), noise))
    assert "seen there at one point" in flat
    # a record of many levels on both sides: nothing said
    assert "at most two levels" not in report_markdown(_diagnosis(noise, noise))


def test_the_significance_lines_give_three_digits_nested_too():
    d = _diagnosis(np.sin(np.arange(400.0)), np.cos(np.arange(400.0)))
    d.tests = {
        "evidence": {
            "effective_samples": 233.87654,
            "mse": {"none": 0.36182950652, "drift": 0.0235661999},
        }
    }
    text = report_markdown(d)
    assert "- evidence: effective_samples=234, mse={none 0.362, drift 0.0236}" in text
