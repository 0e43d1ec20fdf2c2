"""The command line's manners: --version, output safety checked before any work,
unstable models refused, --quiet/--verbose, file permissions, --help examples."""

import json
import os
import stat
import subprocess
import sys
import tomllib
from pathlib import Path

import numpy as np
import pytest

import hamjax
from hamjax.cli.main import main


ROOT = Path(__file__).resolve().parents[2]


def _hamjax(*args, cwd=None):
    """Run `python -m hamjax ARGS` in a child (exit status, stdout, stderr)."""
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    p = subprocess.run(
        [sys.executable, "-m", "hamjax", *map(str, args)],
        capture_output=True,
        text=True,
        env=env,
        cwd=cwd,
    )
    return p.returncode, p.stdout, p.stderr


def _one_error_line(err: str) -> str:
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert len(lines) == 1, err
    assert lines[0].startswith("hamjax: error:") and "Traceback" not in err, err
    return lines[0]


def test_version_flag_and_attribute_agree_with_pyproject():
    with open(ROOT / "pyproject.toml", "rb") as f:
        want = tomllib.load(f)["project"]["version"]
    assert hamjax.__version__ == want
    code, out, err = _hamjax("--version")
    assert code == 0 and out.strip() == f"hamjax {want}", (out, err)


# ------------------------------------------------------------- fixtures ----

MODEL = {
    "nonlinearity": {"kind": "identity"},
    "linear": {"kind": "discrete_tf", "b": [0.0, 0.3], "a": [1.0, -0.7], "dt": 0.05},
}
UNSTABLE = {
    "nonlinearity": {"kind": "identity"},
    "linear": {"kind": "discrete_tf", "b": [0.0, 0.3], "a": [1, -2.1, 1.2], "dt": 0.05},
}


