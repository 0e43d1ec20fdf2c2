"""Monte Carlo engine: determinism, no re-tracing, storage/resume, statistics, CLI."""

import json

import equinox as eqx
import jax
import jax.numpy as jnp
import jax.random as jr
import numpy as np
import pytest
import scipy.signal
import scipy.stats

import hamjax as hj
from hamjax.identification.seed001.normalised_gradient_4_1 import (
    normalised_gradient_time_major,
)
from hamjax.montecarlo import (
    MonteCarloConfig,
    loglog_slope,
    run_monte_carlo,
    runner,
    storage,
    summarise,
)
from hamjax.papers.engine.studies.simulation_throughput import make_trial
from hamjax.simulation.time_major import output_summary


def _trial(key):
    x = jr.normal(key, (6,))
    return {"mean": jnp.mean(x), "x": x, "count": jnp.sum(x > 0)}


def _loop_reference(key, trial, R):
    """Independent reference: a Python loop over realisations, no vmap, no chunks."""
    outs = [trial(jr.fold_in(key, r)) for r in range(R)]
    return jax.tree.map(lambda *xs: np.stack([np.asarray(x) for x in xs]), *outs)


@pytest.mark.parametrize("chunk", [1, 4, 11, 32])
def test_results_depend_only_on_seed_and_index(chunk):
    key, R = jr.key(3), 11
    got = run_monte_carlo(key, _trial, MonteCarloConfig(realisations=R, chunk=chunk))
    ref = _loop_reference(key, _trial, R)
    assert got["x"].shape == (R, 6) and got["count"].dtype == ref["count"].dtype
    # Fixed key 3: the same draws in every run. A mean of 6 terms summed in another
    # order differs by at most 6 eps max|x| (absolute: the mean can be near zero).
    atol = 6 * np.finfo(float).eps * np.abs(ref["x"]).max()
    for name in ("mean", "x"):
        np.testing.assert_allclose(got[name], ref[name], rtol=1e-12, atol=atol)
    np.testing.assert_array_equal(got["count"], ref["count"])


def test_chunk_compiled_once_including_partial_chunk_and_second_run():
    trial = eqx.debug.assert_max_traces(_trial, max_traces=1)
    config = MonteCarloConfig(realisations=10, chunk=4)  # chunks 4, 4, 2 (padded)
    first = run_monte_carlo(jr.key(0), trial, config)
    second = run_monte_carlo(jr.key(1), trial, config)
    assert not np.allclose(first["x"], second["x"])


def test_module_trial_parameters_are_traced_not_static():
    class Scale(eqx.Module):
        gain: jax.Array

        def __call__(self, key):
            return self.gain * jr.normal(key, ())

    counted = eqx.debug.assert_max_traces(lambda t, k: t(k), max_traces=1)

    class Wrapped(eqx.Module):
        inner: Scale

        def __call__(self, key):
            return counted(self.inner, key)

    config = MonteCarloConfig(realisations=5, chunk=5)
    a = run_monte_carlo(jr.key(0), Wrapped(Scale(jnp.array(1.0))), config)
    b = run_monte_carlo(jr.key(0), Wrapped(Scale(jnp.array(2.0))), config)
    # Fixed key 0; doubling is exact in binary floating point, so only the order of
    # the multiplications (gain * z) may differ: 1 ulp, within rtol 1e-14.
    np.testing.assert_allclose(b, 2 * a, rtol=1e-14)


def test_batched_trial_equals_vmap_and_simulate():
    trial = make_trial(n_samples=300, width=0.4, unroll=2)
    keys = jax.vmap(lambda r: jr.fold_in(jr.key(5), r))(jnp.arange(4))
    batched = eqx.filter_jit(trial.batched)(keys)
    looped = jax.lax.map(trial, keys)  # one realisation at a time, no vmap
    simulate = jax.jit(lambda v: hj.simulate(trial.plant, v))
    backlash = jax.jit(lambda v: hj.apply_nonlinearity(trial.plant.nonlinearity, v))
    # Reference: hamjax.simulate, and the linear part by scipy's lfilter.
    for r, k in enumerate(keys):
        v = trial._inputs(k)
        w = np.asarray(simulate(v))
        u = np.asarray(backlash(v))
        w_scipy = scipy.signal.lfilter([0.0, 1.0, -2.0], [1.0, -1.5, 0.56], u)
        np.testing.assert_allclose(w, w_scipy, rtol=1e-10, atol=1e-10)
        # Fixed key 5. The mean of 300 samples may lie near zero: allow its
        # summation-order bound 300 eps mean|w| (absolute) besides rtol 1e-11.
        atol = w.size * np.finfo(float).eps * np.abs(w).mean()
        for name, ref in (
            ("mean", w.mean()),
            ("rms", np.sqrt(np.mean(w**2))),
            ("max_abs", np.abs(w).max()),
        ):
            np.testing.assert_allclose(looped[name][r], ref, rtol=1e-11, atol=atol)
            np.testing.assert_allclose(batched[name][r], ref, rtol=1e-11, atol=atol)


