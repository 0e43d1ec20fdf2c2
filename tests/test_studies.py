"""Every script in studies/ runs with tiny arguments (the NumPyro `test_examples` idea).

Seed 001's studies are exercised in `test_recursive_pl_studies.py`; the diagnosis
and refinement studies in their own test files. This file runs the remaining
registered studies through their `studies/<name>.py` scripts, so the scripts
themselves are tested, and checks that every study script names a registered study.
"""

import importlib.util
import json
from pathlib import Path

import pytest

from hamjax.montecarlo.registry import discover_studies


STUDIES_DIR = Path(__file__).resolve().parents[1] / "studies"

TINY = {
    "nbbi_rate": (["--ns", "3,6,12"], "nbbi_rate.json"),
    "fgi_rate": (["--ms", "1,2,4"], "fgi_rate.json"),
    "fgi_pipeline": (["--noises", "0.1,0.3,1"], "fgi_pipeline.json"),
    "nbbi_shapes": (["--levels", "3", "--hold", "4"], "nbbi_shapes.json"),
}


def _load(script: str):
    spec = importlib.util.spec_from_file_location(script, STUDIES_DIR / f"{script}.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.mark.slow
@pytest.mark.parametrize("script", sorted(TINY))
def test_study_script_runs_tiny(script, tmp_path, mplcleanup):
    extra, summary_name = TINY[script]
    out = tmp_path / script
    argv = ["--realisations", "4", "--chunk", "2", "--quiet", "--out", str(out), *extra]
    assert _load(script).main(argv) == 0
    summary = json.loads((out / summary_name).read_text())
    assert summary  # a non-empty JSON summary ...
    assert list(out.glob("*.png"))  # ... and at least one figure


def test_every_study_script_names_a_registered_study():
    registered = set(discover_studies())
    for path in sorted(STUDIES_DIR.glob("*.py")):
        text = path.read_text()
        if "study_main(" not in text:
            continue
        name = text.split('study_main("', 1)[1].split('"', 1)[0]
        assert name in registered, f"{path.name} runs unregistered study {name!r}"


@pytest.mark.slow
def test_compile_options_study_times_each_configuration(tmp_path):
    # One tiny blind case, each XLA configuration once, each in a fresh process: the
    # compile options change rounding only, so every configuration names the same
    # effect; each compiles the fit program once (a positive compile time).
    import jax.random as jr

    from hamjax.diagnosis.blind import make_cases

    make_cases(jr.key(3), 1, tmp_path / "set")
    case = next((tmp_path / "set" / "cases").iterdir())
    out = tmp_path / "out"
    argv = ["--single", str(case), "--repeats", "1", "--out", str(out)]
    assert _load("diagnosis_compile_options").main(argv) == 0
    summary = json.loads((out / "compile_options.json").read_text())["one_case"]
    assert set(summary) == {"cases", "xla-defaults", "hamjax", "hamjax+opt0"}
    for config in ("xla-defaults", "hamjax", "hamjax+opt0"):
        assert summary[config]["same_effect_as_defaults"] == 1.0
        assert summary[config]["median_s"]["compile"] > 0.0
        assert (
            summary[config]["median_s"]["wall"] > summary[config]["median_s"]["compile"]
        )
