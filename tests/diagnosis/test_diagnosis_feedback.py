"""The effects fed back from the output (`friction`, `feedback_nonlinearity`) and the
sign-blind sensor (`output_nonlinearity`'s `out_abs`): neutral exactly, the loop
against an independent NumPy loop, the fit's gradient against finite differences,
and noise-free recovery through `diagnose_many`."""

import jax
import jax.numpy as jnp
import jax.random as jr
import numpy as np
import pytest
import scipy.signal as sg
from scipy.optimize import brentq

import hamjax as hj
from hamjax.diagnosis.augmented import (
    full_parameters,
    simulate_augmented,
    slot_index,
    uses_feedback,
)
from hamjax.diagnosis.diagnose import diagnose_many
from hamjax.diagnosis.effects.feedback_nonlinearity import feedback_force
from hamjax.diagnosis.effects.friction import EPS_FRACTION, friction_force
from hamjax.diagnosis.effects.output_nonlinearity import output_map
from hamjax.diagnosis.fit import normal_equations
from hamjax.diagnosis.layout import N_MAX, prepare
from hamjax.papers.gap.demo_cases import staircase


DT = 0.05
B, A = [0.0, 0.2, 0.1], [1.0, -1.1, 0.4]
NOMINAL = hj.Hammerstein(hj.Identity(), hj.DiscreteTransferFunction(B, A, DT))
PLANTS = [
    NOMINAL,
    hj.Hammerstein(
        hj.PiecewiseLinear(k1=1.2, k2=0.8, d1=0.1, d2=-0.2, l1=0.1, l2=-0.05),
        hj.ContinuousTransferFunction([1.0, 3.0], [1.0, 1.5, 2.0, 1.0]),
    ),
    hj.Hammerstein(
        hj.Tabulated([-1.0, -0.2, 0.3, 1.0], [-0.8, -0.1, 0.4, 0.9]),
        hj.ContinuousTransferFunction([2.0], [0.5, 1.0]),
    ),
]


def _records(key, n=400):
    k1, k2 = jr.split(key)
    return [
        {"t": np.arange(n) * DT, "v": staircase(k, n), "y": np.zeros(n)}
        for k in (k1, k2)
    ]


def _neutral_params(row, A_):
    p = full_parameters(jnp.zeros_like(row.theta0), row, A_)
    return jnp.where(row.free, A_.neutral, p)


def test_new_shapes_are_exactly_neutral(getkey):
    # any draw: each force is a product with a zero slot, the sign-blind reading
    # adds 0 * (|w| - w); exact equality, not a tolerance
    w = jr.normal(getkey(), (200,))
    w_prev = jr.normal(getkey(), (200,))
    zero = jnp.zeros(())
    assert jnp.array_equal(friction_force(w, w_prev, zero, zero, 0.1, 0.2), 0 * w)
    assert jnp.array_equal(feedback_force(w, 1.5, 0.7, zero, zero, zero), 0 * w)
    inf = jnp.inf
    assert jnp.array_equal(output_map(w, 0.0, 2.0, 0, 0, -inf, inf, 0, 0.0), w)


@pytest.mark.parametrize("plant", PLANTS)
def test_feedback_loop_at_neutral_is_the_plain_filter_bit_for_bit(plant, getkey):
    # the regression guard of every earlier candidate: with the feedback slots at
    # neutral the one-scan loop returns exactly the plain filter's output (and the
    # rows that free no feedback slot never run the loop: `uses_feedback`)
    est, val = _records(getkey())
    prep = prepare(plant, DT, est, val)
    sim = jax.jit(simulate_augmented, static_argnames=("feedback",))
    for name, row in prep.rows:
        assert bool(uses_feedback(row.free)) == (
            name in ("friction", "feedback_nonlinearity")
        )
        p = _neutral_params(row, prep.arrays)
        loop = sim(p, row.tau, prep.arrays.v_est, prep.arrays, feedback=True)
        plain = sim(p, row.tau, prep.arrays.v_est, prep.arrays, feedback=False)
        assert jnp.array_equal(loop, plain), name


def _scales(plant, v):
    """The velocity scales of the diagnosis (`layout.prepare`), recomputed here:
    2 %/98 % quantiles of the nominal output and of its rate, and std(u)."""
    w = sg.lfilter(B, A, v)
    half = lambda x: max(abs(np.quantile(x, 0.98)), abs(np.quantile(x, 0.02)))  # noqa: E731
    return half(w), half(np.diff(w) / DT), float(np.std(v))


