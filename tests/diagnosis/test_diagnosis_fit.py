"""The batched candidate fit and its work queue: the device split, resuming a fit,
the finishing stage's restart of the re-fit, and the reported standard errors."""

import textwrap
from collections import deque

import equinox as eqx
import jax
import jax.numpy as jnp
import jax.random as jr
import jax.tree_util as jtu
import numpy as np
import pytest
from helpers import CAPPED, run_on_two_devices

import hamjax.diagnosis.fit as fit_module
import hamjax.diagnosis.schedule as schedule
from hamjax._results import RESULTS
from hamjax.diagnosis.augmented import (
    NL_TABULATED,
    slot_index,
    uses_feedback,
    uses_memory,
)
from hamjax.diagnosis.fit import LAMBDA0, fit_batch, theta_std
from hamjax.diagnosis.layout import N_MAX, prepare
from hamjax.diagnosis.schedule import (
    REFIT,
    finishing_items,
    judged_row,
    leading_rows,
    merge,
    run_batch,
    run_queue,
)
from hamjax.papers.gap.demo_cases import coloured_case, tiny_case


SETUP = textwrap.dedent(
    """
    import jax.numpy as jnp
    import jax.random as jr
    import jax.tree_util as jtu
    import numpy as np
    from hamjax.diagnosis.layout import prepare
    from hamjax.papers.gap.demo_cases import tiny_case

    def stack(xs):
        return jtu.tree_map(lambda *x: jnp.stack(x), *xs)

    def flat(keys_effects):
        # every row of every case, each row next to its own case
        preps = [
            prepare(*tiny_case(jr.key(k), e, noise=1e-3), length=512, n_params=13)
            for k, e in keys_effects
        ]
        rows = stack([r for p in preps for _, r in p.rows])
        cases = stack([p.arrays for p in preps for _ in p.rows])
        n = rows.theta0.shape[0]
        return rows, cases, np.full(n, 6), np.full(n, 1e-3)
    """
)

CHILD = SETUP + textwrap.dedent(
    """
    import sys
    import jax
    import hamjax as hj
    from hamjax.diagnosis.fit import fit_batch

    # float64 after SETUP's imports: nothing built at import may keep float32
    hj.enable_x64()
    two = fit_batch(*flat([(3, "extra_pole"), (4, "saturation")]))
    np.savez(
        sys.argv[1],
        devices=jax.device_count(),
        **{k: getattr(two, k) for k in ("theta", "sse_est", "y_est", "y_val")},
    )
    """
)


@pytest.mark.slow
def test_two_devices_give_the_single_device_fit(tmp_path):
    # Each row is an independent fit, and each device runs its share with the
    # one-device program (`fit._run_on_devices`), whose lanes round alike at every
    # batch width: bitwise the same fits on one device and on two, under the ISA
    # cap. (With one program partitioned over the devices the SSE differed by up
    # to 3e-7 relative after 6 damped Gauss-Newton steps, and a name now and then;
    # without the cap, hence 1e-5 there: a row fitted on the wrong case or from
    # another row's start differs by O(1).)
    sharded = run_on_two_devices(CHILD, tmp_path)
    assert int(sharded["devices"]) == 2
    ns: dict = {}
    exec(SETUP, ns)
    assert jax.device_count() == 1
    one = fit_batch(*ns["flat"]([(3, "extra_pole"), (4, "saturation")]))
    for k in ("theta", "sse_est", "y_est", "y_val"):
        if CAPPED:
            np.testing.assert_array_equal(sharded[k], getattr(one, k), err_msg=k)
        elif k == "sse_est":
            np.testing.assert_allclose(sharded[k], one.sse_est, rtol=1e-5)


def _stack(xs):
    return jtu.tree_map(lambda *x: jnp.stack(x), *xs)


def _all_rows(prep, steps):
    n = len(prep.rows)
    rows = _stack([r for _, r in prep.rows])
    cases = _stack([prep.arrays] * n)
    fit = fit_batch(rows, cases, np.full(n, steps), np.full(n, LAMBDA0))
    return {k: np.array(x) for k, x in schedule.host_fields(fit).items()}


