"""Seed 001: reparametrisation, gradient, SVD rule, recovery, bad input."""

import equinox as eqx
import jax
import jax.numpy as jnp
import jax.random as jr
import numpy as np
import pytest
from hypothesis import given, settings, strategies as st
from scipy import signal, stats

import hamjax as hj
from hamjax.identification.seed001 import (
    batch_least_squares,
    check_levels,
    dead_zone_rule,
    excitation_level,
    identify_recursive_pl,
    interpolating_polynomial,
    lagrange_basis,
    normalised_gradient,
    preload_rule,
    rank_one_decomposition,
    recover_history,
    recover_parameters,
    regressor,
    slopes_and_offsets,
    structure_consistent,
    symmetric_rule,
)
from hamjax.papers.seed001.plants import paper_case, random_case


PAPER_LEVELS = np.array([-6.0, -3.0, 3.0, 6.0])


def _pl(v, k1, k2, d1, d2, l1, l2):
    """Fig. 2 in NumPy: the independent reference for F."""
    return np.where(v > d1, k1 * (v - d1) + l1, np.where(v < d2, k2 * (v - d2) + l2, 0))


def _paper_data(periods):
    _, v = hj.pe_impulse_sequence(jnp.asarray(PAPER_LEVELS), order=2, periods=periods)
    v = np.asarray(v)
    u = _pl(v, 1.0, 2.0, 1.0, -2.0, 1.0, -2.0)
    return v, signal.lfilter([0, 1.0, -2.0], [1, -1.5, 0.56], u)


_simulate = eqx.filter_jit(lambda case, v: hj.simulate(case.plant(), v))


def _case_data(case, periods):
    _, v = hj.pe_impulse_sequence(case.levels, order=case.order, periods=periods)
    return v, _simulate(case, v)


def test_theta_star_matches_paper_list():
    # Section V.C prints theta* = [0.56 -1.5 1.66 -3.33 1.33 -2.66 1 -2 1 -2]:
    # a2 before a1, then mu_ij = b_i d_j truncated to two decimals.
    printed = np.array([0.56, -1.5, 1.66, -3.33, 1.33, -2.66, 1, -2, 1, -2])
    theta = np.asarray(paper_case().theta_star())
    reordered = np.r_[theta[1], theta[0], theta[2:]]
    assert np.all(np.abs(reordered - printed) < 0.01)
    # Exact values from (3.5) by hand: d = F(V)/V = (10/6, 4/3, 1, 1), b = (1, -2).
    d = np.array([10 / 6, 4 / 3, 1, 1])
    assert np.allclose(theta, np.r_[-1.5, 0.56, np.outer([1, -2], d).T.ravel()])


def test_regression_is_exact_on_paper_plant():
    v, y = _paper_data(20)
    phi = regressor(jnp.asarray(v), jnp.asarray(y), levels=PAPER_LEVELS, order=2)
    assert np.allclose(phi @ paper_case().theta_star(), y, atol=1e-12)


def test_lagrange_polynomial_against_numpy_interpolation(getkey):
    # Random levels 1..5 (two negated and shifted below -2): any two are close only
    # rarely; the 1e-8 tolerances leave room for the quartic's conditioning.
    levels = np.sort(np.asarray(jr.uniform(getkey(), (4,), minval=1, maxval=5)))
    levels = np.r_[-levels[2:][::-1] - 1, levels[:2]]
    levels = np.sort(levels)
    values = np.asarray(jr.normal(getkey(), (4,)))
    basis = np.asarray(lagrange_basis(jnp.asarray(levels), jnp.asarray(levels)))
    assert np.allclose(basis, np.eye(4), atol=1e-12)  # Eq. (3.4)
    x = np.r_[0.0, levels]
    coeffs = np.polyfit(x, np.r_[0.0, values], 4)  # the unique quartic of (3.2)
    grid = np.linspace(levels[0], levels[-1], 11)
    got = interpolating_polynomial(
        jnp.asarray(levels), jnp.asarray(values / levels), grid
    )
    assert np.allclose(got, np.polyval(coeffs, grid), rtol=1e-8, atol=1e-8)


def _numpy_gradient(phi, y, theta0, rho):
    theta, out = theta0.copy(), []
    for p, yt in zip(phi, y, strict=True):
        cand = theta + p * (yt - p @ theta) / (1 + p @ p)
        theta = min(rho, np.linalg.norm(cand)) * cand / np.linalg.norm(cand)
        out.append(theta)
    return np.array(out)


