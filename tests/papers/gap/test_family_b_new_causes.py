"""Family B's friction, feedback nonlinearity and sign-blind sensor (issue 19)."""

import math

import numpy as np
import pytest

from hamjax.papers.gap import family_b as fb


H = 0.01  # fine step of the direct simulations below, s


def _hold(u, n):
    return np.full(n, float(u))


def test_motor_friction_sticks_then_runs_at_the_coulomb_speed():
    # s' = -s/tau + (K/tau)(u - f): from rest it stays at 0 while |u| <= fs; above,
    # it breaks away (f = fs for the first step) and then runs against the Coulomb
    # level only (Stribeck decayed, no viscous part): with a = exp(-h/tau) the exact
    # ZOH lag gives w_j = K (u - fc)(1 - a^j) - K (fs - fc)(1 - a) a^(j-1), j >= 1.
    tau, K, fs, fc = 0.2, 2.0, 0.5, 0.3
    e = {"fc_over_fs": fc / fs, "vstr": 1e-9, "visc": 0.0, "V": 1.0}
    force = fb._friction_force(fs, e)
    w = fb._axis(_hold(0.49, 400), H, [K], [tau, 1.0], force, sticks=True)
    assert np.all(w == 0.0)
    w = fb._axis(_hold(0.9, 400), H, [K], [tau, 1.0], force, sticks=True)
    a, j = math.exp(-H / tau), np.arange(1, 400)
    expected = K * (0.9 - fc) * (1 - a**j) - K * (fs - fc) * (1 - a) * a ** (j - 1)
    assert w[0] == 0.0
    assert np.allclose(w[1:], expected, rtol=1e-10, atol=1e-13)
    assert w[-1] == pytest.approx(K * (0.9 - fc), rel=1e-6)


def test_axis_friction_stops_within_the_static_band():
    # m x'' + c x' + k x = Ka (u - f): from rest the axis does not move while
    # |u| <= fs; above it, it moves and ends stuck where the spring leaves the drive
    # within the static level: |u - k x / Ka| <= fs, with the velocity exactly 0.
    m, c, k, Ka, fs = 1.0, 0.4, 40.0, 40.0, 0.2
    e = {"fc_over_fs": 0.6, "vstr": 0.05, "visc": 0.1, "V": 1.0}
    force = fb._friction_force(fs, e)
    x = fb._axis(_hold(0.15, 500), H, [Ka], [m, c, k], force, sticks=True)
    assert np.all(x == 0.0)
    x = fb._axis(_hold(1.0, 3000), H, [Ka], [m, c, k], force, sticks=True)
    assert np.ptp(x[-500:]) <= 1e-12 * abs(x[-1])  # stuck
    assert abs(1.0 - k * x[-1] / Ka) <= fs + 1e-12
    assert x[-1] > 0


@pytest.mark.parametrize("u", [0.3, 1.5])
def test_cubic_spring_equilibrium(u):
    # m x'' + c x' + k x + k3 x^3 = Ka u settles at the real root of the cubic
    # (numpy.roots, independent of the simulation); k3 W^3 = mag k W.
    m, c, k, Ka, W, mag = 1.0, 3.0, 25.0, 25.0, 1.0, 0.8
    force = fb._spring_force(mag, "cubic_stiffness", {"W": W}, k / Ka)
    x = fb._axis(_hold(u, 3000), H, [Ka], [m, c, k], force, sticks=False)
    k3 = mag * k / W**2
    roots = np.roots([k3, 0.0, k, -Ka * u])
    x_eq = float(np.real(roots[np.abs(np.imag(roots)) < 1e-9][0]))
    assert x[-1] == pytest.approx(x_eq, rel=1e-8)
    assert x_eq < Ka * u / k  # hardening: less than the linear spring's


