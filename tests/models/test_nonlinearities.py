"""Static nonlinearities and the backlash operator against closed forms and the
reference play operator of `../shared/tools/contract_check.py`."""

import equinox as eqx
import hypothesis.extra.numpy as hnp
import hypothesis.strategies as st
import jax
import jax.numpy as jnp
import jax.random as jr
import numpy as np
import pytest
from helpers import reference_backlash
from hypothesis import given, settings

import hamjax as hj


SETTINGS = settings(max_examples=25, deadline=None, derandomize=True)


def _np_piecewise_linear(v, k1, k2, d1, d2, l1, l2):
    """Seed 001 Fig. 2 in the signed convention of `../shared/seeds/README.md`."""
    out = np.zeros_like(v)
    for i, x in enumerate(v):
        if x > d1:
            out[i] = k1 * (x - d1) + l1
        elif x < d2:
            out[i] = k2 * (x - d2) + l2
    return out


# --- static maps ---------------------------------------------------------------


def test_dead_zone_on_a_ramp():
    v = jnp.linspace(-3.0, 3.0, 601)
    u = hj.DeadZone(lower=-1.0, upper=0.5)(v)
    # Closed form on the ramp: slope 1 outside, 0 inside, continuous at the edges.
    expected = np.maximum(np.asarray(v) - 0.5, 0.0) + np.minimum(
        np.asarray(v) + 1.0, 0.0
    )
    np.testing.assert_allclose(u, expected, rtol=0, atol=1e-15)
    inside = (v >= -1.0) & (v <= 0.5)
    assert jnp.all(u[inside] == 0.0)
    np.testing.assert_allclose(jnp.diff(u)[v[1:] > 0.51], 0.01, atol=1e-12)


def test_dead_zone_symmetric_is_the_contract_form():
    v = jnp.linspace(-2.0, 2.0, 41)
    u = hj.DeadZone.symmetric(0.7)(v)
    expected = np.sign(v) * np.maximum(np.abs(v) - 0.7, 0.0)
    np.testing.assert_allclose(u, expected, atol=1e-15)


@given(lo=st.floats(-5, 5), width=st.floats(0.01, 5))
@SETTINGS
def test_saturation_is_clip(lo, width):
    v = jnp.linspace(-12.0, 12.0, 97)
    u = hj.Saturation(lower=lo, upper=lo + width)(v)
    np.testing.assert_array_equal(u, np.clip(np.asarray(v), lo, lo + width))


def test_piecewise_linear_seed001_values():
    # Seed 001, Section V.C: F(V1..V4) with V = (-6, -3, 3, 6).
    F = hj.PiecewiseLinear(k1=1.0, k2=2.0, d1=1.0, d2=-2.0, l1=1.0, l2=-2.0)
    np.testing.assert_array_equal(F(jnp.array([-6.0, -3.0, 3.0, 6.0])), [-10, -4, 3, 6])
    # The dead band [d2, d1] maps to 0, its edges included.
    np.testing.assert_array_equal(F(jnp.array([-2.0, -1.0, 0.0, 1.0])), 0.0)


@given(
    k=st.tuples(st.floats(0.1, 5), st.floats(0.1, 5)),
    d=st.tuples(st.floats(0, 3), st.floats(-3, 0)),
    l=st.tuples(st.floats(-2, 2), st.floats(-2, 2)),
)
@SETTINGS
def test_piecewise_linear_closed_form(k, d, l):
    params = dict(k1=k[0], k2=k[1], d1=d[0], d2=d[1], l1=l[0], l2=l[1])
    v = np.linspace(-6.0, 6.0, 241)
    u = hj.PiecewiseLinear(**params)(jnp.asarray(v))
    # derandomised examples; |u| <= 5 * 9 + 2 = 47, one product and one sum per
    # value: at most ~2 ulp(47) = 1.4e-14 apart, within atol + rtol |u| = 6e-14
    np.testing.assert_allclose(
        u, _np_piecewise_linear(v, **params), rtol=1e-15, atol=1e-14
    )


