"""Bad input to the core models, signals and simulation gets a clear error that
names the problem (pytest.raises with a `match=` on the message)."""

import equinox as eqx
import jax.numpy as jnp
import jax.random as jr
import numpy as np
import pytest

import hamjax as hj


FIRST_ORDER = hj.DiscreteTransferFunction([0.0, 0.5], [1.0, -0.5])


def _plant(linear=FIRST_ORDER, nl=None):
    return hj.Hammerstein(hj.Identity() if nl is None else nl, linear)


# --- linear blocks and simulation ----------------------------------------------------


def test_unstable_discrete_plant_in_simulate():
    unstable = hj.DiscreteTransferFunction([0.0, 1.0], [1.0, -1.5, 0.3])
    with pytest.raises(
        ValueError, match="linear block is unstable: poles .*need \\|p\\| < 1"
    ):
        hj.simulate(_plant(unstable), jnp.ones(5))
    # Explicitly allowed, it runs.
    w = hj.simulate(_plant(unstable), jnp.ones(5), allow_unstable=True)
    assert np.all(np.isfinite(w))


def test_unstable_continuous_plant_in_simulate():
    unstable = hj.ContinuousTransferFunction([1.0], [1.0, -1.0, 2.0])
    with pytest.raises(ValueError, match="unstable: .*Re p < 0"):
        hj.simulate(_plant(unstable), jnp.ones(5), dt=0.1)


def test_a0_must_be_one():
    with pytest.raises(ValueError, match="a\\[0\\] must be 1, got 2"):
        hj.DiscreteTransferFunction([1.0], [2.0, 0.5])


def test_empty_or_non_finite_coefficients():
    with pytest.raises(ValueError, match="`a` must have a leading coefficient"):
        hj.DiscreteTransferFunction([1.0], jnp.zeros(0))
    with pytest.raises(ValueError, match="numerator `b` must be 1-D and non-empty"):
        hj.DiscreteTransferFunction(jnp.zeros(0), [1.0])
    with pytest.raises(ValueError, match="DiscreteTransferFunction.b contains NaN"):
        hj.DiscreteTransferFunction([np.nan], [1.0])
    with pytest.raises(ValueError, match="ContinuousTransferFunction.den contains inf"):
        hj.ContinuousTransferFunction([1.0], [1.0, np.inf])
    with pytest.raises(ValueError, match="den\\[0\\] must be non-zero"):
        hj.ContinuousTransferFunction([1.0], [0.0, 1.0])


def test_improper_continuous_tf():
    with pytest.raises(
        ValueError, match="G\\(s\\) must be proper: deg num <= deg den; got 2 > 1"
    ):
        hj.ContinuousTransferFunction([1.0, 0.0, 1.0], [1.0, 1.0])


def test_v_with_nan_in_simulate():
    with pytest.raises(ValueError, match="input `v` contains NaN"):
        hj.simulate(_plant(), jnp.array([0.0, np.nan, 1.0]))
    with pytest.raises(ValueError, match="input `v` contains inf"):
        hj.simulate(_plant(), jnp.array([0.0, np.inf]))


def test_v_with_nan_under_jit():
    # Under jit the value check is an eqx.error_if, raised when the program runs.
    with pytest.raises(Exception, match="input `v` contains NaN or inf"):
        eqx.filter_jit(hj.simulate)(_plant(), jnp.array([0.0, np.nan, 1.0]))


def test_v_must_be_one_dimensional():
    with pytest.raises(ValueError, match="input `v` must be 1-D"):
        hj.simulate(_plant(), jnp.ones((3, 2)))
    with pytest.raises(ValueError, match="`v` must be a 1-D signal"):
        hj.apply_nonlinearity(hj.Backlash.from_width(1.0), jnp.ones((3, 2)))