@pytest.mark.parametrize("u", [0.1, 1.0])
def test_clearance_spring_equilibrium(u):
    # a share `mag` of the stiffness acts only beyond the clearance g:
    # (1 - mag) k x + mag k (x - clip(x, -g, g)) = Ka u. Inside (|x| <= g):
    # x = Ka u / ((1 - mag) k); outside: x = Ka u / k + mag g.
    m, c, k, Ka, g, mag = 1.0, 3.0, 25.0, 25.0, 0.3, 0.5
    force = fb._spring_force(mag, "spring_clearance", {"W": 1.0, "gap": g}, k / Ka)
    x = fb._axis(_hold(u, 3000), H, [Ka], [m, c, k], force, sticks=False)
    inside = Ka * u / ((1 - mag) * k)
    x_eq = inside if inside <= g else Ka * u / k + mag * g
    assert x[-1] == pytest.approx(x_eq, rel=1e-8)


def test_zero_magnitude_is_the_linear_plant_exactly():
    rng = np.random.default_rng(3)
    u = np.repeat(rng.uniform(-1, 1, 40), 25)
    num, den = [30.0], [1.0, 2.0, 30.0]
    ref = fb._lsim(num, den, u, H)  # modal exact ZOH
    for shape in ("cubic_stiffness", "spring_clearance"):
        force = fb._spring_force(0.0, shape, {"W": 1.0, "gap": 0.2}, 1.0)
        x = fb._axis(u, H, num, den, force, sticks=False)
        assert np.allclose(x, ref, atol=1e-10 * np.max(np.abs(ref)))


# `make_case` redraws until the achieved size is in the range; these check the
# sizing that lands in truth.json against the rule, with the draws' own bounds.
@pytest.mark.parametrize("cause", ["friction", "feedback_nonlinearity"])
def test_new_causes_are_sized_like_the_other_structural_ones(cause):
    seen = set()
    for i in range(6):
        case = fb.make_case(11, i, cause)
        tr = case["truth"]
        seen.add((tr["plant"], tr["shape"]))
        assert tr["effect"] == cause and tr["plant"] in fb.PLANTS_FOR[cause]
        assert 0.8 * fb.RATIO[0] <= tr["effect_rms_over_noise"] <= 1.25 * fb.RATIO[1]
        assert 10.0 - 1e-6 <= tr["snr_db"] <= 40.0 + 1e-6
        errs = np.abs(list(tr["nominal_errors"].values()))
        assert np.all((errs >= 0.15 - 1e-12) & (errs <= 0.20 + 1e-12))
        assert case["model"]["nonlinearity"] == {"kind": "identity"}
        for rec in ("estimation", "validation"):
            assert np.all(np.isfinite(case[rec]["y"]))
    assert len(seen) >= 2  # both plants (friction) or both shapes (feedback)


def test_sign_blind_sensor_case():
    # the motor runs forward with a drive bias, reversing just enough: y >= 0 up to
    # noise, the size after re-fit in the rule's range.
    for i in range(200):
        rng = np.random.default_rng([4, i])
        kinds = fb.PLANTS_FOR["output_nonlinearity"]
        if kinds[int(rng.integers(len(kinds)))] != "motor":
            continue
        case = fb.make_case(4, i, "output_nonlinearity")
        tr = case["truth"]
        if tr["shape"] != "sign_blind":
            continue
        assert tr["forward_bias"] > 0
        assert 0.8 * fb.RATIO[0] <= tr["effect_rms_over_noise"] <= 1.25 * fb.RATIO[1]
        y, s = case["estimation"]["y"], tr["noise_std"]
        # |w| >= 0: a sample below -5 noise std has probability 2.9e-7, ~1e-3 for
        # a whole record of at most 4000
        assert np.min(y) > -5.0 * s
        return
    pytest.fail("no sign-blind case in 200 draws")  # pragma: no cover


def test_twelve_never_draws_the_new_shapes():
    motors = 0
    for i in range(60):
        rng = np.random.default_rng([1, i])
        kinds = fb.PLANTS_FOR["output_nonlinearity"]
        if kinds[int(rng.integers(len(kinds)))] != "motor":
            continue
        tr = fb.make_case(1, i, "output_nonlinearity", classes="twelve")["truth"]
        assert tr["shape"] in ("tanh_offset", "polynomial", "range_limit")
        motors += 1
        if motors == 3:
            return
    pytest.fail("fewer than 3 motor draws in 60")  # pragma: no cover
