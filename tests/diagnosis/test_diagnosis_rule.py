"""The last step of the decision rule (`attribute`): a noise-model effect replaces a
deterministic explanation that closes < 80 % of the gap only when that explanation's
residual, seen through the same noise predictor, does not improve the one-step-ahead
errors significantly over the nominal model's (the veto; fixed keys, one batched
call)."""

import jax.random as jr
import numpy as np
import pytest

from hamjax.diagnosis.diagnose import diagnose_many
from hamjax.papers.gap.blind import _lfilter
from hamjax.papers.gap.demo_cases import coloured_case, tiny_case


def _structural_coloured(key, effect, *, n=400, pole=0.9, std=0.02):
    """`effect` withheld, the output noise AR(1) with no white part (as in
    `coloured_case`): structural effect plus coloured noise."""
    plant, dt, est, val = tiny_case(key, effect, n=n, noise=0.0)
    est, val = dict(est), dict(val)
    for i, rec in enumerate((est, val)):
        e = np.asarray(jr.normal(jr.fold_in(key, 100 + i), (n,))) * std
        rec["y"] = rec["y"] + _lfilter(np.array([1.0]), np.array([1.0, -pole]), e)
    return plant, dt, est, val


def _ramp_case(key):
    """No effect, white noise, plus a ramp: a `drift` that a re-fit partly absorbs
    on the estimation record (the deterministic gap is significant)."""
    case = tiny_case(key, "none", noise=1e-3)
    for i, rec in enumerate(case[2:]):
        rec["y"] = rec["y"] + 0.05 * (1 + i) * rec["t"] / rec["t"][-1]
    return case


@pytest.mark.slow
def test_structural_effect_under_coloured_noise_kept_noise_cases_not():
    structural = [("saturation", 50), ("backlash", 60), ("dead_zone", 90)]
    items = [_structural_coloured(jr.key(k), e) for e, k in structural]
    items += [_ramp_case(jr.key(400)), _ramp_case(jr.key(403))]
    items.append(coloured_case(jr.key(300), n=400, pole=0.9, std=0.05))
    out = diagnose_many(items)
    named = [d.effect for d in out]
    # without the veto (a deterministic explanation closing < 80 % of the gap
    # replaced by any significant noise model with a lower one-step gap) the three
    # structural cases were named `coloured_noise`
    assert named == [e for e, _ in structural] + ["drift", "drift", "coloured_noise"]
    for d in out[:3]:
        t = d.tests["deterministic_over_noise"]
        assert t["noise"] == "coloured_noise" and t["significant"], t
        # the AR(1) fitted on the nominal residual (the one filter applied to both
        # sides) finds the pole
        assert np.isclose(t["noise_param"], 0.9, atol=0.1), t
    for d in out[3:5]:
        # a re-fit soaks up part of the ramp: the deterministic gap is significant,
        # but with the drift model on both sides it brings nothing
        assert d.tests["deterministic_gap"]["significant"], d.tests
        assert not d.tests["deterministic_over_noise"]["significant"], d.tests
