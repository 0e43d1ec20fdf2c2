"""Every seed-001 study runs with tiny arguments and writes its summary."""

import json

import pytest

from hamjax.cli.main import main


STUDIES = {
    "recursive-pl-convergence": ["--orders", "1", "--periods", "40"],
    "recursive-pl-noise": ["--periods", "32"],
    "recursive-pl-excitation": ["--orders", "1,2"],
    "recursive-pl-tuning": ["--periods", "20"],
    "recursive-pl-vs-batch": ["--periods", "20"],
}


@pytest.mark.slow
@pytest.mark.parametrize("name", sorted(STUDIES))
def test_study_tiny(name, tmp_path, mplcleanup):
    out = tmp_path / name
    argv = [
        "study",
        name,
        "--realisations",
        "3",
        "--chunk",
        "2",
        "--quiet",
        "--out",
        str(out),
        *STUDIES[name],
    ]
    assert main(argv) == 0
    summary = json.loads((out / "summary.json").read_text())
    assert summary["study"] == name and summary["verdict"]
    assert list(out.glob("*.png"))