def _record(rng, n: int) -> str:
    """A t,v,y record of the MODEL plant with a withheld saturation (NumPy only)."""
    from scipy import signal

    v = np.repeat(rng.uniform(-2, 2, n // 10), 10)
    w = signal.lfilter([0, 0.3], [1, -0.7], np.clip(v, -1.2, 1.2))
    y = w + 0.01 * rng.standard_normal(n)
    t = np.arange(n) * 0.05
    return "t,v,y\n" + "".join(
        f"{a!r},{b!r},{c!r}\n"
        for a, b, c in zip(t.tolist(), v.tolist(), y.tolist(), strict=True)
    )


def _case(folder: Path, n: int = 300, seed: int = 0, model=MODEL) -> Path:
    folder.mkdir(parents=True)
    rng = np.random.default_rng(seed)
    (folder / "model.json").write_text(json.dumps(model))
    (folder / "estimation.csv").write_text(_record(rng, n))
    (folder / "validation.csv").write_text(_record(rng, n))
    return folder


def _input_csv(path: Path, n: int = 100) -> Path:
    t = np.arange(n) * 0.05
    v = np.sin(t)
    path.write_text(
        "t,v\n"
        + "".join(f"{a!r},{b!r}\n" for a, b in zip(t.tolist(), v.tolist(), strict=True))
    )
    return path


def _main(argv, capsys):
    code = main([str(a) for a in argv])
    io = capsys.readouterr()
    return code, io.out, io.err


def _snapshot(folder: Path) -> dict:
    """Every file under `folder` with its bytes and modification time."""
    return {
        p.relative_to(folder): (p.read_bytes(), p.stat().st_mtime_ns)
        for p in sorted(folder.rglob("*"))
        if p.is_file()
    }


# -------------------------------------------------------- output safety ----


def test_simulate_out_folder_is_refused_before_reading_anything(tmp_path, capsys):
    (tmp_path / "out").mkdir()
    code, out, err = _main(
        [
            "simulate",
            tmp_path / "no-model.json",
            "--input",
            tmp_path / "no.csv",
            "--out",
            tmp_path / "out",
        ],
        capsys,
    )
    line = _one_error_line(err)
    assert code == 2 and "--out is a folder" in line and str(tmp_path / "out") in line
    assert list((tmp_path / "out").iterdir()) == [] and out == ""


def test_simulate_out_under_a_file_or_onto_its_input_is_refused(tmp_path, capsys):
    (tmp_path / "m.json").write_text(json.dumps(MODEL))
    inp = _input_csv(tmp_path / "in.csv")
    before = inp.read_bytes()
    (tmp_path / "afile").write_text("keep")
    for out, match in (
        (tmp_path / "afile" / "d.csv", "is a file, not a folder"),
        (inp, "--out is the --input file"),
    ):
        code, _, err = _main(
            ["simulate", tmp_path / "m.json", "--input", inp, "--out", out], capsys
        )
        assert code == 2 and match in _one_error_line(err)
    assert inp.read_bytes() == before and (tmp_path / "afile").read_text() == "keep"


@pytest.mark.skipif(os.geteuid() == 0, reason="root writes into read-only folders")
def test_unwritable_out_is_refused(tmp_path, capsys):
    (tmp_path / "m.json").write_text(json.dumps(MODEL))
    ro = tmp_path / "ro"
    ro.mkdir()
    ro.chmod(0o555)
    try:
        code, _, err = _main(
            [
                "simulate",
                tmp_path / "m.json",
                "--input",
                _input_csv(tmp_path / "i.csv"),
                "--out",
                ro / "d.csv",
            ],
            capsys,
        )
        assert code == 2 and "not writable" in _one_error_line(err)
        code, _, err = _main(["diagnose", tmp_path, "--out", ro / "res"], capsys)
        assert code == 2 and "not writable" in _one_error_line(err)
    finally:
        ro.chmod(0o755)


def test_diagnose_out_that_is_a_file_is_refused_and_kept(tmp_path, capsys):
    case = _case(tmp_path / "case")
    (tmp_path / "res").write_text("my notes")
    code, out, err = _main(["diagnose", case, "--out", tmp_path / "res"], capsys)
    assert code == 2 and "is an existing file" in _one_error_line(err)
    assert (tmp_path / "res").read_text() == "my notes" and out == ""


def test_diagnose_same_names_order_and_earlier_results(tmp_path, capsys):
    # a/good is longer than b/good and c/other, so the diagnosis finishes it last
    a = _case(tmp_path / "a" / "good", n=600, seed=1)
    b = _case(tmp_path / "b" / "good", n=300, seed=2)
    c = _case(tmp_path / "c" / "other", n=300, seed=3)
    res = tmp_path / "res"
    code, out, err = _main(["diagnose", a, b, c, "--out", res], capsys)
    assert code == 0, err
    assert f"2 cases are named good: {b} is written to {res / 'good-2'}" in err
    assert [ln.split(":")[0] for ln in out.splitlines()] == ["good", "good-2", "other"]
    for name in ("good", "good-2", "other"):
        d = json.loads((res / name / "diagnosis.json").read_text())
        assert d["effect"] == "saturation"
    first = _snapshot(res)

    # a second diagnosis into the same folder: refused, nothing touched
    code, out, err = _main(["diagnose", c, "--out", res], capsys)
    line = _one_error_line(err)
    assert code == 2 and "already holds diagnosis results" in line and "--force" in line
    assert _snapshot(res) == first

    # --force: the earlier cases' outputs go, the user's own file stays
    (res / "notes.txt").write_text("mine")
    code, out, err = _main(["diagnose", c, "--out", res, "--force"], capsys)
    assert code == 0, err
    left = sorted(str(p.relative_to(res)) for p in res.rglob("*"))
    assert left == ["diagnosis.json", "notes.txt", "report.md"]
    assert "# Sim-to-real gap: other" in (res / "report.md").read_text()


# ----------------------------------------------------------------- blind ----


def test_blind_make_into_a_non_empty_folder_needs_force(tmp_path, capsys):
    bench = tmp_path / "bench"
    assert _main(["blind", "make", "--cases", 3, "--out", bench], capsys)[0] == 0
    first = _snapshot(bench)
    code, _, err = _main(["blind", "make", "--cases", 1, "--out", bench], capsys)
    assert code == 2 and "is not empty" in _one_error_line(err)
    assert _snapshot(bench) == first
    (bench / "README.txt").write_text("mine")
    code, _, err = _main(
        ["blind", "make", "--cases", 1, "--seed", 5, "--out", bench, "--force"], capsys
    )
    assert code == 0, err
    assert sorted(p.name for p in (bench / "cases").iterdir()) == ["case_0000"]
    assert (bench / "README.txt").read_text() == "mine"
    assert list(json.loads((bench / "truth.json").read_text())["cases"]) == [
        "case_0000"
    ]


def test_blind_make_refuses_a_family_a_option_for_family_b(tmp_path, capsys):
    bench = tmp_path / "bench"
    args = ["blind", "make", "--cases", 1, "--family", "B", "--out", bench]
    code, _, err = _main([*args, "--estimation-input", "prbs"], capsys)
    assert code == 2 and "applies to family A only" in _one_error_line(err)
    assert not bench.exists()


def _fake_results(bench: Path, res: Path, names) -> None:
    for name in names:
        (res / name).mkdir(parents=True)
        (res / name / "diagnosis.json").write_text(
            json.dumps({"effect": "none", "gap_before": 1.0, "gap_after": 1.0})
        )


def test_blind_score_without_results_is_an_error(tmp_path, capsys):
    bench = tmp_path / "bench"
    assert _main(["blind", "make", "--cases", 3, "--out", bench], capsys)[0] == 0
    (tmp_path / "empty").mkdir()
    code, out, err = _main(["blind", "score", bench, tmp_path / "empty"], capsys)
    line = _one_error_line(err)
    assert code == 2 and "no diagnosis.json for any of the 3 cases" in line
    assert not (tmp_path / "empty" / "score.json").exists()
    code, _, err = _main(["blind", "score", bench, tmp_path / "nowhere"], capsys)
    assert code == 2 and "results folder not found" in _one_error_line(err)

    _fake_results(bench, tmp_path / "some", ["case_0001"])
    code, out, err = _main(["blind", "score", bench, tmp_path / "some"], capsys)
    assert code == 0, err
    assert "2 of 3 cases have no diagnosis.json (case_0000, case_0002)" in err
    s = json.loads((tmp_path / "some" / "score.json").read_text())
    assert s["n_cases"] == 1 and s["missing"] == ["case_0000", "case_0002"]


def test_blind_score_refuses_a_malformed_diagnosis(tmp_path, capsys):
    bench = tmp_path / "bench"
    assert _main(["blind", "make", "--cases", 1, "--out", bench], capsys)[0] == 0
    (tmp_path / "r").mkdir()
    (tmp_path / "r" / "diagnosis.json").write_text('{"effect": 3}')
    code, _, err = _main(["blind", "score", bench, tmp_path / "r"], capsys)
    assert code == 2 and "r/diagnosis.json: not a diagnosis" in _one_error_line(err)


# ------------------------------------------------------- unstable models ----


def test_unstable_model_is_refused_by_diagnose_and_simulate_alike(tmp_path, capsys):
    case = _case(tmp_path / "case", model=UNSTABLE)
    code, out, err = _main(["diagnose", case, "--out", tmp_path / "res"], capsys)
    line = _one_error_line(err)
    assert code == 2 and f"{case / 'model.json'}: " in line and "is unstable" in line
    assert not (tmp_path / "res").exists()  # refused before anything was written
    code, _, err2 = _main(
        [
            "simulate",
            case / "model.json",
            "--input",
            _input_csv(tmp_path / "i.csv"),
            "--out",
            tmp_path / "d.csv",
        ],
        capsys,
    )
    assert code == 2 and _one_error_line(err2) == line  # one check, one message
    assert not (tmp_path / "d.csv").exists()


def test_non_finite_numbers_are_never_a_diagnosis():
    from types import SimpleNamespace

    from hamjax.diagnosis.diagnose import _not_finite

    good = dict(
        gap_before=1.0,
        gap_after=0.5,
        noise_floor=0.1,
        y_nominal=np.zeros(3),
        y_augmented=np.zeros(3),
        residual_before=np.zeros(3),
        residual_after=np.zeros(3),
    )
    assert _not_finite(SimpleNamespace(**good)) is None
    bad = _not_finite(SimpleNamespace(**{**good, "gap_before": float("inf")}))
    assert bad == "gap_before = inf"
    bad = _not_finite(SimpleNamespace(**{**good, "y_nominal": np.array([0, np.nan])}))
    assert bad == "y_nominal has NaN or inf"


@pytest.mark.slow
@pytest.mark.filterwarnings("ignore::RuntimeWarning")  # NumPy overflows on the way
def test_diagnosis_of_an_overflowing_plant_raises(tmp_path):
    from hamjax.diagnosis.case import read_case
    from hamjax.diagnosis.diagnose import DiagnosisNotFinite, diagnose_gap
    from hamjax.io import load_model

    case = read_case(_case(tmp_path / "case", n=12000))
    plant, _ = load_model(UNSTABLE)  # past the reader's check, as a library call
    with pytest.raises(DiagnosisNotFinite, match="not finite") as info:
        diagnose_gap(plant, case.dt, case.estimation, case.validation)
    assert info.value.index == 0


# ---------------------------------------------------------- conventions ----


def test_quiet_and_verbose_before_or_after_the_command(tmp_path):
    (tmp_path / "m.json").write_text(json.dumps(MODEL))
    inp = _input_csv(tmp_path / "i.csv")
    args = ["simulate", tmp_path / "m.json", "--input", inp, "--out"]
    code, out, err = _hamjax(*args, tmp_path / "a.csv")
    assert code == 0 and out.startswith("wrote ")
    for quiet in (["--quiet", *args], ["-q", *args], [*args[:1], "--quiet", *args[1:]]):
        target = tmp_path / f"q{len(list(tmp_path.iterdir()))}.csv"
        code, out, err = _hamjax(*quiet, target)
        assert code == 0 and out == "" and err == "" and target.is_file()
    code, out, err = _hamjax("--verbose", *args, tmp_path / "v.csv")
    assert code == 0 and "hamjax: simulate took" in err
    code, _, err = _hamjax("simulate", "--quiet", "--verbose", tmp_path / "m.json")
    assert code == 2 and "not allowed with argument" in err


def test_outputs_follow_the_umask(tmp_path):
    from hamjax.io import atomic_write_text, write_csv, write_json

    old = os.umask(0o027)
    try:
        write_json(tmp_path / "a.json", {"x": 1})
        atomic_write_text(tmp_path / "b.md", "# b\n")
        write_csv(tmp_path / "c.csv", {"t": np.arange(3.0)})
        os.umask(0o002)
        write_json(tmp_path / "a.json", {"x": 2})  # replacing a file: the umask too
    finally:
        os.umask(old)
    modes = {p.name: stat.S_IMODE(p.stat().st_mode) for p in tmp_path.iterdir()}
    assert modes == {"a.json": 0o664, "b.md": 0o640, "c.csv": 0o640}
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]


def test_cli_outputs_follow_the_umask_in_a_child(tmp_path):
    (tmp_path / "m.json").write_text(json.dumps(MODEL))
    inp = _input_csv(tmp_path / "i.csv")
    code = subprocess.run(
        [
            "sh",
            "-c",
            f'umask 077 && "$0" -m hamjax simulate {tmp_path / "m.json"} '
            f"--input {inp} --out {tmp_path / 'd.csv'}",
            sys.executable,
        ],
        env=dict(os.environ, PYTHONPATH=str(ROOT)),
        capture_output=True,
    ).returncode
    assert code == 0
    assert stat.S_IMODE((tmp_path / "d.csv").stat().st_mode) == 0o600


def _all_parsers(parser, path=""):
    import argparse

    yield path, parser
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for name, sub in action.choices.items():
                yield from _all_parsers(sub, f"{path} {name}".strip())


def test_every_command_help_ends_with_an_example():
    from hamjax.cli.main import build_parser

    parsers = dict(_all_parsers(build_parser(["study"])))
    assert {
        "diagnose",
        "simulate",
        "blind make",
        "blind score",
        "experiment nbbi",
        "identify fgi",
        "reproduce recursive-pl",
        "demo",
        "study",
    } <= set(parsers)
    for path, parser in parsers.items():
        text = parser.format_help()
        assert "example:\n  hamjax " in text, path
        if path and not path.startswith("study "):
            assert f"hamjax {path}" in text.rsplit("example:\n", 1)[1], path
        assert "contracts/" not in text, path


def test_docs_pages_exist_and_help_cites_them():
    for page in ("model-json.md", "experiment-folder.md", "gap-case-folder.md"):
        assert (ROOT / "docs" / page).is_file(), page
    from hamjax.cli.main import build_parser

    parsers = dict(_all_parsers(build_parser(["diagnose"])))
    assert "docs/gap-case-folder.md" in parsers["diagnose"].format_help()
    assert "docs/model-json.md" in parsers["simulate"].format_help()