def _loop(v, force):
    """Independent reference: the plant's state space (scipy) in a Python loop from
    rest, `force = (phi, f)`: u_k = v_k - phi(w_k) - f(w_{k+1}, (w_{k+1} - w_k)/dt)
    with w_k = C x_k (b0 = 0: exact) and w_{k+1} = C (A x_k + B u_k), the
    implicit equation solved by `scipy.optimize.brentq` (bracket v' +- 1)."""
    phi, f = force
    Ass, Bss, Css, _ = sg.tf2ss(B[1:], A)
    x, out = np.zeros(Ass.shape[0]), np.empty(v.shape[0])
    for k, vk in enumerate(v):
        w = float(Css[0] @ x)
        s2 = vk - phi(w)

        def g(u, x=x, w=w, s2=s2):
            w_next = float(Css[0] @ (Ass @ x + Bss[:, 0] * u))
            return u - s2 + f(w_next, (w_next - w) / DT)

        uk = s2 if g(s2) == 0 else brentq(g, s2 - 1, s2 + 1, xtol=1e-14)
        out[k] = w
        x = Ass @ x + Bss[:, 0] * uk
    return out


def _truths(v_est):
    H, V, U = _scales(NOMINAL, v_est)
    eps_w, eps_dw = EPS_FRACTION * H, EPS_FRACTION * V
    none = lambda *_: 0.0  # noqa: E731
    return {
        "friction_output": (
            (none, lambda vw, vd: 0.1 * np.tanh(vw / eps_w)),
            {"fric_w": 0.1},
        ),
        "friction_derivative": (
            (none, lambda vw, vd: 0.1 * np.tanh(vd / eps_dw)),
            {"fric_dw": 0.1},
        ),
        "cubic": ((lambda w: 0.3 * (w / H) ** 3 * U, none), {"fb_cubic": 0.3}),
        "clearance": (
            (lambda w: 0.5 * U / H * (w - np.clip(w, -0.3 * H, 0.3 * H)), none),
            {"fb_gain": 0.5 * U / H, "fb_band": 0.3 * H},
        ),
    }


def test_loop_matches_an_independent_numpy_loop(getkey):
    # the augmented model with one feedback slot set against the loop above; the
    # two sum the same terms in another order: 1e-10 relative to the output peak
    # (400 steps of a stable second-order filter, rounding ~1e-15 per step)
    est, val = _records(getkey())
    prep = prepare(NOMINAL, DT, est, val)
    rows = {name: row for name, row in prep.rows}
    row = rows["friction"]  # its free slots are a superset mask; set values directly
    for name, (force, values) in _truths(est["v"]).items():
        p = _neutral_params(row, prep.arrays)
        for slot, x in values.items():
            p = p.at[slot_index(slot, N_MAX)].set(x)
        got = simulate_augmented(p, row.tau, prep.arrays.v_est, prep.arrays)
        want = _loop(est["v"], force)
        got = np.asarray(got)[: prep.n_est]
        assert np.allclose(got, want, rtol=0, atol=1e-10 * np.abs(want).max()), name


def test_normal_equations_gradient_matches_finite_differences(getkey):
    # J^T r of a feedback row against central differences of r^T r / 2 in theta.
    # The smooth Coulomb law on dw/dt chatters near zero velocity and curves the
    # cost sharply in c: the truncation error of a step h grows as h^2 (measured
    # on one draw: wrong sign at h = 1e-6, 2e-4 relative at h = 1e-7); h = 1e-8
    # leaves truncation ~2e-6 and rounding ~1e-16 |r|^2 / h ~ 1e-7 relative
    # (|r|^2 ~ 1-10 here), so 1e-5 of the largest entry bounds both
    est, val = _records(getkey())
    force, _ = _truths(est["v"])["cubic"]
    est["y"] = _loop(est["v"], force)
    prep = prepare(NOMINAL, DT, est, val)
    neq = jax.jit(normal_equations)
    for name, row in prep.rows:
        if name not in ("friction", "feedback_nonlinearity"):
            continue
        theta = row.theta0 + 0.1 * jr.normal(getkey(), row.theta0.shape)
        sse, _, g = neq(theta, row, prep.arrays)
        h = 1e-8
        fd = np.array(
            [
                (
                    neq(theta + h * e, row, prep.arrays)[0]
                    - neq(theta - h * e, row, prep.arrays)[0]
                )
                / (4 * h)
                for e in np.eye(theta.shape[0])
            ]
        )
        used = np.asarray(row.idx) < prep.arrays.anchor.shape[0]
        scale = np.abs(fd[used]).max()
        assert np.allclose(np.asarray(g)[used], fd[used], atol=1e-5 * scale), name


