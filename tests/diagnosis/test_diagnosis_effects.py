"""Each deterministic effect owns its slots: neutral value, transform, scale, starts."""

import math

import numpy as np
import pytest

from hamjax.diagnosis.augmented import CHAIN, EFFECT_SLOTS, raw_from_physical
from hamjax.diagnosis.effects import StartContext
from hamjax.diagnosis.effects._base import FLIP_SIGN, UNIT_MAX
from hamjax.diagnosis.layout import DETERMINISTIC, QUANTILES


CTX = StartContext(
    v_min=-2.0,
    v_max=3.0,
    v_absmax=3.0,
    max_step=0.5,
    dt=0.1,
    u_quantiles={
        q: float(x) for q, x in zip(QUANTILES, np.linspace(-1, 2, 11), strict=True)
    },
    u_std=0.7,
    w_quantiles={
        q: float(x) for q, x in zip(QUANTILES, np.linspace(-4, 5, 11), strict=True)
    },
    dw_half=3.0,
)


def test_the_slots_are_the_chain_effects_slots_once_each():
    assert len(set(EFFECT_SLOTS)) == len(EFFECT_SLOTS)
    owned = {e.name for e in CHAIN}
    structural = {e.name for e in DETERMINISTIC if e.slots}
    assert owned == structural  # every effect with slots is in the signal chain


@pytest.mark.parametrize("effect", CHAIN, ids=lambda e: e.name)
def test_an_effect_declares_everything_about_its_slots(effect):
    assert set(effect.neutral) == set(effect.slots)
    scales = effect.scales(CTX)
    assert set(scales) == set(effect.slots)
    assert all(math.isfinite(s) and s > 0 for s in scales.values())
    assert set(effect.positive) | set(effect.unit_interval) <= set(effect.slots)
    for start in effect.starts(CTX):
        assert set(start) - {FLIP_SIGN} <= set(effect.slots)
        for slot, value in start.items():
            if slot in effect.positive:
                assert value >= 0
            if slot in effect.unit_interval:
                assert 0 <= value < UNIT_MAX


@pytest.mark.parametrize("value", [0.0, 0.3, 0.85, 0.99])
def test_a_unit_interval_start_round_trips_through_its_raw_value(value):
    raw = raw_from_physical("pole", value)
    back = UNIT_MAX / (1 + math.exp(-raw))
    # the inverse clips to [1e-6, 1 - 1e-6] of UNIT_MAX: exact inside, 1e-6 at 0
    assert back == pytest.approx(value, abs=1.01e-6 * UNIT_MAX)