def test_static_nonlinearity_summary_matches_simulate(getkey):
    plant = hj.Hammerstein(
        hj.DeadZone.symmetric(0.3), hj.DiscreteTransferFunction([0.5, 0.2], [1.0, -0.7])
    )
    v = jr.normal(getkey(), (200,))
    w = np.asarray(hj.simulate(plant, v))
    got = output_summary(plant, v, unroll=3)
    # Any draw: a sum of 200 squares (positive terms) has relative error <= 200 u
    # = 2.2e-14 in any order, so rtol 1e-12 holds without an absolute part.
    np.testing.assert_allclose(got["rms"], np.sqrt(np.mean(w**2)), rtol=1e-12)


def test_normalised_gradient_time_major_equals_recursive_pl(getkey):
    rpl = pytest.importorskip("hamjax.identification.seed001")
    levels = jnp.array([-6.0, -3.0, 3.0, 6.0])
    _, v = hj.pe_impulse_sequence(levels, order=2, periods=6)
    plant = hj.Hammerstein(
        hj.PiecewiseLinear(k1=1.0, k2=2.0, d1=1.0, d2=-2.0, l1=1.0, l2=-2.0),
        hj.DiscreteTransferFunction([0.0, 1.0, -2.0], [1.0, -1.5, 0.56]),
    )
    w = hj.simulate(plant, v)
    ys = w[None] + 0.1 * jr.normal(getkey(), (3, v.shape[0]))
    theta0 = jnp.zeros(10)
    g = rpl.regressor(v, w, levels=levels, order=2)[:, 2:]  # input part only
    got = normalised_gradient_time_major(ys.T, g, order=2, theta0=theta0, rho=12.0)

    @jax.jit
    def reference(y):
        phi = rpl.regressor(v, y, levels=levels, order=2)
        return rpl.normalised_gradient(phi, y, theta0=theta0, rho=12.0)[0]

    for r in range(3):
        ref = reference(ys[r])
        np.testing.assert_allclose(got[r], ref, rtol=1e-10, atol=1e-12)


# --- output folder, manifest, resume -------------------------------------------------


def test_folder_manifest_and_resume_skips_finished_chunks(tmp_path, monkeypatch):
    key, config = jr.key(7), MonteCarloConfig(realisations=9, chunk=4, name="demo")
    meta = {"seed": 7, "note": "x"}
    full = run_monte_carlo(key, _trial, config, out=tmp_path, metadata=meta)
    manifest = json.loads((tmp_path / "manifest.json").read_text())
    assert manifest["seed"] == 7 and manifest["realisations"] == 9
    assert manifest["chunk"] == 4 and manifest["study"] == "demo"
    assert manifest["config"] == meta and "jax" in manifest["versions"]
    names = sorted(p.name for p in (tmp_path / "chunks").iterdir())
    assert len(names) == 3

    (tmp_path / "chunks" / names[1]).unlink()
    (tmp_path / "chunks" / ".chunk_x.npz.123.tmp").write_bytes(b"partial")
    calls = []
    original = runner._run_chunk

    def counting(*args):
        if not isinstance(args[2], jax.core.Tracer):  # not the shape-only trace
            calls.append(1)
        return original(*args)

    monkeypatch.setattr(runner, "_run_chunk", counting)
    resumed = run_monte_carlo(key, _trial, config, out=tmp_path, metadata=meta)
    assert len(calls) == 1  # only the deleted chunk was recomputed
    assert not list((tmp_path / "chunks").glob(".*.tmp"))
    jax.tree.map(np.testing.assert_array_equal, resumed, full)


