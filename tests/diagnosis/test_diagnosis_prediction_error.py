"""The prediction-error fit (`fit.normal_equations` with the case's noise filter,
`schedule.whitening_items`): its residual and Jacobian are the output-error ones
filtered by $A(q)$, against `scipy.signal.lfilter` and finite differences; with
the filter's parameter free (Box-Jenkins), its column too, and the joint fit's
optimum against the closed-form AR(1) estimate on its own residual."""

import equinox as eqx
import jax.numpy as jnp
import jax.random as jr
import numpy as np
import pytest
import scipy.signal

import hamjax.diagnosis.schedule as schedule
from hamjax.diagnosis.attribute import reference, whitening_noise
from hamjax.diagnosis.augmented import simulate_with_filter
from hamjax.diagnosis.fit import (
    _coefficients,
    _normal_equations,
    fit_row,
    normal_equations,
    theta_std,
)
from hamjax.diagnosis.layout import prepare
from hamjax.diagnosis.noise_fit import noise_direction, noise_filter, predictor_errors
from hamjax.diagnosis.schedule import run_queue, whitening_items
from hamjax.papers.gap.demo_cases import coloured_case, tiny_case


@eqx.filter_jit
def _simulated_residual(theta, row, case):
    p, b, a = _coefficients(theta, row, case)
    y = simulate_with_filter(p, b, a, row.tau, case.v_est, case)
    return (y - case.y_est) / case.y_scale


def _residual(theta, row, case, n):
    """The scaled output-error residual of a row on the estimation record."""
    return np.asarray(_simulated_residual(jnp.asarray(theta), row, case))[:n]


@pytest.fixture(scope="module")
def setup():
    # 700 samples padded to 1024: three blocks, the last part padding
    prep = prepare(*tiny_case(jr.key(5), "backlash", noise=0.02, n=700), 1024)
    name, row = next((n, r) for n, r in prep.rows if n == "backlash")
    theta = np.asarray(row.theta0) + 0.05
    return prep, row, theta


@pytest.mark.parametrize(
    "predictor", [("ar1_pole", 0.9), ("level_gain", 0.3), ("level_gain", 0.02)]
)
def test_normal_equations_are_those_of_the_filtered_residual(setup, predictor):
    prep, row, theta = setup
    fir, ar = noise_filter(*predictor)
    case = eqx.tree_at(lambda c: (c.noise_fir, c.noise_ar), prep.arrays, (fir, ar))
    sse, H, g = (np.asarray(x) for x in normal_equations(jnp.asarray(theta), row, case))
    n = prep.n_est
    r = _residual(theta, row, case, n)
    e = scipy.signal.lfilter(fir, [1.0, ar], r)
    # the host twin of the predictor filters the same way
    np.testing.assert_allclose(predictor_errors(*predictor, r), e, rtol=1e-12)
    assert sse == pytest.approx(e @ e, rel=1e-10)
    # the Jacobian by central differences of the filtered residual
    h = 1e-6
    J = np.stack(
        [
            scipy.signal.lfilter(
                fir,
                [1.0, ar],
                _residual(theta + h * dj, row, case, n)
                - _residual(theta - h * dj, row, case, n),
            )
            / (2 * h)
            for dj in np.eye(theta.shape[0])
        ]
    )
    scale = np.linalg.norm(J @ e)
    np.testing.assert_allclose(g, J @ e, atol=1e-5 * scale)
    np.testing.assert_allclose(H, J @ J.T, atol=1e-5 * np.linalg.norm(J @ J.T))


def test_the_identity_filter_is_output_error(setup):
    prep, row, theta = setup
    n = prep.n_est
    r = _residual(theta, row, prep.arrays, n)
    for whiten in (True, False):
        sse, _, _ = normal_equations(
            jnp.asarray(theta), row, prep.arrays, whiten=whiten
        )
        assert float(sse) == pytest.approx(r @ r, rel=1e-10)


