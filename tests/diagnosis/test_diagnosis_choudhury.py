"""The slide variant of the `backlash` effect (Choudhury, Thornhill & Shah 2005):
its step against the benchmark generator's independent implementation
(`papers.gap.control_loops.ChoudhuryStiction`), its neutral value against the
existing rows bit for bit, and its normal equations against finite differences."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from helpers import assert_normal_equations_match_differences

from hamjax.diagnosis.augmented import (
    full_parameters,
    input_memory,
    named,
    simulate_row,
    slot_index,
)
from hamjax.diagnosis.effects.backlash import slide_init, slide_step, stick_slip_step
from hamjax.diagnosis.effects.rate_limit import rate_limit_step
from hamjax.diagnosis.layout import N_MAX, PROFILE_POINTS, prepare
from hamjax.models import DiscreteTransferFunction, Hammerstein, Identity
from hamjax.papers.gap import control_loops as cl


DT = 1.0
B, A = [0.0, 0.3], [1.0, -0.7]


def _slide(v, width, jump):
    """`slide_step` over `v`, at rest at v[0]: positions and the stuck flags."""
    v = jnp.asarray(v)

    def step(carry, vk):
        x_prev, y, ss = carry
        y, ss = slide_step(y, ss, x_prev, vk, width, jump)
        return (vk, y, ss), (y, ss[2])

    return jax.lax.scan(step, (v[0], v[0], slide_init(v[0])), v)[1]


def _rate_and_play(v, max_step, width, jump):
    """The rate limit and the He / plain step scanned on their own, at rest at v[0]."""

    def step(c, vk):
        xr, xb = c
        xr = rate_limit_step(xr, vk, max_step)
        xb = stick_slip_step(xb, xr, width, jump)
        return (xr, xb), xb

    return jax.lax.scan(step, (v[0], v[0]), v)[1]


def _commands(rng, n):
    """Hand-made command sequences: a random walk (slides and reversals), the same
    rounded (stops and restarts in the same direction), ramps with holds."""
    walk = np.cumsum(rng.normal(0.0, 0.3, n))
    ramps = np.cumsum(np.repeat(rng.choice([-0.2, 0.0, 0.15], n // 10 + 1), 10)[:n])
    return [walk, np.round(walk, 1), ramps]


def test_slide_step_is_the_generators_choudhury_valve():
    rng = np.random.default_rng([19, 1])
    moved = 0
    for _ in range(10):
        S = rng.uniform(0.2, 2.0)
        J = rng.uniform(0.1, 1.0) * S
        for v in _commands(rng, 400):
            ref = cl.valve_positions(cl.ChoudhuryStiction(S, J, x0=v[0]), v)
            got, _ = _slide(v, S, J)
            np.testing.assert_allclose(np.asarray(got), ref, rtol=0, atol=1e-12)
            moved += np.count_nonzero(np.diff(ref))
    assert moved > 1000  # the valve slid and slipped, not only stuck


def _case(v, seed=3):
    plant = Hammerstein(Identity(), DiscreteTransferFunction(B, A, DT))
    n = v.shape[0]
    y = np.random.default_rng(seed).normal(size=n)
    rec = {"t": DT * np.arange(n), "v": v, "y": y}
    return prepare(plant, DT, rec, rec, length=512)


def _slide_row(row, case):
    """A sticky (He) row with its jump moved to the slide slot."""
    slip, slide = slot_index("slip_jump", N_MAX), slot_index("slide_jump", N_MAX)
    idx = np.where(np.asarray(row.idx) == slip, slide, np.asarray(row.idx))
    free = np.asarray(row.free).copy()
    free[slip], free[slide] = False, True
    return eqx.tree_at(lambda r: (r.idx, r.free), row, (idx, free))


def test_neutral_slide_leaves_every_row_bit_for_bit():
    # every memory row of the catalogue that leaves the slide slot and the
    # valve's start neutral (the profile's starts free them: the slide's own
    # rows, below; the start: test_diagnosis_valve_start.py): the
    # memory scan is the rate limit and the He / plain step run on their own,
    # bit for bit
    v = np.cumsum(np.random.default_rng([19, 2]).normal(0, 0.3, 300))
    prep = _case(v)
    case = prep.arrays
    vj = jnp.asarray(case.v_est)
    # compiled once for every row (op by op, each row's scans compiled again)
    params, memory = jax.jit(full_parameters), jax.jit(input_memory)
    rate_and_play = jax.jit(_rate_and_play)
    slide_slot = slot_index("slide_jump", N_MAX)
    start_slot = slot_index("valve_start", N_MAX)  # the profile's starts free it
    rows = [
        (name, row)
        for name, row in prep.rows
        if not (row.free[slide_slot] or row.free[start_slot])
    ]
    assert len(rows) >= len(prep.rows) - PROFILE_POINTS  # the profile's starts
    for name, row in rows:
        p = params(row.theta0 + 0.3, row, case)
        at = named(p, case)
        assert float(at("slide_jump")) == 0.0
        max_step, width, jump = at("rate") * case.dt, at("backlash"), at("slip_jump")

        ref = rate_and_play(vj, max_step, width, jump)
        assert np.array_equal(np.asarray(memory(vj, p, case)), ref), name
    # a slide row at slide_jump = 0 is the plain play row of the same width
    slip = slot_index("slip_jump", N_MAX)
    he = next(r for n, r in prep.rows if n == "backlash" and r.free[slip])
    slide = _slide_row(he, case)
    j = list(np.asarray(slide.idx)).index(slot_index("slide_jump", N_MAX))
    theta = np.asarray(he.theta0).copy()
    theta[j] = 0.0
    off = eqx.tree_at(
        lambda r: r.free,
        he,
        np.asarray(he.free) & (np.arange(he.free.shape[0]) != slip),
    )
    np.testing.assert_array_equal(
        np.asarray(simulate_row(jnp.asarray(theta), slide, vj, case)),
        np.asarray(simulate_row(jnp.asarray(theta), off, vj, case)),
    )


def test_slide_normal_equations_match_finite_differences():
    # J^T J and J^T r of the blocked forward-mode Jacobian against central
    # differences of the simulated residual, on a random-walk command (slides,
    # stops, reversals), at a point where no stuck step's move lies within 100
    # steps h of its band (S or J): the differences see the same slips, and the
    # exact model is smooth there. Central differences err by rounding ~ eps/h
    # ~ 1e-10 relative: 1e-6 is ample.
    v = np.cumsum(np.random.default_rng([19, 3]).normal(0, 0.3, 300))
    prep = _case(v)
    case = prep.arrays
    slip, slide = slot_index("slip_jump", N_MAX), slot_index("slide_jump", N_MAX)
    he = next(r for n, r in prep.rows if n == "backlash" and r.free[slip])
    row = _slide_row(he, case)
    theta = jnp.asarray(row.theta0) + 0.1
    p = full_parameters(theta, row, case)
    S, J = float(named(p, case)("backlash")), float(named(p, case)("slide_jump"))
    assert S > J > 0
    h = 1e-6
    near = 100 * h * float(np.max(case.scale[[slide - 2, slide]]))
    # the margins of the stuck steps to their bands, by the generator's valve
    valve = cl.ChoudhuryStiction(S, J, x0=v[0])
    slips = 0
    for xk in v:
        if valve.stuck:
            d = xk - valve.x_ss
            band = J if np.sign(d) == valve.direction else S
            assert abs(abs(d) - band) > near
        was = valve.stuck
        valve(xk)
        slips += was and not valve.stuck
    assert slips > 3
    assert_normal_equations_match_differences(theta, row, case, slide, h=h)
