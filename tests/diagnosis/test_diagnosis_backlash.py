"""A backlash nominal (the `model.json` borders) and the slip jump of the
`backlash` effect: against hand-written references of the published models,
`hj.simulate`, finite differences and noise-free recovery."""

import json

import equinox as eqx
import jax
import jax.numpy as jnp
import jax.random as jr
import numpy as np
import pytest
import scipy.signal as sg
from helpers import assert_normal_equations_match_differences

import hamjax as hj
from hamjax.cli.main import main
from hamjax.diagnosis.augmented import (
    full_parameters,
    named,
    output_play_scan,
    simulate_augmented,
    slot_index,
)
from hamjax.diagnosis.diagnose import diagnose_many
from hamjax.diagnosis.effects.backlash import play_step, stick_slip_step
from hamjax.diagnosis.fit import fit_row
from hamjax.diagnosis.layout import N_MAX, best_row_per_class, prepare
from hamjax.io import load_model, write_csv, write_json


DT = 0.05
B, A = [0.0, 0.3], [1.0, -0.7]
GRID = np.linspace(-1.5, 1.5, 13)
MODEL = {  # borders curved and of unequal width: neither is a shift of the other
    "nonlinearity": {
        "kind": "backlash",
        "v": GRID.tolist(),
        "ascending": (0.8 * GRID - 0.15 + 0.1 * GRID**2).tolist(),
        "descending": (0.9 * GRID + 0.2).tolist(),
    },
    "linear": {"kind": "discrete_tf", "b": B, "a": A},
    "dt": DT,
}


def _he_valve(x, fs, fd):
    """He, Wang, Pottmann & Qin (2007), Fig. 3, as published: the residual force
    u_r accumulates the input's changes; |u_r| > fs slips to u_r = sign fd;
    the valve position is x - u_r (at rest at x[0])."""
    u_r, x_prev, y = 0.0, float(x[0]), []
    for xk in np.asarray(x, float):
        temp = u_r + xk - x_prev
        u_r = np.sign(temp) * fd if abs(temp) > fs else temp
        x_prev = xk
        y.append(xk - u_r)
    return np.array(y)


def _scan(step, v, *params):
    def f(x, vk):
        x = step(x, vk, *params)
        return x, x

    return jax.lax.scan(f, v[0], v)[1]


