"""The valve's start (`valve_start`, `effects/backlash.py`): a sticky valve that
a record finds stuck off its command, on the benchmark's own, independent valve
models (`papers.gap.control_loops`) and an integrating loop."""

import numpy as np
from scipy.signal import lfilter

import hamjax as hj
from hamjax.diagnosis.augmented import (
    full_parameters,
    simulate_augmented,
    slot_index,
)
from hamjax.diagnosis.fit import (
    VALIDATION_STARTS,
    _starts_on_validations,
    validation_start,
)
from hamjax.diagnosis.layout import (
    N_MAX,
    PROFILE_POINTS,
    _valve_positions,
    bucket,
    describe_nominal,
    frees_valve_start,
    prepare,
    stick_slip_profile,
)
from hamjax.papers.gap import control_loops as cl


def _command(seed: int, n: int = 1500) -> np.ndarray:
    """A controller-like command: steps, a slow wander and sample noise."""
    rng = np.random.default_rng([23, seed])
    steps = np.repeat(rng.uniform(-2.0, 2.0, n // 150 + 1), 150)[:n]
    wander = np.cumsum(rng.standard_normal(n)) * 0.02
    return steps + wander + 0.05 * rng.standard_normal(n) + 0.4


def test_the_valve_started_off_its_command_against_the_benchmark_models():
    # the valve stuck at v0 + delta at the start: the profile's scan
    # (`_valve_positions`) and the augmented model's (`memory_init`) against
    # Choudhury et al.'s and He et al.'s models started there, sample by
    # sample; delta = 0 is the contract's start (centred at v0)
    G = 8
    for seed in range(3):
        v = _command(seed)
        S, J = 1.1, 0.4
        deltas = np.linspace(-0.5, 0.5, G)
        for slide in (False, True):
            x = np.asarray(
                _valve_positions(v, np.full(G, S), np.full(G, J), deltas, slide=slide)
            )
            for d, xg in zip(deltas, x, strict=True):
                if slide:
                    ref = cl.ChoudhuryStiction(S, J, x0=v[0] + d)
                else:  # He's f_s, f_d; started at x0 its first residual is -d
                    ref = cl.HeStiction((S + J) / 2, (S - J) / 2, x0=v[0] + d)
                np.testing.assert_allclose(
                    xg, cl.valve_positions(ref, v), rtol=0, atol=1e-12
                )


def test_the_augmented_model_starts_the_valve_where_the_slot_says():
    # simulate_augmented at valve_start = delta against the process driven by
    # the benchmark's valve started at v0 + delta (exact, noise-free)
    v = _command(5)
    b, a = [0.0, 0.2, 0.1], [1.0, -0.7]
    plant = hj.Hammerstein(hj.Identity(), hj.DiscreteTransferFunction(b, a, 1.0))
    rec = {"t": np.arange(v.shape[0]), "v": v, "y": lfilter(b, a, v)}
    prep = prepare(plant, 1.0, rec, rec, screens=False)
    row = next(r for name, r in prep.rows if name == "parameter_mismatch")
    p = np.array(full_parameters(np.zeros_like(row.theta0), row, prep.arrays))
    S, J = 0.9, 0.5
    for delta in (-0.3, 0.0, 0.25):
        q = p.copy()
        for name, x in (("backlash", S), ("slide_jump", J), ("valve_start", delta)):
            q[slot_index(name, N_MAX)] = x
        y = np.asarray(simulate_augmented(q, 0, prep.arrays.v_est, prep.arrays))
        x = cl.valve_positions(cl.ChoudhuryStiction(S, J, x0=v[0] + delta), v)
        np.testing.assert_allclose(
            y[: v.shape[0]], lfilter(b, a, x), rtol=1e-10, atol=1e-10
        )


def _integrating_loop(seed: int, S: float, J: float, n: int = 2400):
    """A PI loop around an integrating process (Ki / (s (t s + 1))), noise-free
    but for a small measurement noise the controller reads, its valve by
    Choudhury et al.'s model at rest at 0 while the first command is not 0 (the
    loop before the record, at rest): estimation and validation records, the
    plant."""
    p, dt, delay = {"Ki": 0.02, "t": 20.0}, 2.0, 1
    b, a = cl.discrete_process(*cl.process_tf("integrating", p), dt, delay)
    pi = cl.simc_pi("integrating", p, delay, dt, detune=1.5)
    out = []
    for r in range(2):
        rng = np.random.default_rng([29, seed, r])
        sp = np.repeat(rng.uniform(-3.0, 3.0, n // 300 + 1), 300)[:n]
        sp[:300] = 0.0  # the first hold at the rest value
        e = 0.05 * rng.standard_normal(n)
        loop = cl.simulate_loop(
            b, a, pi, dt, sp, np.zeros(n), e, valve=cl.ChoudhuryStiction(S, J)
        )
        out.append({"t": dt * np.arange(n), "v": loop["op"], "y": loop["pv"]})
    plant = hj.Hammerstein(hj.Identity(), hj.DiscreteTransferFunction(b, a, dt))
    return plant, dt, out[0], out[1]


def test_an_integrating_loop_started_off_centre_is_profiled_with_its_start():
    # the loop at rest at 0 before the record, the first command already off 0
    # by the controller's reaction to the first noisy reading: an integrating
    # process turns that offset of the valve (stuck at 0, not at v0) into a ramp
    # until the first slip. The profile (on the differenced record first, then
    # on the record with the start) finds S and J within 1 % and the start
    # within 0.5 % of S of the truth; started at v0 instead, its point leaves
    # more than 10 times the SSE it leaves with the start it found
    for seed, S, J in [(0, 1.5, 0.5), (1, 2.5, 1.0)]:
        plant, dt, est, _ = _integrating_loop(seed, S, J)
        v, y = est["v"], est["y"]
        nom = describe_nominal(plant)
        found = stick_slip_profile(nom, plant.linear, dt, v, y, bucket(v.shape[0]))
        S0, J0, start, slot = found[0]
        assert slot == "slide_jump", found
        assert abs(np.log(S0 / S)) < 0.01 and abs(np.log(J0 / J)) < 0.01, found[0]
        assert abs(start["valve_start"] + v[0]) < 0.005 * S, (start, v[0])
        b, a = cl.discrete_process(
            *cl.process_tf("integrating", {"Ki": 0.02, "t": 20.0}), dt, 1
        )

        d = np.array([0.0, start["valve_start"]])
        x = np.asarray(
            _valve_positions(v, np.full(2, S0), np.full(2, J0), d, slide=True)
        )
        sse = np.sum((y - start["gain"] * lfilter(b, a, x)) ** 2, axis=1)
        assert sse[0] > 10 * sse[1], sse


def test_the_validation_record_gets_its_own_start():
    # a row fitted with its start on the estimation record: its validation
    # output is simulated from the validation record's own start (searched over
    # VALIDATION_STARTS within the play's width, then within a step of the
    # best), not the estimation record's: with the true valve parameters that
    # output is within a tenth of what the contract's start (v0) leaves of the
    # noise-free truth
    S, J = 1.5, 0.5
    plant, dt, est, val = _integrating_loop(0, S, J)
    prep = prepare(plant, dt, est, val)
    rows = [(k, r) for k, (n, r) in enumerate(prep.rows) if frees_valve_start(r)]
    assert rows and all(prep.rows[k][0] == "backlash" for k, _ in rows)
    k, row = rows[0]
    p = np.array(full_parameters(np.zeros_like(row.theta0), row, prep.arrays))
    for name, x in (("backlash", S), ("slide_jump", J), ("valve_start", 0.3)):
        p[slot_index(name, N_MAX)] = x  # the estimation record's start: not this
    y = validation_start(p[None], [row], prep.arrays)[0, : val["v"].shape[0]]
    truth = lfilter(
        *cl.discrete_process(
            *cl.process_tf("integrating", {"Ki": 0.02, "t": 20.0}), dt, 1
        ),
        cl.valve_positions(cl.ChoudhuryStiction(S, J), val["v"]),
    )
    # started at v0 instead (the contract's start): a ramp until the first slip
    p0 = p.copy()
    p0[slot_index("valve_start", N_MAX)] = 0.0
    y0 = np.asarray(simulate_augmented(p0, row.tau, prep.arrays.v_val, prep.arrays))
    off = np.sqrt(np.mean((y0[: truth.shape[0]] - truth) ** 2))
    err = np.sqrt(np.mean((y - truth) ** 2))
    assert off > 0.05 * np.std(truth)
    # the search's second step is (2 S / VALIDATION_STARTS)**2 / S: the level it
    # may leave before the first slip is far below the noise (0.05)
    assert err < 0.1 * off, (err, off, VALIDATION_STARTS)


def test_validation_starts_of_one_row_or_several_share_one_program():
    # padded to a multiple of `batch`, one row's validation output is the same
    # whether it is simulated alone or beside others, and the calls with 1 and
    # 3 rows run one compiled program (a cold diagnosis compiled one for each
    # count of such rows, 2.6 s apiece on a loop's record)
    plant, dt, est, val = _integrating_loop(0, 1.5, 0.5)
    prep = prepare(plant, dt, est, val)
    rows = [r for _, r in prep.rows if frees_valve_start(r)]
    assert len(rows) == PROFILE_POINTS
    params = np.stack(
        [np.array(full_parameters(np.asarray(r.theta0), r, prep.arrays)) for r in rows]
    )
    before = _starts_on_validations._cache_size()
    all_rows = validation_start(params, rows, prep.arrays, batch=PROFILE_POINTS)
    one = validation_start(params[1:2], rows[1:2], prep.arrays, batch=PROFILE_POINTS)
    assert all_rows.shape[0] == PROFILE_POINTS and one.shape[0] == 1
    np.testing.assert_array_equal(one[0], all_rows[1])
    assert _starts_on_validations._cache_size() - before <= 1
    assert validation_start(params[:0], [], prep.arrays).shape == (
        0,
        prep.arrays.v_val.shape[0],
    )
