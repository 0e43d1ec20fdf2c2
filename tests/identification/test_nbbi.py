"""NBBI (seed 000, Table 1): exact points, transient bias, Remark 1a, rates, CLI."""

import json

import jax
import jax.numpy as jnp
import jax.random as jr
import numpy as np
import pytest
from helpers import reference_backlash
from scipy import stats

import hamjax as hj
from hamjax.identification.seed000.nbbi_table1 import check_assumptions, identify_nbbi
from hamjax.papers.seed000.border_shapes import SHAPES, cycle_points


LEVELS = np.array([-1.0, -0.5, 0.0, 0.5, 1.0])
NUM, DEN = (
    [1.0],
    [0.25, 1.0, 1.0],
)  # 1/(0.5 s + 1)^2: G(0) = 1, sum of time constants 1 s
DT = 0.01


def reference_zoh(num, den, u, dt):
    """Exact ZOH response by scipy state space (independent of hamjax)."""
    from scipy import signal

    A, B, C, D = signal.tf2ss(num, den)
    sysd = signal.cont2discrete((A, B, C, D), dt, method="zoh")
    _, y, _ = signal.dlsim((*sysd[:4], dt), np.asarray(u, float))
    return np.ravel(y)


def experiment_input(levels, hold, dt=DT, init=None):
    _, v0 = hj.initialisation_step(levels, duration=init or hold, dt=dt)
    _, v1 = hj.nbbi_staircase(levels, hold=hold, dt=dt)
    return np.concatenate([v0, v1]), v0.shape[0]


def straight_cycle(levels, c):
    """Closed-form limit-cycle points of a straight backlash f_a = v - c, f_d = v + c."""
    n = len(levels)
    u1 = levels[0] + c
    asc = [u1] + [max(u1, v - c) for v in levels[1:]]
    top = asc[-1]
    desc = [min(top, v + c) for v in levels[-2:0:-1]]
    return np.array(asc + desc), n


def test_noise_free_points_on_borders_when_settled():
    c, hold = 0.2, 20.0
    v, start = experiment_input(LEVELS, hold)
    u = reference_backlash(v, lambda x: x - c, lambda x: x + c, 0.0)
    y = reference_zoh(NUM, DEN, u, DT)  # scipy, independent of hamjax
    res = identify_nbbi(y, LEVELS, hold=hold, dt=DT, start=start, discard=hold / 2)
    want, n = straight_cycle(LEVELS, c)
    np.testing.assert_allclose(res.cycle_values, want, atol=1e-7)
    np.testing.assert_allclose(res.ascending[:, 1], want[:n], atol=1e-7)
    np.testing.assert_allclose(res.descending[:, 0], LEVELS[::-1])
    np.testing.assert_allclose(
        res.descending[:, 1], np.r_[want[n - 1 :], want[0]], atol=1e-7
    )
    # Fig. 5: points 2..n on f_a, n..2n-2 on f_d, point 1 = (v_m, f_d(v_m)).
    np.testing.assert_allclose(res.ascending[2:, 1], LEVELS[2:] - c, atol=1e-7)


@pytest.mark.parametrize("name", sorted(SHAPES))
def test_every_border_shape_recovered_noise_free(name):
    backlash = SHAPES[name]()
    levels = np.linspace(-1.0, 1.0, 7)
    hold = 20.0  # settled half: transient (1 + 2t) exp(-2t) < 1e-7 at t = 10 s
    v, start = experiment_input(levels, hold, dt=0.05)
    G = hj.ContinuousTransferFunction(NUM, DEN)
    y = hj.simulate(hj.Hammerstein(backlash, G), jnp.asarray(v), dt=0.05)
    res = identify_nbbi(y, levels, hold=hold, dt=0.05, start=start, discard=hold / 2)
    np.testing.assert_allclose(
        res.cycle_values, cycle_points(backlash, levels), atol=1e-6
    )