def test_piecewise_linear_preload_jumps_at_origin():
    F = hj.PiecewiseLinear(k1=1.0, k2=1.0, l1=0.5, l2=-0.5)
    u = F(jnp.array([-1e-9, 0.0, 1e-9]))
    np.testing.assert_allclose(u, [-0.5, 0.0, 0.5], atol=1e-8)


@given(
    values=hnp.arrays(np.float64, 12, elements=st.floats(-5, 5)),
    steps=hnp.arrays(np.float64, 12, elements=st.floats(0.05, 2)),
)
@SETTINGS
def test_tabulated_matches_numpy_interp(values, steps):
    grid = -3.0 + np.cumsum(steps)
    F = hj.Tabulated(grid, values)
    v = np.linspace(grid[0] - 2.0, grid[-1] + 2.0, 301)
    v = np.concatenate([v, grid])  # the knots themselves
    np.testing.assert_allclose(
        F(jnp.asarray(v)), np.interp(v, grid, values), atol=1e-13
    )


def test_shifted_and_scaled():
    v = jnp.linspace(-2.0, 2.0, 9)
    dz = hj.DeadZone(lower=-0.5, upper=0.5)
    np.testing.assert_array_equal(hj.Shifted(offset=0.25)(v), v + 0.25)
    np.testing.assert_array_equal(hj.Shifted(offset=-1.0, inner=dz)(v), dz(v) - 1.0)
    np.testing.assert_array_equal(hj.Scaled(inner=dz, gain=-3.0)(v), -3.0 * dz(v))
    np.testing.assert_array_equal(hj.Identity()(v), v)


# --- backlash -------------------------------------------------------------------


@eqx.filter_jit
def _apply(nl, v):
    return hj.apply_nonlinearity(nl, v)


def _run(nl, v):
    """Jitted so that hypothesis examples of equal shapes share one compilation."""
    return np.asarray(_apply(nl, jnp.asarray(v, dtype=float)))


def _walk(key, n, scale=1.0):
    return scale * jnp.cumsum(jr.normal(key, (n,)))


NON_MONOTONE = hj.Tabulated(
    jnp.array([-3.0, -1.0, -0.5, 0.5, 1.0, 3.0]),
    jnp.array([2.0, -1.0, 1.5, -2.0, 0.0, 1.0]),
)
RELAY_LIKE = hj.PiecewiseLinear(k1=0.5, k2=0.5, l1=1.0, l2=-1.0)


@pytest.mark.parametrize(
    "f",
    [NON_MONOTONE, RELAY_LIKE, hj.DeadZone(lower=-0.3, upper=0.6)],
    ids=["tabulated-non-monotone", "preload-discontinuous", "dead-zone"],
)
def test_superposed_borders_equal_the_static_map(f, getkey):
    # Remark 1b: coinciding borders give exactly (bitwise) the memoryless map, for
    # any input (the clip between equal borders returns f(v) itself).
    bl = hj.Backlash(ascending=f, descending=f)
    v = jnp.concatenate(
        [_walk(getkey(), 300, 0.4), jr.uniform(getkey(), (100,), minval=-3, maxval=3)]
    )
    v = jnp.concatenate([v, jnp.repeat(v[:20], 3)])  # holds and jumps
    np.testing.assert_array_equal(_run(bl, v), f(v))


def test_superposed_borders_equal_static_map_from_table():
    grid = jnp.linspace(-2.0, 2.0, 9)
    shape = jnp.sin(3 * grid)
    bl = hj.Backlash.from_table(grid, shape, shape)
    v = jnp.array([0.0, 1.3, -1.7, 1.9, 1.9, -0.2, 0.3, -2.5, 2.5])
    u = _run(bl, v)
    np.testing.assert_array_equal(u, hj.Tabulated(grid, shape)(v))
    np.testing.assert_allclose(u, np.interp(v, grid, shape), rtol=0, atol=1e-15)


