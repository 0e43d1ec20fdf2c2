"""The default nominal model (`fit_nominal`, for cases without model.json): the map
and the order chosen by BIC, and the fitted model reproducing noise-free data."""

import jax.random as jr
import numpy as np
import pytest
from helpers import pi_loop

import hamjax as hj
from hamjax.diagnosis.nominal_fit import fit_nominal
from hamjax.papers.gap.demo_cases import staircase


def _record(plant, v, dt):
    y = np.asarray(hj.simulate(plant, v, dt=dt))
    return {"t": np.arange(v.shape[0]) * dt, "v": v, "y": y}


def _rms(x):
    return float(np.sqrt(np.mean(np.square(x))))


@pytest.mark.slow
def test_two_level_input_gets_a_linear_nominal():
    # A step test (input 0 or 1 only) determines a gain and dynamics, not a
    # six-parameter map: BIC must pick the identity map, and the fit must reproduce
    # the noise-free output (the ARX start is exact here; 1e-6 of the output range
    # leaves room for the output-error refinement's stopping tolerance).
    dt = 0.01
    lin = hj.DiscreteTransferFunction([0.0, 0.05, 0.03], [1.0, -1.5, 0.58], dt)
    plant = hj.Hammerstein(hj.Identity(), lin)
    v = np.repeat(np.tile([0.0, 1.0], 20), 50)
    rec = _record(plant, v, dt)
    fitted = fit_nominal(dt, rec)
    assert isinstance(fitted.nonlinearity, hj.Identity)
    assert np.max(np.abs(np.roots(np.asarray(fitted.linear.a)))) < 1
    err = np.asarray(hj.simulate(fitted, v, dt=dt)) - rec["y"]
    assert _rms(err) < 1e-6 * np.ptp(rec["y"])


@pytest.mark.slow
def test_rich_input_through_a_dead_zone_map_gets_a_piecewise_linear_nominal():
    # A staircase over [-1, 1] through a map with a dead zone and unequal slopes:
    # BIC must pick the piecewise-linear map, and the fitted nominal must simulate
    # the output far better than any linear model. Reference: least-squares ARX
    # models of orders 1-3 simulated with scipy (error about 0.2 of the output
    # range). The nominal keeps the ARX numerator shape (its documented
    # structure), so it is not exact either; measured about 1 % of the range,
    # hence "five times better than linear" leaves a wide margin yet fails if the
    # map is not fitted at all.
    import scipy.signal

    dt = 0.05
    nl = hj.PiecewiseLinear(k1=1.5, k2=0.7, d1=0.2, d2=-0.3)
    lin = hj.DiscreteTransferFunction([0.0, 0.2, 0.1], [1.0, -1.1, 0.4], dt)
    plant = hj.Hammerstein(nl, lin)
    v = staircase(jr.key(2), 1500)
    rec = _record(plant, v, dt)
    y = rec["y"]
    fitted = fit_nominal(dt, rec)
    assert isinstance(fitted.nonlinearity, hj.PiecewiseLinear)
    assert np.max(np.abs(np.roots(np.asarray(fitted.linear.a)))) < 1
    err = _rms(np.asarray(hj.simulate(fitted, v, dt=dt)) - y)
    linear = []
    for n in (1, 2, 3):
        X = np.array(
            [
                np.r_[-y[k - n : k][::-1], v[k - n : k + 1][::-1]]
                for k in range(n, v.shape[0])
            ]
        )
        th = np.linalg.lstsq(X, y[n:], rcond=None)[0]
        sim = scipy.signal.lfilter(th[n:], np.r_[1.0, th[:n]], v)
        linear.append(_rms(sim - y))
    assert err < 0.2 * min(linear), (err, linear)


@pytest.mark.slow
def test_an_integrating_plant_gets_an_integrating_nominal():
    # A position axis, B / ((1 - 0.7 q^-1)(1 - q^-1)), driven from rest by a
    # zero-mean staircase: a stable structure cannot follow the integrated
    # output, so BIC must pick the integrating one, whose integrator is fixed at
    # exactly 1 and whose fit reproduces the noise-free output (the ARX start on
    # the increments is exact here; tolerance as in the two-level test).
    # (`hj.simulate` refuses a pole on the unit circle: scipy simulates here)
    import scipy.signal

    dt = 0.01
    b, a = [0.0, 0.02, 0.015], np.convolve([1.0, -0.7], [1.0, -1.0])
    v = staircase(jr.key(4), 1200)
    v = v - np.mean(v)
    y = scipy.signal.lfilter(b, a, v)
    rec = {"t": np.arange(v.shape[0]) * dt, "v": v, "y": y}
    fitted = fit_nominal(dt, rec)
    assert isinstance(fitted.nonlinearity, hj.Identity)
    roots = np.roots(np.asarray(fitted.linear.a))
    assert np.min(np.abs(roots - 1.0)) < 1e-12
    y_fit = scipy.signal.lfilter(fitted.linear.b, fitted.linear.a, v)
    assert _rms(y_fit - y) < 1e-6 * np.ptp(y)