@pytest.mark.parametrize("rho", [1e6, 3.0])
def test_normalised_gradient_against_loop(getkey, rho):
    phi = np.asarray(jr.normal(getkey(), (60, 5)))
    y = np.asarray(jr.normal(getkey(), (60,)))
    theta0 = np.asarray(jr.normal(getkey(), (5,)))
    _, hist = normalised_gradient(
        jnp.asarray(phi), jnp.asarray(y), theta0=jnp.asarray(theta0), rho=rho
    )
    # Any draw: each step is a projection (norm-reducing), so rounding does not
    # grow; rtol 1e-12 plus np.allclose's default atol 1e-8 for entries near zero.
    assert np.allclose(hist, _numpy_gradient(phi, y, theta0, rho), rtol=1e-12)
    assert np.all(np.linalg.norm(hist, axis=1) <= rho * (1 + 1e-12))


@pytest.mark.slow
def test_paper_plant_exact_recovery_and_convergence():
    v, y = _paper_data(2000)
    res = identify_recursive_pl(v, y, levels=PAPER_LEVELS, order=2)
    est = res.estimate
    s5 = np.sqrt(5)
    # Normalisation (3.10): b = (1,-2)/sqrt5 has its largest entry -2, so flip.
    assert np.allclose(est.a, [-1.5, 0.56], atol=1e-9)
    assert np.allclose(est.b, [-1 / s5, 2 / s5], atol=1e-9)
    f = _pl(PAPER_LEVELS, 1.0, 2.0, 1.0, -2.0, 1.0, -2.0)
    assert np.allclose(est.points, -s5 * f, atol=1e-8)
    assert np.allclose([est.k1, est.k2], [-s5, -2 * s5], atol=1e-8)
    assert np.allclose([est.h1, est.h2], [0.0, -2 * s5], atol=1e-8)  # H = L - K D
    assert np.all(np.isnan([est.d1, est.d2, est.l1, est.l2]))  # no structure named
    # History: starts at theta0 = 0 and ends at theta*.
    err = np.abs(np.asarray(res.history) - np.asarray(paper_case().theta_star())).max(1)
    assert err[0] > 1 and err[-1] < 1e-9
    hist = recover_history(res, every=1000)
    assert hist.k1.shape == (y.shape[0] // 1000,)


STRUCTURES = ["dead-zone", "preload", "symmetric"]


# Orders 1-2 here; order 3 random plants can come close to a pole-zero cancellation
# and then need far more samples (study recursive_pl_convergence measures that).
@pytest.mark.slow
@pytest.mark.parametrize("order, structure", [(1, "dead-zone"), (2, "preload")])
def test_random_plants_exact_recovery_gradient(structure, order):
    case = random_case(jr.fold_in(jr.key(11), order), order, structure)
    v, y = _case_data(case, 3000)
    res = identify_recursive_pl(
        v, y, levels=case.levels, order=order, structure=structure
    )
    truth = case.normalised_truth()
    for name, want in truth.items():
        assert np.allclose(getattr(res.estimate, name), want, atol=1e-6), name
    assert res.result == hj.RESULTS.successful


@pytest.mark.slow
@pytest.mark.parametrize("order, structure", [(3, "symmetric")])
def test_random_plants_exact_recovery_batch(order, structure):
    # Fixed-key property test: 16 random plants, levels and maps per (order, structure).
    _, v0 = hj.pe_impulse_sequence(jnp.asarray(PAPER_LEVELS), order=order, periods=4)

    def trial(key):
        case = random_case(key, order, structure)
        # The (5.1) pattern with the case's own levels V_j in place of the paper's.
        v = jnp.select([v0 == x for x in PAPER_LEVELS], list(case.levels), 0.0)
        y = hj.simulate(case.plant(), v)
        phi = regressor(v, y, levels=case.levels, order=order)
        theta = batch_least_squares(phi, y)
        est = recover_parameters(
            theta, levels=case.levels, order=order, structure=structure
        )
        return theta, case.theta_star(), est, case.normalised_truth()

    keys = jax.vmap(lambda i: jr.fold_in(jr.key(100 + order), i))(jnp.arange(16))
    theta, want, est, truth = jax.jit(jax.vmap(trial))(keys)
    assert np.allclose(theta, want, atol=1e-8)
    for name, value in truth.items():
        assert np.allclose(getattr(est, name), value, atol=1e-6), name
    assert np.all(est.consistent)


@settings(max_examples=10, deadline=None)
@given(seed=st.integers(0, 2**31 - 1), n=st.integers(1, 5), negate=st.booleans())
def test_svd_rule_on_rank_one(seed, n, negate):
    kb, kd = jr.split(jr.key(seed))
    b = jr.normal(kb, (n,))
    d = jr.normal(kd, (4,))
    m = jnp.outer(b, d) * (-1 if negate else 1)
    bh, dh, sigma = rank_one_decomposition(m)
    assert np.isclose(np.sum(bh**2), 1.0)
    first = np.asarray(bh)[np.argmax(np.abs(np.asarray(bh)))]
    assert first > 0  # Eq. (3.13)
    assert np.allclose(jnp.outer(bh, dh), m, atol=1e-12)
    assert np.allclose(np.abs(bh), np.abs(b) / np.linalg.norm(b))
    assert np.all(np.asarray(sigma)[1:] < 1e-12 * np.asarray(sigma)[0])


def test_svd_rule_ties_and_noise(getkey):
    # Equal magnitudes: the *first* one decides the sign (3.10).
    bh, dh, _ = rank_one_decomposition(jnp.outer(jnp.array([-1.0, 1.0]), jnp.ones(4)))
    assert np.allclose(bh, [1 / np.sqrt(2), -1 / np.sqrt(2)])
    # Not rank 1 (Proposition 4.2): b d^T is the best rank-1 approximation.
    # Any draw of a 3x4 normal matrix: entries O(1), a top-singular-value gap far
    # above 1e-4 (probability ~ gap^2 of less), so the rank-1 terms agree to 1e-12.
    m = np.asarray(jr.normal(getkey(), (3, 4)))
    bh, dh, _ = rank_one_decomposition(jnp.asarray(m))
    u, s, vt = np.linalg.svd(m)
    assert np.allclose(np.outer(bh, dh), s[0] * np.outer(u[:, 0], vt[0]), atol=1e-12)


def _rule_inputs(f):
    points = jnp.asarray(_pl(PAPER_LEVELS, **f))
    return slopes_and_offsets(jnp.asarray(PAPER_LEVELS), points)


def _structure_ok(structure, f, rule):
    khh = _rule_inputs(f)
    return bool(
        structure_consistent(structure, jnp.asarray(PAPER_LEVELS), *khh, *rule(*khh))
    )


def test_rule_3_18a_dead_zone():
    f = dict(k1=1.5, k2=0.7, d1=0.8, d2=-1.9, l1=0.0, l2=0.0)
    assert np.allclose(dead_zone_rule(*_rule_inputs(f)), [0.8, -1.9, 0, 0])
    assert _structure_ok("dead-zone", f, dead_zone_rule)
    # A preload named as a dead zone gives a negative width: flagged.
    g = dict(k1=1.5, k2=0.7, d1=0.0, d2=0.0, l1=1.0, l2=-1.0)
    assert not _structure_ok("dead-zone", g, dead_zone_rule)


def test_rule_3_18b_preload():
    f = dict(k1=1.5, k2=0.7, d1=0.0, d2=0.0, l1=0.4, l2=-1.2)
    assert np.allclose(preload_rule(*_rule_inputs(f)), [0, 0, 0.4, -1.2])
    assert _structure_ok("preload", f, preload_rule)
    g = dict(k1=1.5, k2=0.7, d1=0.8, d2=-1.9, l1=0.0, l2=0.0)
    assert not _structure_ok("preload", g, preload_rule)


def test_rule_3_18c_symmetric():
    f = dict(k1=1.5, k2=0.7, d1=0.9, d2=-0.9, l1=0.6, l2=-0.6)
    assert np.allclose(symmetric_rule(*_rule_inputs(f)), [0.9, -0.9, 0.6, -0.6])
    assert _structure_ok("symmetric", f, symmetric_rule)
    g = dict(k1=1.0, k2=1.0, d1=0.9, d2=-0.9, l1=0.6, l2=-0.6)  # K1 = K2: undefined
    assert not _structure_ok("symmetric", g, symmetric_rule)


def test_inconsistent_structure_is_a_result_code():
    case = random_case(jr.key(3), 2, "preload")
    v, y = _case_data(case, 5)
    kw = dict(levels=case.levels, order=2, structure="dead-zone", estimator="batch")
    res = identify_recursive_pl(v, y, throw=False, **kw)
    assert res.result == hj.RESULTS.inconsistent_structure
    assert not bool(res.estimate.consistent)
    with pytest.raises(Exception, match="inconsistent"):
        identify_recursive_pl(v, y, throw=True, **kw)


def test_excitation_pe_vs_constant():
    case = paper_case()
    v, y = _case_data(case, 3)
    phi = regressor(v, y, levels=case.levels, order=2)
    assert excitation_level(phi[-14:]) > 1e-6  # one period of (5.1) (Prop. 5.1)
    v2 = jnp.where(v != 0, case.levels[3], 0.0)  # only V4: d1..d3 unexcited
    y2 = hj.simulate(case.plant(), v2)
    res = identify_recursive_pl(v2, y2, levels=case.levels, order=2, throw=False)
    assert res.result == hj.RESULTS.not_exciting


def test_vmap_equals_loop_and_no_retrace():
    case = paper_case()
    v, w = _case_data(case, 30)

    def trial(key):
        y = w + 0.01 * jr.normal(key, w.shape)
        r = identify_recursive_pl(
            v, y, levels=PAPER_LEVELS, order=2, keep_history=False, throw=False
        )
        return r.theta

    keys = jax.vmap(lambda i: jr.fold_in(jr.key(0), i))(jnp.arange(3))
    batched = jax.jit(jax.vmap(eqx.debug.assert_max_traces(trial, max_traces=1)))
    out = batched(keys)
    out2 = batched(keys)  # a second Monte Carlo pass must not re-trace
    single = jax.jit(trial)
    loop = np.stack([np.asarray(single(keys[i])) for i in range(3)])
    assert np.allclose(out, loop, rtol=1e-10, atol=1e-12)
    assert np.array_equal(out, out2)


def _lfilter_reg(v, y, order):
    """NumPy regressor, zero before t = 0: the oracle for the bias formula."""
    return np.asarray(
        regressor(jnp.asarray(v), jnp.asarray(y), levels=PAPER_LEVELS, order=order)
    )


@pytest.mark.slow
@pytest.mark.statistical
def test_noisy_batch_ls_has_the_equation_error_bias():
    # With y = w + z, z white of variance s2, Phi holds -z(t-i) and
    # eta(t) = A(q^-1) z(t), so E[Phi eta] = -s2 (a, 0) and least squares tends to
    # theta* - (R_w + s2 J)^-1 s2 J a (J selects the y-part): a floor that does not
    # shrink with T. Check the Monte Carlo mean against it component-wise, with a
    # Bonferroni z-bound: false-failure rate <= 1e-3 (plus an O(1/N) finite-sample
    # term, < 0.1 MCSE here).
    periods, reps, std = 100, 300, 0.5
    v, w = _paper_data(periods)
    theta = np.asarray(paper_case().theta_star())
    phi_w = _lfilter_reg(v, w, 2)
    p = theta.shape[0]
    j = np.diag(np.r_[np.ones(2), np.zeros(p - 2)])
    r_w = phi_w.T @ phi_w / len(w)
    bias = -np.linalg.solve(
        r_w + std**2 * j, std**2 * j @ np.r_[theta[:2], np.zeros(p - 2)]
    )
    vj, wj = jnp.asarray(v), jnp.asarray(w)

    def trial(key):
        y = wj + std * jr.normal(key, wj.shape)
        return batch_least_squares(regressor(vj, y, levels=PAPER_LEVELS, order=2), y)

    keys = jax.vmap(lambda i: jr.fold_in(jr.key(2024), i))(jnp.arange(reps))
    est = np.asarray(jax.jit(jax.vmap(trial))(keys))
    mcse = est.std(0, ddof=1) / np.sqrt(reps)
    z = (est.mean(0) - theta - bias) / mcse
    assert np.max(np.abs(z)) < stats.norm.ppf(1 - 1e-3 / (2 * p))
    # ... and the bias is real: far outside the Monte Carlo error in a1, a2.
    assert np.all(np.abs(bias[:2]) > 10 * mcse[:2])


def test_bad_levels():
    with pytest.raises(ValueError, match=r"\(3.1\)"):
        check_levels([-6.0, -3.0, -1.0, 6.0])  # three negative levels
    with pytest.raises(ValueError, match="distinct"):
        check_levels([-6.0, -3.0, 3.0, 3.0])
    with pytest.raises(ValueError, match="exactly four"):
        check_levels([-6.0, 3.0, 6.0])
    with pytest.raises(ValueError, match="D_M"):
        check_levels([-6.0, -3.0, 3.0, 6.0], d_max=4.0)
    with pytest.raises(ValueError, match="V1 < V2 < V3 < V4"):
        check_levels([-3.0, -6.0, 3.0, 6.0])


def test_bad_data():
    v, y = _paper_data(3)
    kw = dict(levels=PAPER_LEVELS, order=2)
    with pytest.raises(ValueError, match="fewer than one period"):
        identify_recursive_pl(v[:10], y[:10], **kw)
    with pytest.raises(ValueError, match="fewer than one period"):
        identify_recursive_pl(v, y, levels=PAPER_LEVELS, order=7)
    bad = v.copy()
    bad[5] = 1.5
    with pytest.raises(ValueError, match=r"v\[5\] = 1.5 is not in"):
        identify_recursive_pl(bad, y, **kw)
    with pytest.raises(ValueError, match="structure"):
        identify_recursive_pl(v, y, structure="saturation", **kw)
    with pytest.raises(ValueError, match="same length|equal length"):
        identify_recursive_pl(v, y[:-1], **kw)
    with pytest.raises(ValueError, match="rho"):
        identify_recursive_pl(v, y, rho=0.0, **kw)


@pytest.mark.slow
@pytest.mark.statistical
def test_noisy_gradient_error_has_a_floor():
    # Prop. 5.2(1) claims only a bound K2 mu; the study finds a floor: the mean
    # error over [T/2, T] does not shrink from T = N/2 to N (a consistent
    # estimator's would shrink by ~1/sqrt2). Check mean(e_N) > 0.85 mean(e_N/2) by
    # a one-sided z-test on the paired differences: false-failure rate 1e-3 if
    # the true ratio is >= 0.85 (the study measures 0.97 at 30 dB).
    periods, reps = 1000, 40
    v, w = _paper_data(periods)
    std = 0.03 * np.sqrt(np.mean(w**2))  # about 30 dB
    theta_star = paper_case().theta_star()
    vj, wj = jnp.asarray(v), jnp.asarray(w)
    n = w.shape[0]

    def trial(key):
        y = wj + std * jr.normal(key, wj.shape)
        phi = regressor(vj, y, levels=PAPER_LEVELS, order=2)
        _, hist = normalised_gradient(phi, y, theta0=jnp.zeros(10), rho=1e6)
        err = jnp.linalg.norm(hist - theta_star[None, :], axis=1)
        return jnp.mean(err[n // 4 : n // 2]), jnp.mean(err[n // 2 :])

    keys = jax.vmap(lambda i: jr.fold_in(jr.key(7), i))(jnp.arange(reps))
    e_half, e_full = (np.asarray(x) for x in jax.jit(jax.vmap(trial))(keys))
    diff = e_full - 0.85 * e_half
    z = diff.mean() / (diff.std(ddof=1) / np.sqrt(reps))
    assert z > -stats.norm.ppf(1 - 1e-3)


def test_untrustworthy_records_are_reported_not_successful():
    # The procedure itself says when its estimate cannot be trusted: a constant
    # output (degenerate) and a gradient held on a ball below ||Theta*||
    # (constrained); the batch estimator has no ball.
    from hamjax._results import RESULTS

    case = paper_case()
    _, v = hj.pe_impulse_sequence(case.levels, order=2, periods=100)
    w = hj.simulate(case.plant(), v)
    kw = dict(levels=case.levels, order=2, throw=False)
    assert hj.identify_recursive_pl(v, w, **kw).result == RESULTS.successful
    dead = hj.identify_recursive_pl(v, jnp.full_like(w, -1.25), **kw)
    assert dead.result == RESULTS.degenerate
    small = float(jnp.linalg.norm(case.theta_star())) / 10
    held = hj.identify_recursive_pl(v, w, rho=small, **kw)
    assert held.result == RESULTS.constrained
    batch = hj.identify_recursive_pl(v, w, rho=small, estimator="batch", **kw)
    assert batch.result == RESULTS.successful
    with pytest.raises(Exception, match="projection ball"):
        hj.identify_recursive_pl(v, w, levels=case.levels, order=2, rho=small)
