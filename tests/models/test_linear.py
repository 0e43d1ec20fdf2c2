"""Linear blocks against scipy.signal: responses, static gains, poles, frequency
responses, state-space realisation and the exact zero-order-hold discretisation."""

import equinox as eqx
import hypothesis.extra.numpy as hnp
import hypothesis.strategies as st
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from helpers import random_stable_poly
from hypothesis import given, settings
from scipy import signal

import hamjax as hj


SETTINGS = settings(max_examples=25, deadline=None, derandomize=True)


@st.composite
def discrete_plants(draw, max_order=4):
    """Random stable A(q^-1) of order 1..4 and B(q^-1), possibly with b[0] = 0."""
    order = draw(st.integers(1, max_order))
    a = random_stable_poly(
        draw(hnp.arrays(np.float64, order, elements=st.floats(-1, 1)))
    )
    nb = draw(st.integers(1, order + 1))
    b = draw(hnp.arrays(np.float64, nb, elements=st.floats(-2, 2)))
    if draw(st.booleans()):
        b = np.concatenate([[0.0], b])  # a pure delay
    return b, a


@st.composite
def continuous_plants(draw, max_order=4):
    """Random stable G(s) of order 1..4 with poles in [-5, -0.2] (+/- 3j), proper."""
    order = draw(st.integers(1, max_order))
    x = list(draw(hnp.arrays(np.float64, order, elements=st.floats(0, 1))))
    roots = []
    while len(x) >= 2:
        re, im = -0.2 - 4.8 * x.pop(), 3.0 * x.pop()
        roots += [re + 1j * im, re - 1j * im]
    if x:
        roots.append(-0.2 - 4.8 * x.pop())
    den = np.real(np.poly(roots)) * draw(st.floats(0.5, 2.0))
    m = draw(st.integers(1, order + 1))
    num = draw(hnp.arrays(np.float64, m, elements=st.floats(-2, 2)))
    num[0] = np.copysign(0.2 + abs(num[0]), num[0])  # a genuine leading coefficient
    return num, den


_response = eqx.filter_jit(lambda G, u: G.response(u))  # one compile per shape


def _u(n=200, seed=0):
    # A deterministic, broadband input: a chirp-like sum plus steps.
    k = np.arange(n)
    return np.sin(0.01 * k**1.5 + seed) + (k % 37 < 12) - 0.3


# --- discrete transfer function --------------------------------------------------


@given(plant=discrete_plants())
@SETTINGS
def test_discrete_response_equals_lfilter(plant):
    b, a = plant
    u = _u()
    y = _response(hj.DiscreteTransferFunction(b, a), jnp.asarray(u))
    ref = signal.lfilter(b, a, u)
    np.testing.assert_allclose(y, ref, rtol=0, atol=1e-12 * max(1.0, np.abs(ref).max()))


@pytest.mark.parametrize("order", [1, 2, 3, 4])
def test_pure_delay_each_order(order):
    a = random_stable_poly(np.linspace(-0.9, 0.8, order))
    b = np.concatenate([[0.0], np.arange(1.0, order + 1)])
    G = hj.DiscreteTransferFunction(b, a)
    u = _u(120)
    y = G.response(jnp.asarray(u))
    np.testing.assert_allclose(y, signal.lfilter(b, a, u), rtol=0, atol=1e-12)
    assert y[0] == 0.0  # b[0] = 0: the current input does not reach the output
    impulse = G.response(jnp.zeros(10).at[0].set(1.0))
    # Impulse response: h_0 = b_0 = 0, h_1 = b_1 - a_1 b_0 = b_1.
    assert impulse[0] == 0.0 and impulse[1] == pytest.approx(float(b[1]), abs=1e-15)


def test_static_gain_only_numerator():
    G = hj.DiscreteTransferFunction([0.5, -0.2], [1.0])
    np.testing.assert_allclose(G.static_gain(), 0.3)
    np.testing.assert_allclose(G.response(jnp.array([1.0, 2.0, 0.0])), [0.5, 0.8, -0.4])
    assert G.is_stable() and G.poles().shape == (0,)


@given(plant=discrete_plants())
@SETTINGS
def test_discrete_static_gain_stability_and_frequency_response(plant):
    b, a = plant
    G = hj.DiscreteTransferFunction(b, a, dt=0.1)
    # Static gain: B(1)/A(1), and the settled step response.
    np.testing.assert_allclose(
        G.static_gain(), np.polyval(b[::-1], 1) / np.polyval(a[::-1], 1)
    )
    poles = np.sort_complex(G.poles())
    # Poles: the n roots of z^n A(z^-1) = z^n + a_1 z^(n-1) + ... + a_n.
    assert poles.shape == (len(a) - 1,)
    np.testing.assert_allclose(np.polyval(a, poles), 0.0, atol=1e-10)
    assert G.is_stable()
    # An A with the same roots pushed outside the unit circle is unstable.
    bad = np.real(np.poly(np.concatenate([poles[1:], [1.05]])))
    assert not hj.DiscreteTransferFunction(b, bad).is_stable()
    omega = np.linspace(0.0, np.pi, 33)
    _, ref = signal.freqz(b, a, worN=omega)
    np.testing.assert_allclose(G.frequency_response(omega), ref, rtol=1e-10, atol=1e-12)