def test_docstring_example_width_one():
    bl = hj.Backlash.from_width(1.0)
    u = _run(bl, [0.0, 1.0, 2.0, 1.5, 1.0, 0.0])
    np.testing.assert_allclose(u, [0.0, 0.5, 1.5, 1.5, 1.5, 0.5], atol=1e-15)


def test_monotone_sweep_stays_on_one_border():
    f_a = hj.Tabulated(jnp.array([-2.0, 0.0, 2.0]), jnp.array([-3.0, -0.5, 1.0]))
    f_d = hj.Shifted(offset=1.0, inner=f_a)
    bl = hj.Backlash(ascending=f_a, descending=f_d, u0=0.0)
    v = np.linspace(-2.0, 2.0, 401)
    u = _run(bl, v)
    fa = np.interp(v, [-2.0, 0.0, 2.0], [-3.0, -0.5, 1.0])
    # Before the play is taken up u stays at u0 = 0; afterwards it is f_a(v).
    contact = np.argmax(fa >= 0.0)
    assert 0 < contact < len(v) - 1
    np.testing.assert_array_equal(u[:contact], 0.0)
    np.testing.assert_allclose(u[contact:], fa[contact:], atol=1e-14)
    # Falling all the way: u stays at f_a(2) until f_d meets it, then follows f_d.
    u_down = _run(bl, np.concatenate([v, v[::-1]]))[len(v) :]
    fd = fa[::-1] + 1.0
    meet = np.argmax(fd <= fa[-1])
    np.testing.assert_array_equal(u_down[:meet], u[-1])
    np.testing.assert_allclose(u_down[meet:], fd[meet:], atol=1e-14)


def test_reversal_moves_horizontally_until_the_other_border():
    c = 0.8
    bl = hj.Backlash.from_width(c)
    up = np.linspace(0.0, 2.0, 201)
    down = np.linspace(2.0, -1.0, 301)[1:]
    u = _run(bl, np.concatenate([up, down]))
    top = 2.0 - c / 2
    u_down = u[len(up) :]
    horizontal = down + c / 2 > top  # f_d(v) > u: not yet met
    assert horizontal.sum() == np.sum(down > 2.0 - c) > 10
    np.testing.assert_array_equal(u_down[horizontal], top)
    np.testing.assert_allclose(
        u_down[~horizontal], down[~horizontal] + c / 2, atol=1e-14
    )


def test_small_reversal_inside_the_play_leaves_output_constant():
    bl = hj.Backlash.from_width(1.0)
    v = np.concatenate(
        [np.linspace(0, 2, 21), 2 - 0.4 * np.abs(np.sin(np.linspace(0, 9, 90)))]
    )
    u = _run(bl, v)
    np.testing.assert_array_equal(u[21:], u[20])


def _fig5_borders():
    grid = jnp.linspace(-2.0, 2.0, 41)
    f_a = grid + 0.2 * jnp.sin(2 * grid) - 0.1
    f_d = grid + 0.2 * jnp.sin(2 * grid) + 0.1
    return hj.Backlash.from_table(grid, f_a, f_d), (np.asarray(grid), f_a, f_d)


