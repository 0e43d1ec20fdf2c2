"""Every registered study runs with tiny arguments through `hamjax study NAME` (the
NumPyro `test_examples` idea), and every module of the study packages is a study.

Seed 001's studies are exercised in `test_recursive_pl_studies.py`; the diagnosis
and refinement studies in their own test files. This file runs the remaining
registered studies through the command line, and the compile-options benchmark
through its script in `benchmarks/`.
"""

import json
import pkgutil

import pytest
from helpers import benchmark_module

from hamjax.cli.main import main as hamjax_main
from hamjax.montecarlo.registry import discover_studies
from hamjax.papers import STUDY_PACKAGES


TINY = {
    "nbbi-rate": (["--ns", "3,6,12"], "nbbi_rate.json"),
    "fgi-rate": (["--ms", "1,2,4"], "fgi_rate.json"),
    "fgi-pipeline": (["--noises", "0.1,0.3,1"], "fgi_pipeline.json"),
    "nbbi-shapes": (["--levels", "3", "--hold", "4"], "nbbi_shapes.json"),
}


@pytest.mark.slow
@pytest.mark.parametrize("name", sorted(TINY))
def test_study_runs_tiny(name, tmp_path, mplcleanup):
    extra, summary_name = TINY[name]
    out = tmp_path / name
    argv = ["--realisations", "4", "--chunk", "2", "--quiet", "--out", str(out), *extra]
    assert hamjax_main(["study", name, *argv]) == 0
    summary = json.loads((out / summary_name).read_text())
    assert summary  # a non-empty JSON summary ...
    assert list(out.glob("*.png"))  # ... and at least one figure


def test_every_module_of_the_study_packages_is_a_working_study():
    # A module that fails to import or lacks NAME/DESCRIPTION/run is listed with
    # its error in parentheses; none may be, and each module gives one study.
    import importlib

    studies = discover_studies(STUDY_PACKAGES)
    modules = [
        info.name
        for package in STUDY_PACKAGES
        for info in pkgutil.iter_modules(importlib.import_module(package).__path__)
        if not info.name.startswith("_")
    ]
    assert len(studies) == len(modules)
    broken = {n: s.description for n, s in studies.items() if s.description[:1] == "("}
    assert broken == {}


def test_a_study_name_defined_twice_is_refused(tmp_path, monkeypatch):
    for package in ("pkg_a", "pkg_b"):
        folder = tmp_path / package
        folder.mkdir()
        (folder / "__init__.py").write_text("")
        (folder / "same.py").write_text(
            'NAME = "same"\nDESCRIPTION = "d"\n\n\ndef run(key, **kw):\n    return {}\n'
        )
    monkeypatch.syspath_prepend(str(tmp_path))
    assert list(discover_studies(["pkg_a"])) == ["same"]
    with pytest.raises(ValueError, match="defined twice"):
        discover_studies(["pkg_a", "pkg_b"])


@pytest.mark.slow
def test_compile_options_study_times_each_configuration(tmp_path):
    # One tiny blind case, each XLA configuration once, each in a fresh process: the
    # compile options change rounding only, so every configuration names the same
    # effect; each compiles the fit program once (a positive compile time).
    import jax.random as jr

    from hamjax.papers.gap.blind import make_cases

    make_cases(jr.key(3), 1, tmp_path / "set")
    case = next((tmp_path / "set" / "cases").iterdir())
    out = tmp_path / "out"
    argv = ["--single", str(case), "--repeats", "1", "--out", str(out)]
    assert benchmark_module("diagnosis_compile_options").main(argv) == 0
    summary = json.loads((out / "compile_options.json").read_text())["one_case"]
    assert set(summary) == {"cases", "xla-defaults", "hamjax", "hamjax+opt0"}
    for config in ("xla-defaults", "hamjax", "hamjax+opt0"):
        assert summary[config]["same_effect_as_defaults"] == 1.0
        assert summary[config]["median_s"]["compile"] > 0.0
        assert (
            summary[config]["median_s"]["wall"] > summary[config]["median_s"]["compile"]
        )