@pytest.mark.slow
def test_resumed_fit_is_the_uninterrupted_fit():
    # A fit stopped after 5 steps and resumed exactly (its theta, its damping lam,
    # `resume`; `fitting.BatchedLevenbergMarquardt`) retraces the uninterrupted fit
    # step for step: the resumed one re-evaluates its starting point once, so
    # 5 + 31 steps reach the point of 35, bit for bit (same program, same width,
    # same arithmetic). Resumed the old way (lam0 = 3 lam, no `resume`), its first
    # step is damped by 3 lam / 3, not always lam in floating point.
    prep = prepare(*tiny_case(jr.key(3), "extra_pole", noise=1e-3))
    n = len(prep.rows)
    rows = _stack([r for _, r in prep.rows])
    cases = _stack([prep.arrays] * n)
    first = fit_batch(rows, cases, np.full(n, 5), np.full(n, LAMBDA0))
    # stopped at the 5-step budget, not converged
    moving = np.asarray(first.result._value) == RESULTS.not_converged._value
    assert moving.any()
    resumed = fit_batch(
        eqx.tree_at(lambda r: r.theta0, rows, first.theta),
        cases,
        np.full(n, 31),
        np.asarray(first.lam),
        resume=np.ones(n, bool),
    )
    straight = fit_batch(rows, cases, np.full(n, 35), np.full(n, LAMBDA0))
    for name in ("theta", "sse_est", "lam"):
        np.testing.assert_array_equal(
            np.asarray(getattr(resumed, name))[moving],
            np.asarray(getattr(straight, name))[moving],
        )


def test_a_padded_batch_is_its_rows_fitted_alone():
    # `fit_padded` fills a batch of `width` rows with copies of the first at no
    # budget: the first m fits are those of the m rows in a batch of their own
    # (to rounding: the batch width changes only the order of arithmetic); the
    # padding returns nothing, and a batch wider than `width` is refused.
    from hamjax.diagnosis.fit import fit_padded

    prep = prepare(*tiny_case(jr.key(3), "extra_pole", noise=1e-3))
    m = min(3, len(prep.rows))
    rows = _stack([r for _, r in prep.rows[:m]])
    cases = _stack([prep.arrays] * m)
    alone = fit_batch(rows, cases, np.full(m, 8), np.full(m, LAMBDA0))
    padded = fit_padded(rows, cases, np.full(m, 8), np.full(m, LAMBDA0), m + 3)
    assert np.shape(padded.sse_est) == (m,)
    np.testing.assert_allclose(padded.sse_est, alone.sse_est, rtol=1e-9)
    np.testing.assert_allclose(padded.theta, alone.theta, rtol=1e-7, atol=1e-10)
    np.testing.assert_array_equal(padded.steps, alone.steps)
    with pytest.raises(ValueError, match="rows for a batch of"):
        fit_padded(rows, cases, np.full(m, 8), np.full(m, LAMBDA0), m - 1)


def _split_queue(monkeypatch, keys_effects) -> list:
    """A queue whose finishing rows split (a 2-step screening, passes of 3 steps,
    a 10-step finishing budget) and the tiny cases `(key, effect)` it fits."""
    monkeypatch.setattr(schedule, "SCREEN_STEPS", 2)
    monkeypatch.setattr(schedule, "FIRST_PASS", 3)
    monkeypatch.setattr(schedule, "FINISH_STEPS", 10)
    return [
        prepare(*tiny_case(jr.key(k), e, noise=1e-3), length=512, n_params=13)
        for k, e in keys_effects
    ]


