"""Effects of the gap catalogue: neutral at neutral parameters, against independent
references; the universal augmented model against `hj.simulate`; residual tests."""

import os
import subprocess
import sys

import jax
import jax.numpy as jnp
import jax.random as jr
import jax.tree_util as jtu
import numpy as np
import pytest
import scipy.signal as sg
import scipy.stats as st

import hamjax as hj
from hamjax.diagnosis.augmented import (
    EFFECT_SLOTS,
    full_parameters,
    linear_polynomials,
    simulate_augmented,
    simulate_row,
    simulate_rows,
    slot_index,
    uses_feedback,
    uses_memory,
)
from hamjax.diagnosis.effects.backlash import play_step
from hamjax.diagnosis.effects.coloured_noise import ar1_errors, fit_ar1
from hamjax.diagnosis.effects.dead_zone import dead_zone
from hamjax.diagnosis.effects.drift import local_level_errors
from hamjax.diagnosis.effects.output_nonlinearity import (
    OutputNonlinearityEffect,
    output_map,
)
from hamjax.diagnosis.effects.preload import add_preload
from hamjax.diagnosis.effects.rate_limit import rate_limit_step
from hamjax.diagnosis.effects.saturation import saturate
from hamjax.diagnosis.effects.time_delay import delay
from hamjax.diagnosis.fit import normal_equations
from hamjax.diagnosis.layout import N_MAX, prepare
from hamjax.diagnosis.residuals import improvement_z, ljung_box, noise_floor_hf


def _scan(step, v, param):
    def f(x, vk):
        x = step(x, vk, param)
        return x, x

    return jax.lax.scan(f, v[0], v)[1]


def test_effects_neutral_exactly(getkey):
    # Exact for any draw: each neutral effect is the identity by construction.
    v = jr.normal(getkey(), (200,))
    inf = jnp.inf
    assert jnp.array_equal(_scan(play_step, v, 0.0), v)
    assert jnp.array_equal(_scan(rate_limit_step, v, inf), v)
    assert jnp.array_equal(dead_zone(v, 0.0, 0.0), v)
    assert jnp.array_equal(saturate(v, -inf, inf), v)
    assert jnp.array_equal(add_preload(v, v, 0.0), v)
    assert jnp.array_equal(delay(v, jnp.asarray(0)), v)
    neutral = OutputNonlinearityEffect.neutral  # the effect's own neutral values
    assert jnp.array_equal(output_map(v, neutral.__getitem__, 0.3, 2.0), v)
    assert jnp.array_equal(ar1_errors(v, 0.0), v)
    assert jnp.array_equal(local_level_errors(v, 0.0), v)


def test_play_operator_equals_core_backlash(getkey):
    v = jnp.repeat(jr.uniform(getkey(), (40,), minval=-1, maxval=1), 7)
    c = 0.37
    ref = hj.apply_nonlinearity(hj.Backlash.from_width(c, u0=v[0]), v)
    # any draw: |v| <= 1, each step one clip to v +- c/2 (no accumulation), so the
    # two differ by at most a few ulp(1.2) ~ 2.2e-16 each, below 1e-14
    assert np.allclose(_scan(play_step, v, c), ref, rtol=0, atol=1e-14)


def test_effect_forms_against_numpy(getkey):
    v = np.asarray(jr.uniform(getkey(), (300,), minval=-2, maxval=2))
    w = 0.4
    # Any draw: |v| <= 2, so one subtraction is off by at most ulp(2)/2 = 2.2e-16
    # (< 1e-15). The rate limit's forms differ only on unsaturated steps (by an ulp);
    # saturated steps carry that difference without growing it (< 1e-14).
    ref_dz = np.sign(v) * np.maximum(np.abs(v) - w, 0)
    assert np.allclose(dead_zone(jnp.asarray(v), w, w), ref_dz, atol=1e-15)
    ref_delay = np.r_[np.full(3, v[0]), v[:-3]]
    assert np.array_equal(delay(jnp.asarray(v), jnp.asarray(3)), ref_delay)
    step = 0.05
    x, ref_rate = v[0], []
    for vk in v:
        x = x + np.clip(vk - x, -step, step)
        ref_rate.append(x)
    assert np.allclose(
        _scan(rate_limit_step, jnp.asarray(v), step), ref_rate, atol=1e-14
    )
    assert np.array_equal(
        add_preload(jnp.zeros(3), jnp.array([-1.0, 0.0, 2.0]), 0.5), [-0.5, 0, 0.5]
    )