def test_continuous_simulation_needs_positive_dt():
    plant = _plant(hj.ContinuousTransferFunction([1.0], [1.0, 1.0]))
    with pytest.raises(ValueError, match="needs the sampling period `dt`"):
        hj.simulate(plant, jnp.ones(4))
    with pytest.raises(ValueError, match="sampling period dt must be > 0; got -0.1"):
        hj.simulate(plant, jnp.ones(4), dt=-0.1)
    with pytest.raises(ValueError, match="sampling period dt must be > 0"):
        hj.DiscreteTransferFunction([1.0], [1.0], dt=-1.0)


def test_simulate_diffrax_bad_inputs():
    G = hj.ContinuousTransferFunction([1.0], [1.0, 1.0])
    t = jnp.linspace(0.0, 1.0, 11)
    with pytest.raises(
        ValueError,
        match="`t` and `v` must be 1-D of equal length; got \\(11,\\), \\(10,\\)",
    ):
        hj.simulate_diffrax(G, t, jnp.ones(10))
    with pytest.raises(ValueError, match="`t` and `v` must be 1-D of equal length"):
        hj.simulate_diffrax(_plant(G, hj.Backlash.from_width(0.2)), t, jnp.ones(12))
    with pytest.raises(ValueError, match="input `v` contains NaN"):
        hj.simulate_diffrax(G, t, jnp.ones(11).at[3].set(np.nan))
    with pytest.raises(
        ValueError, match="sample times `t` must be strictly increasing"
    ):
        hj.simulate_diffrax(G, t.at[5].set(0.1), jnp.ones(11))
    with pytest.raises(ValueError, match="interpolation must be 'hold' or 'linear'"):
        hj.simulate_diffrax(G, t, jnp.ones(11), interpolation="cubic")
    with pytest.raises(TypeError, match="needs a ContinuousTransferFunction"):
        hj.simulate_diffrax(FIRST_ORDER, t, jnp.ones(11))


def test_hammerstein_parts_must_be_hamjax_models():
    with pytest.raises(
        TypeError, match="Hammerstein.nonlinearity must be a hamjax nonlinearity"
    ):
        hj.Hammerstein(lambda v: v, FIRST_ORDER)
    with pytest.raises(
        TypeError, match="Hammerstein.linear must be a hamjax linear block"
    ):
        hj.Hammerstein(hj.Identity(), (np.ones(1), np.ones(1)))


# --- nonlinearities --------------------------------------------------------------------


def test_dead_zone_bad_bounds():
    with pytest.raises(
        ValueError, match="DeadZone needs lower <= 0 <= upper; got 0.5, 1.0"
    ):
        hj.DeadZone(lower=0.5, upper=1.0)
    with pytest.raises(ValueError, match="DeadZone needs lower <= 0 <= upper"):
        hj.DeadZone(lower=-1.0, upper=-0.2)
    with pytest.raises(ValueError, match="DeadZone needs lower <= 0 <= upper"):
        hj.DeadZone.symmetric(-0.3)


def test_saturation_bad_bounds():
    with pytest.raises(
        ValueError, match="Saturation needs lower < upper; got 2.0, 1.0"
    ):
        hj.Saturation(lower=2.0, upper=1.0)
    with pytest.raises(ValueError, match="Saturation needs lower < upper"):
        hj.Saturation(lower=1.0, upper=1.0)


def test_piecewise_linear_bad_breakpoints():
    with pytest.raises(ValueError, match="needs d2 <= 0 <= d1 \\(seed 001, Fig. 2\\)"):
        hj.PiecewiseLinear(k1=1.0, k2=1.0, d1=1.0, d2=0.5)
    with pytest.raises(ValueError, match="PiecewiseLinear.k1 must be a scalar"):
        hj.PiecewiseLinear(k1=jnp.ones(2), k2=1.0)


