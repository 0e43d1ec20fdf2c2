"""The `real-data-gap` study on a small copy of the data layout: every adapted case
is diagnosed or reported as skipped; a dead sensor does not stop the study."""

import json

import numpy as np
import pytest

from hamjax.cli.study import study_main


@pytest.mark.slow
def test_study_diagnoses_and_skips_without_stopping(tmp_path):
    from conftest import SHARED

    real = SHARED / "data" / "real"
    if not real.is_dir():
        pytest.skip("../shared/data/real is not beside this clone")
    root = tmp_path / "real"
    (root / "stiction_plant_loops" / "csv").mkdir(parents=True)
    (root / "daisy_ball_beam").symlink_to(real / "daisy_ball_beam")
    (root / "stiction_plant_loops" / "index.csv").write_text("csv_file\n")
    t = np.arange(400) * 10.0
    op = np.sin(t / 300.0) + 0.1 * np.sign(np.sin(t / 70.0))
    loops = (
        ("loop_000", t, op, 0.5 * op),
        ("loop_001", t, op, np.full(400, 3.5e-44)),  # dead sensor: dropped
        ("loop_002", t[:60], op[:60], op[:60]),  # 30-sample halves: refused
    )
    for name, tt, u, pv in loops:
        rows = "\n".join(f"{a},{b},{c}" for a, b, c in zip(tt, u, pv, strict=True))
        (root / "stiction_plant_loops" / "csv" / f"{name}.csv").write_text(
            "t,op,pv\n" + rows
        )
    out = tmp_path / "out"
    code = study_main(
        "real-data-gap", ["--data", str(root), "--out", str(out), "--quiet"]
    )
    assert code == 0
    summary = json.loads((out / "summary.json").read_text())
    # the dead-sensor loop is dropped by the adapter, the short one is refused by
    # the case check and reported; the others are diagnosed
    assert set(summary["cases"]) == {"ball_beam", "stiction_loop_000"}
    assert set(summary["skipped"]) == {"stiction_loop_002"}
    assert "samples" in summary["skipped"]["stiction_loop_002"]
    for row in summary["cases"].values():
        assert row["noise_floor"] <= row["gap_after"] * (1 + 1e-12)
        assert row["gap_after"] <= row["gap_before"] * (1 + 1e-12)
    assert (out / "results" / "ball_beam" / "diagnosis.json").is_file()
    assert "ball_beam" in (out / "table.md").read_text()


def test_a_data_folder_without_any_dataset_is_a_user_error(tmp_path, capsys):
    # a wrong --data (or ../shared absent) used to give an empty table and exit 0
    out = tmp_path / "out"
    code = study_main(
        "real-data-gap", ["--data", str(tmp_path / "nothing"), "--out", str(out)]
    )
    assert code == 2
    err = capsys.readouterr().err.strip()
    assert "nothing: no real dataset found there" in err
    assert len(err.splitlines()) == 1
    assert not (out / "table.md").exists()


def test_a_subset_of_cases_is_selected_by_name():
    from hamjax.papers.gap.studies.real_data_gap import select_cases

    names = ["a", "b", "c"]
    assert select_cases(names, "") == names
    assert select_cases(names, "c, a") == ["a", "c"]
    with pytest.raises(ValueError, match="no such case: d"):
        select_cases(names, "a,d")