@pytest.mark.slow
def test_a_case_fits_the_same_alone_and_among_other_cases(monkeypatch):
    # The queue's first pass (FIRST_PASS steps) and continuation split a finishing
    # row's budget only when the call has enough cases to fill a batch; alone, a
    # case's finishing rows run their whole budget at once. With exact
    # continuation and an order-free merge the case's rows end the same: a 2-step
    # screening, a 3-step first pass and a 10-step finishing budget make every
    # finishing row split and stop at its budget, and the case alone (one batch)
    # and with three others (batches of 4 rows) must agree to rounding of the
    # other batch widths (1e-9; a lost step moves an unconverged row by far more).
    preps = _split_queue(
        monkeypatch,
        ((3, "extra_pole"), (5, "saturation"), (6, "backlash"), (7, "none")),
    )
    alone, among = {}, {}
    run_queue(preps[:1], 4 * len(preps[0].rows), lambda c, f: alone.setdefault(c, f))
    run_queue(preps, 4, lambda c, f: among.setdefault(c, f))
    assert sorted(among) == [0, 1, 2, 3]
    # finishing rows that stopped at their budget: the ones a lost step would move
    finished = (alone[0]["steps"] > 2) & (alone[0]["result"] != 0)
    assert finished.any()
    np.testing.assert_allclose(among[0]["sse_est"], alone[0]["sse_est"], rtol=1e-9)
    np.testing.assert_allclose(
        among[0]["theta"], alone[0]["theta"], rtol=1e-7, atol=1e-9
    )


def test_the_queues_passes_leave_every_fit_as_one_pass_would(monkeypatch):
    # After screening, every row runs in passes of at most FIRST_PASS steps per
    # batch and, still moving, resumes exactly where it stopped (`fit_batch`'s
    # `resume`): the finishing rows, their continuations and the prediction-error
    # fits alike. With a 3-step pass (each of them split, several times) and with
    # the whole 10-step budget in one pass, the rows and the prediction-error fits
    # must agree to rounding of the other batch widths (1e-9 on the SSE, as the
    # test above; a lost or repeated step moves an unconverged row by far more).
    monkeypatch.setattr(schedule, "SCREEN_STEPS", 2)
    monkeypatch.setattr(schedule, "FINISH_STEPS", 10)
    preps = [
        prepare(*coloured_case(jr.key(11)), length=512, n_params=13),
        prepare(*tiny_case(jr.key(6), "backlash", noise=1e-3), length=512, n_params=13),
    ]
    run_batch, resumed = schedule.run_batch, {}

    def spy(take, budgets, *args, **kwargs):  # the stages of the resumed items
        for it in take:
            resumed[it.stage] = resumed.get(it.stage, 0) + it.resume
        return run_batch(take, budgets, *args, **kwargs)

    monkeypatch.setattr(schedule, "run_batch", spy)
    got = {}
    for first in (3, 10):
        monkeypatch.setattr(schedule, "FIRST_PASS", first)
        fits = got[first] = {}
        resumed.clear()
        run_queue(preps, 8, lambda c, f, fits=fits: fits.setdefault(c, f))
        # split: finishing rows and prediction-error fits resumed (a lost or
        # repeated step would move them); whole: none of them
        assert (resumed.get("whiten", 0) > 0) == (first == 3), resumed
        assert (resumed.get("more", 0) > 0) == (first == 3), resumed
    split, whole = got[3], got[10]
    assert sorted(split) == [0, 1] and "whitened" in split[0]
    for c in (0, 1):
        pairs = [(split[c], whole[c])]
        if "whitened" in whole[c]:
            pairs.append((split[c]["whitened"], whole[c]["whitened"]))
        for a, b in pairs:
            np.testing.assert_allclose(a["sse_est"], b["sse_est"], rtol=1e-9)
            np.testing.assert_allclose(a["theta"], b["theta"], rtol=1e-7, atol=1e-9)