def test_discrete_settled_step_response_is_static_gain():
    G = hj.DiscreteTransferFunction([0.0, 1.0, -2.0], [1.0, -1.5, 0.56])  # seed 001
    y = G.response(jnp.ones(400))
    # Deterministic (no key). Poles 0.7 and 0.8: the transient is 0.8^400 ~ 1e-39;
    # the recursion's rounding, relative ~ 1e-15 per step, is not amplified.
    np.testing.assert_allclose(y[-1], G.static_gain(), rtol=1e-12)
    np.testing.assert_allclose(G.static_gain(), -1.0 / 0.06)


def test_scaled_discrete_block():
    G = hj.DiscreteTransferFunction([0.0, 0.3], [1.0, -0.7], dt=0.5)
    H = G.scaled(-2.0)
    u = jnp.asarray(_u(50))
    np.testing.assert_allclose(H.response(u), -2.0 * G.response(u), atol=1e-14)
    assert H.dt == 0.5
    np.testing.assert_allclose(H.static_gain(), -2.0)


# --- continuous transfer function -------------------------------------------------

# Jitted so that hypothesis examples of one order share a compilation.
_state_space = eqx.filter_jit(lambda G: G.state_space())
_discretise = eqx.filter_jit(lambda G, dt: G.discretise(dt))


@given(plant=continuous_plants())
@SETTINGS
def test_continuous_gain_poles_and_frequency_response(plant):
    num, den = plant
    G = hj.ContinuousTransferFunction(num, den)
    _, dc = signal.freqs(num, den, worN=[0.0])
    # hypothesis is derandomised (fixed examples); both are num[-1] / den[-1]
    np.testing.assert_allclose(G.static_gain(), dc[0].real, rtol=1e-12)
    np.testing.assert_allclose(
        np.sort_complex(G.poles()), np.sort_complex(np.roots(den)), atol=1e-8
    )
    assert G.is_stable()
    omega = np.logspace(-2, 2, 40)
    _, ref = signal.freqs(num, den, worN=omega)
    np.testing.assert_allclose(G.frequency_response(omega), ref, rtol=1e-10)


def test_continuous_stability_examples():
    assert hj.ContinuousTransferFunction([1.0, -10.0], [1.0, 2.0, 1.0]).is_stable()
    assert not hj.ContinuousTransferFunction([1.0], [1.0, -1.0, 1.0]).is_stable()
    assert not hj.ContinuousTransferFunction(
        [1.0], [1.0, 0.0]
    ).is_stable()  # integrator
    G = hj.ContinuousTransferFunction([1.0, -10.0], [1.0, 2.0, 1.0])  # seed 000 Fig. 6
    np.testing.assert_allclose(G.static_gain(), -10.0)


@given(plant=continuous_plants())
@SETTINGS
def test_state_space_is_scipy_tf2ss(plant):
    num, den = plant
    A, B, C, D = _state_space(hj.ContinuousTransferFunction(num, den))
    # derandomised examples; entries are coefficients divided by den[0] (one
    # rounding each), zero entries exact, so 1e-12 holds for any example
    for mine, ref in zip((A, B, C, D), signal.tf2ss(num, den), strict=True):
        np.testing.assert_allclose(mine, ref, rtol=1e-12, atol=1e-12)


@given(plant=continuous_plants(), dt=st.just(0.37))
@settings(max_examples=15, deadline=None, derandomize=True)  # one compile per shape
def test_zoh_discretisation_equals_cont2discrete(plant, dt):
    num, den = plant
    padded = np.pad(num, (len(den) - len(num), 0))  # one compilation per order
    Gd = _discretise(hj.ContinuousTransferFunction(padded, den), dt)
    Ad, Bd, Cd, Dd, _ = signal.cont2discrete(signal.tf2ss(num, den), dt, method="zoh")
    for mine, ref in zip((Gd.A, Gd.B, Gd.C, Gd.D), (Ad, Bd, Cd, Dd), strict=True):
        np.testing.assert_allclose(mine, ref, rtol=1e-10, atol=1e-12)
    assert Gd.dt == dt
    # The ZOH keeps the static gain and maps poles p to exp(p dt).
    G = hj.ContinuousTransferFunction(num, den)
    # (I - A_d) has condition ~ (|p| dt)^-n: allow for it (here <= 1e8 eps).
    np.testing.assert_allclose(Gd.static_gain(), G.static_gain(), rtol=1e-7, atol=1e-8)
    # Compared through the characteristic polynomial: repeated poles are
    # ill-conditioned one by one, their polynomial is not.
    np.testing.assert_allclose(
        np.poly(Gd.poles()).real, np.poly(np.exp(G.poles() * dt)).real, atol=1e-9
    )
    assert Gd.is_stable()