def test_a_prediction_error_fit_is_consistent_under_a_random_walk_disturbance():
    """With a random-walk disturbance on the estimation record (a drift no
    simulation follows), the output-error re-fit of the nominal parameters is
    pulled far off, while the prediction-error fit through the walk's
    differencing filter, whose errors are then white, stays within 6 of its own
    Gauss-Newton standard errors of the truth (the nominal: a two-sided
    false-failure rate of about 2e-9 per parameter)."""
    plant, dt, est, val = tiny_case(jr.key(11), "none", noise=1e-3, n=2000)
    walk = np.cumsum(np.asarray(jr.normal(jr.key(12), (2000,)))) * 0.02
    est = dict(est, y=np.asarray(est["y"]) + walk)
    prep = prepare(plant, dt, est, val, nominal_uncertainty=None)
    row = next(r for n, r in prep.rows if n == "parameter_mismatch")
    fir, ar = noise_filter("level_gain", 1.0)  # pure differencing: 1 - q^-1
    pe_case = eqx.tree_at(lambda c: (c.noise_fir, c.noise_ar), prep.arrays, (fir, ar))
    used = np.asarray(row.idx) < prep.arrays.anchor.shape[0]
    oe, pe = fit_row(row, prep.arrays, 100), fit_row(row, pe_case, 100)
    std = theta_std(np.asarray(pe.jtj), float(pe.s2), used)[used]
    theta_pe, theta_oe = np.asarray(pe.theta)[used], np.asarray(oe.theta)[used]
    assert np.all(np.abs(theta_pe) < 6 * std)
    assert np.max(np.abs(theta_oe) / std) > 10  # what the walk does without it


def test_the_queue_refits_by_prediction_error_only_where_noise_is_coloured():
    """A case with AR(1) output noise gets prediction-error fits of its leading
    rows through the nominal's AR(1) predictor (each equal to that row's fit
    from its output-error optimum with the filter and the scaled prior set, run
    alone); a case with white noise gets none."""
    coloured = prepare(*coloured_case(jr.key(4), pole=0.95, std=0.05), 512, 13)
    white = prepare(*tiny_case(jr.key(7), "none", noise=1e-2), 512, 13)
    got = {}
    run_queue([coloured, white], 64, lambda c, f: got.setdefault(c, f))
    assert "whitened" not in got[1]
    assert whitening_items(1, white, got[1]) == []
    fits = got[0]
    items = whitening_items(0, coloured, {k: fits[k] for k in fits if k != "whitened"})
    assert items
    fir, ar, weight, dfir, dar, shift = items[0].noise
    predictor = whitening_noise(fits["noise"], reference(coloured, fits)[2]).whitening
    np.testing.assert_array_equal(fir, noise_filter(*predictor)[0])
    assert ar == 0.0 and -1 < fir[1] < -0.5  # the AR(1) predictor 1 - a q^-1
    assert weight > 0
    # the pole is fitted with the row (its direction: d(fir)/da = (0, -1, 0))
    np.testing.assert_array_equal(dfir, [0.0, -1.0, 0.0])
    assert dar == 0.0 and shift == 0.0
    for it in items:
        _, row = coloured.rows[it.row]
        case = eqx.tree_at(
            lambda c: (c.noise_fir, c.noise_ar, c.prior_weight, c.noise_dfir),
            coloured.arrays,
            (fir, ar, weight, dfir),
        )
        alone = fit_row(
            eqx.tree_at(lambda r: r.theta0, row, jnp.asarray(it.theta0)),
            case,
            schedule.FINISH_STEPS,
        )
        np.testing.assert_allclose(
            fits["whitened"]["sse_est"][it.row], float(alone.sse_est), rtol=1e-8
        )
        np.testing.assert_allclose(
            fits["whitened"]["noise_shift"][it.row],
            float(alone.noise_shift),
            rtol=1e-6,
            atol=1e-9,
        )
        # the host's one-step errors through the row's own predictor (the
        # reference's parameter moved by its shift: `attribute._est_through_noise`)
        # are the fit's own prediction errors
        n = coloured.n_est
        r = (
            np.asarray(coloured.arrays.y_est)[:n]
            - fits["whitened"]["y_est"][it.row][:n]
        )
        shift = fits["whitened"]["noise_shift"][it.row]
        e = predictor_errors(predictor[0], predictor[1] + shift, r)
        np.testing.assert_allclose(
            e @ e, fits["whitened"]["sse_est"][it.row], rtol=1e-8
        )
        # the output-error fit of the row is kept beside it
        assert fits["sse_est"][it.row] != fits["whitened"]["sse_est"][it.row]


@pytest.mark.parametrize("predictor", [("ar1_pole", 0.6), ("level_gain", 0.3)])
def test_the_noise_parameters_column_is_the_derivative_of_the_filtered_residual(
    setup, predictor
):
    """The joint fit's last column (`fit._normal_equations`): the derivative of
    the filtered residual in the predictor's parameter, by central differences
    of `scipy.signal.lfilter` with the parameter moved."""
    prep, row, theta = setup
    name, value = predictor
    dfir, dar = noise_direction(name)
    fir, ar = noise_filter(name, value)
    case = eqx.tree_at(
        lambda c: (c.noise_fir, c.noise_ar, c.noise_dfir, c.noise_dar),
        prep.arrays,
        (fir, ar, dfir, dar),
    )
    eta = 0.03
    flags = (True, True, True, True)
    (sse, H, g), _ = _normal_equations(jnp.asarray(np.r_[theta, eta]), row, case, flags)
    r = _residual(theta, row, case, prep.n_est)
    e = predictor_errors(name, value + eta, r)
    assert float(sse) == pytest.approx(e @ e, rel=1e-10)
    h = 1e-6
    de = (
        predictor_errors(name, value + eta + h, r)
        - predictor_errors(name, value + eta - h, r)
    ) / (2 * h)
    np.testing.assert_allclose(float(g[-1]), de @ e, rtol=1e-6)
    np.testing.assert_allclose(float(H[-1, -1]), de @ de, rtol=1e-6)