@pytest.mark.parametrize(
    "change, field",
    [
        ({"key": jr.key(8)}, "key"),
        (
            {"config": MonteCarloConfig(realisations=10, chunk=4, name="demo")},
            "realisations",
        ),
        ({"config": MonteCarloConfig(realisations=9, chunk=3, name="demo")}, "chunk"),
        ({"metadata": {"seed": 7, "note": "y"}}, "config"),
        ({"trial": lambda k: {"mean": jr.normal(k, ())}}, "outputs"),
    ],
)
def test_mismatched_manifest_is_a_clear_error(tmp_path, change, field):
    base = dict(
        key=jr.key(7),
        trial=_trial,
        config=MonteCarloConfig(realisations=9, chunk=4, name="demo"),
        metadata={"seed": 7, "note": "x"},
    )
    run_monte_carlo(
        base["key"],
        base["trial"],
        base["config"],
        out=tmp_path,
        metadata=base["metadata"],
    )
    args = {**base, **change}
    with pytest.raises(ValueError, match=f"different Monte Carlo run.*{field}"):
        run_monte_carlo(
            args["key"],
            args["trial"],
            args["config"],
            out=tmp_path,
            metadata=args["metadata"],
        )


def test_keyboard_interrupt_keeps_finished_chunks(tmp_path, monkeypatch):
    key, config = jr.key(2), MonteCarloConfig(realisations=10, chunk=2)
    original = storage.write_chunk
    written = []

    def interrupt_third(*args):
        if len(written) == 2:
            raise KeyboardInterrupt
        original(*args)
        written.append(args[1])

    monkeypatch.setattr(storage, "write_chunk", interrupt_third)
    with pytest.raises(KeyboardInterrupt):
        run_monte_carlo(key, _trial, config, out=tmp_path)
    assert len(list((tmp_path / "chunks").glob("chunk_*.npz"))) == 2
    monkeypatch.setattr(storage, "write_chunk", original)
    resumed = run_monte_carlo(key, _trial, config, out=tmp_path)
    ref = run_monte_carlo(key, _trial, config)
    jax.tree.map(np.testing.assert_array_equal, resumed, ref)


def test_overlapping_chunk_files_are_an_error(tmp_path):
    config = MonteCarloConfig(realisations=8, chunk=4)
    run_monte_carlo(jr.key(0), _trial, config, out=tmp_path)
    src = storage.chunk_path(tmp_path, 0, 4)
    (tmp_path / "chunks" / "chunk_0000000002-0000000004.npz").write_bytes(
        src.read_bytes()
    )
    with pytest.raises(ValueError, match="overlap"):
        run_monte_carlo(jr.key(0), _trial, config, out=tmp_path)


def test_quiet_off_terminal_prints_nothing(capfd):
    run_monte_carlo(jr.key(0), _trial, MonteCarloConfig(realisations=3, chunk=2))
    captured = capfd.readouterr()
    assert captured.err == "" and captured.out == ""


def test_bad_inputs_are_named():
    with pytest.raises(ValueError, match="realisations"):
        MonteCarloConfig(realisations=0)
    with pytest.raises(ValueError, match="chunk"):
        MonteCarloConfig(realisations=3, chunk=2.5)
    with pytest.raises(ValueError, match="pytree of arrays"):
        run_monte_carlo(
            jr.key(0),
            lambda k: {"a": jr.normal(k), "b": "text"},
            MonteCarloConfig(realisations=2),
        )
    with pytest.raises(ValueError, match="MonteCarloConfig"):
        run_monte_carlo(jr.key(0), _trial, {"realisations": 2})


# --- statistics ----------------------------------------------------------------------


