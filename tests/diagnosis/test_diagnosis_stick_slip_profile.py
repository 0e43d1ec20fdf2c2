"""The profile of the stick-slip play in (f_s, f_d) (`layout.stick_slip_profile`)
on a PI loop with a sticky valve, simulated by the benchmark's own, independent
implementation of He et al. (2007) (`papers.gap.control_loops.HeStiction`)."""

import jax.tree_util as jtu
import numpy as np
from scipy.signal import lfilter

import hamjax as hj
from hamjax.diagnosis.attribute import _params
from hamjax.diagnosis.augmented import (
    full_parameters,
    simulate_augmented,
    slot_index,
    slot_names,
)
from hamjax.diagnosis.effects._base import IDENTITY_MAP, REFIT_LINEAR
from hamjax.diagnosis.fit import fit_row
from hamjax.diagnosis.layout import (
    IDENTITY_PL,
    KINETIC_RATIOS,
    LINEAR_TWIN,
    N_MAX,
    PROFILE_POINTS,
    STATIC_BAND_GRID,
    VARIANTS,
    _free_numerator_sse,
    _lagged_sums,
    _profile_block,
    _profile_sums,
    _refit_denominator,
    _solve_lagged,
    _valve_positions,
    best_row_per_class,
    bucket,
    describe_nominal,
    identity_twin_start,
    prepare,
    refits_linear,
    starts_at_nominal_numerator,
    stick_slip_profile,
)
from hamjax.models.nonlinearities.piecewise_linear import piecewise_linear_map
from hamjax.papers.gap import control_loops as cl


FOPDT = ("fopdt", {"K": 1.5, "tau": 60.0})
# time constants 40 and 15
SOPDT = ("sopdt", {"K": 1.5, "t1": 40.0, "t2": 15.0})


