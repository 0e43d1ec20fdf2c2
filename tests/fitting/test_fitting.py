"""The fitting layer: one least-squares interface over both solvers (checked against
scipy), the one standard-error routine (against NumPy inverses), the compiled
programs' cache."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx
import pytest
import scipy.optimize

from hamjax._results import RESULTS
from hamjax.fitting import (
    BatchedLevenbergMarquardt,
    CompiledPrograms,
    GaussianPrior,
    NormalEquations,
    covariance_from_information,
    least_squares,
    standard_errors_from_information,
)


T = np.linspace(0.0, 4.0, 60)


def _data(seed):
    rng = np.random.default_rng([seed, 0])
    truth = np.array([2.0, 1.3, 0.4])
    return truth, truth[0] * np.exp(-truth[1] * T) + truth[2] + 0.05 * rng.normal(
        size=T.shape
    )


def _residuals(theta, y):
    return theta[0] * jnp.exp(-theta[1] * T) + theta[2] - y


def _scipy(y, prior=None):
    def fun(th):
        r = np.asarray(_residuals(jnp.asarray(th), y))
        if prior is not None:
            w, mask = prior
            r = np.r_[r, np.sqrt(w) * np.where(mask, th, 0.0)]
        return r

    return scipy.optimize.least_squares(
        fun, np.array([1.0, 1.0, 0.0]), xtol=1e-15, ftol=1e-15, gtol=1e-15
    ).x


@pytest.mark.parametrize(
    "solver",
    [BatchedLevenbergMarquardt(), optx.LevenbergMarquardt(rtol=1e-12, atol=1e-12)],
)
def test_both_solvers_reach_scipys_minimum(solver):
    # A nonlinear exponential fit with noise: both solvers behind the one
    # interface must land on scipy's minimiser (a well-conditioned minimum, so
    # to 1e-7 of the parameters' size whatever the stopping rules).
    _, y = _data(1)
    sol = least_squares(_residuals, solver, jnp.array([1.0, 1.0, 0.0]), y)
    assert sol.result == RESULTS.successful
    np.testing.assert_allclose(sol.value, _scipy(y), rtol=1e-7, atol=1e-9)


def test_prior_is_the_same_problem_for_both_solvers():
    # A Gaussian prior on entries 0 and 2 is the cost |r|^2 + w |theta_mask|^2:
    # scipy on the residuals augmented by sqrt(w) theta_mask is the reference.
    _, y = _data(2)
    w, mask = 3.0, np.array([True, False, True])
    want = _scipy(y, (w, mask))
    prior = GaussianPrior(w, jnp.asarray(mask))
    for solver in (
        BatchedLevenbergMarquardt(),
        optx.LevenbergMarquardt(rtol=1e-12, atol=1e-12),
    ):
        theta0 = jnp.array([1.0, 1.0, 0.0])
        sol = least_squares(_residuals, solver, theta0, y, prior=prior)
        np.testing.assert_allclose(sol.value, want, rtol=1e-7, atol=1e-9)


def test_normal_equations_are_the_residual_problem():
    # The same problem given as normal equations (J never stored) takes the same
    # steps as the residual form: same iterate count, same point to rounding.
    _, y = _data(3)

    def normal(theta, y):
        r = _residuals(theta, y)
        J = jax.jacfwd(_residuals)(theta, y)
        return (r @ r, J.T @ J, J.T @ r), jnp.sum(r)

    theta0 = jnp.array([1.0, 1.0, 0.0])
    solver = BatchedLevenbergMarquardt()
    a = least_squares(NormalEquations(normal), solver, theta0, y)
    b = least_squares(_residuals, solver, theta0, y)
    np.testing.assert_allclose(a.value, b.value, rtol=1e-12)
    assert int(a.stats["num_steps"]) == int(b.stats["num_steps"])
    r = np.asarray(_residuals(a.value, y))
    np.testing.assert_allclose(a.aux, r.sum(), rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(a.stats["sse"], r @ r, rtol=1e-12)
    with pytest.raises(TypeError, match="residual function"):
        least_squares(NormalEquations(normal), optx.GaussNewton(1e-8, 1e-8), theta0, y)


def test_budget_and_damping_are_traced_and_failures_are_values():
    # Under vmap each problem has its own step budget and initial damping (one
    # compilation); a budget of 2 cannot converge from this start: not_converged
    # as a value, an error with throw=True.
    _, y = _data(4)
    theta0 = jnp.array([1.0, 1.0, 0.0])

    @eqx.filter_jit
    def solve(steps, lam0):
        sol = least_squares(
            _residuals,
            BatchedLevenbergMarquardt(lam0=lam0),
            theta0,
            y,
            max_steps=steps,
            throw=False,
        )
        return sol.result, sol.stats["num_steps"], sol.value

    result, steps, value = jax.vmap(solve)(jnp.array([2, 200]), jnp.array([1e-3, 1.0]))
    codes = np.asarray(result._value)
    assert codes[0] == RESULTS.not_converged._value
    assert codes[1] == RESULTS.successful._value
    assert int(steps[0]) == 2 and int(steps[1]) > 2
    np.testing.assert_allclose(value[1], _scipy(y), rtol=1e-7, atol=1e-9)
    with pytest.raises(Exception, match="did not converge"):
        least_squares(
            _residuals, BatchedLevenbergMarquardt(), theta0, y, max_steps=2
        ).value.block_until_ready()


def _spd(seed, n=5):
    rng = np.random.default_rng([seed, 1])
    X = rng.normal(size=(3 * n, n)) * np.logspace(0, 3, n)  # spread scales
    return X.T @ X


# the routine runs on NumPy arrays (host, no compilation) and on JAX arrays
ARRAYS = pytest.mark.parametrize("to", [np.asarray, jnp.asarray], ids=["np", "jax"])


@ARRAYS
def test_both_treatments_equal_the_inverse_when_regular(to):
    # A regular information matrix: both treatments give D I^-1 D^T (NumPy's
    # inverse as the reference, to the matrix's condition times rounding).
    info = to(_spd(0))
    D = to(np.random.default_rng([0, 2]).normal(size=(2, 5)))
    want = D @ np.linalg.inv(info) @ D.T
    for singular in ("pseudo-inverse", "infinite"):
        got = covariance_from_information(info, jacobian=D, singular=singular)
        assert isinstance(got, np.ndarray) == isinstance(info, np.ndarray)
        np.testing.assert_allclose(got, want, rtol=1e-8)
        std = standard_errors_from_information(info, variance=2.0, singular=singular)
        np.testing.assert_allclose(
            std, np.sqrt(2.0 * np.diag(np.linalg.inv(info))), rtol=1e-8
        )


@ARRAYS
def test_singular_directions_nan_or_infinite(to):
    # Entries 3 and 4 enter only through their sum: that sum is identified
    # (pseudo-inverse: finite, equal to the bound of the reduced problem), each
    # alone is not (NaN); the diagnosis's treatment makes every used entry
    # infinite and keeps an unused (padding) entry at 0.
    rng = np.random.default_rng([1, 3])
    X = rng.normal(size=(40, 4))
    Xs = np.c_[X, X[:, 3]]  # column 4 = column 3
    info = to(Xs.T @ Xs)
    cov = np.asarray(covariance_from_information(info, singular="pseudo-inverse"))
    assert np.all(np.isnan(cov[3:, :])) and np.all(np.isfinite(cov[:3, :3]))
    reduced = np.linalg.inv(X.T @ X)
    np.testing.assert_allclose(cov[:3, :3], reduced[:3, :3], rtol=1e-8)
    D = to(np.array([[0, 0, 0, 1.0, 1.0]]))
    summed = covariance_from_information(info, jacobian=D, singular="pseudo-inverse")
    np.testing.assert_allclose(summed[0, 0], reduced[3, 3], rtol=1e-6)
    bad = to(np.diag([1.0, 1.0, 1.0, -1.0, 0.0]))  # indefinite; 4 is padding
    used = to(np.array([True, True, True, True, False]))
    std = np.asarray(
        standard_errors_from_information(bad, used=used, singular="infinite")
    )
    assert np.all(np.isinf(std[:4])) and std[4] == 0.0
    ok = np.asarray(standard_errors_from_information(info[:4, :4], singular="infinite"))
    np.testing.assert_allclose(ok, np.sqrt(np.diag(reduced)), rtol=1e-8)
    with pytest.raises(ValueError, match="singular"):
        standard_errors_from_information(info, singular="drop")


def test_compiled_programs_cache_clear_and_fallback():
    # One compilation per shape; clear() forgets it; an XLA without a requested
    # option compiles with its defaults, any other compile error is raised.
    programs = CompiledPrograms(
        {"double": jax.jit(lambda x: 2.0 * x)},
        compiler_options={"xla_no_such_option": 1},
    )
    x = jnp.ones(3)
    np.testing.assert_array_equal(programs.get("double", (x,), {})(x), 2.0)
    programs.get("double", (x,), {})
    assert len(programs) == 1
    programs.get("double", (jnp.ones(4),), {})
    assert len(programs) == 2
    programs.clear()
    assert len(programs) == 0

    class Broken:
        def compile(self, **kwargs):
            raise RuntimeError("out of memory")

    with pytest.raises(RuntimeError, match="out of memory"):
        programs._compile(Broken())
