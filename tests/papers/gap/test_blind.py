"""Family A's generator (`papers.gap.blind`): the PRBS estimation input."""

import jax.random as jr
import numpy as np
import pytest

from hamjax.papers.gap.blind import make_case, make_cases


KEYS = [jr.fold_in(jr.key(0), i) for i in range(6)]


@pytest.mark.parametrize("realism", ["exact", "realistic"])
def test_prbs_estimation_replaces_only_the_estimation_input(realism):
    for key in KEYS:
        plain = make_case(key, realism=realism)
        prbs = make_case(key, realism=realism, estimation="prbs")
        v = prbs["estimation"]["v"]
        assert set(np.unique(v)) == {-1.0, 1.0}
        # the clock: every run of equal signs before the last (which the
        # record's end may cut) is a whole number of clocks of 3-40 samples
        edges = np.flatnonzero(np.diff(v) != 0) + 1
        runs = np.diff(np.r_[0, edges])
        assert 3 <= np.gcd.reduce(runs) <= 40
        # every other draw as in the default set: the nominal's structure (a
        # realistic nominal's small errors are sized on the estimation record),
        # the class, the validation input and the record lengths
        if realism == "exact":
            assert prbs["model"] == plain["model"]
        a, b = prbs["model"]["linear"], plain["model"]["linear"]
        assert a["kind"] == b["kind"]
        assert all(np.shape(a[k]) == np.shape(b[k]) for k in a if k != "kind")
        assert prbs["truth"]["effect"] == plain["truth"]["effect"]
        np.testing.assert_array_equal(prbs["validation"]["v"], plain["validation"]["v"])
        assert prbs["estimation"]["t"].shape == plain["estimation"]["t"].shape
        assert prbs["truth"]["excitation"] == {"estimation": "prbs"}
        assert "excitation" not in plain["truth"]


def test_prbs_estimation_is_recorded_in_the_truth_and_refused_when_unknown(tmp_path):
    truth = make_cases(jr.key(3), 2, tmp_path, realism="exact", estimation="prbs")
    assert truth["estimation"] == "prbs"
    assert "estimation" not in make_cases(jr.key(3), 1, tmp_path / "d")
    with pytest.raises(ValueError, match="estimation must be one of"):
        make_case(jr.key(0), estimation="square")