def test_the_narrower_tail_batches_leave_every_fit_as_full_batches_would(monkeypatch):
    # A call's last batches, holding few rows, run at a narrower width (one more
    # compiled shape, `schedule.TAIL_FRACTION`); a row's fit does not depend on
    # its batch's width beyond rounding (`fit_padded`), so with the tail batches
    # and without them every row and every prediction-error fit must agree to
    # rounding of the other width (1e-9 on the SSE, as the tests above).
    monkeypatch.setattr(schedule, "SCREEN_STEPS", 2)
    monkeypatch.setattr(schedule, "FINISH_STEPS", 10)
    monkeypatch.setattr(schedule, "FIRST_PASS", 3)
    monkeypatch.setattr(schedule, "TAIL_BATCHES", 1)
    preps = [
        prepare(*coloured_case(jr.key(11)), length=512, n_params=13),
        prepare(*tiny_case(jr.key(6), "backlash", noise=1e-3), length=512, n_params=13),
    ]
    run_batch, widths = schedule.run_batch, []

    def spy(take, budgets, rows, arrays, width, *args, **kwargs):
        widths.append((len(take), width))
        return run_batch(take, budgets, rows, arrays, width, *args, **kwargs)

    monkeypatch.setattr(schedule, "run_batch", spy)
    got, used = {}, {}
    for fraction in (1, 2):
        monkeypatch.setattr(schedule, "TAIL_FRACTION", fraction)
        fits = got[fraction] = {}
        widths.clear()
        run_queue(preps, 8, lambda c, f, fits=fits: fits.setdefault(c, f))
        used[fraction] = sorted({w for _, w in widths})
        assert all(m <= w for m, w in widths)
    # without the tail every batch is 8 rows wide; with it the short ones are 4
    assert used[1] == [8] and used[2] == [4, 8], used
    assert "whitened" in got[2][0]
    for c in (0, 1):
        pairs = [(got[1][c], got[2][c])]
        if "whitened" in got[1][c]:
            pairs.append((got[1][c]["whitened"], got[2][c]["whitened"]))
        for a, b in pairs:
            np.testing.assert_allclose(a["sse_est"], b["sse_est"], rtol=1e-9)
            np.testing.assert_allclose(a["theta"], b["theta"], rtol=1e-7, atol=1e-9)


def test_each_device_share_after_screening_holds_rows_of_one_need():
    # A device's share of a batch runs the input-memory scan and the feedback
    # loop for every row in it if one row needs them (`fit._fit_flat`), so after
    # screening `_compose` gives each share rows of one need: whole shares first
    # (of a need that fills the batch alone, else of the costlier needs before
    # the plain one), then what is left. A share's free lanes take rows that
    # need nothing more than it (a plain row beside a memory row, never a
    # feedback row); the rest of a share is padded with copies of its first
    # item and a missing share with the batch's first, none of them fitted
    # (`real` False). Every queued item is taken exactly once.
    later = {
        (False, False): deque(["a1", "a2", "a3", "a4", "a5"]),
        (True, False): deque(["b1", "b2", "b3"]),
        (False, True): deque(["c1"]),
    }
    first = schedule._compose(later, 2, 2)
    second = schedule._compose(later, 2, 2)
    third = schedule._compose(later, 2, 2)
    assert first == (["a1", "a2", "a3", "a4"], [True] * 4)
    assert second == (["b1", "b2", "b3", "a5"], [True] * 4)
    assert third == (["c1"] * 4, [True, False, False, False])
    assert not any(later.values())


@pytest.mark.slow
def test_the_queue_batches_each_need_apart_after_screening(monkeypatch):
    # With one device a share is the whole batch: after screening no batch holds
    # a row that needs the input-memory scan beside one that needs the feedback
    # loop (`_compose`), and every case is still finished, its rows as
    # they end when it is fitted alone (to rounding of the other batch widths,
    # as in the tests above).
    preps = _split_queue(
        monkeypatch, ((3, "extra_pole"), (5, "saturation"), (6, "backlash"))
    )
    run_batch, needs = schedule.run_batch, []

    def spy(take, budgets, rows, arrays, width, *args, **kwargs):
        if take[0].stage != "screen":
            needs.append(
                {
                    (
                        bool(
                            uses_memory(
                                rows[it.case].free[it.row],
                                preps[it.case].nominal.nl_kind,
                            )
                        ),
                        bool(uses_feedback(rows[it.case].free[it.row])),
                    )
                    for it, b in zip(take, budgets, strict=True)
                    if b > 0
                }
            )
        return run_batch(take, budgets, rows, arrays, width, *args, **kwargs)

    monkeypatch.setattr(schedule, "run_batch", spy)
    among, alone = {}, {}
    run_queue(preps, 16, lambda c, f: among.setdefault(c, f))
    assert sorted(among) == [0, 1, 2]
    # a batch's need is that of one of its rows: every other row rides along
    tops = [tuple(map(any, zip(*n, strict=True))) for n in needs]
    assert len(needs) > 1 and all(t in n for t, n in zip(tops, needs, strict=True))
    assert len(set(tops)) > 1, needs  # rows of several needs were finished
    run_queue(preps[2:], 16, lambda c, f: alone.setdefault(c, f))
    np.testing.assert_allclose(among[2]["sse_est"], alone[0]["sse_est"], rtol=1e-9)
    np.testing.assert_allclose(
        among[2]["theta"], alone[0]["theta"], rtol=1e-7, atol=1e-9
    )