def test_summarise_matches_closed_forms(getkey):
    R, truth = 500, np.array([0.5, -1.0])
    x = np.asarray(jr.exponential(getkey(), (R, 2))) ** 2 + np.array([0.0, -2.0])
    s = summarise(x, truth)
    z = scipy.stats.norm.ppf(0.975)
    # A sum of R terms in any order is within (R - 1) u sum|x_i| of the exact one
    # (u = eps/2), so XLA's and NumPy's means differ by at most R eps mean|x|. That
    # bound is absolute: the second column's mean (E[x] = 0) can be near zero, where
    # a relative tolerance alone fails for some seeds (1.6e-13 for seed 2016057559).
    # Any real bug (a wrong divisor, a missed term) is O(1/R), 1e10 times larger.
    sum_atol = R * np.finfo(float).eps * np.abs(x).mean(0).max()  # the larger column
    np.testing.assert_allclose(s.mean, x.mean(0), rtol=1e-13, atol=sum_atol)
    np.testing.assert_allclose(s.bias, x.mean(0) - truth, rtol=1e-12, atol=sum_atol)
    # Sums of squares have positive terms: relative error <= R u = 5.6e-14 each way,
    # halved by the square root, so these relative tolerances hold for every draw.
    np.testing.assert_allclose(s.std, x.std(0, ddof=1), rtol=1e-13)
    np.testing.assert_allclose(s.mean_mcse, scipy.stats.sem(x, axis=0), rtol=1e-12)
    # m4 >= var^2 (Jensen) and for squared exponentials (kurtosis ~ 100) m4 - var^2
    # never cancels: the moments' ~1e-13 relative error stays below 1e-10.
    np.testing.assert_allclose(s.rmse, np.sqrt(((x - truth) ** 2).mean(0)), rtol=1e-13)
    m4 = scipy.stats.moment(x, 4, axis=0)
    var = x.var(0, ddof=1)
    np.testing.assert_allclose(
        s.std_mcse, np.sqrt((m4 - var**2) / R) / (2 * np.sqrt(var)), rtol=1e-10
    )
    sq = (x - truth) ** 2
    rmse = np.sqrt(sq.mean(0))
    np.testing.assert_allclose(
        s.rmse_mcse, scipy.stats.sem(sq, axis=0) / (2 * rmse), rtol=1e-10
    )
    np.testing.assert_allclose(s.mean_ci[0], x.mean(0) - z * scipy.stats.sem(x, axis=0))
    np.testing.assert_allclose(s.rmse_ci[1], s.rmse + z * s.rmse_mcse)
    json.dumps(s.to_dict())


def _coverage_bounds(m, p_low, p_high, rate=1e-3):
    """Accept band for a Binomial(m, p) count with p in [p_low, p_high]: both tails
    together fail with probability <= `rate` at the ends of that range."""
    return scipy.stats.binom.ppf(rate / 2, m, p_low), scipy.stats.binom.ppf(
        1 - rate / 2, m, p_high
    )


@pytest.mark.statistical
def test_summary_intervals_cover_at_nominal_rate():
    # M independent experiments of R normal estimates (columns): count how many 95%
    # intervals cover the truth. Wald intervals at R = 400 have coverage within
    # [0.93, 0.96] (normal quantile instead of t; delta method for std and RMSE), so
    # a count outside the Binomial band below is a false failure with prob. <= 1e-3.
    M, R, mu, sigma, theta = 1000, 400, 1.3, 2.0, 1.0
    x = mu + sigma * np.asarray(jr.normal(jr.key(20240611), (R, M)))
    s = summarise(x, jnp.full(M, theta))
    lo, hi = _coverage_bounds(M, 0.93, 0.96)
    rmse_true = np.sqrt((mu - theta) ** 2 + sigma**2)
    for name, value in (
        ("mean", mu),
        ("bias", mu - theta),
        ("std", sigma),
        ("rmse", rmse_true),
    ):
        ci = np.asarray(getattr(s, f"{name}_ci"))
        covered = int(np.sum((ci[0] <= value) & (value <= ci[1])))
        assert lo <= covered <= hi, (name, covered, lo, hi)