def test_superposed_borders_give_the_static_map():
    backlash = SHAPES["superposed"]()
    hold = 20.0
    v, start = experiment_input(LEVELS, hold, dt=0.05)
    y = hj.simulate(
        hj.Hammerstein(backlash, hj.ContinuousTransferFunction(NUM, DEN)),
        jnp.asarray(v),
        dt=0.05,
    )
    res = identify_nbbi(y, LEVELS, hold=hold, dt=0.05, start=start, discard=10.0)
    f = LEVELS + 0.4 * np.sin(3 * LEVELS)
    np.testing.assert_allclose(res.ascending[:, 1], f, atol=1e-6)
    np.testing.assert_allclose(res.descending[:, 1], f[::-1], atol=1e-6)


def test_plain_average_transient_bias_matches_closed_form():
    # The average (5) of a settled-from-the-previous-level step response misses
    # Delta U * (sum of time constants) / (N Tr): here sum = 1 s.
    c = 0.2
    for hold in (10.0, 20.0):
        v, start = experiment_input(LEVELS, hold)
        u = reference_backlash(v, lambda x: x - c, lambda x: x + c, 0.0)
        y = reference_zoh(NUM, DEN, u, DT)
        res = identify_nbbi(y, LEVELS, hold=hold, dt=DT, start=start)
        want, _ = straight_cycle(LEVELS, c)
        jumps = np.diff(np.r_[want[0], want])  # the first level is the init's v_m
        bias = np.asarray(res.cycle_values) - want
        # rectangle rule on samples: extra O(dt) relative error
        np.testing.assert_allclose(
            bias[1:], -jumps[1:] * 1.0 / hold, rtol=0.02, atol=1e-9
        )


def test_narrow_working_interval_is_detected():
    hold = 10.0
    v, start = experiment_input(LEVELS, hold)
    wide = 4.0  # the play is wider than [V1, Vn]: u never leaves its initial value
    u = reference_backlash(v, lambda x: x - wide, lambda x: x + wide, 0.3)
    y = reference_zoh(NUM, DEN, u, DT)
    res = identify_nbbi(y, LEVELS, hold=hold, dt=DT, start=start, throw=False)
    assert res.result == hj.RESULTS.not_exciting
    with pytest.raises(Exception, match="does not excite"):
        identify_nbbi(y, LEVELS, hold=hold, dt=DT, start=start)


@pytest.mark.statistical
def test_narrow_detection_under_noise():
    # Pure noise on a flat output: flagged; the same noise on a real cycle: not.
    # Threshold 6 standard errors of a difference: false alarm < 1e-6 per test.
    hold, sigma = 10.0, 0.05
    v, start = experiment_input(LEVELS, hold)
    flat = reference_zoh(NUM, DEN, np.full(v.shape, 0.3), DT)
    u = reference_backlash(v, lambda x: x - 0.2, lambda x: x + 0.2, 0.0)
    cyc = reference_zoh(NUM, DEN, u, DT)
    noise = sigma * jr.normal(jr.key(11), v.shape)
    flagged = identify_nbbi(
        flat + noise, LEVELS, hold=hold, dt=DT, start=start, throw=False
    )
    passed = identify_nbbi(
        cyc + noise, LEVELS, hold=hold, dt=DT, start=start, throw=False
    )
    assert flagged.result == hj.RESULTS.not_exciting
    assert passed.result == hj.RESULTS.successful


def _trial_factory(hold, sigma, discard):
    v, start = experiment_input(LEVELS, hold, dt=0.05)
    backlash = SHAPES["straight"]()
    plant = hj.Hammerstein(backlash, hj.ContinuousTransferFunction(NUM, DEN))
    w = hj.simulate(plant, jnp.asarray(v), dt=0.05)
    truth = cycle_points(backlash, LEVELS)

    def trial(key):
        y = hj.add_noise(key, w, hj.WhiteNoise(sigma))
        res = identify_nbbi(
            y, LEVELS, hold=hold, dt=0.05, start=start, discard=discard, throw=False
        )
        return res.cycle_values - truth, res.stderr

    return trial