def test_a_rows_fit_does_not_see_a_diverging_batch_mate():
    # A batch-mate whose parameters are not finite (a diverging trial step) once
    # made every row of its batch NaN: the extra pole's and the delay fraction's
    # polynomial products were `jnp.convolve`, which `vmap` turns into one grouped
    # convolution, computed densely with zero weights between rows (0 x NaN).
    # Rows then rejected every step and kept their start; a real case's name
    # changed with the cases diagnosed beside it. Same batch width both times,
    # so the rows' fits must agree bit for bit.
    prep = prepare(*tiny_case(jr.key(5), "saturation", noise=1e-3))
    rows = _stack([r for _, r in prep.rows[:3]] * 2)
    bad = eqx.tree_at(lambda r: r.theta0, rows, rows.theta0.at[3:].set(jnp.nan))
    cases = _stack([prep.arrays] * 6)

    def fit(r):
        return fit_batch(r, cases, np.full(6, 5), np.full(6, LAMBDA0))

    good, mixed = fit(rows), fit(bad)
    assert np.isfinite(np.asarray(good.sse_est)).all()
    for name in ("sse_est", "theta", "steps"):
        np.testing.assert_array_equal(
            np.asarray(getattr(mixed, name))[:3], np.asarray(getattr(good, name))[:3]
        )


@pytest.mark.slow
def test_batch_without_memory_rows_skips_the_memory_scan_exactly():
    # `_fit_flat` skips the input-memory scan (rate limit, backlash) in a batch in
    # which no row frees either. At their neutral values the scan is the identity,
    # so rows fitted in a batch that runs it (one backlash row in the last place) and
    # in one that skips it agree to rounding (same rows, same places, same width);
    # and the backlash row, fitted with the scan, closes a gap the re-fit cannot.
    prep = prepare(*tiny_case(jr.key(5), "backlash", noise=1e-3))
    names = [name for name, _ in prep.rows]
    plain = [k for k, (_, r) in enumerate(prep.rows) if not uses_memory(r.free)]
    assert 0 < len(plain) < len(names)

    def fit(ks):
        rows = _stack([prep.rows[k][1] for k in ks])
        cases = _stack([prep.arrays] * len(ks))
        n = len(ks)
        return np.asarray(
            fit_batch(rows, cases, np.full(n, 20), np.full(n, LAMBDA0)).sse_est
        )

    without = fit(plain)
    with_scan = fit(plain[:-1] + [names.index("backlash")])
    np.testing.assert_allclose(with_scan[:-1], without[:-1], rtol=1e-9)
    assert with_scan[-1] < 0.1 * without[plain.index(names.index(REFIT))]


