"""Noise-free recovery of every catalogue effect, and the false-alarm rate of the
significance rule on `none` cases (one batched, compiled-once call each)."""

import jax.numpy as jnp
import jax.random as jr
import numpy as np
import pytest

from hamjax.diagnosis.diagnose import diagnose_many
from hamjax.io import load_model
from hamjax.papers.gap.blind import make_case
from hamjax.papers.gap.demo_cases import EXACT_PARAMS, coloured_case, tiny_case


EFFECTS = [
    "backlash",
    "dead_zone",
    "saturation",
    "preload",
    "rate_limit",
    "time_delay",
    "extra_pole",
    "output_nonlinearity",
]


def _param(d, name):
    return d.ranking[0]["params"][name]["value"]


@pytest.mark.slow
def test_each_effect_recovered_noise_free():
    # noise 1e-6 (effects are ~0.1-1 in output units): the named effect must be the
    # withheld one, its gap must close to the noise, its parameters be recovered.
    items = [tiny_case(jr.key(10 + i), e, noise=1e-6) for i, e in enumerate(EFFECTS)]
    out = diagnose_many(items)
    for effect, d in zip(EFFECTS, out, strict=False):
        assert d.effect == effect, (effect, d.effect, d.tests)
        assert d.gap_after < 1e-4 * d.gap_before + 5e-6, effect
    p = dict(zip(EFFECTS, out, strict=False))
    assert np.isclose(
        _param(p["backlash"], "backlash"), EXACT_PARAMS["backlash"]["c"], rtol=1e-3
    )
    assert np.isclose(_param(p["dead_zone"], "dz_lo"), 0.2, rtol=1e-3)
    assert np.isclose(_param(p["dead_zone"], "dz_hi"), 0.2, rtol=1e-3)
    assert np.isclose(_param(p["saturation"], "sat_lo"), -0.5, rtol=1e-3)
    assert np.isclose(_param(p["saturation"], "sat_hi"), 0.6, rtol=1e-3)
    assert np.isclose(_param(p["preload"], "preload"), 0.2, rtol=1e-3)
    assert np.isclose(_param(p["rate_limit"], "rate"), 4.0, rtol=1e-3)
    # m + f with f <= UNIT_MAX = 0.995: a whole delay is reached within 0.005 from
    # the row below it, or as f -> 0 from its own row
    assert abs(_param(p["time_delay"], "tau_samples") - 3) < 0.01
    assert np.isclose(_param(p["extra_pole"], "pole"), 0.7, rtol=1e-3)


@pytest.mark.slow
def test_noise_effects_and_parameter_mismatch_named():
    items = [coloured_case(jr.key(3), n=400, pole=0.9, std=0.02)]
    drift = tiny_case(jr.key(4), "none", noise=1e-3)
    for i, rec in enumerate(drift[2:]):
        rec["y"] = rec["y"] + 0.05 * (1 + i) * rec["t"] / rec["t"][-1]
    items.append(drift)
    plant, dt, est, val = tiny_case(jr.key(5), "none", noise=1e-3)
    est, val = dict(est), dict(val)
    # the truth's gain is 20 % higher than the nominal one: a parameter mismatch
    est["y"], val["y"] = 1.2 * est["y"], 1.2 * val["y"]
    items.append((plant, dt, est, val))
    # flicker (1/f) noise in place of the white noise, shaped in frequency (no
    # predictor's formula): its own predictor, fractional of order d = 1/2
    plant, dt, est, val = tiny_case(jr.key(6), "none", noise=1e-6)
    est, val = dict(est), dict(val)
    for rec, key in ((est, jr.key(7)), (val, jr.key(8))):
        n = rec["y"].shape[0]
        spec = np.fft.rfft(np.asarray(jr.normal(key, (n,))))
        spec[1:] /= np.sqrt(np.fft.rfftfreq(n)[1:])
        spec[0] = 0.0
        e = np.fft.irfft(spec, n)
        rec["y"] = rec["y"] + 0.02 * e / np.std(e)
    items.append((plant, dt, est, val))
    out = diagnose_many(items)
    assert [d.effect for d in out] == [
        "coloured_noise",
        "drift",
        "parameter_mismatch",
        "coloured_noise",
    ]
    assert np.isclose(out[0].ranking[0]["params"]["ar1_pole"]["value"], 0.9, atol=0.05)
    # d: at these 400 samples, over 100 keys of the same noise alone, the class's
    # predictor is the fractional one for 88 (the fixed keys here give it), d
    # 0.45-0.65, mean 0.54, std 0.04: 0.2 is about 4 std
    flicker = next(r for r in out[3].ranking if r["effect"] == "coloured_noise")
    assert abs(flicker["params"]["fractional_d"]["value"] - 0.5) < 0.2, flicker


