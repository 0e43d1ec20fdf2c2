"""FGI (seed 000, Table 2): Fourier coefficients, Parseval selection, G(jk omega)."""

import json

import jax
import jax.numpy as jnp
import jax.random as jr
import numpy as np
import pytest
from helpers import INNER_FA, INNER_FD, INNER_LEVELS, backlash_periods
from scipy import signal, stats

import hamjax as hj
from hamjax.identification.seed000.fgi_table2 import (
    identify_fgi,
    steady_cycle_indices,
    steady_cycle_values,
    trans_period_average,
)
from hamjax.identification.seed000.fourier_13_22 import (
    piecewise_constant_coefficients,
    sampled_coefficients,
)
from hamjax.papers.seed000.border_shapes import SHAPES, cycle_points


LEVELS = np.array([-1.0, -0.5, 0.0, 0.5, 1.0])
NUM, DEN = [1.0], [0.25, 1.0, 1.0]


def g_true(omega):
    return 1.0 / np.polyval(DEN, 1j * np.asarray(omega))


def test_piecewise_constant_coefficients_match_numpy_fft():
    # Segments on a fine grid of L cells; midpoint samples + numpy FFT give c_k to
    # O((k w h)^2), h = T/L.
    L, T = 2**14, 3.0
    w = 2 * np.pi / T
    cuts = np.array([0, 1000, 3000, 3001, 7000, 12000, L])
    values = np.array([0.3, -1.2, 2.0, 0.7, -0.4, 1.1])
    fine = np.repeat(values, np.diff(cuts))
    h = T / L
    ref = (2 / L) * np.fft.rfft(fine)[:21] * np.exp(-1j * np.arange(21) * w * h / 2)
    a, b = piecewise_constant_coefficients(values, cuts * h, w, jnp.arange(21))
    np.testing.assert_allclose(np.asarray(a) - 1j * np.asarray(b), ref, atol=2e-6)
    # Parseval (27): sum of harmonic powers -> mean square.
    a, b = piecewise_constant_coefficients(values, cuts * h, w, jnp.arange(4000))
    power = np.sum(values**2 * np.diff(cuts)) / L
    total = a[0] ** 2 / 4 + np.sum((a[1:] ** 2 + b[1:] ** 2) / 2)
    assert abs(total - power) < 1e-3 * power


def test_sampled_coefficients_hold_and_rectangle():
    key = jr.key(0)
    y = jr.normal(key, (60,))
    k = jnp.arange(0, 30)
    # hold: samples held over their cell = a piecewise-constant signal (closed form)
    a, b = sampled_coefficients(y, k, quadrature="hold")
    a2, b2 = piecewise_constant_coefficients(
        y, jnp.arange(61) * 0.1, 2 * np.pi / 6.0, k
    )
    np.testing.assert_allclose(a, a2, atol=1e-12)
    np.testing.assert_allclose(b, b2, atol=1e-12)
    # rectangle: (2/P) * numpy's DFT
    a, b = sampled_coefficients(y, k, quadrature="rectangle")
    ref = (2 / 60) * np.fft.fft(np.asarray(y))[:30]
    np.testing.assert_allclose(np.asarray(a) - 1j * np.asarray(b), ref, atol=1e-12)