@pytest.mark.slow
def test_refit_restarted_from_structural_row_leaves_a_local_minimum():
    # A `none` case: the re-fit's optimum is the best any row reaches. Plant a fake
    # local minimum in the re-fit row (far parameters, high SSE, marked converged):
    # the finishing stage must restart it from the best structural row's nominal
    # parameters and land on the optimum of an uninterrupted fit.
    plant, dt, est, val = tiny_case(jr.key(8), "none", noise=1e-3)
    prep = prepare(plant, dt, est, val)
    full = _all_rows(prep, 200)
    i_pm = [name for name, _ in prep.rows].index(REFIT)
    bad = {k: v.copy() for k, v in full.items()}
    bad["theta"][i_pm] = bad["theta"][i_pm] + 5.0
    bad["sse_est"][i_pm] = 1e3 * full["sse_est"][i_pm]
    bad["result"][i_pm] = 0
    items = finishing_items(0, prep, bad)
    # converged: restarts only (from the leading row and the tested one)
    assert {it.replace for it in items if it.row == i_pm} == {"lower"}
    rows = [_stack([r for _, r in prep.rows])]
    arrays = _stack([prep.arrays])
    out = run_batch(items, [200] * len(items), rows, arrays, len(items))
    before = {k: v.copy() for k, v in bad.items()}
    for j, it in enumerate(items):
        merge(bad, it, {name: x[j] for name, x in out.items()})
    np.testing.assert_allclose(bad["sse_est"][i_pm], full["sse_est"][i_pm], rtol=1e-6)
    # rows that had converged and are not the re-fit are left untouched
    others = [k for k in range(len(prep.rows)) if k != i_pm and full["result"][k] == 0]
    np.testing.assert_array_equal(bad["sse_est"][others], before["sse_est"][others])


@pytest.mark.slow
def test_refit_restarted_from_the_row_the_decision_tests():
    # The re-fit is also restarted from the nominal part of the structural row
    # of least validation error (`judged_row`), the one the nested
    # likelihood-ratio test will judge over it, where that test finds it
    # significant: never on a `none` case fitted to the end; on a re-fit stuck
    # far off, from that row, whichever class leads by estimation SSE.
    plant, dt, est, val = tiny_case(jr.key(8), "none", noise=1e-3)
    prep = prepare(plant, dt, est, val)
    full = _all_rows(prep, 200)
    assert judged_row(prep, full) is None
    i_pm = [name for name, _ in prep.rows].index(REFIT)
    nominal = np.asarray(prep.rows[i_pm][1].idx) < len(prep.arrays.anchor)
    bad = {k: v.copy() for k, v in full.items()}
    bad["theta"][i_pm] = bad["theta"][i_pm] + 5.0
    bad["sse_est"][i_pm] = 1e3 * full["sse_est"][i_pm]
    bad["result"][i_pm] = 0
    _, sse_val, _, best, lead = leading_rows(prep, bad)
    k = min(best.values(), key=lambda k: sse_val[k])
    assert judged_row(prep, bad) == k
    starts = [it.theta0 for it in finishing_items(0, prep, bad) if it.row == i_pm]
    want = [
        np.where(nominal, bad["theta"][j], 0.0) for j in dict.fromkeys([*lead[:1], k])
    ]
    assert len(starts) == len(want)
    for a, b in zip(starts, want, strict=True):
        np.testing.assert_array_equal(a, b)


@pytest.mark.slow
def test_structural_row_restarted_from_the_nominal_leaves_a_local_minimum():
    # A saturation case: plant a fake local minimum in every saturation row (limits
    # at their optimum, nominal part far off, marked converged, SSE twice the
    # optimum: still the lowest structural class). The finishing stage must restart
    # the class's best row from its limits with the nominal part at the nominal
    # values and land on the optimum of an uninterrupted fit from its own start.
    plant, dt, est, val = tiny_case(jr.key(4), "saturation", noise=1e-3)
    prep = prepare(plant, dt, est, val)
    full = _all_rows(prep, 200)
    names = [name for name, _ in prep.rows]
    sat_rows = [k for k, n in enumerate(names) if n == "saturation"]
    best = min(sat_rows, key=lambda k: full["sse_est"][k])
    structural = [k for k, n in enumerate(names) if n != REFIT]
    assert full["sse_est"][best] == full["sse_est"][structural].min()
    nominal = np.asarray(prep.rows[names.index(REFIT)][1].idx) < len(prep.arrays.anchor)
    bad = {k: v.copy() for k, v in full.items()}
    bad["theta"][sat_rows] = np.where(nominal, 3.0, 0.0) + full["theta"][best]
    bad["sse_est"][sat_rows] = 2.0 * full["sse_est"][best]
    bad["result"][sat_rows] = 0
    items = [it for it in finishing_items(0, prep, bad) if it.row in sat_rows]
    assert [it.replace for it in items] == ["lower"]
    rows = [_stack([r for _, r in prep.rows])]
    arrays = _stack([prep.arrays])
    out = run_batch(items, [200], rows, arrays, 1)
    merge(bad, items[0], {name: x[0] for name, x in out.items()})
    k = items[0].row
    np.testing.assert_allclose(bad["sse_est"][k], full["sse_est"][k], rtol=1e-6)


