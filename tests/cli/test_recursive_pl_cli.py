"""`hamjax experiment/identify/reproduce recursive-pl`: contract files and errors."""

import json

import numpy as np
import pytest
from scipy import signal

from hamjax.cli.main import main
from hamjax.io import read_csv


def _pl(v, k1, k2, d1, d2, l1, l2):
    return np.where(v > d1, k1 * (v - d1) + l1, np.where(v < d2, k2 * (v - d2) + l2, 0))


def _experiment(tmp_path, periods=20, levels="-6,-3,3,6"):
    out = tmp_path / "exp"
    code = main(
        [
            "experiment",
            "recursive-pl",
            f"--levels={levels}",
            "--order",
            "2",
            "--periods",
            str(periods),
            "--dt",
            "0.5",
            "--out",
            str(out),
        ]
    )
    assert code == 0
    return out


def _write_data(folder, nl, b=(0, 1.0, -2.0), a=(1, -1.5, 0.56)):
    x = read_csv(folder / "input.csv", required=("t", "v"))
    y = signal.lfilter(b, a, _pl(x["v"], **nl))
    rows = np.c_[x["t"], x["v"], y]
    np.savetxt(
        folder / "data.csv",
        rows,
        delimiter=",",
        header="t,v,y",
        comments="",
        fmt="%.17g",
    )
    return x


def test_experiment_files(tmp_path):
    out = _experiment(tmp_path)
    design = json.loads((out / "experiment.json").read_text())
    assert design["method"] == "recursive-pl" and design["dt"] == 0.5
    assert design["order"] == 2 and design["levels"] == [-6, -3, 3, 6]
    x = read_csv(out / "input.csv", required=("t", "v"))
    assert x["t"].shape[0] == 14 * 20 and x["t"][0] == 0.0
    assert set(np.unique(x["v"])) == {0.0, -6.0, -3.0, 3.0, 6.0}
    assert np.allclose(np.diff(x["t"]), 0.5)


def test_identify_preload_round_trip(tmp_path):
    out = _experiment(tmp_path)
    nl = dict(k1=1.5, k2=0.5, d1=0.0, d2=0.0, l1=0.7, l2=-1.1)
    _write_data(out, nl)
    assert (
        main(
            [
                "identify",
                "recursive-pl",
                str(out),
                "--estimator",
                "batch",
                "--structure",
                "preload",
            ]
        )
        == 0
    )
    r = json.loads((out / "result.json").read_text())
    s = -np.sqrt(5)  # b = (1, -2) -> (-1, 2)/sqrt5: F scales by -sqrt5
    assert np.allclose(r["a"], [-1.5, 0.56], atol=1e-8)
    assert np.allclose(r["b"], np.array([1, -2]) / s, atol=1e-8)
    v = np.array([-6.0, -3, 3, 6])
    assert np.allclose(np.array(r["points"]), np.c_[v, s * _pl(v, **nl)], atol=1e-7)
    assert np.allclose(
        [r["k1"], r["k2"], r["h1"], r["h2"]],
        s * np.array([1.5, 0.5, 0.7, -1.1]),
        atol=1e-7,
    )
    assert np.allclose([r["d1"], r["d2"]], 0.0) and r["consistent"] is True
    assert np.allclose([r["l1"], r["l2"]], s * np.array([0.7, -1.1]), atol=1e-7)


def test_identify_without_structure_and_inconsistent(tmp_path, capsys):
    out = _experiment(tmp_path)
    _write_data(out, dict(k1=1.5, k2=0.5, d1=0.0, d2=0.0, l1=0.7, l2=-1.1))
    assert main(["identify", "recursive-pl", str(out), "--estimator", "batch"]) == 0
    r = json.loads((out / "result.json").read_text())
    assert all(r[k] is None for k in ("d1", "d2", "l1", "l2"))
    assert (
        main(
            [
                "identify",
                "recursive-pl",
                str(out),
                "--estimator",
                "batch",
                "--structure",
                "dead-zone",
            ]
        )
        == 0
    )
    r = json.loads((out / "result.json").read_text())
    assert r["consistent"] is False and "inconsistent" in capsys.readouterr().err