@pytest.mark.parametrize("n", [3, 4, 6])
def test_staircase_traces_the_closed_cycle_of_fig5(n):
    # Seed 000, Fig. 5: after (3), the staircase (4a-b) visits (V1, f_d(V1)), then
    # (V_i, f_a(V_i)) up to Vn, then (V_i, f_d(V_i)) down to V2, and closes.
    bl, (grid, f_a, f_d) = _fig5_borders()
    levels = np.linspace(-1.5, 1.5, n)
    fa, fd = np.interp(levels, grid, f_a), np.interp(levels, grid, f_d)
    # Levels wide enough for each step to cross the play.
    assert np.all(fa[1:] > fd[:-1])
    dt = 0.5
    _, v0 = hj.initialisation_step(levels, duration=1.0, dt=dt)
    _, v1 = hj.nbbi_staircase(levels, hold=1.5, dt=dt)  # N Tr = 3 samples
    # (4a-b) applied twice is the periodic staircase (24) with tau = N Tr.
    _, v24 = hj.periodic_staircase(levels, period_samples=v1.shape[0], periods=2, dt=dt)
    np.testing.assert_array_equal(v24, jnp.concatenate([v1, v1]))
    u = _run(bl, jnp.concatenate([v0, v1, v1]))
    assert u[len(v0) - 1] == pytest.approx(float(fd[0]), abs=1e-14)  # position 1
    u_cycle = u[len(v0) :].reshape(2, 2 * n - 2, 3)
    assert np.all(u_cycle == u_cycle[..., :1])  # constant on each hold
    expected = np.concatenate([[fd[0]], fa[1:], fd[-2:0:-1]])
    np.testing.assert_allclose(u_cycle[0, :, 0], expected, atol=1e-14)
    np.testing.assert_array_equal(u_cycle[1], u_cycle[0])  # the cycle is closed


@given(
    steps=hnp.arrays(np.float64, 8, elements=st.floats(0.05, 1.0)),
    slopes=hnp.arrays(np.float64, 8, elements=st.floats(0.0, 3.0)),
    gaps=hnp.arrays(np.float64, 8, elements=st.floats(0.0, 1.5)),
)
@SETTINGS
def test_staircase_paths_for_random_monotone_borders(steps, slopes, gaps):
    # Fig. 5 in general: from u_1 (where (3) leaves the point: on f_d(v_m) if the
    # play is taken up), the ascending path P_a is max(u_1, f_a(V_i)) (horizontal
    # segment, then f_a), the descending path min(P_a(v_M), f_d(V_i)).
    grid = np.cumsum(steps) - 2.0
    f_a = np.cumsum(slopes * steps)
    f_d = np.maximum.accumulate(f_a + gaps)  # monotone, above f_a
    bl = hj.Backlash.from_table(grid, f_a, f_d)
    levels = np.linspace(grid[0], grid[-1], 5)
    fa, fd = np.interp(levels, grid, f_a), np.interp(levels, grid, f_d)
    _, v0 = hj.initialisation_step(levels, duration=1.0, dt=1.0)
    _, v1 = hj.nbbi_staircase(levels, hold=2.0, dt=1.0)
    u = _run(bl, jnp.concatenate([v0, v1]))[len(v0) :: 2]
    u_1 = min((fa[-1] + fd[-1]) / 2, fd[0])  # u0 = centre of the play at v_M
    up = np.maximum(u_1, fa)
    down = np.minimum(up[-1], fd[-2:0:-1])
    np.testing.assert_allclose(u, np.concatenate([up, down]), atol=1e-12)


@st.composite
def monotone_borders(draw):
    steps = draw(hnp.arrays(np.float64, 10, elements=st.floats(0.05, 1.0)))
    grid = np.cumsum(steps) - 3.0
    f_a = np.cumsum(
        draw(hnp.arrays(np.float64, 10, elements=st.floats(0.0, 2.0))) * steps
    )
    f_d = f_a + draw(hnp.arrays(np.float64, 10, elements=st.floats(0.0, 1.0)))
    # f_d must stay monotone: a running maximum keeps f_d >= f_a and non-decreasing.
    return grid, f_a - f_a.mean(), np.maximum.accumulate(f_d) - f_a.mean()


@given(borders=monotone_borders(), seed=st.integers(0, 2**30), u0=st.floats(-0.5, 0.5))
@SETTINGS
def test_equals_reference_play_operator(borders, seed, u0):
    grid, f_a, f_d = borders
    bl = hj.Backlash.from_table(grid, f_a, f_d, u0=u0)
    walk_key, jump_key = jr.split(jr.key(seed))
    walk = _walk(walk_key, 150, 0.3)
    jumps = jnp.repeat(jr.uniform(jump_key, (30,), minval=-4, maxval=4), 3)
    v = np.asarray(jnp.concatenate([walk, jumps]))
    expected = reference_backlash(
        v, lambda x: np.interp(x, grid, f_a), lambda x: np.interp(x, grid, f_d), u0
    )
    np.testing.assert_allclose(_run(bl, v), expected, rtol=0, atol=1e-12)