@pytest.mark.statistical
def test_settled_average_is_unbiased_with_calibrated_stderr():
    # R = 300 realisations x 8 points: z = err/stderr should be N(0, 1).
    # Mean of z: |mean| < 4.5/sqrt(2400) (false failure ~ 7e-6, ignoring the
    # slight dependence through the pooled sigma); var of z within 15 %.
    trial = _trial_factory(hold=20.0, sigma=0.1, discard=10.0)
    keys = jax.vmap(lambda r: jr.fold_in(jr.key(3), r))(jnp.arange(300))
    err, se = jax.jit(jax.vmap(trial))(keys)
    z = np.asarray(err / se).ravel()
    assert abs(z.mean()) < 4.5 / np.sqrt(z.size)
    assert abs(z.var() - 1) < 0.15


@pytest.mark.slow
@pytest.mark.statistical
def test_proposition_1_rate_noise_dominated():
    # Settled average: RMSE ~ N^-1/2. R = 200 per N, 8 points each: log-RMSE se
    # about 1/sqrt(2*1600) = 1.8 %, slope se about 0.01 over a 16x range of N;
    # band 0.08 is > 5 se (false failure < 1e-6).
    ns = np.array([10.0, 40.0, 160.0])
    rmse = []
    for hold in ns:
        trial = _trial_factory(hold=float(hold), sigma=0.2, discard=float(hold) / 2)
        keys = jax.vmap(lambda r: jr.fold_in(jr.key(5), r))(jnp.arange(200))
        err, _ = jax.jit(jax.vmap(trial))(keys)
        rmse.append(float(jnp.sqrt(jnp.mean(err**2))))
    slope = stats.linregress(np.log(ns), np.log(rmse)).slope
    assert abs(slope + 0.5) < 0.08, slope


