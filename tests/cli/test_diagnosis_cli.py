"""`hamjax diagnose` / `hamjax blind`: contract output, one-line errors, exit 2."""

import json

import jax.random as jr
import numpy as np
import pytest

from hamjax.cli.main import main
from hamjax.diagnosis.attribute import DETERMINISTIC_NAMES, NOISE_NAMES
from hamjax.io import model_to_dict, write_csv, write_json
from hamjax.papers.gap.blind import format_score, make_case, score
from hamjax.papers.gap.demo_cases import tiny_case


def _write_case(folder, effect="saturation", key=0, n=300):
    plant, dt, est, val = tiny_case(jr.key(key), effect, n=n, noise=1e-3)
    folder.mkdir(parents=True)
    write_json(folder / "model.json", model_to_dict(plant, dt))
    write_csv(folder / "estimation.csv", est)
    write_csv(folder / "validation.csv", val)
    return folder


def _run(argv, capsys):
    code = main([str(a) for a in argv])
    return code, capsys.readouterr()


BAD = {
    "malformed": lambda f: (f / "estimation.csv").write_text(
        "t,v,y\n0,1,x\n0.05,2,3\n"
    ),
    "nan": lambda f: (f / "validation.csv").write_text(
        (f / "validation.csv").read_text().replace("\n0.05", "\nnan", 1)
    ),
    "nonuniform": lambda f: (f / "estimation.csv").write_text(
        "t,v,y\n"
        + "\n".join(f"{t},{np.sin(t)},{t}" for t in np.r_[0:60, 70:130] * 0.05)
    ),
    "dt": lambda f: (f / "validation.csv").write_text(
        "t,v,y\n" + "\n".join(f"{k * 0.1},{np.sin(k)},{k}" for k in range(100))
    ),
    "constant": lambda f: (f / "estimation.csv").write_text(
        "t,v,y\n" + "\n".join(f"{k * 0.05},1.0,{k}" for k in range(100))
    ),
    "dead_sensor": lambda f: (f / "validation.csv").write_text(
        "t,v,y\n" + "\n".join(f"{k * 0.05},{np.sin(k)},3.5e-44" for k in range(100))
    ),
    "kind": lambda f: (f / "model.json").write_text(
        json.dumps(
            {"nonlinearity": {"kind": "spline"}, "linear": {"kind": "discrete_tf"}}
        )
    ),
}