def _noisy_piecewise_record():
    """`(dt, v, record)`: a staircase through a piecewise-linear map and a
    second-order block, white noise of std 0.02 on the output."""
    dt = 0.05
    nl = hj.PiecewiseLinear(k1=1.5, k2=0.7, d1=0.2, d2=-0.3)
    lin = hj.DiscreteTransferFunction([0.0, 0.2, 0.1], [1.0, -1.1, 0.4], dt)
    v = staircase(jr.key(3), 600)
    rec = _record(hj.Hammerstein(nl, lin), v, dt)
    rec["y"] = rec["y"] + 0.02 * np.asarray(jr.normal(jr.key(4), v.shape))
    return dt, v, rec


@pytest.mark.slow
def test_stable_candidates_are_scored_by_their_fit_sse(monkeypatch):
    # `fit_nominal` scores a stable candidate by the SSE its output-error fit
    # already computed instead of simulating it again. That SSE must be the
    # returned model's simulated SSE on y (reference: `hj.simulate`, not the fit's
    # scan) to rounding, 1e-9 relative; and forcing the re-simulation of every
    # candidate must pick the same nominal.
    from hamjax.diagnosis import nominal_fit
    from hamjax.diagnosis.layout import bucket

    dt, v, rec = _noisy_piecewise_record()
    checked = 0
    starts = (hj.PiecewiseLinear(k1=1.0, k2=1.0), hj.Identity())
    jobs = [
        (dt, rec, start, *nominal_fit._arx(v, rec["y"], n))
        for n in (1, 2)
        for start in starts
    ]
    got = nominal_fit._fit_structures(jobs, bucket(v.shape[0]))
    for (_, _, start, _, _), (fitted, b_fit, den, _, sse) in zip(
        jobs, got, strict=True
    ):
        if sse is None:  # a clipped dead zone: simulated instead
            continue
        model = hj.Hammerstein(fitted, hj.DiscreteTransferFunction(b_fit, den, dt))
        y_sim = np.asarray(hj.simulate(model, v, dt=dt))
        want = float(np.sum(np.square(rec["y"] - y_sim)))
        assert abs(sse - want) <= 1e-9 * want, (start, sse, want)
        checked += 1
    assert checked >= 2
    chosen = fit_nominal(dt, rec)
    original = nominal_fit._read_structure
    monkeypatch.setattr(
        nominal_fit,
        "_read_structure",
        lambda *args: (*original(*args)[:4], None),  # simulate every candidate
    )
    again = fit_nominal(dt, rec)
    assert type(again.nonlinearity) is type(chosen.nonlinearity)
    np.testing.assert_array_equal(np.asarray(again.linear.a), chosen.linear.a)
    np.testing.assert_array_equal(np.asarray(again.linear.b), chosen.linear.b)