def test_tabulated_bad_tables():
    with pytest.raises(
        ValueError,
        match="Tabulated.v must be strictly increasing; got Tabulated.v\\[1\\]=1",
    ):
        hj.Tabulated([0.0, 1.0, 1.0], [0.0, 1.0, 2.0])
    with pytest.raises(ValueError, match="same length"):
        hj.Tabulated([0.0, 1.0], [0.0, 1.0, 2.0])
    with pytest.raises(ValueError, match="at least two grid points"):
        hj.Tabulated([0.0], [1.0])
    with pytest.raises(ValueError, match="Tabulated.u contains NaN"):
        hj.Tabulated([0.0, 1.0], [0.0, np.nan])


def test_backlash_bad_parameters():
    with pytest.raises(ValueError, match="backlash width must be >= 0; got -0.5"):
        hj.Backlash.from_width(-0.5)
    with pytest.raises(
        TypeError, match="Backlash.ascending must be a static nonlinearity"
    ):
        hj.Backlash(ascending=hj.Backlash.from_width(1.0), descending=hj.Identity())
    with pytest.raises(ValueError, match="strictly increasing"):
        hj.Backlash.from_table([0.0, 2.0, 1.0], [0.0, 1.0, 2.0], [1.0, 2.0, 3.0])


def test_apply_nonlinearity_rejects_other_callables():
    with pytest.raises(TypeError, match="expected a hamjax nonlinearity; got function"):
        hj.apply_nonlinearity(lambda v: v, jnp.ones(3))


def test_noise_bad_parameters():
    with pytest.raises(ValueError, match="noise std must be finite and >= 0; got -1.0"):
        hj.WhiteNoise(-1.0)
    with pytest.raises(
        ValueError, match="AR\\(1\\) pole must satisfy \\|pole\\| < 1; got 1.0"
    ):
        hj.AR1Noise(1.0, 1.0)
    with pytest.raises(ValueError, match="noise std must be >= 0"):
        hj.AR1Noise(-0.1, 0.5)


# --- signals ----------------------------------------------------------------------------


@pytest.mark.parametrize(
    "make",
    [
        lambda lv: hj.initialisation_step(lv, duration=1.0, dt=0.1),
        lambda lv: hj.nbbi_staircase(lv, hold=1.0, dt=0.1),
        lambda lv: hj.periodic_staircase(lv, period_samples=40, periods=1, dt=0.1),
        lambda lv: hj.pe_impulse_sequence(lv[:4], order=2, periods=1),
    ],
    ids=["(3)", "(4a-b)", "(24)", "(5.1)"],
)
def test_levels_not_strictly_increasing(make):
    with pytest.raises(
        ValueError,
        match="levels must be strictly increasing; got levels\\[2\\]=3 >= levels\\[3\\]=2",
    ):
        make([0.0, 1.0, 3.0, 2.0, 4.0])
    with pytest.raises(ValueError, match="levels contains NaN"):
        make([0.0, 1.0, np.nan, 3.0, 4.0])


def test_too_few_or_too_many_levels():
    with pytest.raises(ValueError, match="need at least 3 levels; got 2"):
        hj.nbbi_staircase([0.0, 1.0], hold=1.0, dt=0.1)
    with pytest.raises(ValueError, match="needs exactly 4 levels V1..V4; got 5"):
        hj.pe_impulse_sequence([0.0, 1.0, 2.0, 3.0, 4.0], order=2, periods=1)


def test_negative_or_fractional_hold():
    with pytest.raises(
        ValueError, match="hold N\\*Tr must be finite and > 0; got -1.0"
    ):
        hj.nbbi_staircase([0.0, 1.0, 2.0], hold=-1.0, dt=0.1)
    with pytest.raises(
        ValueError, match="hold N\\*Tr = 0.25 s is not a whole number of samples"
    ):
        hj.nbbi_staircase([0.0, 1.0, 2.0], hold=0.25, dt=0.1)
    with pytest.raises(
        ValueError, match="initialisation duration T0 must be finite and > 0"
    ):
        hj.initialisation_step([0.0, 1.0], duration=-2.0, dt=0.1)
    with pytest.raises(ValueError, match="hold must be an integer >= 1 sample; got 0"):
        hj.random_staircase(jr.key(0), n_samples=10, hold=0, low=0.0, high=1.0)
    with pytest.raises(ValueError, match="hold must be an integer >= 1 sample; got -2"):
        hj.prbs(jr.key(0), n_samples=10, hold=-2)