def test_vmap_equals_loop():
    trial = _trial_factory(hold=5.0, sigma=0.1, discard=0.0)
    keys = jax.vmap(lambda r: jr.fold_in(jr.key(0), r))(jnp.arange(2))
    batched = jax.vmap(trial)(keys)[0]
    looped = jnp.stack([jax.jit(trial)(keys[i])[0] for i in range(2)])
    # fixed key 0 (same draws every run); the same program, vmapped or not
    np.testing.assert_allclose(batched, looped, rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize(
    "levels, match",
    [([-1.0, 1.0, 0.5], "strictly increasing"), ([-1.0, 1.0], "at least 3")],
)
def test_bad_levels(levels, match):
    with pytest.raises(ValueError, match=match):
        identify_nbbi(np.zeros(100), levels, hold=0.1, dt=0.01)


def test_bad_hold_and_short_data():
    with pytest.raises(ValueError, match="whole number of samples"):
        identify_nbbi(np.zeros(1000), LEVELS, hold=0.015, dt=0.01)
    with pytest.raises(ValueError, match="staircase needs"):
        identify_nbbi(np.zeros(10), LEVELS, hold=0.1, dt=0.01)


def test_assumptions_on_G():
    with pytest.raises(ValueError, match="stable"):
        check_assumptions(hj.ContinuousTransferFunction([1.0], [1.0, -1.0]))
    with pytest.raises(ValueError, match="G\\(0\\) = 0"):
        check_assumptions(hj.ContinuousTransferFunction([1.0, 0.0], [1.0, 2.0, 1.0]))
    with pytest.raises(ValueError, match="normalise"):
        check_assumptions(hj.ContinuousTransferFunction([1.0, -10.0], [1.0, 2.0, 1.0]))
    g = hj.normalise_static_gain(
        hj.Hammerstein(
            SHAPES["straight"](),
            hj.ContinuousTransferFunction([1.0, -10.0], [1.0, 2.0, 1.0]),
        )
    ).linear
    check_assumptions(g)


# ----------------------------------------------------------------------------- CLI


def _run(argv, capsys):
    from hamjax.cli.main import main

    code = main([str(a) for a in argv])
    return code, capsys.readouterr().err


def _write_data(folder, y=None, *, drop=None, v_shift=0.0, rows=None):
    x = np.genfromtxt(folder / "input.csv", delimiter=",", names=True)
    t, v = x["t"], x["v"] + v_shift
    if y is None:
        u = reference_backlash(v, lambda z: z - 0.2, lambda z: z + 0.2, 0.0)
        y = reference_zoh(NUM, DEN, u, 0.05)
    cols = {"t": t, "v": v, "y": y}
    if drop:
        cols.pop(drop)
    if rows is not None:
        cols = {k: c[:rows] for k, c in cols.items()}
    arr = np.c_[tuple(cols.values())]
    np.savetxt(
        folder / "data.csv", arr, delimiter=",", header=",".join(cols), comments=""
    )


def test_cli_round_trip_and_data_checks(tmp_path, capsys):
    d = tmp_path / "n"
    code, err = _run(
        [
            "experiment",
            "nbbi",
            "--levels=-1,-0.5,0,0.5,1",
            "--hold",
            20,
            "--dt",
            0.05,
            "--out",
            d,
        ],
        capsys,
    )
    assert code == 0, err
    design = json.loads((d / "experiment.json").read_text())
    assert design["levels"] == LEVELS.tolist() and design["dt"] == 0.05
    _write_data(d)
    assert _run(["identify", "nbbi", d, "--settled"], capsys)[0] == 0
    r = json.loads((d / "result.json").read_text())
    want, n = straight_cycle(LEVELS, 0.2)
    np.testing.assert_allclose(np.array(r["cycle"])[:, 1], want, atol=1e-6)
    assert len(r["ascending"]) == n and len(r["descending"]) == n

    for kwargs, match in [
        ({"rows": 50}, "rows but experiment.json"),
        ({"v_shift": 0.1}, "column v differs"),
        ({"drop": "y"}, "missing column"),
    ]:
        _write_data(d, **kwargs)
        code, err = _run(["identify", "nbbi", d], capsys)
        assert code == 2 and "data.csv" in err and match in err, err
    x = np.genfromtxt(d / "input.csv", delimiter=",", names=True)
    y = np.zeros(x.shape[0])
    y[7] = np.nan
    _write_data(d, y)
    code, err = _run(["identify", "nbbi", d], capsys)
    assert code == 2 and "data.csv" in err and "NaN" in err, err
    _write_data(d, np.full(x.shape[0], 0.3))
    code, err = _run(["identify", "nbbi", d], capsys)
    assert code == 2 and "too narrow" in err, err


@pytest.mark.parametrize(
    "levels, match", [("-1,1,0.5", "strictly increasing"), ("-1,1", "n >= 3")]
)
def test_cli_bad_levels(tmp_path, capsys, levels, match):
    code, err = _run(
        [
            "experiment",
            "nbbi",
            f"--levels={levels}",
            "--hold",
            1,
            "--dt",
            0.1,
            "--out",
            tmp_path / "x",
        ],
        capsys,
    )
    assert code == 2 and match in err, err


def test_monte_carlo_trial_compiles_once_and_is_chunk_independent():
    import equinox as eqx

    from hamjax.montecarlo import MonteCarloConfig, run_monte_carlo

    base = _trial_factory(hold=2.0, sigma=0.1, discard=1.0)

    @eqx.debug.assert_max_traces(max_traces=1)
    def trial(key):
        return base(key)[0]

    cfg = MonteCarloConfig(realisations=6, chunk=3)
    a = run_monte_carlo(jr.key(0), trial, cfg, quiet=True)
    b = run_monte_carlo(jr.key(0), trial, cfg, quiet=True)
    np.testing.assert_array_equal(a, b)
    c = run_monte_carlo(
        jr.key(0),
        lambda k: base(k)[0],
        MonteCarloConfig(realisations=6, chunk=4),
        quiet=True,
    )
    # fixed key 0; other chunking, same per-realisation programs
    np.testing.assert_allclose(a, c, rtol=1e-12, atol=1e-14)
