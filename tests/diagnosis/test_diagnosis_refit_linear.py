"""The sign-blind sensor behind hamjax's own nominal (`REFIT_LINEAR`): a linear fit
to $y = |w|$ under a symmetric input keeps a numerator of about zero static gain
($E[|w_k| v_{k-j}] = 0$), so only a row that re-fits the whole linear block, with
an output level for a record centred on its means, can recover $G$.

Checked: the row and its linear twin (the same re-fit with the effect held
neutral) exist only for a fitted discrete nominal; at neutral values both are the
nominal exactly; the row stands for its class only if it beats the twin by the
nested likelihood ratio and on validation; on a noise-free sign-blind plant (the premise measured:
the fitted nominal's static gain is near zero) it names `output_nonlinearity`,
closes the gap and recovers the poles of $G$, where the same nominal given as a
model.json (no such row) cannot close it."""

import jax
import jax.random as jr
import numpy as np
import pytest
import scipy.signal as sg

import hamjax as hj
from hamjax.diagnosis.augmented import numerator_slots, simulate_augmented
from hamjax.diagnosis.diagnose import _fitted_n_params, diagnose_many
from hamjax.diagnosis.layout import (
    FITTED_ORDER,
    LINEAR_TWIN,
    LR_ALPHA,
    N_MAX,
    best_row_per_class,
    n_fitted,
    nominal_output,
    prepare,
    refits_linear,
)
from hamjax.diagnosis.nominal_fit import fit_nominal


DT = 0.05
B, A = np.array([0.0, 0.3, 0.15]), np.array([1.0, -1.2, 0.45])  # poles 0.6 +- 0.3j