def test_negative_dt_in_signals():
    with pytest.raises(
        ValueError, match="sampling period dt must be finite and > 0; got -0.1"
    ):
        hj.nbbi_staircase([0.0, 1.0, 2.0], hold=1.0, dt=-0.1)
    with pytest.raises(ValueError, match="sampling period dt must be > 0"):
        hj.fgi_period_samples(1.0, -0.01, 3)
    with pytest.raises(ValueError, match="sampling period dt must be > 0"):
        hj.multisine(jr.key(0), n_samples=64, harmonics=3, dt=0.0)


def test_bad_period():
    levels = [0.0, 1.0, 2.0]  # 2n-2 = 4
    with pytest.raises(
        ValueError, match="period of -8 samples must be a positive multiple of 2n-2 = 4"
    ):
        hj.periodic_staircase(levels, period_samples=-8, periods=2, dt=0.1)
    with pytest.raises(
        ValueError, match="period of 10 samples must be a positive multiple of 2n-2 = 4"
    ):
        hj.periodic_staircase(levels, period_samples=10, periods=2, dt=0.1)
    with pytest.raises(ValueError, match="periods must be >= 1; got 0"):
        hj.periodic_staircase(levels, period_samples=8, periods=0, dt=0.1)
    with pytest.raises(ValueError, match="periods must be an integer >= 1; got -1"):
        hj.pe_impulse_sequence([0.0, 1.0, 2.0, 3.0], order=2, periods=-1)
    with pytest.raises(ValueError, match="order n must be an integer >= 1; got 0"):
        hj.pe_impulse_sequence([0.0, 1.0, 2.0, 3.0], order=0, periods=1)


def test_random_signal_bad_ranges():
    key = jr.key(0)
    with pytest.raises(ValueError, match="need low < high; got 1.0, 1.0"):
        hj.random_staircase(key, n_samples=10, hold=2, low=1.0, high=1.0)
    with pytest.raises(
        ValueError, match="number of samples must be an integer >= 1; got 0"
    ):
        hj.prbs(key, n_samples=0)
    with pytest.raises(
        ValueError, match="harmonics must be in \\[1, n_samples/2\\); got 40 for 64"
    ):
        hj.multisine(key, n_samples=64, harmonics=40)


def test_non_integer_counts():
    with pytest.raises(ValueError, match="n_levels must be an integer >= 2; got 1"):
        hj.fgi_period_samples(1.0, 0.01, 1)
    with pytest.raises(ValueError, match="period_samples and periods must be integers"):
        hj.periodic_staircase([0.0, 1.0, 2.0], period_samples=7.5, periods=1, dt=0.1)
    with pytest.raises(
        ValueError, match="hold must be an integer >= 1 sample; got 2.5"
    ):
        hj.random_staircase(jr.key(0), n_samples=10, hold=2.5, low=0.0, high=1.0)


def test_grid_with_nan_or_inf():
    with pytest.raises(ValueError, match="Tabulated.v contains NaN"):
        hj.Tabulated([0.0, np.nan, 1.0], [0.0, 1.0, 2.0])
    with pytest.raises(ValueError, match="Tabulated.v contains inf"):
        hj.Tabulated([0.0, 1.0, np.inf], [0.0, 1.0, 2.0])
    with pytest.raises(ValueError, match="sample times `t` contains NaN"):
        hj.simulate_diffrax(
            hj.ContinuousTransferFunction([1.0], [1.0, 1.0]),
            jnp.array([0.0, np.nan, 1.0]),
            jnp.ones(3),
        )