def test_parseval_selection_square_wave():
    # U = square wave over 6 segments: odd harmonics 4/(pi k), even ones exactly 0.
    u = np.array([-1.0, -1.0, -1.0, 1.0, 1.0, 1.0])
    P = 600
    y = np.tile(np.repeat(u, P // 6), 3)  # "G = 1": output = input
    for eps in (0.2, 0.05, 0.02):
        res = identify_fgi(
            y,
            u,
            period_samples=P,
            periods=3,
            dt=0.01,
            epsilon=eps,
            max_harmonic=60,
            quadrature="hold",
        )
        k = np.arange(1, 61)
        share = np.where(k % 2 == 1, (4 / (np.pi * k)) ** 2 / 2, 0.0)
        p = int(np.argmax(np.cumsum(share) >= 1 - eps)) + 1
        want = (k <= p) & (k % 2 == 1)
        np.testing.assert_array_equal(res.keep, want)
        assert int(res.order) == p
        # G = 1 recovered on the kept harmonics (hold quadrature of a staircase
        # whose jumps are on samples is exact)
        np.testing.assert_allclose(res.g[res.keep], 1.0, atol=1e-9)


def test_negligible_by_stderr_dropped_not_divided():
    u = np.array([-1.0, -1.0, -1.0, 1.0, 1.0, 1.0]) + np.array([0, 0, 1e-3, 0, 0, 0])
    y = np.tile(np.repeat(u, 100), 2)
    loose = identify_fgi(y, u, period_samples=600, periods=2, dt=0.01, epsilon=0.01)
    assert bool(loose.keep[1])  # 1e-3 perturbation makes k=2 nonzero
    strict = identify_fgi(
        y,
        u,
        period_samples=600,
        periods=2,
        dt=0.01,
        epsilon=0.01,
        cycle_stderr=np.full(6, 1e-2),
    )
    assert not bool(strict.keep[1]) and bool(strict.keep[0])
    assert np.all(np.isnan(np.asarray(strict.g)[~np.asarray(strict.keep)]))


def _fgi_record(omega, dt, periods, transient, backlash=None):
    backlash = backlash or SHAPES["straight"]()
    P, used = hj.fgi_period_samples(omega, dt, len(LEVELS))
    _, v0 = hj.initialisation_step(LEVELS, duration=5.0, dt=dt)
    _, v1 = hj.periodic_staircase(
        LEVELS, period_samples=P, periods=periods + transient, dt=dt
    )
    v = jnp.concatenate([v0, v1])
    plant = hj.Hammerstein(backlash, hj.ContinuousTransferFunction(NUM, DEN))
    w = hj.simulate(plant, v, dt=dt)
    return w, P, used, v0.shape[0] + transient * P, cycle_points(backlash, LEVELS)


@pytest.mark.parametrize("omega", [0.5, 2.0])
def test_fgi_recovers_G_with_exact_u(omega):
    dt = 0.01
    w, P, used, start, U = _fgi_record(omega, dt, periods=3, transient=8)
    res = identify_fgi(
        w, U, period_samples=P, periods=3, dt=dt, start=start, quadrature="rectangle"
    )
    k = np.asarray(res.harmonics)[np.asarray(res.keep)]
    assert set(k) <= set(range(1, 40, 2))  # symmetric cycle: odd harmonics only
    np.testing.assert_allclose(
        np.asarray(res.g)[np.asarray(res.keep)], g_true(k * used), atol=1e-6
    )
    hold = identify_fgi(w, U, period_samples=P, periods=3, dt=dt, start=start)
    # ZOH convention: error about |G| k w dt / 2
    err = np.abs(np.asarray(hold.g)[np.asarray(hold.keep)] - g_true(k * used))
    bound = np.abs(g_true(k * used)) * (k * used * dt / 2) * 1.1 + 1e-6
    assert np.all(err < bound)


@pytest.mark.slow
def test_diffrax_cross_check_of_the_fgi_experiment():
    dt = 0.05
    P, _ = hj.fgi_period_samples(2.0, dt, len(LEVELS))
    _, v = hj.periodic_staircase(LEVELS, period_samples=P, periods=2, dt=dt)
    plant = hj.Hammerstein(
        SHAPES["composed"](), hj.ContinuousTransferFunction(NUM, DEN)
    )
    t = jnp.arange(v.shape[0]) * dt
    np.testing.assert_allclose(
        hj.simulate_diffrax(plant, t, v), hj.simulate(plant, v, dt=dt), atol=1e-7
    )


def test_trans_period_average_against_loop():
    y = jr.normal(jr.key(1), (50,))
    got = trans_period_average(y, start=2, period_samples=12, periods=4)
    want = sum(np.asarray(y)[2 + 12 * i : 14 + 12 * i] for i in range(4)) / 4
    np.testing.assert_allclose(got, want, atol=1e-14)


@pytest.mark.slow
@pytest.mark.statistical
def test_proposition_2_rate():
    # |G_M - G| RMSE ~ M^-1/2 (noise-dominated: rectangle quadrature, floor 1e-6).
    # R = 200 per M; harmonic k = 1: complex error, log-RMSE se ~ 1/sqrt(2*2*200)
    # = 3.5 %, slope se ~ 0.025 over M = 4..64; band 0.15 = 6 se (false failure
    # < 1e-8).
    dt, sigma = 0.05, 0.2
    ms = np.array([4, 16, 64])
    w, P, used, start, U = _fgi_record(1.0, dt, periods=int(ms[-1]), transient=6)
    truth = g_true(used)

    def trial(key, M):
        y = hj.add_noise(key, w, hj.WhiteNoise(sigma))
        res = identify_fgi(
            y,
            U,
            period_samples=P,
            periods=M,
            dt=dt,
            start=start,
            quadrature="rectangle",
            throw=False,
        )
        return res.g[0] - truth

    rmse = []
    for M in ms:
        keys = jax.vmap(lambda r: jr.fold_in(jr.key(7), r))(jnp.arange(200))
        e = jax.jit(jax.vmap(lambda k, M=int(M): trial(k, M)))(keys)
        rmse.append(float(jnp.sqrt(jnp.mean(jnp.abs(e) ** 2))))
    slope = stats.linregress(np.log(ms), np.log(rmse)).slope
    assert abs(slope + 0.5) < 0.15, (slope, rmse)


@pytest.mark.parametrize(
    "kwargs, match",
    [
        ({"period_samples": 4}, "2n-2"),
        ({"period_samples": 20}, "multiple of"),
        ({"periods": 0}, "periods"),
        ({"epsilon": 0.0}, "epsilon"),
    ],
)
def test_identify_fgi_bad_input(kwargs, match):
    base = dict(period_samples=16, periods=2, dt=0.1)
    base.update(kwargs)
    with pytest.raises(ValueError, match=match):
        identify_fgi(np.zeros(100), np.arange(8.0), **base)


@pytest.mark.parametrize(
    "omega, match", [(0.0, "> 0"), (-1.0, "> 0"), (500.0, "too high")]
)
def test_bad_omega(omega, match):
    with pytest.raises(ValueError, match=match):
        hj.fgi_period_samples(omega, 0.01, 5)


def test_flat_cycle_is_not_exciting():
    y = np.ones(160)
    res = identify_fgi(y, np.ones(8), period_samples=80, periods=2, dt=0.1, throw=False)
    assert res.result == hj.RESULTS.not_exciting


# ------------------------------------------------------- the periodic u (rebuilt)


def _play(levels, fa, fd, periods):
    """Hand-written play operator on the level indices (seed 000 Section II): a
    step in the direction of the last move follows that border, otherwise the
    point moves onto the border of the new direction iff it is reached (f_a >= u
    rising, f_d <= u falling). Starts as (3) does: from the centre of the play at
    v_M, then v_m. Returns u on the staircase (4a-b), one row per period."""
    n = len(levels)
    cycle = list(range(n)) + list(range(n - 2, 0, -1))
    order = [n - 1] + cycle * periods
    u, side, out = (fa[n - 1] + fd[n - 1]) / 2, None, []
    for prev, i in zip(order[:-1], order[1:], strict=True):
        up = i > prev
        f = fa[i] if up else fd[i]
        if (side == up) or (f >= u if up else f <= u):
            u, side = f, up
        else:
            side = None  # a horizontal move, off both borders
        out.append(u)
    return np.array(out).reshape(periods, -1)


@pytest.mark.parametrize("n", [3, 4, 6, 9])
@pytest.mark.parametrize("sign", [1.0, -1.0])
def test_steady_u_is_the_nbbi_cycle_when_the_path_meets_f_d(n, sign):
    # Every shape of Remark 1b: the second and third periods of the model equal
    # the first cycle, and the rebuild returns it (also after (kF, G/k), k < 0).
    levels = np.linspace(-1.0, 1.0, n)
    for name in sorted(SHAPES):
        u = sign * backlash_periods(SHAPES[name](), levels)
        values, ok = steady_cycle_values(u[0])
        assert bool(ok), name
        np.testing.assert_allclose(values, u[-1], atol=1e-12, err_msg=name)
        index, _, first = steady_cycle_indices(u[0])
        assert int(first) == 0, name  # the first period of (24) is already steady
        np.testing.assert_allclose(u[0][np.asarray(index)], u[-1], atol=1e-12)
        np.testing.assert_allclose(u[0], u[-1], atol=1e-12, err_msg=name)


@pytest.mark.parametrize("sign", [1.0, -1.0])
def test_steady_u_when_the_input_reverses_before_the_border(sign):
    bl = hj.Backlash.from_table(INNER_LEVELS, INNER_FA, INNER_FD)
    u = backlash_periods(bl, INNER_LEVELS)
    ref = _play(INNER_LEVELS, INNER_FA, INNER_FD, periods=3)
    np.testing.assert_allclose(u, ref, atol=1e-12)  # the two references agree
    assert abs(u[0, 0] - u[1, 0]) > 0.1  # the first cycle is not the steady one
    values, ok = steady_cycle_values(sign * u[0])
    assert bool(ok)
    np.testing.assert_allclose(values, sign * u[-1], atol=1e-12)
    # u is a selection of NBBI's points; the model's second period is steady
    index, _, first = steady_cycle_indices(sign * u[0])
    np.testing.assert_allclose(u[0][np.asarray(index)], u[1], atol=1e-12)
    assert int(first) == 1
    # FGI with "G = 1" (output = u, periodic): G-hat = 1 exactly from the rebuilt
    # u; the NBBI staircase itself (the old assumption) is off.
    P = 8 * 40
    y = np.tile(np.repeat(sign * u[-1], P // 8), 3)
    kw = dict(period_samples=P, periods=3, dt=0.01, quadrature="hold")
    res = identify_fgi(y, sign * u[0], **kw)
    keep = np.asarray(res.keep)
    assert keep.any()
    np.testing.assert_allclose(np.asarray(res.g)[keep], 1.0, atol=1e-10)
    np.testing.assert_allclose(res.cycle_values, sign * u[-1], atol=1e-12)
    T = P * 0.01
    a, b = piecewise_constant_coefficients(
        sign * u[0], jnp.arange(9) * (T / 8), 2 * np.pi / T, res.harmonics[:1]
    )
    old = (res.alpha[0] - 1j * res.beta[0]) / (a[0] - 1j * b[0])
    assert abs(complex(old) - 1) > 0.05


def test_steady_u_that_cannot_be_rebuilt_is_reported():
    # As above but f_a(V_2) below f_d(v_m): the first cycle stays at f_d(v_m) at
    # V_2, so it never shows f_a(V_2); in the steady state u arrives at V_2 below
    # f_d(v_m), and whether it reaches f_a(V_2) is not in the NBBI points.
    fa = np.array([-2.0, -1.0, 1.0, 0.5, -0.5])
    bl = hj.Backlash.from_table(INNER_LEVELS, fa, INNER_FD)
    u = backlash_periods(bl, INNER_LEVELS)
    np.testing.assert_allclose(u, _play(INNER_LEVELS, fa, INNER_FD, 3), atol=1e-12)
    assert abs(u[0, 0] - u[-1, 0]) > 0.1
    _, ok = steady_cycle_values(u[0])
    assert not bool(ok)
    P = 8 * 40
    y = np.tile(np.repeat(u[-1], P // 8), 3)
    kw = dict(period_samples=P, periods=3, dt=0.01)
    res = identify_fgi(y, u[0], throw=False, **kw)
    assert res.result == hj.RESULTS.cycle_not_rebuilt
    with pytest.raises(Exception, match="cannot rebuild the periodic backlash output"):
        identify_fgi(y, u[0], **kw)


def test_steady_u_with_noisy_points_and_their_stderr():
    # NBBI-like estimates (noise 1e-3, stated stderr): the flat inner segment is
    # flat within z standard errors, and the rebuilt u is the steady one to the
    # noise; a cycle that repeats comes back unchanged.
    noise = 1e-3 * jr.normal(jr.key(3), (8,))
    bl = hj.Backlash.from_table(INNER_LEVELS, INNER_FA, INNER_FD)
    u = backlash_periods(bl, INNER_LEVELS)
    values, ok = steady_cycle_values(u[0] + noise, cycle_stderr=np.full(8, 1e-3))
    assert bool(ok)
    np.testing.assert_allclose(values, u[-1], atol=5e-3)
    w = backlash_periods(SHAPES["straight"](), INNER_LEVELS)[0] + noise
    values, ok = steady_cycle_values(w, cycle_stderr=np.full(8, 1e-3))
    assert bool(ok)
    np.testing.assert_allclose(values, w, atol=1e-14)


# ----------------------------------------------------------------------------- CLI


def _run(argv, capsys):
    from hamjax.cli.main import main

    code = main([str(a) for a in argv])
    return code, capsys.readouterr().err


def _simulate_folder(folder, dt):
    x = np.genfromtxt(folder / "input.csv", delimiter=",", names=True)
    A, B, C, D = signal.tf2ss(NUM, DEN)
    sysd = signal.cont2discrete((A, B, C, D), dt, method="zoh")
    u = np.asarray(hj.apply_nonlinearity(SHAPES["straight"](), jnp.asarray(x["v"])))
    _, y, _ = signal.dlsim((*sysd[:4], dt), u)
    np.savetxt(
        folder / "data.csv",
        np.c_[x["t"], x["v"], np.ravel(y)],
        delimiter=",",
        header="t,v,y",
        comments="",
    )


@pytest.mark.slow
def test_cli_round_trip_two_omegas(tmp_path, capsys):
    n, f, dt = tmp_path / "n", tmp_path / "f", 0.05
    assert (
        _run(
            [
                "experiment",
                "nbbi",
                "--levels=-1,-0.5,0,0.5,1",
                "--hold",
                20,
                "--dt",
                dt,
                "--out",
                n,
            ],
            capsys,
        )[0]
        == 0
    )
    _simulate_folder(n, dt)
    assert _run(["identify", "nbbi", n, "--settled"], capsys)[0] == 0
    code, err = _run(
        [
            "experiment",
            "fgi",
            "--nbbi",
            n,
            "--omega",
            1.0,
            "--omega",
            3.0,
            "--periods",
            4,
            "--dt",
            dt,
            "--out",
            f,
        ],
        capsys,
    )
    assert code == 0, err
    design = json.loads((f / "experiment.json").read_text())
    for b in design["blocks"]:
        assert b["period_samples"] % 8 == 0
        assert b["transient_periods"] * b["period_samples"] * dt >= 20.0
        assert abs(b["omega"] - 2 * np.pi / (b["period_samples"] * dt)) < 1e-12
    _simulate_folder(f, dt)
    code, err = _run(["identify", "fgi", f, "--quadrature", "rectangle"], capsys)
    assert code == 0, err
    fr = json.loads((f / "result.json").read_text())["frequency_response"]
    assert {e["base_omega"] for e in fr} == set(design["omega"])
    for e in fr:
        assert abs(e["omega"] - e["k"] * e["base_omega"]) < 1e-12
        assert abs(complex(e["re"], e["im"]) - g_true(e["omega"])) < 1e-4
    # data.csv not matching the design
    x = np.genfromtxt(f / "data.csv", delimiter=",", names=True)
    np.savetxt(
        f / "data.csv",
        np.c_[x["t"][:-5], x["v"][:-5], x["y"][:-5]],
        delimiter=",",
        header="t,v,y",
        comments="",
    )
    code, err = _run(["identify", "fgi", f], capsys)
    assert code == 2 and "data.csv" in err and "rows" in err, err
    code, err = _run(
        [
            "experiment",
            "fgi",
            "--nbbi",
            n,
            "--omega",
            1000,
            "--periods",
            4,
            "--dt",
            dt,
            "--out",
            tmp_path / "g",
        ],
        capsys,
    )
    assert code == 2 and "too high" in err, err


def test_plots(mplcleanup):
    from hamjax.identification.seed000.nbbi_table1 import identify_nbbi
    from hamjax.plotting.backlash import plot_bode, plot_cycle, plot_nbbi_experiment

    dt, hold = 0.05, 5.0
    backlash = SHAPES["straight"]()
    _, v = hj.nbbi_staircase(LEVELS, hold=hold, dt=dt)
    plant = hj.Hammerstein(backlash, hj.ContinuousTransferFunction(NUM, DEN))
    w = hj.simulate(plant, v, dt=dt)
    nb = identify_nbbi(w, LEVELS, hold=hold, dt=dt)
    fig = plot_cycle(
        nb,
        borders=(backlash.ascending, backlash.descending),
        true_values=cycle_points(backlash, LEVELS),
    )
    assert len(fig.axes) == 1 and len(fig.axes[0].lines) >= 5
    fig = plot_nbbi_experiment(jnp.arange(v.shape[0]) * dt, v, w, w=w)
    assert len(fig.axes) == 2
    wf, P, _, start, U = _fgi_record(2.0, dt, periods=2, transient=4)
    res = identify_fgi(wf, U, period_samples=P, periods=2, dt=dt, start=start)
    fig = plot_bode([res], linear=plant.linear)
    assert len(fig.axes) == 2


@pytest.mark.slow
def test_reproduce_backlash_frequency_tiny(tmp_path, capsys):
    out = tmp_path / "bf"
    code, err = _run(
        [
            "reproduce",
            "backlash-frequency",
            "--out",
            out,
            "--hold",
            10,
            "--omega",
            "1",
            "--periods",
            3,
            "--noise",
            0.1,
        ],
        capsys,
    )
    assert code == 0, err
    summary = json.loads((out / "backlash_frequency.json").read_text())
    for name in ("fig5_cycle_points.png", "fig6_nbbi_experiment.png", "bode_fgi.png"):
        assert (out / name).is_file()
    # settled NBBI beats the plain average (5) on this slow non-minimum-phase plant
    nb = summary["nbbi"]
    assert nb["max_abs_error_settled"] < nb["max_abs_error_plain"]
    assert summary["fgi"]["n_points"] >= 1
