"""The `hamjax` command: `simulate`, and errors without tracebacks."""

import json
import subprocess
import sys

import numpy as np
import pytest
from scipy import signal
from scipy.linalg import expm

from hamjax.cli.main import main
from hamjax.io import read_csv, write_csv


def _zoh_reference(num, den, u, dt):
    A, B, C, D = signal.tf2ss(num, den)
    n = A.shape[0]
    M = np.zeros((n + 1, n + 1))
    M[:n, :n], M[:n, n:] = A * dt, B * dt
    E = expm(M)
    x, y = np.zeros((n, 1)), np.empty(len(u))
    for k, uk in enumerate(u):
        y[k] = (C @ x + D * uk).item()
        x = E[:n, :n] @ x + E[:n, n:] * uk
    return y


def test_simulate_continuous_model_matches_independent_zoh(tmp_path):
    model = {
        "nonlinearity": {"kind": "identity"},
        "linear": {
            "kind": "continuous_tf",
            "num": [1.0, -10.0],
            "den": [1.0, 2.0, 1.0],
        },
    }
    (tmp_path / "model.json").write_text(json.dumps(model))
    v = np.repeat(np.random.default_rng(0).uniform(-1, 1, 20), 10)
    write_csv(tmp_path / "input.csv", {"t": np.arange(200) * 0.05, "v": v})
    rc = main(
        [
            "simulate",
            str(tmp_path / "model.json"),
            "--input",
            str(tmp_path / "input.csv"),
            "--out",
            str(tmp_path / "data.csv"),
        ]
    )
    assert rc == 0
    got = read_csv(tmp_path / "data.csv")
    np.testing.assert_allclose(
        got["y"], _zoh_reference([1, -10], [1, 2, 1], v, 0.05), rtol=1e-10, atol=1e-10
    )


def test_simulate_noise_has_the_requested_std(tmp_path):
    model = {
        "nonlinearity": {"kind": "identity"},
        "linear": {"kind": "discrete_tf", "b": [0.0], "a": [1.0], "dt": 1.0},
    }
    (tmp_path / "m.json").write_text(json.dumps(model))
    n = 4000
    write_csv(tmp_path / "in.csv", {"t": np.arange(n, dtype=float), "v": np.zeros(n)})
    assert (
        main(
            [
                "simulate",
                str(tmp_path / "m.json"),
                "--input",
                str(tmp_path / "in.csv"),
                "--noise-std",
                "0.5",
                "--seed",
                "3",
                "--out",
                str(tmp_path / "d.csv"),
            ]
        )
        == 0
    )
    y = read_csv(tmp_path / "d.csv")["y"]
    # Sample std of n Gaussian draws has relative sd 1/sqrt(2n) = 1.1%; 5 sd: ~6e-7 false fails.
    assert abs(np.std(y) / 0.5 - 1) < 5 / np.sqrt(2 * n)


@pytest.mark.parametrize(
    "model, csv_text, match",
    [
        (
            {"nonlinearity": {"kind": "magic"}, "linear": {}},
            "t,v\n0,1\n1,2\n",
            "unknown kind",
        ),
        (
            {
                "nonlinearity": {"kind": "identity"},
                "linear": {"kind": "discrete_tf", "b": [1.0], "a": [1.0, -1.5]},
            },
            "t,v\n0,1\n1,2\n",
            "unstable",
        ),
        (
            {
                "nonlinearity": {"kind": "identity"},
                "linear": {"kind": "discrete_tf", "b": [1.0], "a": [1.0]},
            },
            "t,v\n0,1\n1,nan\n",
            "column v has NaN",
        ),
        (
            {
                "nonlinearity": {"kind": "identity"},
                "linear": {"kind": "discrete_tf", "b": [1.0], "a": [1.0], "dt": 0.5},
            },
            "t,v\n0,1\n1,2\n",
            "dt",
        ),
    ],
)
def test_user_mistakes_exit_2_with_one_line(tmp_path, model, csv_text, match):
    (tmp_path / "m.json").write_text(json.dumps(model))
    (tmp_path / "in.csv").write_text(csv_text)
    proc = subprocess.run(
        [
            sys.executable,
            "-m",
            "hamjax",
            "simulate",
            str(tmp_path / "m.json"),
            "--input",
            str(tmp_path / "in.csv"),
            "--out",
            str(tmp_path / "out.csv"),
        ],
        capture_output=True,
        text=True,
    )
    assert proc.returncode == 2
    assert "Traceback" not in proc.stderr
    assert proc.stderr.strip().count("\n") == 0
    assert match in proc.stderr
    assert not (tmp_path / "out.csv").exists()