def _binary(key, n: int, level: float) -> np.ndarray:
    # a random binary input held 4 samples: symmetric about 0
    s = np.asarray(jr.bernoulli(key, 0.5, (n // 4,)), float)
    return level * np.repeat(2.0 * s - 1.0, 4)[:n]


# The rows these tests count are those of an open-loop record. Its feedback test
# (`looks_closed_loop`) still fires at its level alpha (seed 2017960134 does),
# and then the stick-slip profile adds backlash starts that re-fit the linear
# block too; `screens=False` leaves that screen (and the delay screen) out.
OPEN = {"screens": False}


def _records(key):
    k1, k2, k3, k4 = jr.split(key, 4)
    out = []
    for kv, ke, level in ((k1, k2, 1.5), (k3, k4, 1.0)):
        v = _binary(kv, 800, level)
        y = np.abs(sg.lfilter(B, A, v)) + 1e-6 * np.asarray(jr.normal(ke, (800,)))
        out.append({"t": np.arange(800) * DT, "v": v, "y": y})
    # centred on the estimation record's means (as a real record is)
    mv, my = out[0]["v"].mean(), out[0]["y"].mean()
    return [{"t": r["t"], "v": r["v"] - mv, "y": r["y"] - my} for r in out]


def test_row_offered_only_for_a_fitted_discrete_nominal(getkey):
    est, val = _records(getkey())
    plant = fit_nominal(DT, est)
    P = _fitted_n_params()
    own = prepare(plant, DT, est, val, n_params=P, fitted_nominal=True, **OPEN)
    given = prepare(plant, DT, est, val, n_params=P, **OPEN)
    lin = hj.ContinuousTransferFunction(np.array([1.0]), np.array([0.5, 1.0]))
    ct = prepare(
        hj.Hammerstein(hj.Identity(), lin), DT, est, val, fitted_nominal=True, **OPEN
    )
    rows = [(n, r) for n, r in own.rows if refits_linear(r)]
    assert [n for n, _ in rows] == ["output_nonlinearity", LINEAR_TWIN]
    assert not any(refits_linear(r) for _, r in given.rows + ct.rows)
    assert len(own.rows) == len(given.rows) + 2
    names = hj.diagnosis.augmented.slot_names(N_MAX)
    free = [
        {n for n, f in zip(names, np.asarray(r.free), strict=True) if f}
        for _, r in rows
    ]
    # the block of the highest order the nominal fit selects, whatever it
    # selected, from the nominal's dead time on (its leading zeros stay, as
    # `prepare` documents; the fit selects the delay)
    first = int(np.flatnonzero(np.asarray(plant.linear.b))[0])
    dens = {f"den{j}" for j in range(1, FITTED_ORDER + 1)}
    nums = set(numerator_slots(N_MAX)[first : FITTED_ORDER + 1])
    assert free[0] == dens | nums | {"out_abs", "out_off"}
    # the twin: the same re-fit and output level, the effect (out_abs) neutral
    assert free[1] == dens | nums | {"out_off"}


def test_a_strictly_proper_nominal_keeps_its_zero_b0(getkey):
    # `fit_nominal` gives a closed-loop record b0 = 0 (the loop's delay); the
    # linear re-fit must keep it there: db0 held, db1.. free as before
    est, val = _records(getkey())
    names = hj.diagnosis.augmented.slot_names(N_MAX)
    for b, freed in (([0.0, 0.3, 0.15], False), ([0.1, 0.3, 0.15], True)):
        plant = hj.Hammerstein(hj.Identity(), hj.DiscreteTransferFunction(b, A, DT))
        prep = prepare(
            plant,
            DT,
            est,
            val,
            n_params=_fitted_n_params(),
            fitted_nominal=True,
            **OPEN,
        )
        rows = [np.asarray(r.free) for _, r in prep.rows if refits_linear(r)]
        assert len(rows) == 2
        for free in rows:
            assert bool(free[names.index("db0")]) is freed
            assert free[names.index("db1")] and free[names.index("db2")]


def test_row_at_neutral_is_the_nominal(getkey):
    est, val = _records(getkey())
    plant = fit_nominal(DT, est)
    prep = prepare(
        plant, DT, est, val, n_params=_fitted_n_params(), fitted_nominal=True, **OPEN
    )
    rows = [r for _, r in prep.rows if refits_linear(r)]
    assert len(rows) == 2  # the row and its twin
    p = np.asarray(prep.arrays.neutral)  # every slot at neutral, db included
    ref = nominal_output(plant, val["v"], DT)
    for row in rows:
        y = jax.jit(simulate_augmented)(p, row.tau, prep.arrays.v_val, prep.arrays)
        np.testing.assert_allclose(
            np.asarray(y)[: ref.shape[0]], ref, rtol=0, atol=1e-12
        )


def test_row_stands_for_its_class_only_over_its_twin(getkey):
    # What a re-fit of the whole linear block gains (a closed loop's dynamics, an
    # order the selection missed) must not name an output nonlinearity: the row
    # needs the nested ratio (S_twin - S_row) / (S_row / (n - p)) above
    # 2 ln(1 / alpha) (chi2_1 at alpha) and a lower validation SSE than its twin.
    est, val = _records(getkey())
    prep = prepare(
        fit_nominal(DT, est),
        DT,
        est,
        val,
        n_params=_fitted_n_params(),
        fitted_nominal=True,
    )
    names = [n for n, _ in prep.rows]
    k_row = next(
        k
        for k, (n, r) in enumerate(prep.rows)
        if n == "output_nonlinearity" and refits_linear(r)
    )
    k_twin = names.index(LINEAR_TWIN)
    others = [
        k for k, n in enumerate(names) if n == "output_nonlinearity" and k != k_row
    ]
    s_row = 100.0
    s2 = s_row / (prep.n_est - n_fitted(prep, k_row))
    star = 2.0 * np.log(1.0 / LR_ALPHA)

    def chosen(lr: float, val_row: float) -> bool:
        sse = np.full(len(names), 1e3)
        val_sse = np.full(len(names), 1e3)
        sse[k_row], sse[k_twin] = s_row, s_row + lr * s2
        val_sse[k_row], val_sse[k_twin] = val_row, 50.0
        best = best_row_per_class(prep, sse, val_sse)
        assert LINEAR_TWIN not in best
        assert best["output_nonlinearity"] in [k_row, *others]
        return best["output_nonlinearity"] == k_row

    assert chosen(1.05 * star, 40.0)
    assert not chosen(0.95 * star, 40.0)  # the ratio too small
    assert not chosen(1.05 * star, 60.0)  # worse than the twin on validation


@pytest.mark.slow
def test_sign_blind_sensor_behind_a_fitted_nominal_named_and_gap_closed():
    # Fixed keys 0..3 (no `getkey`): the row starts at the linear fit's numerator
    # and poles, and from there Levenberg-Marquardt reaches a local minimum that
    # closes most of the gap, not all (the sign of w is hidden: measured on keys
    # 0..11, 11/12 named, gap after / before 0.02-0.44, median 0.14; one draw
    # whose linear fit put its pole at 0.986 stayed coloured_noise). So: 3 of 4
    # named with the gap at most halved, and the same nominal given as a
    # model.json (no such row) leaves the gap where the nominal has it.
    items = []
    for k in range(4):
        est, val = _records(jr.key(k))
        plant = fit_nominal(DT, est)
        b = np.asarray(plant.linear.b)
        # the premise: the linear fit's numerator is a small part of G's
        assert np.abs(b).max() < 0.1 * np.abs(B).max()
        items.append((plant, DT, est, val))
    out = diagnose_many([*items, items[0]], fitted=[True] * 4 + [False])
    named = [d for d in out[:4] if d.effect == "output_nonlinearity"]
    assert len(named) >= 3, [d.effect for d in out]
    assert all(d.gap_after < 0.5 * d.gap_before for d in named)
    assert _class_gap(out[4]) > 0.9 * out[4].gap_before
    assert _class_gap(out[0]) < 0.5 * out[0].gap_before


def _class_gap(d) -> float:
    """The validation gap of the best `output_nonlinearity` row."""
    (gap,) = [r["gap_after"] for r in d.ranking if r["effect"] == "output_nonlinearity"]
    return gap