@pytest.mark.slow
def test_nominal_fits_in_passes_are_the_fits_in_one(monkeypatch):
    # The nominal's structures are fitted in batches of NOMINAL_BATCH rows, first
    # for NOMINAL_FIRST_PASS steps, the rows still moving then resumed exactly
    # (`fit_batch`'s `resume`, through `fit_padded`) for the rest of
    # NOMINAL_STEPS. Three structures in
    # batches of two (one padded) with a 4-step first pass, against one pass of
    # the whole budget: the same fits to rounding of the other batch widths (1e-9
    # on the SSE; a lost or repeated step moves an unconverged fit by far more).
    from hamjax.diagnosis import nominal_fit
    from hamjax.diagnosis.layout import bucket

    dt, v, rec = _noisy_piecewise_record()
    jobs = [
        (dt, rec, start, *nominal_fit._arx(v, rec["y"], n))
        for n, start in ((1, hj.PiecewiseLinear(k1=1.0, k2=1.0)), (2, hj.Identity()))
        + ((2, hj.PiecewiseLinear(k1=1.0, k2=1.0)),)
    ]
    monkeypatch.setattr(nominal_fit, "NOMINAL_BATCH", 2)
    resumed = []  # the resumed passes' live rows
    fit_padded = nominal_fit.fit_padded

    def spy(rows, cases, steps, lam0, width, **kw):
        assert width == 2 and np.shape(steps)[0] <= width
        resumed.append(int(np.sum(kw["resume"] & (np.asarray(steps) > 0))))
        return fit_padded(rows, cases, steps, lam0, width, **kw)

    monkeypatch.setattr(nominal_fit, "fit_padded", spy)
    got = {}
    for first in (4, nominal_fit.NOMINAL_STEPS):
        monkeypatch.setattr(nominal_fit, "NOMINAL_FIRST_PASS", first)
        resumed.clear()
        got[first] = nominal_fit._fit_structures(jobs, bucket(v.shape[0]))
        assert (sum(resumed) > 0) == (first < nominal_fit.NOMINAL_STEPS), resumed
    for split, whole in zip(got[4], got[nominal_fit.NOMINAL_STEPS], strict=True):
        assert type(split[0]) is type(whole[0])
        np.testing.assert_allclose(split[1], whole[1], rtol=1e-7, atol=1e-12)
        np.testing.assert_allclose(split[2], whole[2], rtol=1e-7, atol=1e-12)
        if whole[4] is not None:
            np.testing.assert_allclose(split[4], whole[4], rtol=1e-9)


SEED_PI = 3  # a draw of `helpers.pi_loop` (the closed-loop tests' PI loop)


@pytest.mark.slow
def test_a_closed_loop_record_gets_a_strictly_proper_consistent_nominal(monkeypatch):
    # Under a controller acting within the sample, a direct term b0 lets the fit
    # explain y_k by the controller's law inverted, and an output-error fit to y
    # is biased (the input is correlated with the noise). `fit_nominal` must hold
    # b0 at exactly 0 there (the Granger test flags these loops at p < 1e-6, see
    # test_diagnosis_closed_loop) and fit the low order to `loop_response` (the
    # high-order ARX's response). Against the true plant on a fresh input,
    # measured on draws 0-3 of the loop: relative errors 0.01-0.15; output error
    # to y with b0 = 0 (`loop_response` off) 0.40-0.52; b0 free (the record
    # declared open-loop) 0.60-0.81 with b0 = -0.62 to -0.84. The bound 0.25
    # sits between the first two.
    import scipy.signal

    from hamjax.diagnosis import nominal_fit

    y, v = pi_loop(SEED_PI)
    rec = {"t": np.arange(v.shape[0]) * 1.0, "v": v, "y": y}
    b_true, a_true = [0.0, 0.2], [1.0, -0.8]  # pi_loop's plant
    u = np.repeat(np.random.default_rng(5).uniform(-1, 1, 40), 30)
    want = scipy.signal.lfilter(b_true, a_true, u)

    def rel_error(plant) -> float:
        got = np.asarray(hj.simulate(plant, u, dt=1.0))
        return float(np.std(got - want) / np.std(want))

    fitted = fit_nominal(1.0, rec)
    assert float(fitted.linear.b[0]) == 0.0
    assert rel_error(fitted) < 0.25
    monkeypatch.setattr(nominal_fit, "loop_response", lambda v, y: None)
    output_error = fit_nominal(1.0, rec)
    assert float(output_error.linear.b[0]) == 0.0
    assert rel_error(output_error) > 0.25
    monkeypatch.setattr(nominal_fit, "looks_closed_loop", lambda y, v: False)
    direct = fit_nominal(1.0, rec)
    assert abs(float(direct.linear.b[0])) > 0.1
    assert rel_error(direct) > rel_error(output_error)


@pytest.mark.slow
def test_many_records_in_one_batch_fit_as_each_alone():
    # `fit_nominal_many` pads every structure of the records of one padded
    # length to it (`layout.ONE_GROUP` for records up to that length) and fits
    # them side by side, in batches of records alike in length: each nominal
    # must be that record's own `fit_nominal` (same structure; coefficients to
    # rounding, 1e-8 relative, far below the 1e-6 of the fits' own stopping
    # tolerance)
    from hamjax.diagnosis.nominal_fit import fit_nominal_many

    dt = 0.05
    nl = hj.PiecewiseLinear(k1=1.5, k2=0.7, d1=0.2, d2=-0.3)
    lin = hj.DiscreteTransferFunction([0.0, 0.2, 0.1], [1.0, -1.1, 0.4], dt)
    records = []
    # of three lengths, padded to one (each alone to the same)
    for i, n in enumerate((600, 900, 400)):
        v = staircase(jr.key(10 + i), n)
        rec = _record(hj.Hammerstein(nl, lin), v, dt)
        rec["y"] = rec["y"] + 0.02 * np.asarray(jr.normal(jr.key(20 + i), v.shape))
        records.append(rec)
    together = fit_nominal_many([(dt, r) for r in records])
    for rec, got in zip(records, together, strict=True):
        alone = fit_nominal(dt, rec)
        assert type(got.nonlinearity) is type(alone.nonlinearity)
        for x, y in ((got.linear.b, alone.linear.b), (got.linear.a, alone.linear.a)):
            np.testing.assert_allclose(np.asarray(x), np.asarray(y), rtol=1e-8)