@pytest.mark.slow
def test_queue_finishes_rows_stopped_in_screening(monkeypatch):
    # With a 2-step screening every row stops; the finishing stage (12-step first
    # pass, then the rest of a 200-step budget in the continuation queue) must bring
    # the re-fit row to the optimum of an uninterrupted 200-step fit.
    monkeypatch.setattr(schedule, "SCREEN_STEPS", 2)
    monkeypatch.setattr(schedule, "FINISH_STEPS", 200)
    preps = [prepare(*tiny_case(jr.key(k), "extra_pole", noise=1e-3)) for k in (3, 5)]
    got = {}
    run_queue(preps, 2 * len(preps[0].rows), lambda c, f: got.setdefault(c, f))
    assert sorted(got) == [0, 1]
    for c, prep in enumerate(preps):
        full = _all_rows(prep, 200)
        i_pm = [name for name, _ in prep.rows].index(REFIT)
        assert got[c]["result"][i_pm] == 0
        np.testing.assert_allclose(
            got[c]["sse_est"][i_pm], full["sse_est"][i_pm], rtol=1e-6
        )
        assert got[c]["theta_std"].shape == got[c]["theta"].shape


@pytest.mark.slow
def test_reported_std_matches_the_monte_carlo_spread():
    # One plant and input, R = 64 noise realisations, the extra-pole row fitted to
    # convergence on each. The Gauss-Newton std of the pole parameter must match
    # the spread of its estimates: the sample std of R draws has relative standard
    # error 1/sqrt(2(R-1)) = 0.09; 4 of those bound the ratio (a wrong dof, scale or
    # Jacobian would be off by a large factor).
    plant, dt, est, val = tiny_case(jr.key(4), "extra_pole", noise=0.0)
    R, sigma = 64, 0.01
    preps = []
    for i in range(R):
        e = dict(est)
        e["y"] = est["y"] + sigma * np.asarray(
            jr.normal(jr.key(100 + i), est["y"].shape)
        )
        preps.append(prepare(plant, dt, e, val))
    # the extra-pole row of each case (the number of rows before it may differ:
    # a record that looks closed-loop gets stick-slip starts for the backlash rows)
    picked = [next(r for name, r in p.rows if name == "extra_pole") for p in preps]
    n_slots = preps[0].arrays.anchor.shape[0]
    idx = np.asarray(picked[0].idx)
    assert all(np.array_equal(np.asarray(r.idx), idx) for r in picked)
    j = int(np.flatnonzero(idx == slot_index("pole", N_MAX))[0])
    rows = _stack(picked)
    cases = _stack([p.arrays for p in preps])
    fit = fit_batch(rows, cases, np.full(R, 200), np.full(R, LAMBDA0))
    assert np.all(np.asarray(fit.result._value) == RESULTS.successful._value)
    used = idx < n_slots
    std = np.array([theta_std(fit.jtj[i], fit.s2[i], used)[j] for i in range(R)])
    spread = np.std(np.asarray(fit.theta)[:, j], ddof=1)
    ratio = np.mean(std) / spread
    assert abs(ratio - 1) < 4 / np.sqrt(2 * (R - 1)), ratio