@pytest.mark.slow
@pytest.mark.statistical
def test_false_alarm_on_none_cases():
    # 24 `none` cases with fixed keys. The rule is built for a false-alarm rate near
    # 1-2 %; if it were 2 %, P(more than 3 alarms in 24) = 1.4e-3 (binomial): the
    # false-failure rate of this test.
    items = [tiny_case(jr.key(1000 + i), "none", noise=0.01) for i in range(24)]
    out = diagnose_many(items)
    alarms = sum(d.effect != "none" for d in out)
    assert alarms <= 3, [d.effect for d in out]


@pytest.mark.slow
def test_saturation_biting_on_one_side_is_found():
    # A blind-benchmark case (`hamjax blind make --seed 301`, case 137): a slow
    # third-order continuous plant behind a piecewise-linear map, clipped on about
    # 10 % of the samples below and on its top 5 % above. Started with both limits
    # well inside the range, the fit has to walk the upper one out while the
    # re-fitted map and poles compensate; it stalled and the case was called
    # coloured noise. The noise std is 0.05 x the effect's RMS.
    case = make_case(jr.fold_in(jr.key(301), 137), realism="exact")
    truth = case["truth"]
    assert truth["effect"] == "saturation"
    plant, _ = load_model(case["model"])
    est, val = case["estimation"], case["validation"]
    u = np.asarray(plant.nonlinearity(jnp.asarray(est["v"])))
    lo, hi = truth["params"]["lo"], truth["params"]["hi"]
    assert np.mean(u > hi) < 0.05 < np.mean(u < lo)
    (d,) = diagnose_many([(plant, float(est["t"][1] - est["t"][0]), est, val)])
    assert d.effect == "saturation", (d.effect, d.tests)
    # the limits are recovered to a few noise-induced parts per thousand
    assert np.isclose(_param(d, "sat_lo"), lo, rtol=5e-3)
    assert np.isclose(_param(d, "sat_hi"), hi, rtol=5e-3)


@pytest.mark.slow
def test_an_integrating_nominal_is_diagnosed():
    # A position axis B / ((1 - 0.6 q^-1)(1 - q^-1)) whose drive saturates at
    # [-0.5, 0.6]; records from rest, zero-mean staircases, noise 1e-6: the
    # integrating nominal is diagnosed like any other (saturation named, its
    # levels recovered, the gap closed to the noise). Reference: scipy.
    import scipy.signal

    import hamjax as hj
    from hamjax.papers.gap.demo_cases import staircase

    dt = 0.01
    b, a = np.array([0.0, 0.05]), np.convolve([1.0, -0.6], [1.0, -1.0])
    nominal = hj.Hammerstein(hj.Identity(), hj.DiscreteTransferFunction(b, a, dt))
    records = []
    for i in range(2):
        v = staircase(jr.key(40 + i), 600)
        v = v - np.mean(v)
        y = scipy.signal.lfilter(b, a, np.clip(v, -0.5, 0.6))
        y = y + 1e-6 * np.asarray(jr.normal(jr.key(50 + i), y.shape))
        records.append({"t": np.arange(600) * dt, "v": v, "y": y})
    (d,) = diagnose_many([(nominal, dt, *records)])
    assert d.effect == "saturation", (d.effect, d.tests)
    assert np.isclose(_param(d, "sat_lo"), -0.5, rtol=1e-3)
    assert np.isclose(_param(d, "sat_hi"), 0.6, rtol=1e-3)
    assert d.gap_after < 1e-3 * d.gap_before