def _sticky_loop(
    i: int,
    fs: float,
    fd: float,
    n: int = 2000,
    valve=None,
    noise: float = 0.0,
    process: tuple = FOPDT,
):
    """A process (`process`: its kind and physics, one sample of dead time;
    FOPDT by default) under SIMC PI control, setpoint steps every 250 samples,
    noise-free unless `noise` (the std of white measurement noise on the PV, which
    the controller reads); the valve by He et al.'s model (or `valve`). Returns
    the plant, op, pv."""
    rng = np.random.default_rng([19, i])
    (kind, p), dt, delay = process, 2.0, 1
    b, a = cl.discrete_process(*cl.process_tf(kind, p), dt, delay)
    pi = cl.simc_pi(kind, p, delay, dt, detune=1.0)
    sp = np.repeat(rng.uniform(-3.0, 3.0, n // 250 + 1), 250)[:n]
    sp[:50] = 0.0  # from rest, as the valve model starts
    zero = np.zeros(n)
    e = noise * np.random.default_rng([19, 1000 + i]).standard_normal(n)
    loop = cl.simulate_loop(
        b, a, pi, dt, sp, zero, e, valve=valve or cl.HeStiction(fs, fd, x0=0.0)
    )
    plant = hj.Hammerstein(hj.Identity(), hj.DiscreteTransferFunction(b, a, dt))
    return plant, dt, loop["op"], loop["pv"]


def _impulse_error(start: dict, b_nom, b, a) -> float:
    """The largest difference of the impulse responses (300 samples) of a
    `REFIT_LINEAR` start's linear block (the nominal numerator `b_nom` plus the
    start's changes `db..`, over its `den..`) and of the true `b / a`, over
    the truth's peak."""
    full = np.zeros(N_MAX + 1)
    full[: len(b_nom)] = b_nom
    for k in range(N_MAX + 1):
        full[k] += start.get(f"db{k}", 0.0)
    den = np.r_[1.0, [start.get(f"den{j}", 0.0) for j in range(1, N_MAX + 1)]]
    pulse = np.r_[1.0, np.zeros(299)]
    true = lfilter(b, a, pulse)
    return float(np.max(np.abs(lfilter(full, den, pulse) - true)) / np.abs(true).max())


def _fitted_profile(nominal, dt, op, pv):
    """`stick_slip_profile` of the loop `op -> pv` beside `nominal` as beside a
    fitted discrete nominal (`refit_linear`)."""
    return stick_slip_profile(
        describe_nominal(nominal),
        nominal.linear,
        dt,
        op,
        pv,
        bucket(op.shape[0]),
        refit_linear=True,
    )


def test_the_profile_finds_the_static_band_of_a_closed_loop():
    for i, fs_rel, ratio in [(0, 0.08, 0.1), (1, 0.15, 0.05), (4, 0.05, 0.1)]:
        plant, dt, op, pv = _sticky_loop(i, 1.0, 1.0)  # a first run for the range
        fs = fs_rel * np.ptp(op)
        plant, dt, op, pv = _sticky_loop(i, fs, ratio * fs)
        assert 0.5 * np.ptp(op) > fs  # the valve slips more than once
        profile = stick_slip_profile(
            describe_nominal(plant), plant.linear, dt, op, pv, bucket(op.shape[0])
        )
        S, J = next((S, J) for S, J, _, slot in profile if slot == "slip_jump")
        # noise-free with the true process: the best grid point's f_s within two
        # grid steps (ratio 2**(1/64)) of the truth, f_d within one step of its
        # ratio grid (2**(1/3)): the grid holds nothing closer, and a wrong slip
        # threshold leaves an SSE far above the near-truth points'. Only loops of
        # a large slip jump (f_d <= f_s / 10) are found this way: with f_d / f_s
        # of 0.2-0.5 the needle is narrower than the f_d grid and the profile's
        # best is a near-plain play (measured; a known limit of the grid, which
        # the refinement of the best points lifts: the next test).
        step_s = STATIC_BAND_GRID[0] / STATIC_BAND_GRID[1]
        step_d = KINETIC_RATIOS[0] / KINETIC_RATIOS[1]
        assert abs(np.log(((S + J) / 2) / fs)) <= 2.0 * np.log(step_s)
        assert abs(np.log(((S - J) / 2) / (ratio * fs))) <= np.log(step_d) * 1.01


def test_the_refinement_finds_the_needle_the_grid_misses():
    # f_d / f_s of 0.2 and 0.35, where the grid's best point is a near-plain
    # play (the test above): the refined point of the He variant (coordinate
    # search in S, J and the start, `REFINE_SPANS`) is within 0.3 % of the
    # truth in both, noise-free with the true process. (At 0.5 the He variant's
    # best grid point lies outside the first span and the slide variant's
    # refined point stays ahead: a limit left.)
    for i, fs_rel, ratio in [(0, 0.08, 0.2), (1, 0.15, 0.35), (3, 0.12, 0.45)]:
        plant, dt, op, pv = _sticky_loop(i, 1.0, 1.0)
        fs = fs_rel * np.ptp(op)
        plant, dt, op, pv = _sticky_loop(i, fs, ratio * fs)
        found = stick_slip_profile(
            describe_nominal(plant), plant.linear, dt, op, pv, bucket(op.shape[0])
        )
        S, J, start, slot = found[0]
        assert slot == "slip_jump", found
        S0, J0 = fs * (1 + ratio), fs * (1 - ratio)
        assert abs(np.log(S / S0)) < 3e-3 and abs(np.log(J / J0)) < 3e-3, found[0]


def test_an_open_loop_record_gets_no_profile():
    # open loop (the test for feedback silent): the backlash rows keep their
    # plain starts only
    rng = np.random.default_rng([19, 99])
    n, dt = 2000, 1.0
    v = np.repeat(rng.uniform(-1, 1, n // 20), 20)
    b, a = [0.0, 0.3], [1.0, -0.7]
    plant = hj.Hammerstein(hj.Identity(), hj.DiscreteTransferFunction(b, a, dt))
    t = dt * np.arange(n)
    y = lfilter(b, a, v) + 0.01 * rng.standard_normal(n)
    rec = {"t": t, "v": v, "y": y}
    prep = prepare(plant, dt, rec, rec)
    assert prep.ctx.stick_slip == ()
    plant_c, dt_c, op, pv = _sticky_loop(0, 1.0, 0.3, noise=0.01)
    rec = {"t": dt_c * np.arange(op.shape[0]), "v": op, "y": pv}
    # the same kind of record from a PI loop that reads the noisy PV (a loop that
    # no noise reaches shows no feedback to a test of it): the profile's starts
    # are there
    found = prepare(plant_c, dt_c, rec, rec).ctx.stick_slip
    assert len(found) == PROFILE_POINTS, found
    assert all(slot in VARIANTS for *_, slot in found)
    # noise-free, the He variant's first (the loop's valve); with the fed-back
    # noise the Choudhury variant's slide fits that noisy record's SSE better
    plant_c, dt_c, op, pv = _sticky_loop(0, 1.0, 0.3)
    nom = describe_nominal(plant_c)
    found = stick_slip_profile(nom, plant_c.linear, dt_c, op, pv, bucket(op.shape[0]))
    assert found[0][3] == "slip_jump", found


def test_a_choudhury_valve_recovered_noise_free_from_the_profile_start():
    # Choudhury et al.'s valve (it slides while the command keeps its direction),
    # noise-free, the true process as the nominal. The profile ranks a slide point
    # first; its S lies within two grid steps of the truth (as He's f_s above).
    # From that start the fit moves the sliding offset f_d = (S - J)/2 (the only
    # direction with a derivative) to within one grid step (2**(1/64), 1.1 %) of
    # the truth -- the instants of slipping stay at the grid point's, which is
    # what is left -- and explains all but 1 % of the nominal's residual energy.
    for i, s_rel, j_rel in [(0, 0.2, 0.12), (1, 0.1, 0.05), (2, 0.15, 0.12)]:
        plant, dt, op, pv = _sticky_loop(i, 1.0, 1.0)  # a first run for the range
        S, J = s_rel * np.ptp(op), j_rel * np.ptp(op)
        valve = cl.ChoudhuryStiction(S, J, x0=0.0)
        plant, dt, op, pv = _sticky_loop(i, 0.0, 0.0, valve=valve)
        rec = {"t": dt * np.arange(op.shape[0]), "v": op, "y": pv}
        prep = prepare(plant, dt, rec, rec)
        S0, J0, _, slot = prep.ctx.stick_slip[0]
        assert slot == "slide_jump", prep.ctx.stick_slip
        step_s = STATIC_BAND_GRID[0] / STATIC_BAND_GRID[1]
        assert abs(np.log(S0 / S)) <= 2.0 * np.log(step_s), (S0, S)
        slide, width = slot_index("slide_jump", N_MAX), slot_index("backlash", N_MAX)
        row = next(  # the row of the profile's best point (its start)
            r
            for n, r in prep.rows
            if n == "backlash"
            and r.free[slide]
            and np.isclose(_start(r, prep, width), S0)
        )
        fit = fit_row(row, prep.arrays, 100)
        Sf, Jf = float(fit.params[width]), float(fit.params[slide])
        assert abs(np.log(((Sf - Jf) / 2) / ((S - J) / 2))) <= np.log(step_s)
        gap = np.sum((pv - prep.w_est) ** 2)
        assert float(fit.sse_est) < 0.01 * gap, (float(fit.sse_est), gap)


def _start(row, prep, slot):
    """The physical starting value of `slot` in `row`."""
    j = list(np.asarray(row.idx)).index(slot)
    return prep.arrays.anchor[slot] + prep.arrays.scale[slot] * float(row.theta0[j])


def test_screens_off_changes_only_the_rows_the_screens_place():
    # `prepare(screens=False)` (`nominal_fit`, which fits the re-fit row alone)
    # skips the stick-slip profile and the delay screen; the re-fit row and the
    # case arrays it is fitted on are those of the full preparation
    plant, dt, op, pv = _sticky_loop(0, 1.0, 0.3, noise=0.01)
    rec = {"t": dt * np.arange(op.shape[0]), "v": op, "y": pv}
    full = prepare(plant, dt, rec, rec)
    bare = prepare(plant, dt, rec, rec, screens=False)
    assert len(full.ctx.stick_slip) == PROFILE_POINTS and bare.ctx.stick_slip == ()
    taus = lambda p: {int(r.tau) for name, r in p.rows if name == "time_delay"}
    assert taus(bare) == {0} and len(taus(full)) == 2  # the shortlist keeps two
    refit = lambda p: next(r for name, r in p.rows if name == "parameter_mismatch")
    for a, b in zip(
        jtu.tree_leaves(refit(full)), jtu.tree_leaves(refit(bare)), strict=True
    ):
        np.testing.assert_array_equal(a, b)
    for a, b in zip(
        jtu.tree_leaves(full.arrays), jtu.tree_leaves(bare.arrays), strict=True
    ):
        np.testing.assert_array_equal(a, b)


def test_free_numerator_least_squares_against_lstsq():
    # the normal equations from lagged products (`_free_numerator_sse`) against
    # NumPy's least squares on the explicit lagged regressors, rows of a random
    # walk plus noise (ill-conditioned like an integrator's x / A), lags with and
    # without a leading zero, with and without a constant: the SSE and the
    # coefficients agree to rounding
    rng = np.random.default_rng([19, 7])
    G, n = 9, 700
    u = np.cumsum(rng.standard_normal((G, n)), 1) * 0.05 + rng.standard_normal((G, n))
    y = rng.standard_normal(n)
    cases = [(np.array([0, 1, 2, 3]), False), (np.array([1, 2, 3]), False)]
    cases += [(np.array([2, 5]), False), (np.array([1, 2, 3]), True)]
    for lags, level in cases:  # `level`: a constant column too
        sse, coef = _free_numerator_sse(u, y, lags, level=level)
        for g in range(G):
            R = np.stack(
                [np.concatenate([np.zeros(k), u[g, : n - k]]) for k in lags], 1
            )
            if level:
                R = np.column_stack([R, np.ones(n)])
            ref, *_ = np.linalg.lstsq(R, y, rcond=None)
            np.testing.assert_allclose(coef[g], ref, rtol=1e-9, atol=1e-12)
            np.testing.assert_allclose(sse[g], np.sum((y - R @ ref) ** 2), rtol=1e-10)


def test_profile_sums_against_the_host_path():
    # the fused scan (`_profile_sums`: valve, map, 1/A and the lagged sums in one
    # pass, over blocks of `PROFILE_BLOCK` steps) against the same least squares
    # on the host from the valve positions (`_valve_positions`, the map on NumPy,
    # scipy's lfilter and `_free_numerator_sse`, itself checked against lstsq
    # above): both variants, both maps, a record that ends inside a block, with
    # and without the constant. The sums run in another order, so they agree to
    # rounding relative to the SSE
    rng = np.random.default_rng([19, 8])
    n, G = 600, 7  # 600: a block and a part of one
    v = np.cumsum(rng.standard_normal(n)) * 0.1
    y = rng.standard_normal(n)
    S = rng.uniform(0.05, 0.8, G)
    J = S * rng.uniform(0.0, 0.9, G)
    a = np.array([1.0, -1.6, 0.7])
    pl = np.array([1.3, 0.8, 0.1, -0.2, 0.05, -0.1])
    for slide in (False, True):
        x = np.asarray(_valve_positions(v, S, J, slide=slide))
        gram, rhs, total = _profile_sums(
            v, y, S, J, a, pl, slide=slide, mapped=(True, False), depth=4
        )
        for k, u in enumerate([piecewise_linear_map(x, *pl, xp=np), x]):
            w = lfilter([1.0], a, u, axis=-1)
            # every lagged sum, though the scan accumulates only their first
            # row (`_lagged_gram` derives the rest from the last inputs)
            sums = _lagged_sums(w, y, np.arange(4))
            for got, want in zip((gram[k], rhs[k], total[k]), sums, strict=True):
                scale = np.max(np.abs(want))
                np.testing.assert_allclose(got, want, rtol=0, atol=1e-12 * scale)
            for lags, level in [(np.array([1, 2, 3]), True), (np.arange(4), False)]:
                sse, coef = _free_numerator_sse(w, y, lags, level=level)
                sse2, coef2 = _solve_lagged(
                    gram[k], rhs[k], total[k], y, lags, level=level
                )
                np.testing.assert_allclose(sse2, sse, rtol=1e-9)
                np.testing.assert_allclose(coef2, coef, rtol=1e-8, atol=1e-10)


def test_profile_sums_compile_once_whatever_the_length():
    # the blocks carry the scan's state (`_profile_block`): records of two and
    # of three blocks share one compiled program per variant and maps
    rng = np.random.default_rng([19, 9])
    S = np.linspace(0.1, 0.5, 5)
    a = np.array([1.0, -0.9])
    _profile_block.clear_cache()
    for n in (600, 1300):
        v = np.cumsum(rng.standard_normal(n)) * 0.1
        _profile_sums(
            v, v, S, S / 2, a, np.zeros(6), slide=True, mapped=(False,), depth=3
        )
    assert _profile_block._cache_size() == 1


def test_the_profile_is_blind_to_the_nominal_numerator():
    # the nominal's denominator right, its numerator wrong in gain and shape (a
    # fitted nominal absorbs the valve so): the profile fits the numerator at
    # every grid point, so it still finds f_s (as in the first test, two grid
    # steps); beside a fitted discrete nominal (`refit_linear`) its start re-fits
    # the linear block from the fitted numerator and denominator (at the order
    # the row re-fits, `refit_linear_order`), whose impulse response is the true
    # one to 5 % of its peak (noise-free: what is left comes from the grid
    # point's valve, which slips a sample or so off the truth's), elsewhere the
    # gain alone
    plant, dt, op, pv = _sticky_loop(0, 1.0, 1.0)
    fs = 0.08 * np.ptp(op)
    plant, dt, op, pv = _sticky_loop(0, fs, 0.1 * fs)
    b, a = np.asarray(plant.linear.b), np.asarray(plant.linear.a)
    wrong = np.convolve(0.6 * b, [0.2, 0.8])  # a lag spread over two samples
    nominal = hj.Hammerstein(hj.Identity(), hj.DiscreteTransferFunction(wrong, a, dt))
    nom = describe_nominal(nominal)
    step_s = STATIC_BAND_GRID[0] / STATIC_BAND_GRID[1]
    for refit in (False, True):
        found = stick_slip_profile(
            nom, nominal.linear, dt, op, pv, bucket(op.shape[0]), refit_linear=refit
        )
        S, J, start, slot = found[0]
        assert abs(np.log(((S + J) / 2) / fs)) <= 2.0 * np.log(step_s), found
        if not refit:
            assert set(start) == {"gain", "valve_start"}
            continue
        assert start[REFIT_LINEAR] == 1.0
        assert _impulse_error(start, wrong, b, a) < 0.05, start


def test_a_piecewise_linear_nominal_is_also_profiled_without_its_map():
    # a fitted nominal's dead-band map (which the valve's band suggests) in front
    # of the true process: the profile scores the identity map too, and its best
    # point is one with the map undone ({"k1": g, "k2": g, "d1": 0, ...}: the
    # re-fit frees the map's slots), near the truth
    plant, dt, op, pv = _sticky_loop(1, 1.0, 1.0)
    fs = 0.15 * np.ptp(op)
    plant, dt, op, pv = _sticky_loop(1, fs, 0.05 * fs)
    band = hj.PiecewiseLinear(k1=1.6, k2=1.6, d1=0.3 * fs, d2=-0.3 * fs, l1=0.0, l2=0.0)
    nominal = hj.Hammerstein(band, plant.linear)
    found = stick_slip_profile(
        describe_nominal(nominal), nominal.linear, dt, op, pv, bucket(op.shape[0])
    )
    S, J, start, _ = found[0]
    assert set(start) == {"k1", "k2", "d1", "d2", "l1", "l2", "valve_start"}, found
    assert start["d1"] == start["d2"] == start["l1"] == start["l2"] == 0.0
    # the gain at the grid point, within 1 % of the truth's 1 (noise-free)
    assert np.isclose(start["k1"], 1.0, rtol=0.01) and start["k1"] == start["k2"]
    step_s = STATIC_BAND_GRID[0] / STATIC_BAND_GRID[1]
    assert abs(np.log(((S + J) / 2) / fs)) <= 2.0 * np.log(step_s), found


def test_an_identity_map_point_beside_a_fitted_nominal_holds_the_map():
    # a fitted nominal with a dead-band map (taken from the valve's band) and
    # poles 1.5 x too slow: the profile's best point is scored without the map,
    # and its start re-fits the whole linear block with the map held at the
    # identity (`IDENTITY_MAP`): its denominator re-fitted (impulse response
    # within 5 % of the truth's peak; before, such a start freed the map and
    # kept the nominal's poles). The row built from it (`prepare`) holds the
    # map's slots at the identity (`Row.held`) and, at its start, simulates
    # exactly what the benchmark's own He valve through the start's linear
    # block gives (1e-9). The impulse response is not that close on every loop:
    # a first-order process re-fitted at third order may leave two near-cancelling
    # slow modes (loops 1 and 2 of this helper: 0.33 and 0.10, measured)
    plant, dt, op, pv = _sticky_loop(0, 1.0, 1.0, noise=0.01)
    fs = 0.15 * np.ptp(op)
    plant, dt, op, pv = _sticky_loop(0, fs, 0.05 * fs, noise=0.01)
    b, a = np.asarray(plant.linear.b), np.asarray(plant.linear.a)
    a_wrong = np.real(np.poly(np.roots(a) ** 1.5))
    band = hj.PiecewiseLinear(k1=1.6, k2=1.6, d1=0.3 * fs, d2=-0.3 * fs, l1=0.0, l2=0.0)
    nominal = hj.Hammerstein(band, hj.DiscreteTransferFunction(0.6 * b, a_wrong, dt))
    found = _fitted_profile(nominal, dt, op, pv)
    S, J, start, slot = found[0]
    assert start[REFIT_LINEAR] == start[IDENTITY_MAP] == 1.0, found
    assert not {"k1", "k2", "d1", "d2", "l1", "l2"} & set(start), start
    step_s = STATIC_BAND_GRID[0] / STATIC_BAND_GRID[1]
    assert abs(np.log(((S + J) / 2) / fs)) <= 2.0 * np.log(step_s), found
    assert _impulse_error(start, 0.6 * b, b, a) < 0.05, start

    rec = {"t": dt * np.arange(op.shape[0]), "v": op, "y": pv}
    prep = prepare(nominal, dt, rec, rec, fitted_nominal=True)
    names = slot_names(N_MAX)
    pl = [names.index(n) for n in ("k1", "k2", "d1", "d2", "l1", "l2")]
    held = [
        (k, n, r)
        for k, (n, r) in enumerate(prep.rows)
        if not np.allclose(np.asarray(r.held)[pl], np.asarray(prep.arrays.neutral)[pl])
    ]
    # the profile's identity starts and one linear twin that holds the map too
    assert [n for _, n, _ in held].count(LINEAR_TWIN) == 1, held
    assert all(n in ("backlash", LINEAR_TWIN) for _, n, _ in held), held
    k, _, row = next(h for h in held if h[1] == "backlash")
    # that row stands for its class over the twin of its own map: what the
    # identity map alone explains better than the nominal's is no play
    k_twin = next(j for j, n, _ in held if n == LINEAR_TWIN)
    # which starts from its own linear fit (`identity_twin_start`)
    assert not starts_at_nominal_numerator(prep.rows[k_twin][1])
    k_nominal_twin = next(
        j
        for j, (n, _) in enumerate(prep.rows)
        if n == LINEAR_TWIN and j not in [h[0] for h in held]
    )

    def stands(gain: float) -> bool:
        sse, val_sse = np.full(len(prep.rows), 1e3), np.full(len(prep.rows), 1e3)
        sse[k_nominal_twin], sse[k_twin], sse[k] = 1e3, 100.0 + gain, 100.0
        val_sse[k_nominal_twin], val_sse[k_twin], val_sse[k] = 1e3, 100.0, 90.0
        return best_row_per_class(prep, sse, val_sse).get("backlash") == k

    assert stands(50.0)  # a ratio of about 1000 over its own twin
    assert not stands(0.0)  # nothing over its own twin, 900 over the other
    assert not np.any(np.asarray(row.free)[pl])
    np.testing.assert_array_equal(np.asarray(row.held)[pl], IDENTITY_PL)
    p = np.asarray(full_parameters(row.theta0, row, prep.arrays))
    y = np.asarray(simulate_augmented(p, 0, prep.arrays.v_est, prep.arrays))
    get = lambda n: p[names.index(n)]  # noqa: E731
    S1, J1, d = get("backlash"), get(_jump_slot(row, names)), get("valve_start")
    fs1, fd1 = (S1 + J1) / 2, (S1 - J1) / 2
    x = cl.valve_positions(cl.HeStiction(fs1, fd1, x0=op[0] + d), op)
    full = np.zeros(N_MAX + 1)
    full[: b.shape[0]] = 0.6 * b
    full += [get(f"db{k}") for k in range(N_MAX + 1)]
    den = np.r_[1.0, [get(f"den{j}") for j in range(1, N_MAX + 1)]]
    expected = lfilter(full, den, x) + get("out_off")
    np.testing.assert_allclose(y[: op.shape[0]], expected, rtol=1e-9, atol=1e-9)
    # the report gives the held map with the re-fit (held: no std)
    phys = np.zeros((len(prep.rows), len(names)))
    phys[k] = p
    width = np.asarray(row.idx).shape[0]
    fit = {"params": phys, "theta_std": np.zeros((len(prep.rows), width))}
    refit = _params(prep, fit, k, "backlash")["nominal_refit"]
    assert [refit[n]["value"] for n in ("k1", "k2", "d1", "d2")] == [1, 1, 0, 0]
    assert refit["k1"]["std"] == 0.0 and "den1" in refit


def test_the_identity_twin_starts_from_its_own_linear_fit():
    # noise-free, no valve: y = b / a v + c. Beside a fitted nominal with a
    # dead-band map and poles 1.5 x too slow, the identity twin's start (the
    # linear block fitted to v itself by variable projection) is the truth:
    # impulse response within 1e-6 of its peak, the level c to 1e-6
    rng = np.random.default_rng([19, 77])
    n = 1500
    v = np.repeat(rng.uniform(-2.0, 2.0, n // 60 + 1), 60)[:n]
    v = v + 0.05 * rng.standard_normal(n)
    b, a = np.array([0.0, 0.05, 0.03]), np.array([1.0, -1.5, 0.6])
    y = lfilter(b, a, v) + 0.4
    a_wrong = np.real(np.poly(np.roots(a) ** 1.5))
    band = hj.PiecewiseLinear(k1=1.2, k2=1.2, d1=0.2, d2=-0.2, l1=0.0, l2=0.0)
    nominal = hj.Hammerstein(band, hj.DiscreteTransferFunction(0.7 * b, a_wrong, 1.0))
    start = identity_twin_start(
        describe_nominal(nominal), nominal.linear, 1.0, v, y, dens=[]
    )
    assert start[IDENTITY_MAP] == 1.0
    assert _impulse_error(start, 0.7 * b, b, a) < 1e-6, start
    assert abs(start["out_off"] - 0.4) < 1e-6, start


def _jump_slot(row, names) -> str:
    """The stick-slip variant's jump slot a row frees."""
    free = np.asarray(row.free)
    return next(s for s in VARIANTS if free[names.index(s)])


def test_the_denominator_refit_recovers_an_output_error_model():
    # variable projection (`_refit_denominator`) on a noise-free second-order
    # output-error record, from poles 10 % off: the true denominator to 1e-6
    rng = np.random.default_rng([19, 8])
    u = np.repeat(rng.standard_normal(100), 10)
    b, a = np.array([0.0, 0.05, 0.03]), np.array([1.0, -1.6, 0.68])
    y = lfilter(b, a, u)
    a0 = np.real(np.poly(0.9 * np.roots(a)))
    found = _refit_denominator(u, y, a0, np.array([1, 2]))
    np.testing.assert_allclose(found, a, atol=1e-6)
    # an error that cannot fall (the start is the optimum already) gives None
    assert _refit_denominator(u, y, a, np.array([1, 2])) is None


def test_beside_a_fitted_nominal_the_profile_refits_the_denominator():
    # a fitted nominal's poles wrong too (moved by 10 %, as a valve's limit cycle
    # moves a fitted nominal's), numerator and all: `refit_linear` re-fits the
    # denominator at the best point, at the order the row re-fits (third: the
    # nominal's first-order A with zeros to start from), and scores the grid near
    # it again, so the start's linear block responds as the true one (its
    # impulse response to 5 % of the peak, as above) and f_s stays within two
    # grid steps
    plant, dt, op, pv = _sticky_loop(0, 1.0, 1.0)
    fs = 0.08 * np.ptp(op)
    plant, dt, op, pv = _sticky_loop(0, fs, 0.1 * fs)
    b, a = np.asarray(plant.linear.b), np.asarray(plant.linear.a)
    a_wrong = np.real(np.poly(np.roots(a) ** 1.5))  # slower poles, 1.5 x the time
    nominal = hj.Hammerstein(
        hj.Identity(), hj.DiscreteTransferFunction(0.6 * b, a_wrong, dt)
    )
    found = _fitted_profile(nominal, dt, op, pv)
    S, J, start, _ = found[0]
    step_s = STATIC_BAND_GRID[0] / STATIC_BAND_GRID[1]
    assert abs(np.log(((S + J) / 2) / fs)) <= 2.0 * np.log(step_s), found
    assert any(start.get(f"den{j}", 0.0) != 0.0 for j in (2, 3)), start
    assert _impulse_error(start, 0.6 * b, b, a) < 0.05, start


def test_the_profile_starts_are_not_continued_as_far_from_their_optimum():
    # beside a fitted discrete nominal the profile's starts re-fit the linear block
    # from the fitted numerator (`db..` set): `starts_at_nominal_numerator` tells
    # them from the rows that start at the nominal's numerator (the sign-blind
    # sensor's, the linear twins), which alone the finishing stage continues to
    # the nominal fit's budget
    plant, dt, op, pv = _sticky_loop(0, 1.0, 0.3, noise=0.01)
    rec = {"t": dt * np.arange(op.shape[0]), "v": op, "y": pv}
    prep = prepare(plant, dt, rec, rec, fitted_nominal=True)
    linear = [(n, r) for n, r in prep.rows if refits_linear(r)]
    profiled = [r for n, r in linear if n == "backlash"]
    others = [r for n, r in linear if n != "backlash"]
    assert len(profiled) == PROFILE_POINTS and others
    assert not any(starts_at_nominal_numerator(r) for r in profiled)
    assert all(starts_at_nominal_numerator(r) for r in others)


def test_the_output_level_of_a_profile_start_is_reported_with_the_refit():
    # the output level that the profile's starts free beside a fitted nominal (a
    # level of the backlash class, another effect's slot) is a fitted parameter:
    # `attribute._params` reports it with the re-fit's, as it does the denominator
    plant, dt, op, pv = _sticky_loop(0, 1.0, 0.3, noise=0.01)
    rec = {"t": dt * np.arange(op.shape[0]), "v": op, "y": pv}
    prep = prepare(plant, dt, rec, rec, fitted_nominal=True)
    k = next(
        i for i, (n, r) in enumerate(prep.rows) if n == "backlash" and refits_linear(r)
    )
    names = slot_names(N_MAX)
    phys = np.zeros((len(prep.rows), len(names)))
    phys[k, names.index("out_off")] = 0.7
    width = np.asarray(prep.rows[k][1].idx).shape[0]
    fit = {"params": phys, "theta_std": np.zeros((len(prep.rows), width))}
    out = _params(prep, fit, k, "backlash")
    assert out["nominal_refit"]["out_off"]["value"] == 0.7
    assert "den1" in out["nominal_refit"] and "out_off" not in out


def test_the_denominator_is_refitted_at_the_order_the_row_refits():
    # a fitted nominal of first order (as a sticky record's selection may give)
    # in front of a second-order process: the profile's denominator re-fit
    # starts from the nominal's A with zeros up to the order the row re-fits
    # (`refit_linear_order`, third), so the start's linear block responds as
    # the true process (impulse response within a tenth of its peak; at the
    # nominal's own order the start's is off by four times the peak, measured)
    # and S and J are found within 1 % (noise-free). Not every loop: with
    # f_s 8 % of the command's range and f_d / f_s 0.3 the re-fit at the best
    # grid point settles with S 10 % low (measured; a limit left)
    for i, fs_rel, ratio in [(1, 0.12, 0.5), (3, 0.1, 0.1)]:
        plant, dt, op, pv = _sticky_loop(i, 1.0, 1.0, process=SOPDT)  # the range
        fs = fs_rel * np.ptp(op)
        plant, dt, op, pv = _sticky_loop(i, fs, ratio * fs, process=SOPDT)
        b, a = np.asarray(plant.linear.b), np.asarray(plant.linear.a)
        pole = np.exp(-dt / 55.0)  # one time constant for the two
        b_nom = np.array([0.0, 0.0, 1.5 * (1.0 - pole)])
        nominal = hj.Hammerstein(
            hj.Identity(), hj.DiscreteTransferFunction(b_nom, [1.0, -pole], dt)
        )
        found = _fitted_profile(nominal, dt, op, pv)
        S, J, start, slot = found[0]
        assert slot == "slip_jump", found
        S0, J0 = fs * (1 + ratio), fs * (1 - ratio)
        assert abs(np.log(S / S0)) < 0.01 and abs(np.log(J / J0)) < 0.01, found[0]
        assert start.get("den3", 0.0) != 0.0  # the third order reached
        assert _impulse_error(start, b_nom, b, a) < 0.1, start