@pytest.mark.slow
def test_static_flags_give_the_run_time_decision():
    # A call that knows what all its batches need compiles a smaller program:
    # `table=False` leaves the table look-up out (exact for a map that is not
    # tabulated), `memory=True` always runs the input-memory scan (the identity for
    # rows that free neither the rate limit nor the backlash). Same rows, same
    # places: equal to rounding to the run-time decision (default, None).
    prep = prepare(*tiny_case(jr.key(6), "backlash", noise=1e-3))
    assert prep.nominal.nl_kind != NL_TABULATED
    n = len(prep.rows)
    rows = _stack([r for _, r in prep.rows])
    cases = _stack([prep.arrays] * n)

    def sse(**flags):
        fit = fit_batch(rows, cases, np.full(n, 15), np.full(n, LAMBDA0), **flags)
        return np.asarray(fit.sse_est)

    default = sse()
    np.testing.assert_allclose(sse(memory=True, table=False), default, rtol=1e-9)
    # and the flags are not ignored: without the scan the backlash row cannot fit
    k = [name for name, _ in prep.rows].index("backlash")
    assert sse(memory=False)[k] > 10 * default[k]


@pytest.mark.slow
def test_compiler_options_change_only_rounding(monkeypatch):
    # `fit.PROGRAMS.compiler_options` (XLA's older CPU loop emitters: a faster
    # compile) and
    # XLA's defaults compile the same program: same fits to rounding.
    prep = prepare(*tiny_case(jr.key(7), "dead_zone", noise=1e-3))
    n = len(prep.rows)
    rows = _stack([r for _, r in prep.rows])
    cases = _stack([prep.arrays] * n)

    def fit():
        fit_module.clear_compiled()  # compile again
        out = fit_batch(rows, cases, np.full(n, 15), np.full(n, LAMBDA0))
        return np.asarray(out.sse_est), np.asarray(out.theta)

    assert fit_module.PROGRAMS.compiler_options  # the shipped options are in use
    sse, theta = fit()
    monkeypatch.setattr(fit_module.PROGRAMS, "compiler_options", {})
    sse_default, theta_default = fit()
    np.testing.assert_allclose(sse, sse_default, rtol=1e-9)
    np.testing.assert_allclose(theta, theta_default, rtol=1e-6, atol=1e-9)


def test_clear_compiled_drops_the_programs():
    # `fit.clear_compiled()` (used by tests/conftest.py between modules) empties
    # the cache, and the next call compiles again with the same result (to
    # rounding: a fresh compilation may partition its loops differently, seen
    # 7e-13 relative).
    prep = prepare(*tiny_case(jr.key(8), "extra_pole", noise=1e-3))
    first = _all_rows(prep, 3)
    assert len(fit_module.PROGRAMS) >= 1
    fit_module.clear_compiled()
    assert len(fit_module.PROGRAMS) == 0
    again = _all_rows(prep, 3)
    assert len(fit_module.PROGRAMS) == 1
    np.testing.assert_allclose(first["theta"], again["theta"], rtol=1e-9, atol=1e-12)


@pytest.mark.parametrize("kind", ["discrete", "continuous"])
def test_numpy_nominal_response_equals_the_jax_simulator(kind):
    # The diagnosis's host twin of the linear response (no compilation per record
    # length) is the same map as `hamjax.simulate`'s: exact ZOH in continuous time.
    import hamjax as hj
    from hamjax.diagnosis.layout import _response_numpy

    dt = 0.05
    linear = (
        hj.DiscreteTransferFunction([0.0, 0.3, 0.1], [1.0, -1.2, 0.5], dt=dt)
        if kind == "discrete"
        else hj.ContinuousTransferFunction([1.0, 2.0], [1.0, 1.4, 2.0])
    )
    u = np.random.default_rng(3).normal(size=400)
    plant = hj.Hammerstein(hj.Identity(), linear)
    ref = np.asarray(hj.simulate(plant, jnp.asarray(u), dt=dt))
    got = _response_numpy(linear, u, dt)
    np.testing.assert_allclose(got, ref, rtol=0, atol=1e-10 * np.max(np.abs(ref)))
