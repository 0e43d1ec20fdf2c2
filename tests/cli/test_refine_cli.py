"""`hamjax identify METHOD DIR --refine`: closed form kept, refined + standard errors added."""

import json

import numpy as np
import pytest
from scipy import signal

from hamjax.cli.main import main
from hamjax.io import read_csv, write_csv


def _pl(v):  # seed 001 Section V.C map, signed convention
    return np.where(v > 1, (v - 1) + 1, np.where(v < -2, 2 * (v + 2) - 2, 0.0))


@pytest.mark.slow
def test_recursive_pl_refine_beats_biased_closed_form(tmp_path):
    d = tmp_path / "rpl"
    assert (
        main(
            [
                "experiment",
                "recursive-pl",
                "--levels=-6,-3,3,6",
                "--order",
                "2",
                "--periods",
                "100",
                "--dt",
                "1",
                "--out",
                str(d),
            ]
        )
        == 0
    )
    x = read_csv(d / "input.csv", ("t", "v"))
    w = signal.lfilter([0, 1.0, -2.0], [1, -1.5, 0.56], _pl(x["v"]))
    y = w + 0.5 * np.random.default_rng(0).standard_normal(w.shape[0])
    write_csv(d / "data.csv", {"t": x["t"], "v": x["v"], "y": y})
    assert (
        main(["identify", "recursive-pl", str(d), "--estimator", "batch", "--refine"])
        == 0
    )
    r = json.loads((d / "result.json").read_text())
    truth = np.array([-1.5, 0.56])
    assert r["converged"] is True
    assert set(r["refined"]) >= {"a", "b", "points", "k1", "k2", "h1", "h2"}
    err_closed = np.abs(np.array(r["a"]) - truth)
    err_refined = np.abs(np.array(r["refined"]["a"]) - truth)
    se = np.array(r["standard_errors"]["a"])
    # Output-error ML is consistent: within 5 standard errors (P(fail) < 1e-6 per
    # entry if the Fisher-information errors are right) ...
    assert np.all(err_refined < 5 * se)
    # ... while the equation-error closed form is biased by many standard errors.
    assert np.max(err_closed) > 5 * np.max(se)


@pytest.mark.slow
def test_nbbi_refine_recovers_noise_free_points_and_g(tmp_path):
    c, dt = 0.2, 0.05
    n = tmp_path / "nbbi"
    assert (
        main(
            [
                "experiment",
                "nbbi",
                "--levels=-1,-0.5,0,0.5,1",
                "--hold",
                "6",
                "--dt",
                str(dt),
                "--out",
                str(n),
            ]
        )
        == 0
    )
    x = read_csv(n / "input.csv", ("t", "v"))
    u, prev, out = 0.0, x["v"][0], []
    for vk in x["v"]:  # reference play operator, borders v -/+ c
        u = max(u, vk - c) if vk > prev else min(u, vk + c) if vk < prev else u
        out.append(u)
        prev = vk
    sysd = signal.cont2discrete(signal.tf2ss([1.0], [0.25, 1.0, 1.0]), dt, "zoh")
    y = signal.dlsim(signal.dlti(*sysd[:4], dt=dt), np.array(out))[1][:, 0]
    write_csv(n / "data.csv", {"t": x["t"], "v": x["v"], "y": y})
    assert main(["identify", "nbbi", str(n), "--refine", "--num-order", "0"]) == 0
    r = json.loads((n / "result.json").read_text())
    want = np.array([-0.8, -0.7, -0.2, 0.3, 0.8, 0.7, 0.2, -0.3])  # the cycle's U_i
    # Short holds: the plain average (5) carries the transient bias ...
    assert np.max(np.abs(np.array(r["cycle"])[:, 1] - want)) > 1e-3
    # ... which the joint fit removes exactly on noise-free data.
    np.testing.assert_allclose(np.array(r["refined"]["cycle"])[:, 1], want, atol=1e-6)
    np.testing.assert_allclose(
        r["refined"]["transfer_function"]["den"],
        np.array([0.25, 1.0, 1.0]) / 0.25 * r["refined"]["transfer_function"]["den"][0],
        rtol=1e-5,
    )