@pytest.mark.parametrize("problem", sorted(BAD))
def test_bad_input_one_line_exit_2(problem, tmp_path, capsys):
    case = _write_case(tmp_path / "case")
    BAD[problem](case)
    code, io = _run(["diagnose", case, "--out", tmp_path / "out"], capsys)
    assert code == 2
    lines = [ln for ln in io.err.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("hamjax: error:"), io.err
    assert "Traceback" not in io.err
    assert ".csv" in lines[0] or "model.json" in lines[0]


@pytest.mark.slow
def test_diagnose_contract_and_multi_case_with_a_bad_case(tmp_path, capsys):
    good = _write_case(tmp_path / "good", "saturation", key=1)
    other = _write_case(tmp_path / "other", "dead_zone", key=4)
    bad = _write_case(tmp_path / "bad", "none", key=2)
    BAD["constant"](bad)
    code, io = _run(["diagnose", good, bad, other, "--out", tmp_path / "out"], capsys)
    assert code == 2  # a case failed; the other one still ran
    assert "bad" in io.err and "constant" in io.err
    r = json.loads((tmp_path / "out" / "good" / "diagnosis.json").read_text())
    assert {
        "effect",
        "gap_before",
        "gap_after",
        "noise_floor",
        "ranking",
        "where",
    } <= set(r)
    assert r["effect"] == "saturation"
    # every candidate (dead_zone included: identity map)
    assert len(r["ranking"]) == len(DETERMINISTIC_NAMES) + len(NOISE_NAMES)
    assert r["gap_after"] < r["gap_before"]
    other_r = json.loads((tmp_path / "out" / "other" / "diagnosis.json").read_text())
    assert other_r["effect"] == "dead_zone"
    assert (tmp_path / "out" / "good" / "report.md").is_file()
    assert (
        not (tmp_path / "out" / "bad").exists()
        or not (tmp_path / "out" / "bad" / "diagnosis.json").exists()
    )


def test_blind_make_keeps_truth_out_of_cases(tmp_path, capsys):
    code, _ = _run(
        ["blind", "make", "--cases", 2, "--seed", 3, "--out", tmp_path / "b"], capsys
    )
    assert code == 0
    truth = json.loads((tmp_path / "b" / "truth.json").read_text())
    assert len(truth["cases"]) == 2
    for name in truth["cases"]:
        files = {p.name for p in (tmp_path / "b" / "cases" / name).iterdir()}
        assert files == {"estimation.csv", "validation.csv", "model.json"}
        assert (
            "effect" not in (tmp_path / "b" / "cases" / name / "model.json").read_text()
        )


def test_blind_realistic_draws_and_score_arithmetic():
    case = make_case(jr.key(9), realism="realistic")
    assert 1000 <= case["truth"]["n_samples"] <= 4000
    assert case["estimation"]["v"].shape == (case["truth"]["n_samples"],)
    truth = {
        "cases": {
            "a": {"effect": "none", "noise_std": 1.0},
            "b": {"effect": "none", "noise_std": 1.0},
            "c": {"effect": "saturation", "noise_std": 1.0},
            "d": {"effect": "backlash", "noise_std": 1.0},
        }
    }
    named = {"a": "none", "b": "drift", "c": "saturation", "d": "dead_zone"}
    s = score(truth, named, {"c": (3.0, 1.5), "d": (5.0, 1.0)})
    assert s["accuracy"] == 0.5
    assert s["false_alarm_none"] == 0.5
    assert np.isclose(s["median_shrink_deterministic"], np.median([0.75, 1.0]))
    assert s["confusion"]["backlash"]["dead_zone"] == 1
    assert s["accuracy_by_excitation"] == {}  # the truth records no excitation
    # by each record's excitation (family B's truth): c right, d wrong
    truth["cases"]["c"]["excitation"] = {"estimation": "prbs", "validation": "prbs"}
    truth["cases"]["d"]["excitation"] = {"estimation": "prbs", "validation": "x"}
    s = score(truth, named)
    assert s["accuracy_by_excitation"] == {
        "estimation": {"prbs": [1, 2]},
        "validation": {"prbs": [1, 1], "x": [0, 1]},
    }
    text = format_score(s)
    assert "accuracy by estimation excitation: prbs 0.500 (1/2)" in text
    assert "accuracy by validation excitation: prbs 1.000 (1/1), x 0.000 (0/1)" in text


@pytest.mark.slow
def test_demo_section_writes_report_and_figures(tmp_path, mplcleanup):
    from hamjax.papers.gap.demo_cases import run_demo

    made = run_demo(jr.key(0), tmp_path)
    for path, _ in made:
        assert (tmp_path / "diagnosis" / path.split("/")[-1]).stat().st_size > 0
    report = (tmp_path / "diagnosis" / "report.md").read_text()
    assert "saturation" in report
    d = json.loads((tmp_path / "diagnosis" / "diagnosis.json").read_text())
    assert d["effect"] == "saturation"


@pytest.mark.slow
def test_studies_run_tiny(tmp_path):
    from hamjax.cli.study import study_main

    argv = ["--realisations", "2", "--chunk", "2", "--modes", "exact", "--quiet"]
    assert study_main("blind-benchmark", [*argv, "--out", str(tmp_path / "bb")]) == 0
    s = json.loads((tmp_path / "bb" / "summary.json").read_text())
    assert (
        s["exact"]["n_cases"] == 2
        and (tmp_path / "bb" / "confusion_exact.png").is_file()
    )