@pytest.mark.parametrize("direct", [True, False])
@pytest.mark.parametrize("delay", [0, 1, 2])
def test_arx_delay_recovers_the_dead_time(delay, direct):
    # Noise-free data of a first-order block behind `delay` samples of dead
    # time (and, for a closed-loop record, the sample of the hold): the ARX fit
    # at the true delay is exact (SSE at rounding), at any other it is not (a
    # tap outside its lags), so `arx_delay` must return the true one and `_arx`
    # the true coefficients.
    from scipy import signal

    from hamjax.diagnosis.nominal_fit import _arx, arx_delay

    v = np.random.default_rng([3, delay]).standard_normal(500)
    # order 1: the numerator's lags delay..delay+1 (b_0 free), or delay+1
    # alone (closed loop, b_0 = 0); every tap nonzero, so no other delay holds it
    b_true = np.r_[np.zeros(delay), [0.4, 0.25] if direct else [0.0, 0.4]]
    a_true = np.array([1.0, -0.7])
    y = signal.lfilter(b_true, a_true, v)
    d = arx_delay(v, y, 1, direct=direct, max_delay=2)
    assert d == delay
    b, a = _arx(v, y, 1, direct=direct, delay=d)
    np.testing.assert_allclose(a, a_true, atol=1e-10)
    np.testing.assert_allclose(b, b_true[: b.shape[0]], atol=1e-10)
    assert b.shape[0] == 2 + delay


@pytest.mark.slow
def test_a_delayed_plant_gets_its_dead_time_not_a_higher_order():
    # A first-order block behind two samples of dead time (b nonzero at lag 3
    # only), identity map, noise-free staircase: an order-3 block can imitate
    # the dead time (its numerator's lags 0-3), but the order-1 block behind
    # the delay `arx_delay` selects is exact with three fewer parameters, so
    # BIC must pick it: an order-1 denominator, a numerator at lag 3, and the
    # output reproduced (1e-6 of its range: the refinement's stopping
    # tolerance).
    dt = 0.1
    lin = hj.DiscreteTransferFunction([0.0, 0.0, 0.0, 0.3], [1.0, -0.7], dt)
    plant = hj.Hammerstein(hj.Identity(), lin)
    v = np.repeat(np.random.default_rng(7).uniform(-1.0, 1.0, 60), 15)
    rec = _record(plant, v, dt)
    fitted = fit_nominal(dt, rec)
    assert np.asarray(fitted.linear.a).shape[0] == 2
    b = np.asarray(fitted.linear.b)
    assert np.flatnonzero(np.abs(b) > 1e-6 * np.abs(b).max()).tolist() == [3]
    err = np.asarray(hj.simulate(fitted, v, dt=dt)) - rec["y"]
    assert _rms(err) < 1e-6 * np.ptp(rec["y"])


def test_the_selected_structure_is_described():
    # The report's nominal line states what the selection chose (issue 19: the
    # selection reported): the map, the order apart from an integrator, and the
    # dead time as the first nonzero numerator lag.
    from hamjax.diagnosis.nominal_fit import describe_structure

    dt = 0.1
    stable = hj.Hammerstein(
        hj.PiecewiseLinear(k1=1.0, k2=1.0),
        hj.DiscreteTransferFunction([0.0, 0.0, 0.3, 0.1], [1.0, -1.2, 0.35], dt),
    )
    assert describe_structure(stable) == (
        "piecewise-linear map, order 2, dead time 2 sample(s)"
    )
    # B / (A (1 - q^-1)) with deg A = 1, as `_select` builds it
    den = np.convolve([1.0, -0.6], [1.0, -1.0])
    integrating = hj.Hammerstein(
        hj.Identity(), hj.DiscreteTransferFunction([0.0, 0.2, 0.0], den, dt)
    )
    assert describe_structure(integrating) == (
        "identity map, order 1 with an integrator, dead time 1 sample(s)"
    )