def test_a_joint_fit_recovers_the_noise_pole_and_the_plant():
    """Box-Jenkins: the re-fit with the AR(1) pole free, started from a wrong
    pole (0.5, the truth 0.95), ends where the pole is the least-squares AR(1)
    coefficient of its own residual (the joint optimum's condition in the pole),
    within 6 of that estimate's asymptotic standard error
    $\\sqrt{(1 - a^2)/n}$ of the truth, the plant's parameters within 6 of their
    standard errors of the nominal (the truth; a two-sided false-failure rate of
    about 2e-9 each); the same fit from pole 0.8 ends at the same point."""
    plant, dt, est, val = coloured_case(jr.key(21), n=2000, pole=0.95, std=0.05)
    prep = prepare(plant, dt, est, val, nominal_uncertainty=None)
    row = next(r for n, r in prep.rows if n == "parameter_mismatch")
    used = np.asarray(row.idx) < prep.arrays.anchor.shape[0]
    dfir, dar = noise_direction("ar1_pole")
    ends = []
    for start in (0.5, 0.8):
        fir, ar = noise_filter("ar1_pole", start)
        case = eqx.tree_at(
            lambda c: (c.noise_fir, c.noise_ar, c.noise_dfir, c.noise_dar),
            prep.arrays,
            (fir, ar, dfir, dar),
        )
        fit = fit_row(row, case, 200)
        pole = start + float(fit.noise_shift)
        r = _residual(np.asarray(fit.theta), row, case, prep.n_est)
        ls = float(r[1:] @ r[:-1] / (r[:-1] @ r[:-1]))
        assert pole == pytest.approx(ls, abs=1e-6)
        assert abs(pole - 0.95) < 6 * np.sqrt((1 - 0.95**2) / prep.n_est)
        std = theta_std(np.asarray(fit.jtj), float(fit.s2), used)[used]
        assert np.all(np.abs(np.asarray(fit.theta)[used]) < 6 * std)
        ends.append((pole, np.asarray(fit.theta)[used]))
    assert ends[0][0] == pytest.approx(ends[1][0], abs=1e-6)
    np.testing.assert_allclose(ends[0][1], ends[1][1], atol=1e-4 * np.max(std))


def test_a_stopped_joint_fit_resumes_where_it_would_have_gone():
    """A joint fit stopped at its budget and resumed as the queue resumes it (the
    filter moved by the shift so far: `schedule.NoiseSpec.moved`, theta and the
    damping as they were) ends where the uninterrupted fit ends, to rounding."""
    plant, dt, est, val = coloured_case(jr.key(22), n=1000, pole=0.9, std=0.05)
    prep = prepare(plant, dt, est, val, nominal_uncertainty=0.2)
    row = next(r for n, r in prep.rows if n == "parameter_mismatch")
    spec = schedule.NoiseSpec(
        *noise_filter("ar1_pole", 0.4), 1.0, *noise_direction("ar1_pole")
    )

    def case_of(s):
        return eqx.tree_at(
            lambda c: (c.noise_fir, c.noise_ar, c.noise_dfir, c.noise_dar),
            prep.arrays,
            (s.fir, s.ar, s.dfir, s.dar),
        )

    whole = fit_row(row, case_of(spec), 12)
    first = fit_row(row, case_of(spec), 5)
    assert int(first.steps) == 5 and float(first.noise_shift) != 0.0
    moved = spec.moved(float(first.noise_shift))
    rest = fit_row(
        eqx.tree_at(lambda r: r.theta0, row, first.theta),
        case_of(moved),
        12 - 5 + 1,
        first.lam,
        resume=True,
    )
    assert int(rest.steps) == int(whole.steps) - 5 + 1
    np.testing.assert_allclose(rest.theta, whole.theta, rtol=1e-7, atol=1e-9)
    np.testing.assert_allclose(
        moved.shift + float(rest.noise_shift), float(whole.noise_shift), rtol=1e-7
    )
    np.testing.assert_allclose(rest.sse_est, whole.sse_est, rtol=1e-9)