@given(borders=monotone_borders(), seed=st.integers(0, 2**30))
@SETTINGS
def test_output_stays_within_the_band(borders, seed):
    grid, f_a, f_d = borders
    bl = hj.Backlash.from_table(grid, f_a, f_d)  # u0: centre of the play
    v = np.asarray(_walk(jr.key(seed), 200, 0.4))
    u = _run(bl, v)
    lo, hi = np.interp(v, grid, f_a), np.interp(v, grid, f_d)
    assert np.all(u >= lo - 1e-12)
    assert np.all(u <= hi + 1e-12)


def test_jump_equals_a_continuous_sweep_for_monotone_borders():
    # A piecewise-constant input jumps; for monotone borders the sampled operator
    # lands where a dense sweep between the same levels lands.
    bl = hj.Backlash.from_width(0.6)
    levels = np.array([0.0, 1.5, 1.2, -1.0, 0.1, 0.05, 2.0])
    dense = np.concatenate(
        [
            np.linspace(a, b, 200, endpoint=False)
            for a, b in zip(levels[:-1], levels[1:], strict=True)
        ]
        + [levels[-1:]]
    )
    u_jump = _run(bl, levels)
    u_dense = _run(bl, dense)[::200]
    np.testing.assert_allclose(u_jump, u_dense, atol=1e-14)


def test_jump_tests_the_border_only_at_the_new_sample():
    # The documented rule for jumps: one move, border tested at v_k only. With a
    # non-monotone f_a whose bump lies between two samples, a jump does not see
    # the bump; a dense sweep meets it and then follows f_a down (seed 000).
    f_a = hj.Tabulated(
        jnp.array([-1.0, 0.0, 0.5, 1.0, 2.0]), jnp.array([-2.0, -1.0, 1.0, -1.0, -0.5])
    )
    f_d = hj.Shifted(offset=3.0, inner=hj.Identity())
    bl = hj.Backlash(ascending=f_a, descending=f_d, u0=0.0)
    u_jump = _run(bl, [-1.0, 2.0])
    np.testing.assert_array_equal(u_jump, [0.0, 0.0])  # f_a(2) = -0.5 < u: no contact
    u_dense = _run(bl, np.linspace(-1.0, 2.0, 301))
    np.testing.assert_allclose(u_dense[-1], -0.5, atol=1e-12)  # met the bump, then f_a


def test_crossing_borders_follow_the_border_of_the_direction():
    # f_a > f_d for v > 0: there the point is on the border of the current direction.
    f_a = hj.Tabulated(jnp.array([-2.0, 2.0]), jnp.array([-2.5, 2.5]))
    f_d = hj.Tabulated(jnp.array([-2.0, 2.0]), jnp.array([-1.5, 1.5]))
    bl = hj.Backlash(ascending=f_a, descending=f_d)
    v = np.array([-2.0, 0.0, 1.0, 2.0, 1.0, 1.5])
    u = _run(bl, v)
    np.testing.assert_allclose(u[3], 2.5)  # rising on f_a
    np.testing.assert_allclose(u[4], 0.75)  # falling: f_d(1) <= u, on f_d
    np.testing.assert_allclose(u[5], 1.875)  # rising: f_a(1.5) >= u