def test_cli_errors(tmp_path, capsys):
    assert (
        main(
            [
                "experiment",
                "recursive-pl",
                "--levels=-6,-3,-1,6",
                "--order",
                "2",
                "--periods",
                "3",
                "--dt",
                "1",
                "--out",
                str(tmp_path / "x"),
            ]
        )
        == 2
    )
    assert "(3.1)" in capsys.readouterr().err
    out = _experiment(tmp_path)
    x = _write_data(out, dict(k1=1.0, k2=2.0, d1=1.0, d2=-2.0, l1=1.0, l2=-2.0))
    text = (out / "data.csv").read_text().replace("t,v,y", "t,v,w")
    (out / "data.csv").write_text(text)
    assert main(["identify", "recursive-pl", str(out)]) == 2
    assert "missing column" in capsys.readouterr().err
    v = x["v"].copy()
    v[3] = 1.5
    np.savetxt(
        out / "data.csv",
        np.c_[x["t"], v, np.zeros_like(v)],
        delimiter=",",
        header="t,v,y",
        comments="",
        fmt="%.17g",
    )
    assert main(["identify", "recursive-pl", str(out)]) == 2
    assert "differs from the designed input" in capsys.readouterr().err


@pytest.mark.slow
def test_reproduce_small(tmp_path, mplcleanup):
    out = tmp_path / "rep"
    assert (
        main(["reproduce", "recursive-pl", "--out", str(out), "--periods", "700"]) == 0
    )
    r = json.loads((out / "reproduce.json").read_text())
    assert r["max_abs_difference_to_print"] < 0.01
    assert r["samples_to_tolerance"]["theta_0.001"] is not None
    for name in ("fig3a.png", "fig3b.png", "convergence.png"):
        assert (out / name).stat().st_size > 0


def test_a_dead_sensor_is_degenerate_not_successful(tmp_path, capsys):
    # y constant (a stuck sensor): the record holds no response, whatever the fit.
    out = _experiment(tmp_path)
    x = _write_data(out, dict(k1=1.0, k2=2.0, d1=1.0, d2=-2.0, l1=1.0, l2=-2.0))
    rows = np.c_[x["t"], x["v"], np.full(x["t"].shape, 0.37)]
    np.savetxt(out / "data.csv", rows, delimiter=",", header="t,v,y", comments="")
    assert main(["identify", "recursive-pl", str(out)]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "result degenerate" in err[0] and "dead sensor" in err[0]
    r = json.loads((out / "result.json").read_text())  # written, not lost
    assert r["result"] == "degenerate" and "constant" in r["result_message"]


def test_a_projection_radius_below_the_parameter_norm_is_constrained(tmp_path, capsys):
    # ||Theta*|| = 6.5 for this plant: a ball of radius 0.1 holds the estimate on
    # its surface, far from Theta*; with the default radius the same record is fine.
    out = _experiment(tmp_path, periods=200)
    _write_data(out, dict(k1=1.0, k2=2.0, d1=1.0, d2=-2.0, l1=1.0, l2=-2.0))
    assert main(["identify", "recursive-pl", str(out), "--rho", "0.1"]) == 1
    r = json.loads((out / "result.json").read_text())
    assert r["result"] == "constrained"
    assert np.linalg.norm(r["theta"]) == pytest.approx(0.1, rel=1e-9)
    assert "raise --rho" in capsys.readouterr().err
    assert main(["identify", "recursive-pl", str(out)]) == 0
    assert json.loads((out / "result.json").read_text())["result"] == "successful"


def test_identify_writes_where_out_says_and_checks_it_first(tmp_path, capsys):
    out = _experiment(tmp_path)
    _write_data(out, dict(k1=1.0, k2=2.0, d1=1.0, d2=-2.0, l1=1.0, l2=-2.0))
    target = tmp_path / "elsewhere" / "r.json"
    assert main(["identify", "recursive-pl", str(out), "--out", str(target)]) == 0
    assert json.loads(target.read_text())["method"] == "recursive-pl"
    assert not (out / "result.json").exists()
    folder = tmp_path / "a_folder"
    folder.mkdir()
    assert main(["identify", "recursive-pl", str(out), "--out", str(folder)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "a_folder" in err[0] and "Traceback" not in err[0]