def _records(key, n=300):
    k1, k2 = jr.split(key)
    mk = lambda k: np.repeat(
        np.asarray(jr.uniform(k, (n // 20 + 1,), minval=-1, maxval=1)), 20
    )[:n]
    return [{"t": np.arange(n) * 0.05, "v": mk(k), "y": np.zeros(n)} for k in (k1, k2)]


PLANTS = [
    hj.Hammerstein(
        hj.Identity(), hj.DiscreteTransferFunction([0.0, 0.3], [1.0, -0.7], 0.05)
    ),
    hj.Hammerstein(
        hj.PiecewiseLinear(k1=1.2, k2=0.8, d1=0.1, d2=-0.2, l1=0.1, l2=-0.05),
        hj.DiscreteTransferFunction([0.1, 0.2, 0.1], [1.0, -1.2, 0.5, -0.05], 0.05),
    ),
    hj.Hammerstein(
        hj.Tabulated([-1.0, -0.2, 0.3, 1.0], [-0.8, -0.1, 0.4, 0.9]),
        hj.ContinuousTransferFunction([2.0], [0.5, 1.0]),
    ),
    hj.Hammerstein(
        hj.Identity(), hj.ContinuousTransferFunction([1.0, 3.0], [1.0, 1.5, 2.0, 1.0])
    ),
    # a backlash nominal (the model.json form: borders tabulated on one grid),
    # curved and of unequal width, so that neither border is a shift of the other
    hj.Hammerstein(
        hj.Backlash.from_table(
            np.linspace(-1.2, 1.2, 9),
            0.8 * np.linspace(-1.2, 1.2, 9)
            - 0.15
            + 0.1 * np.linspace(-1.2, 1.2, 9) ** 2,
            0.9 * np.linspace(-1.2, 1.2, 9) + 0.2,
        ),
        hj.DiscreteTransferFunction([0.0, 0.3], [1.0, -0.7], 0.05),
    ),
]


@pytest.mark.parametrize("plant", PLANTS)
def test_augmented_at_neutral_is_nominal(plant, getkey):
    # any draw: inputs are levels in [-1, 1]; the tolerances below are relative
    # plus 1e-10 of the record's own peak (absolute part scaled by the data)
    est, val = _records(getkey())
    prep = prepare(plant, 0.05, est, val)
    ct = isinstance(plant.linear, hj.ContinuousTransferFunction)
    ref = hj.simulate(plant, jnp.asarray(est["v"]), dt=0.05 if ct else None)
    sim = jax.jit(simulate_augmented)
    for name, row in prep.rows:
        if name == "time_delay":
            continue
        # every row at its neutral effect value (theta = 0 moves nothing but the
        # effect slot, which we put back to neutral)
        theta = jnp.zeros_like(row.theta0)
        p = full_parameters(theta, row, prep.arrays)
        p = jnp.where(row.free, prep.arrays.neutral, p)
        y = sim(p, row.tau, prep.arrays.v_est, prep.arrays)[: prep.n_est]
        assert np.allclose(
            y, ref, rtol=1e-9, atol=1e-10 * float(jnp.max(jnp.abs(ref)))
        ), name
    # the NumPy nominal output (gap_before) is the same simulation
    assert np.allclose(
        prep.w_est, ref, rtol=1e-9, atol=1e-10 * float(jnp.max(jnp.abs(ref)))
    )


def test_continuous_block_matches_scipy_zoh():
    lin = hj.ContinuousTransferFunction([1.0, 3.0], [1.0, 1.5, 2.0, 1.0])
    plant = hj.Hammerstein(hj.Identity(), lin)
    est, val = _records(jr.key(0))
    prep = prepare(plant, 0.05, est, val)
    row = prep.rows[0][1]
    b, a = linear_polynomials(
        full_parameters(row.theta0, row, prep.arrays), prep.arrays
    )
    bz, az, _ = sg.cont2discrete(([1.0, 3.0], [1.0, 1.5, 2.0, 1.0]), 0.05, method="zoh")
    u = est["v"]
    ref = sg.lfilter(np.ravel(bz), az, u)
    got = sg.lfilter(np.asarray(b), np.asarray(a), u)
    assert np.allclose(got, ref, atol=1e-11)


def test_vmap_rows_equals_loop():
    plant = PLANTS[1]
    est, val = _records(jr.key(1))
    prep = prepare(plant, 0.05, est, val)
    rows = [r for _, r in prep.rows]
    stacked = jtu.tree_map(lambda *x: jnp.stack(x), *rows)
    batch = simulate_rows(stacked.theta0, stacked, prep.arrays.v_est, prep.arrays)
    one_row = jax.jit(simulate_row)
    for i, r in enumerate(rows):
        one = one_row(r.theta0, r, prep.arrays.v_est, prep.arrays)
        # fixed key 1 (the same records each run); the outputs are O(1), so
        # atol 1e-12 is ~1e4 ulp of the record's scale (vmap may fuse differently)
        assert np.allclose(batch[i], one, rtol=1e-12, atol=1e-12)


def test_slot_layout():
    assert slot_index("den1", N_MAX) == slot_index(EFFECT_SLOTS[-1], N_MAX) + 1


@pytest.mark.statistical
def test_noise_floor_and_improvement_z_calibrated():
    # 400 white records of 1000 samples (fixed key). The HF noise floor is unbiased
    # to within 4 Monte Carlo standard errors (false-failure rate ~6e-5); the
    # improvement z between two independent "models" that differ by a fixed
    # deterministic delta has a rejection rate at z > 3.5 below 1 % + 3 MCSE.
    key = jr.key(1234)
    e = np.asarray(jr.normal(key, (400, 1000)))
    floors = np.array([noise_floor_hf(x) for x in e])
    mcse = floors.std() / np.sqrt(400)
    assert abs(floors.mean() - 1.0) < 4 * mcse + 0.01
    delta = 0.1 * np.sin(np.arange(1000) / 30)
    z = np.array([improvement_z(x, x - delta) for x in e])  # a worse "after" model
    rate = np.mean(z > 3.5)
    assert rate < 0.01 + 3 * np.sqrt(0.01 * 0.99 / 400)


def test_ljung_box_p_value_matches_scipy():
    x = np.asarray(jr.normal(jr.key(5), (500,)))
    x = sg.lfilter([1.0], [1.0, -0.2], x)
    lb = ljung_box(x, 10)
    assert np.isclose(lb["p_value"], st.chi2.sf(lb["Q"], 10), rtol=1e-6, atol=1e-12)


def test_fit_ar1_recovers_pole():
    e = np.asarray(jr.normal(jr.key(7), (20000,)))
    r = sg.lfilter([1.0], [1.0, -0.8], e)
    a = fit_ar1(jnp.asarray(r), jnp.ones(r.shape[0]))
    # standard error of the AR(1) estimate: sqrt((1 - a^2)/N) = 0.0042; 5 se
    assert abs(float(a) - 0.8) < 5 * np.sqrt((1 - 0.64) / 20000)


@pytest.mark.parametrize("plant", PLANTS)
def test_blocked_normal_equations_equal_the_full_record_jacobian(plant, getkey):
    # `fit.normal_equations` accumulates r^T r, J^T J and J^T r over 256-sample
    # blocks, only up to the record's own length (300 samples: one full block and
    # a partial one, in arrays padded to 1024). The reference is the forward-mode
    # Jacobian of the full-length simulation (`simulate_row`, one `lax.scan` per
    # record), at a perturbed point of every row. The two sum the same terms in a
    # different order, so they agree to rounding (relative 1e-14 per term; 1e-9
    # leaves room for the ~300-term sums and the filter's error growth).
    est, val = _records(getkey())
    est["y"] = np.asarray(jr.normal(getkey(), (300,)))
    prep = prepare(plant, 0.05, est, val, length=1024)
    A = prep.arrays
    tabulated = isinstance(plant.nonlinearity, hj.Tabulated | hj.Backlash)
    kind = prep.nominal.nl_kind
    # flags as arrays: one compilation serves the run-time skips and the full model
    blocked = jax.jit(normal_equations)

    @jax.jit
    def reference(theta, row):
        def residual(t):
            return (simulate_row(t, row, A.v_est, A) - A.y_est) * A.m_est / A.y_scale

        r, J = residual(theta), jax.jacfwd(residual)(theta)
        return r @ r, J.T @ J, J.T @ r

    on = jnp.asarray(True)
    for name, row in prep.rows:
        theta = row.theta0 + 0.2 * jr.normal(getkey(), row.theta0.shape)
        ref = reference(theta, row)
        # skipping the memory scan, the table or the feedback loop is exact where
        # they are unused
        used = (
            uses_memory(row.free, kind),
            jnp.asarray(tabulated),
            uses_feedback(row.free),
        )
        for flags in ((on, on, on), used):
            for got, want in zip(blocked(theta, row, A, *flags), ref, strict=True):
                scale = float(jnp.max(jnp.abs(want)))
                assert np.allclose(got, want, rtol=1e-9, atol=1e-9 * scale), name
    if tabulated:  # and the table is not skipped silently where it is used
        row = prep.rows[0][1]
        sse = blocked(row.theta0, row, A, on, on, on)[0]
        assert not np.isclose(sse, blocked(row.theta0, row, A, on, ~on, on)[0])


def test_diagnosis_without_float64_is_refused():
    # In a process that never enabled float64 the diagnosis would silently fit in
    # float32 (other minima, other effects named): it says what to do instead.
    code = (
        "import jax.random as jr\n"
        "from hamjax.diagnosis.diagnose import diagnose_gap\n"
        "from hamjax.papers.gap.demo_cases import tiny_case\n"
        "try:\n"
        "    diagnose_gap(*tiny_case(jr.key(0), 'backlash', noise=1e-3))\n"
        "except RuntimeError as e:\n"
        "    print(e)\n"
    )
    env = {k: v for k, v in os.environ.items() if k != "JAX_ENABLE_X64"}
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, env=env
    )
    assert out.returncode == 0, out.stderr
    assert "needs float64: call hamjax.enable_x64()" in out.stdout


def test_a_record_too_long_to_hold_is_refused_before_any_work(tmp_path):
    # 3 KB per sample of peak memory: past MAX_SAMPLES a one-line refusal that says
    # how to decimate, read from the files alone (no fit is started).
    import numpy as np

    from hamjax._errors import UserInputError
    from hamjax.diagnosis.case import MAX_SAMPLES, read_case
    from hamjax.io import write_csv

    n = MAX_SAMPLES + 1
    t = np.arange(n) * 0.01
    rng = np.random.default_rng(0)
    rec = {"t": t, "v": rng.normal(size=n), "y": rng.normal(size=n)}
    write_csv(tmp_path / "estimation.csv", rec)
    write_csv(tmp_path / "validation.csv", {k: x[:1000] for k, x in rec.items()})
    with pytest.raises(UserInputError) as err:
        read_case(tmp_path)
    message = str(err.value)
    assert "\n" not in message and "estimation.csv" in message
    assert "decimate" in message and "scipy.signal.decimate(x, 2)" in message