@pytest.mark.slow
def test_feedback_effects_and_sign_blind_sensor_recovered_noise_free():
    # noise 1e-6 against effects of ~0.05-0.5 in output units: the withheld effect
    # is named, its gap closes to the noise, and its parameter is recovered to
    # 1e-3 relative (the fit's noise-limited error is ~1e-5; 1e-3 leaves room for
    # the convergence test, a relative cost decrease of 1e-10)
    items, expected = [], []
    for i, (name, (force, values)) in enumerate(
        _truths(staircase(jr.key(40), 400)).items()  # H, V, U of the est. record
    ):
        recs = []
        for j in range(2):
            v = staircase(jr.key(40 + 2 * j), 400)
            noise = 1e-6 * np.asarray(jr.normal(jr.key(90 + 10 * i + j), (400,)))
            recs.append(
                {"t": np.arange(400) * DT, "v": v, "y": _loop(v, force) + noise}
            )
        items.append((NOMINAL, DT, *recs))
        effect = "friction" if name.startswith("friction") else "feedback_nonlinearity"
        expected.append((name, effect, values))
    for j_gain, gain in enumerate((1.0, -0.8)):  # sign-blind sensor, a = 0.9
        recs = []
        for j in range(2):
            v = staircase(jr.key(60 + j), 400)
            w = gain * sg.lfilter(B, A, v)
            noise = 1e-6 * np.asarray(jr.normal(jr.key(70 + 2 * j_gain + j), (400,)))
            y = w + 0.9 * (np.abs(w) - w) + noise
            recs.append({"t": np.arange(400) * DT, "v": v, "y": y})
        items.append((NOMINAL, DT, *recs))
        expected.append(("sign_blind", "output_nonlinearity", {"out_abs": 0.9}))
    out = diagnose_many(items)
    for (name, effect, values), d in zip(expected, out, strict=True):
        assert d.effect == effect, (name, d.effect, d.tests)
        assert d.gap_after < 1e-4 * d.gap_before + 5e-6, name
        params = d.ranking[0]["params"]
        for slot, x in values.items():
            assert np.isclose(params[slot]["value"], x, rtol=1e-3), (name, slot)
        if effect == "friction":
            velocity = name.removeprefix("friction_")
            assert params["velocity"]["value"] == velocity
    # the re-fitted gain takes the sign the sign-blind reading leaves visible
    refit = out[-1].ranking[0]["params"]["nominal_refit"]
    assert np.isclose(refit["gain"]["value"], -0.8, rtol=1e-3)


def test_blind_generator_draws_the_feedback_classes():
    # family A: the loop without a force is the generator's own linear response
    # (same state space, same order of operations for continuous blocks; scipy's
    # tf2ss against direct form II for discrete: 1e-12 of the peak), and both
    # feedback classes come out of `make_case` in both modes, visible (effect RMS
    # > 0) and finite (a diverging loop is drawn again)
    from hamjax.papers.gap import blind

    v = staircase(jr.key(5), 300)
    for lin in (
        hj.DiscreteTransferFunction(B, A, DT),
        hj.ContinuousTransferFunction([2.0], [0.5, 1.5, 1.0]),
    ):
        ref = blind._lsim(lin, v, DT)
        got = blind._lsim_loop(lin, v, DT, (lambda w: 0.0, lambda vw, vd: 0.0, 0.0))
        assert np.allclose(got, ref, rtol=0, atol=1e-12 * np.abs(ref).max())
    seen = set()
    for i in range(16):  # seed 7: cases 1 and 11 are friction, 15 feedback
        for realism in ("exact", "realistic"):
            case = blind.make_case(jr.fold_in(jr.key(7), i), realism=realism)
            truth = case["truth"]
            if truth["effect"] in blind.FEEDBACK_EFFECTS:
                seen.add((truth["effect"], realism))
                assert truth["effect_rms_over_noise"] > 0
                assert np.all(np.isfinite(case["estimation"]["y"]))
    assert seen == {
        (e, r) for e in blind.FEEDBACK_EFFECTS for r in ("exact", "realistic")
    }