def test_biproper_continuous_block_has_feedthrough():
    G = hj.ContinuousTransferFunction([2.0, 1.0], [1.0, 3.0])  # (2s + 1)/(s + 3)
    A, B, C, D = G.state_space()
    np.testing.assert_allclose(D, [[2.0]])
    Gd = G.discretise(0.1)
    y = Gd.response(jnp.ones(3))
    np.testing.assert_allclose(y[0], 2.0)  # the step passes D at once


def test_discrete_state_space_equals_dlsim():
    A = np.array([[0.5, 0.2], [-0.3, 0.8]])
    B, C, D = np.array([[1.0], [0.5]]), np.array([[1.0, -1.0]]), np.array([[0.1]])
    G = hj.DiscreteStateSpace(A, B, C, D, dt=1.0)
    u = _u(80)
    ref = signal.dlsim((A, B, C, D, 1.0), u)[1]
    np.testing.assert_allclose(G.response(jnp.asarray(u)), ref[:, 0], atol=1e-12)
    np.testing.assert_allclose(
        G.static_gain(), (C @ np.linalg.solve(np.eye(2) - A, B) + D)[0, 0]
    )
    assert G.is_stable() and not hj.DiscreteStateSpace(2 * A, B, C, D).is_stable()


def test_continuous_frequency_response_is_differentiable():
    def mag(den0):
        G = hj.ContinuousTransferFunction(jnp.array([1.0]), jnp.stack([den0, 1.0]))
        return jnp.abs(G.frequency_response(jnp.array([2.0])))[0]

    # |1/(j w T + 1)| with T = den0: d/dT = -w^2 T / (1 + w^2 T^2)^(3/2).
    T, w = 0.5, 2.0
    # deterministic; the derivative (-0.354) is far from zero: rtol alone suffices
    np.testing.assert_allclose(
        jax.grad(mag)(jnp.asarray(T)),
        -(w**2) * T / (1 + w**2 * T**2) ** 1.5,
        rtol=1e-12,
    )


def test_traced_and_host_stability_checks_agree():
    # `stable()` (traced, under jit) and `is_stable()` (NumPy on the host) are one
    # computation: they agree on stable, unstable and marginal blocks.
    import jax

    import hamjax as hj

    blocks = [
        hj.DiscreteTransferFunction([0.0, 1.0, -2.0], [1.0, -1.5, 0.56]),
        hj.DiscreteTransferFunction([0.0, 1.0], [1.0, -2.1, 1.2]),
        hj.DiscreteTransferFunction([0.0, 1.0], [1.0, -1.0]),  # an integrator
        hj.DiscreteTransferFunction([2.0], [1.0]),
        hj.ContinuousTransferFunction([1.0, -10.0], [1.0, 2.0, 1.0]),
        hj.ContinuousTransferFunction([1.0], [1.0, -1.0]),
        hj.ContinuousTransferFunction([1.0], [1.0, 0.0]),
    ]
    expected = [True, False, False, True, True, False, False]
    for block, want in zip(blocks, expected, strict=True):
        assert block.is_stable() is want
        assert bool(jax.jit(lambda b: b.stable())(block)) is want


@pytest.mark.parametrize("kind", ["tf", "tf-order-0", "ss"])
def test_batched_step_equals_scipy_per_column(kind):
    """`step` with a batch axis (what the time-major simulation scans) gives, for
    every column of the input, scipy's response to that column alone."""
    U = np.stack([_u(120, seed) for seed in range(3)], axis=1)  # (time, batch)
    if kind == "ss":
        A = np.array([[0.5, 0.2], [-0.3, 0.8]])
        B, C, D = np.array([[1.0], [0.5]]), np.array([[1.0, -1.0]]), np.array([[0.1]])
        G = hj.DiscreteStateSpace(A, B, C, D)
        ref = np.stack([signal.dlsim((A, B, C, D, 1.0), u)[1][:, 0] for u in U.T], 1)
    else:
        b, a = ([0.0, 1.0, -2.0], [1.0, -1.5, 0.56]) if kind == "tf" else ([3.0], [1.0])
        G = hj.DiscreteTransferFunction(b, a)
        ref = signal.lfilter(b, a, U, axis=0)
    Uj = jnp.asarray(U)
    _, Y = jax.lax.scan(lambda z, u: G.step(z, u), G.zero_state(Uj[0]), Uj)
    np.testing.assert_allclose(Y, ref, rtol=0, atol=1e-12 * np.abs(ref).max())