def test_loglog_slope_matches_linregress(getkey):
    ns = np.array([50.0, 100, 200, 400, 800, 1600])
    errors = 3.0 * ns**-0.5 * np.exp(0.1 * np.asarray(jr.normal(getkey(), (6,))))
    fit = loglog_slope(ns, errors, level=0.9)
    ref = scipy.stats.linregress(np.log(ns), np.log(errors))
    # For any draw the slope is -1/2 (standard error 0.035: noise 0.1 on six log
    # points) and the intercept log 3 = 1.1 (standard error 0.2): neither comes
    # near zero, so relative tolerances suffice.
    np.testing.assert_allclose(fit.slope, ref.slope, rtol=1e-12)
    np.testing.assert_allclose(fit.intercept, ref.intercept, rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(fit.stderr, ref.stderr, rtol=1e-10)
    half = scipy.stats.t.ppf(0.95, 4) * ref.stderr
    np.testing.assert_allclose(fit.ci, [ref.slope - half, ref.slope + half], rtol=1e-10)
    assert fit.method == "ols-t"


@pytest.mark.statistical
def test_loglog_slope_interval_coverage():
    # Log-errors scatter normally about a line of slope -1/2, so the t interval is
    # exact: coverage 0.95 and the Binomial band fails with probability <= 1e-3.
    M, ns = 400, np.array([100.0, 200, 400, 800, 1600])
    noise = 0.2 * np.asarray(jr.normal(jr.key(99), (M, ns.shape[0])))
    covered = 0
    for row in noise:
        ci = np.asarray(loglog_slope(ns, 2.0 * ns**-0.5 * np.exp(row)).ci)
        covered += int(ci[0] <= -0.5 <= ci[1])
    lo, hi = _coverage_bounds(M, 0.95, 0.95)
    assert lo <= covered <= hi, (covered, lo, hi)


@pytest.mark.statistical
def test_loglog_slope_bootstrap_on_per_realisation_errors():
    # Per-realisation errors e_r(N) = N^-1/2 * z_r (z normal): the RMSE follows N^-1/2.
    # A 99.9% bootstrap interval misses -1/2 with probability about 1e-3.
    ns = np.array([100.0, 200, 400, 800])
    z = np.asarray(jr.normal(jr.key(5), (300, 1)))
    e = z * ns**-0.5 * (1 + 0.1 * np.asarray(jr.normal(jr.key(6), (300, 4))))
    fit = loglog_slope(ns, e, key=jr.key(7), bootstrap=500, level=0.999)
    rmse = np.sqrt((e**2).mean(0))
    # fixed keys 5, 6, 7 (a bootstrap interval that misses with probability 1e-3);
    # the slope is about -1/2, far from zero, so rtol 1e-12 alone is safe
    np.testing.assert_allclose(
        fit.slope, scipy.stats.linregress(np.log(ns), np.log(rmse)).slope, rtol=1e-12
    )
    assert fit.ci[0] <= -0.5 <= fit.ci[1] and fit.method == "bootstrap-percentile"
    with pytest.raises(ValueError, match="key"):
        loglog_slope(ns, e)


def test_loglog_slope_bad_inputs():
    with pytest.raises(ValueError, match="at least 3"):
        loglog_slope([1.0, 2.0], [1.0, 0.5])
    with pytest.raises(ValueError, match="> 0"):
        loglog_slope([1.0, 2.0, 4.0], [1.0, 0.0, 0.5])
    with pytest.raises(ValueError, match="shape"):
        loglog_slope([1.0, 2.0, 4.0], [1.0, 0.5])


# --- registry and CLI ----------------------------------------------------------------


def test_cli_lists_and_runs_a_study(tmp_path, capsys):
    from hamjax.cli.main import main

    assert main(["study", "--list"]) == 0
    listed = capsys.readouterr().out
    assert "simulation-throughput" in listed
    out = tmp_path / "st"
    argv = [
        "study",
        "simulation-throughput",
        "--realisations",
        "6",
        "--chunk",
        "4",
        "--samples",
        "50",
        "--out",
        str(out),
        "--quiet",
    ]
    assert main(argv) == 0
    summary = json.loads((out / "summary.json").read_text())
    assert summary["realisations"] == 6 and (out / "output_rms.png").exists()
    assert main(argv) == 0  # resumes from the finished chunks
    assert (
        json.loads((out / "summary.json").read_text())["output_rms"]
        == summary["output_rms"]
    )
    assert main(["study"]) == 2
    assert "NAME" in capsys.readouterr().err


def test_study_options_are_built_only_when_the_study_command_runs():
    # Finding the studies imports every study module, so another command gets the
    # bare `study` entry; `hamjax study NAME --help` and the top-level help keep
    # the whole parser.
    from hamjax.cli.main import build_parser

    def study_names(argv):
        parser = build_parser(argv)
        (commands,) = [a for a in parser._actions if a.dest == "command"]
        study = commands.choices["study"]
        names = [a for a in study._actions if a.dest == "study"]
        return set(names[0].choices) if names else set()

    assert "simulation-throughput" in study_names(["study", "--list"])
    assert "simulation-throughput" in study_names([])
    assert study_names(["diagnose", "CASE", "--out", "study"]) == set()