def _staircase(rng, n, hold=25):
    return np.repeat(rng.uniform(-1, 1, n // hold + 1), hold)[:n]


def test_stick_slip_step_is_the_published_model(getkey):
    # a slow wandering input (random walk plus a sine): many stick-slip cycles
    n = 600
    v = np.cumsum(0.03 * np.asarray(jr.normal(getkey(), (n,))))
    v = v + 0.8 * np.sin(np.arange(n) * 0.05)
    fs, fd = 0.3, 0.1  # Choudhury's S = fs + fd, J = fs - fd
    got = _scan(stick_slip_step, jnp.asarray(v), fs + fd, fs - fd)
    # He's u_r is a running sum of input changes (rounding ~ n ulp(|v|) ~ 1e-12 at
    # |v| < 10); the decisions are the same unless a sample sits within that of the
    # threshold, which a continuous draw does with probability ~0
    np.testing.assert_allclose(got, _he_valve(v, fs, fd), rtol=0, atol=1e-11)
    # J = 0 is the plain play operator exactly, values and tangents
    c = 0.4
    for f in (lambda c: _scan(stick_slip_step, jnp.asarray(v), c, 0.0),):
        y, dy = jax.jvp(f, (c,), (1.0,))
        y0, dy0 = jax.jvp(lambda c: _scan(play_step, jnp.asarray(v), c), (c,), (1.0,))
        assert jnp.array_equal(y, y0) and jnp.array_equal(dy, dy0)
    # where it acts, the jump has a derivative: d x / d J = -+1/2 after each slip
    dJ = jax.jvp(
        lambda J: _scan(stick_slip_step, jnp.asarray(v), 0.4, J), (0.2,), (1.0,)
    )[1]
    assert set(np.unique(np.asarray(dJ)).tolist()) == {-0.5, 0.0, 0.5}


def _records(seed, n=300):
    rng = np.random.default_rng(seed)
    return [
        {"t": np.arange(n) * DT, "v": 1.2 * _staircase(rng, n), "y": np.zeros(n)}
        for _ in range(2)
    ]


@pytest.mark.parametrize("scaled", [False, True])
def test_backlash_nominal_at_neutral_is_the_model_json_plant(scaled):
    # every candidate row at its neutral values is the nominal: the loaded
    # model.json plant (or, scaled, seed 000's k F with k < 0) through hj.simulate
    plant, _ = load_model(MODEL)
    if scaled:
        nl = hj.OutputScaled(inner=plant.nonlinearity, gain=-1.5)
        plant = hj.Hammerstein(nl, plant.linear)
    est, val = _records(0)
    prep = prepare(plant, DT, est, val)
    ref = np.asarray(hj.simulate(plant, jnp.asarray(est["v"])))
    # the same operations in the same order up to the filter's summation order:
    # rounding ~ 1e-15 of the peak; 1e-12 of it leaves the filter's growth room
    tol = 1e-12 * np.max(np.abs(ref))
    np.testing.assert_allclose(prep.w_est, ref, rtol=0, atol=tol)  # NumPy twin
    sim = jax.jit(simulate_augmented)
    for name, row in prep.rows:
        if name == "time_delay":
            continue
        p = full_parameters(jnp.zeros_like(row.theta0), row, prep.arrays)
        p = jnp.where(row.free, prep.arrays.neutral, p)
        y = sim(p, row.tau, prep.arrays.v_est, prep.arrays)[: prep.n_est]
        np.testing.assert_allclose(y, ref, rtol=0, atol=tol, err_msg=name)


def _saturated_backlash_case(folder, seed):
    # truth: the model.json backlash, its output saturated, then G; noise-free
    plant, _ = load_model(MODEL)
    folder.mkdir(parents=True)
    write_json(folder / "model.json", MODEL)
    for i, name in enumerate(("estimation", "validation")):
        v = 1.2 * _staircase(np.random.default_rng([seed, i]), 600)
        u = np.asarray(hj.apply_nonlinearity(plant.nonlinearity, jnp.asarray(v)))
        y = sg.lfilter(B, A, np.clip(u, -0.5, 0.6))
        write_csv(folder / f"{name}.csv", {"t": np.arange(600) * DT, "v": v, "y": y})


@pytest.mark.slow
def test_backlash_model_json_diagnosed_through_the_cli(tmp_path, capsys):
    # a withheld saturation behind a backlash nominal, noise-free: named, its
    # levels recovered (exact model: only the fit's own convergence, 1e-3), and
    # the gap closed to rounding
    _saturated_backlash_case(tmp_path / "case", 1)
    code = main(["diagnose", str(tmp_path / "case"), "--out", str(tmp_path / "out")])
    assert code == 0, capsys.readouterr().err
    (found,) = (tmp_path / "out").rglob("diagnosis.json")  # one case: one report
    r = json.loads(found.read_text())
    assert r["effect"] == "saturation", r
    params = r["ranking"][0]["params"]
    assert np.isclose(params["sat_lo"]["value"], -0.5, rtol=1e-3)
    assert np.isclose(params["sat_hi"]["value"], 0.6, rtol=1e-3)
    assert r["gap_after"] < 1e-4 * r["gap_before"]


def _noise_prep(seed: int, noise_seed: int):
    """`prepare` of the model.json's G with an identity map on `_records(seed)`,
    the estimation output standard normal noise (300 samples, padded to 512)."""
    plant, _ = load_model({**MODEL, "nonlinearity": {"kind": "identity"}})
    est, val = _records(seed)
    est["y"] = np.random.default_rng(noise_seed).normal(size=300)
    return prepare(plant, DT, est, val, length=512)


def test_stick_slip_normal_equations_match_finite_differences():
    # J^T J and J^T r of the blocked forward-mode Jacobian against central
    # differences of the simulated residual, at a point of a sticky row away from
    # the slip instants: no sample within 100 steps h of the threshold (the
    # differences see the same slips: the exact model is smooth there). Central
    # differences err by rounding ~ eps/h ~ 1e-10 relative: 1e-6 is ample.
    prep = _noise_prep(2, 3)
    case = prep.arrays
    jump_slot = slot_index("slip_jump", N_MAX)
    row = next(r for n, r in prep.rows if n == "backlash" and r.free[jump_slot])
    theta = row.theta0 + 0.1
    p = full_parameters(theta, row, case)
    width, jump = (float(named(p, case)(k)) for k in ("backlash", "slip_jump"))
    h = 1e-6
    # h moves the threshold (S + J)/2 by at most h times the slots' scales
    near = 100 * h * float(np.max(case.scale[jump_slot - 1 : jump_slot + 1]))
    x, slips = float(case.v_est[0]), 0
    for vk in np.asarray(case.v_est[: prep.n_est]):
        over = abs(vk - x) - (width + jump) / 2
        assert abs(over) > near
        slips += over > 0
        x = float(stick_slip_step(x, vk, width, jump))
    assert slips > 3
    assert_normal_equations_match_differences(theta, row, case, jump_slot, h=h)


@pytest.mark.slow
def test_sticky_valve_recovered_noise_free():
    # A sticky valve (He et al. 2007: fs = 0.1, fd = 0.06, i.e. S = 0.16 and
    # J = 0.04) before G, levels in [-1, 1], noise-free. fd sets the position
    # after each slip (a value: recovered to the fit's convergence, 1e-6); fs
    # only which level changes slip, so noise-free data pin it to the interval
    # between the largest move that stuck and the smallest that slipped (any fs
    # in it gives the same output) and no closer.
    plant, _ = load_model({**MODEL, "nonlinearity": {"kind": "identity"}})
    fs, fd = 0.1, 0.06
    recs, lo, hi = [], 0.0, np.inf
    for i in range(2):
        v = _staircase(np.random.default_rng([7, i]), 600)
        y_valve = _he_valve(v, fs, fd)
        if i == 0:  # the fit sees the estimation record
            moves = np.abs(v[1:] - y_valve[:-1])
            slipped = np.abs(np.diff(y_valve)) > 1e-9  # (stuck: rounding only)
            lo, hi = moves[~slipped].max(), moves[slipped].min()
        y = sg.lfilter(B, A, y_valve)
        recs.append({"t": np.arange(600) * DT, "v": v, "y": y})
    assert lo < fs < hi
    # the class is named (from the catalogue's starts)
    (d,) = diagnose_many([(plant, DT, *recs)])
    assert d.effect == "backlash", (d.effect, d.tests)
    # the sticky row from a start with fs in the interval and fd 30 % off: the
    # fit recovers fd and keeps fs in the interval (the output exactly)
    prep = prepare(plant, DT, *recs)
    case = prep.arrays
    jump_slot = slot_index("slip_jump", N_MAX)
    row = next(r for n, r in prep.rows if n == "backlash" and r.free[jump_slot])
    theta0 = np.array(row.theta0)
    fs0, fd0 = (lo + hi) / 2, 1.3 * fd
    for slot, value in ((jump_slot - 1, fs0 + fd0), (jump_slot, fs0 - fd0)):
        j = list(np.asarray(row.idx)).index(slot)
        theta0[j] = (value - case.anchor[slot]) / case.scale[slot]
    fit = fit_row(eqx.tree_at(lambda r: r.theta0, row, jnp.asarray(theta0)), case, 100)
    S, J = float(fit.params[jump_slot - 1]), float(fit.params[jump_slot])
    assert np.isclose((S - J) / 2, fd, rtol=1e-6), (S, J)
    assert lo <= (S + J) / 2 < hi, (S, J, lo, hi)
    # noise-free: the residual is rounding (1e-20 of the output's energy)
    assert float(fit.sse_est) < 1e-20 * np.sum(recs[0]["y"] ** 2)


def _numpy_play(w, c):
    """The play operator of total width `c` on `w`, at rest at 0 (a Python loop)."""
    x, out = 0.0, []
    for wk in np.asarray(w, float):
        x = min(max(x, wk - c / 2), wk + c / 2)
        out.append(x)
    return np.array(out)


def _output_play_row(prep):
    slot = slot_index("out_backlash", N_MAX)
    return slot, next(r for n, r in prep.rows if n == "backlash" and r.free[slot])


def test_output_play_scan_is_the_play_and_exactly_neutral(getkey):
    # against a `lax.scan` of `play_step` started from `prev` (bit for bit, with
    # holds); at width 0 the output and its tangent are `w` itself, where the
    # clamp to [w_k, w_k] would tie in its derivative wherever w holds
    prep = _noise_prep(4, 5)
    slot, row = _output_play_row(prep)
    p0 = full_parameters(row.theta0, row, prep.arrays)
    w = jnp.repeat(jnp.cumsum(jr.normal(getkey(), (60,))), 5)  # held for 5 samples
    for width, prev in ((0.7, 0.0), (0.7, 3.0), (2.5, -1.0)):
        p = p0.at[slot].set(width)
        last, got = output_play_scan(w, jnp.asarray(prev), p, prep.arrays)
        want = _scan(play_step, jnp.concatenate([jnp.full(1, prev), w]), width)[1:]
        assert jnp.array_equal(got, want) and last == want[-1]
    tw = jr.normal(getkey(), w.shape)
    neutral = p0.at[slot].set(0.0)
    y, dy = jax.jvp(
        lambda w: output_play_scan(w, jnp.zeros(()), neutral, prep.arrays)[1],
        (w,),
        (tw,),
    )
    assert jnp.array_equal(y, w) and jnp.array_equal(dy, tw)


def test_output_play_is_a_play_on_the_filter_output():
    # the play of width c_o on the output of G (a gear between drive and load),
    # simulated and through the blocked normal equations (300 samples: two blocks
    # of `fit.BLOCK`, the play's state carried across) against lfilter and a
    # Python play; the same operations in another order: 1e-12 of the peak
    prep = _noise_prep(4, 5)
    case = prep.arrays
    slot, row = _output_play_row(prep)
    est = {"v": np.asarray(case.v_est)[: prep.n_est]}
    p = full_parameters(row.theta0, row, case).at[slot].set(0.3)
    got = jax.jit(simulate_augmented)(p, row.tau, case.v_est, case)[: prep.n_est]
    want = _numpy_play(sg.lfilter(B, A, est["v"]), 0.3)
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-12 * np.abs(want).max())
    assert np.abs(want - sg.lfilter(B, A, est["v"])).max() > 0.1  # the play acts
    # the fit's blocked Jacobian (the play's width among its columns)
    assert_normal_equations_match_differences(row.theta0 + 0.1, row, case, slot)


@pytest.mark.slow
def test_output_play_recovered_noise_free():
    # a play of width 0.25 on the output of G (a gear behind the drive's lag),
    # noise-free: named backlash, placed at the output, the width recovered to
    # the fit's convergence (1e-3) and the gap closed to rounding
    plant, _ = load_model({**MODEL, "nonlinearity": {"kind": "identity"}})
    recs = []
    for i in range(2):
        v = _staircase(np.random.default_rng([9, i]), 600)
        y = _numpy_play(sg.lfilter(B, A, v), 0.25)
        recs.append({"t": np.arange(600) * DT, "v": v, "y": y})
    (d,) = diagnose_many([(plant, DT, *recs)])
    assert d.effect == "backlash", (d.effect, d.tests)
    params = d.ranking[0]["params"]
    assert params["placement"]["value"] == "output"
    assert np.isclose(params["out_backlash"]["value"], 0.25, rtol=1e-3), params
    assert d.gap_after < 1e-4 * d.gap_before


def test_output_play_stands_for_backlash_only_when_better_on_both_records():
    # `best_row_per_class`: the play on the output (`alternative`) replaces the
    # class's best row of the contract's form (a play on v) only with a lower
    # estimation SSE and a lower validation SSE
    plant, _ = load_model({**MODEL, "nonlinearity": {"kind": "identity"}})
    prep = prepare(plant, DT, *_records(6))
    out_slot, _ = _output_play_row(prep)
    names = [n for n, _ in prep.rows]
    k_out = [
        k for k, (n, r) in enumerate(prep.rows) if n == "backlash" and r.free[out_slot]
    ]
    k_in = [
        k
        for k, (n, r) in enumerate(prep.rows)
        if n == "backlash" and not r.free[out_slot]
    ]
    assert len(k_out) == 2 and k_in

    def best(est_out: float, val_out: float) -> int:
        # the first play on v at 100, the other rows at 1e3
        sse = np.full(len(names), 1e3)
        val_sse = np.full(len(names), 1e3)
        sse[k_out], val_sse[k_out] = 500.0, 500.0  # the other output row: worse
        sse[k_out[0]], val_sse[k_out[0]] = est_out, val_out
        sse[k_in[0]], val_sse[k_in[0]] = 100.0, 100.0
        return best_row_per_class(prep, sse, val_sse)["backlash"]

    assert best(90.0, 90.0) == k_out[0]
    assert best(90.0, 110.0) == k_in[0]  # better on estimation only
    assert best(110.0, 90.0) == k_in[0]  # better on validation only