@pytest.mark.parametrize("gain", [2.5, -10.0])
def test_scaled_backlash_is_gain_times_backlash(gain, getkey):
    # kF of seed 000's normalisation, for either sign of k (Fig. 6 has k = -10).
    bl, _ = _fig5_borders()
    scaled = hj.models.scale_nonlinearity(bl, gain)
    v = _walk(getkey(), 300, 0.3)
    # Any draw: scaling by k > 0 is monotone, so max/min between scaled borders pick
    # the same branch and the outputs are equal up to where k is multiplied (1 ulp
    # of |k u|); k < 0 multiplies the output. Absolute part: 4 ulp of the peak.
    ref = gain * _run(bl, v)
    np.testing.assert_allclose(
        _run(scaled, v),
        ref,
        rtol=1e-14,
        atol=4 * np.finfo(float).eps * np.abs(ref).max(),
    )


# --- transformations -------------------------------------------------------------


def test_backlash_jit_vmap_and_grad_of_width():
    v = jnp.sin(jnp.linspace(0.0, 9.0, 120)) * 2.0

    def out(c, v):
        return hj.apply_nonlinearity(hj.Backlash.from_width(c, u0=0.0), v)

    np.testing.assert_array_equal(jax.jit(out)(0.5, v), out(0.5, v))
    widths = jnp.array([0.1, 0.5, 1.3])
    batched = jax.vmap(out, in_axes=(0, None))(widths, v)
    np.testing.assert_array_equal(batched, np.stack([out(c, v) for c in widths]))
    loss = jax.jit(lambda c: jnp.sum(out(c, v) ** 2))
    g = jax.grad(loss)(0.5)
    h = 1e-6
    fd = (loss(0.5 + h) - loss(0.5 - h)) / (2 * h)
    assert float(g) == pytest.approx(float(fd), rel=1e-6)
    assert abs(g) > 1e-3


def test_static_map_grad_matches_finite_differences():
    v = jnp.linspace(-5.0, 5.0, 37) + 0.013

    @jax.jit
    def loss(p):
        F = hj.PiecewiseLinear(k1=p[0], k2=p[1], d1=p[2], d2=p[3], l1=p[4], l2=p[5])
        return jnp.sum(jnp.sin(F(v)))

    p = jnp.array([1.0, 2.0, 1.0, -2.0, 1.0, -2.0])
    g = jax.grad(loss)(p)
    h = 1e-6
    fd = [(loss(p.at[i].add(h)) - loss(p.at[i].add(-h))) / (2 * h) for i in range(6)]
    np.testing.assert_allclose(g, fd, rtol=1e-6, atol=1e-8)


def test_static_nonlinearities_under_filter_jit():
    v = jnp.linspace(-3.0, 3.0, 13)
    for f in (
        NON_MONOTONE,
        RELAY_LIKE,
        hj.Saturation(lower=-1, upper=2),
        hj.DeadZone.symmetric(1),
    ):
        np.testing.assert_array_equal(eqx.filter_jit(lambda f, v: f(v))(f, v), f(v))


@pytest.mark.parametrize(
    "make",
    [
        lambda: hj.PiecewiseLinear(k1=1, k2=2, d1=1, d2=-2),
        lambda: hj.DeadZone(lower=-1, upper=1),
        lambda: hj.Scaled(inner=hj.Identity(), gain=3),
        lambda: hj.OutputScaled(inner=hj.Backlash.from_width(1), gain=-2),
        lambda: hj.Shifted(offset=1),
        lambda: hj.Tabulated([0, 1, 2], [0, 1, 0]),
        lambda: hj.ContinuousTransferFunction([1], [1, 2]),
        lambda: hj.AR1Noise(1, 0),
    ],
)
def test_fields_given_as_integers_are_stored_as_float64(make):
    """`float_field`: whatever array-like a model is built from, its arrays are
    float64 (so no integer arithmetic leaks into the simulation)."""
    leaves = [x for x in jax.tree.leaves(make()) if eqx.is_array(x)]
    assert leaves and all(x.dtype == jnp.float64 for x in leaves)


def test_keyword_only_fields_refuse_positions():
    with pytest.raises(TypeError):
        hj.PiecewiseLinear(1.0, 2.0)
    with pytest.raises(TypeError):
        hj.DeadZone(-1.0, 1.0)
