"""Blind family B (papers/gap/family_b.py): physical-model gap cases, held out."""

import hashlib
import json
from collections import Counter
from pathlib import Path

import numpy as np
import pytest
from helpers import run_hamjax, tree_hash

from hamjax.diagnosis.case import read_case
from hamjax.io import load_model, read_json, write_json
from hamjax.papers.gap import family_b as fb
from hamjax.papers.gap.blind import TRUTH_CLASSES


@pytest.fixture(scope="module")
def bench(tmp_path_factory):
    out = tmp_path_factory.mktemp("family_b")
    truth = fb.make_cases(0, 12, out, classes="twelve")
    return out, truth


@pytest.mark.parametrize("classes", ["fourteen", "twelve"])
def test_classes_are_the_contracts_and_balanced(classes):
    names = fb.CLASS_SETS[classes]
    assert set(names) <= set(TRUTH_CLASSES)
    assert len(names) == len(set(names)) == {"fourteen": 14, "twelve": 12}[classes]
    labels = fb.classes_for(0, 20 * len(names), classes=classes)
    counts = Counter(labels)
    assert set(counts) == set(names)
    assert set(counts.values()) == {20}
    # every block of K is a permutation: every class appears in any aligned K cases
    for b in range(3):
        block = fb.classes_for(5, 3 * len(names), classes=classes)[
            b * len(names) : (b + 1) * len(names)
        ]
        assert sorted(block) == sorted(names)


def test_cases_are_valid_gap_case_folders(bench):
    out, truth = bench
    assert truth["family"] == "B"
    assert read_json(out / "truth.json") == read_json(out / "truth.json")
    names = sorted(p.name for p in (out / "cases").iterdir())
    assert names == sorted(truth["cases"]) and len(names) == 12
    seen = set()
    for name in names:
        folder = out / "cases" / name
        assert sorted(p.name for p in folder.iterdir()) == [
            "estimation.csv",
            "model.json",
            "validation.csv",
        ]  # the truth never goes into a case folder
        case = read_case(folder)
        assert case.model is not None
        tr = truth["cases"][name]
        seen.add(tr["effect"])
        assert tr["effect"] in fb.TWELVE and tr["noise_std"] > 0
        n = case.estimation["t"].shape[0]
        assert fb.N_SAMPLES[0] <= n <= fb.N_SAMPLES[1] == 4000
        assert np.isclose(case.dt, fb.DT[tr["plant"]])
        for rec in (case.estimation, case.validation):
            assert np.all(np.isfinite(rec["y"]))
        if tr["effect"] in fb.STRUCTURAL:  # sized after a re-fit: 0.3-2 x noise
            assert (
                0.8 * fb.RATIO[0] <= tr["effect_rms_over_noise"] <= 1.25 * fb.RATIO[1]
            )
        if tr["effect"] != "parameter_mismatch":  # SNR range (pm may pass 40 dB)
            assert 10.0 - 1e-6 <= tr["snr_db"] <= 40.0 + 1e-6
    assert seen == set(fb.TWELVE)


def test_same_seed_same_files_and_cases_independent_of_count(bench, tmp_path):
    out, _ = bench
    again = fb.make_cases(0, 12, tmp_path / "again", classes="twelve")
    assert tree_hash(out) == tree_hash(tmp_path / "again")
    assert again == read_json(out / "truth.json")
    fewer = fb.make_cases(0, 3, tmp_path / "fewer", classes="twelve")
    for name in fewer["cases"]:
        for f in ("model.json", "estimation.csv", "validation.csv"):
            a = (tmp_path / "fewer" / "cases" / name / f).read_bytes()
            assert a == (out / "cases" / name / f).read_bytes()
    other = fb.make_cases(1, 3, tmp_path / "other", classes="twelve")
    assert other["cases"] != fewer["cases"]


def test_none_cases_consistent_with_nominal_within_noise(tmp_path):
    from hamjax.simulation.discrete import simulate

    checked = 0
    for i, cause in enumerate(fb.classes_for(2, 42)):  # 3 blocks: 3 `none`
        if cause != "none":
            continue
        case = fb.make_case(2, i, cause)
        folder = tmp_path / f"c{i}"
        write_json(folder / "model.json", case["model"])
        plant, _ = load_model(folder / "model.json")
        sigma = case["truth"]["noise_std"]
        for rec in ("estimation", "validation"):
            v, y, t = (case[rec][k] for k in ("v", "y", "t"))
            w = np.asarray(simulate(plant, v, dt=float(t[1] - t[0])))
            r = y - w
            assert 0.9 < np.std(r) / sigma < 1.1
            assert abs(np.mean(r)) < 4 * sigma / np.sqrt(len(r)) + 0.1 * sigma
            # white: lag-1 autocorrelation near 0
            rho = np.corrcoef(r[1:], r[:-1])[0, 1]
            assert abs(rho) < 0.12
        checked += 1
    assert checked == 3


def test_structural_nominal_errors_are_15_to_20_percent(bench):
    _, truth = bench
    for tr in truth["cases"].values():
        errs = np.abs(list(tr["nominal_errors"].values()))
        assert 2 <= len(errs) <= 4
        if tr["effect"] in fb.STRUCTURAL or tr["effect"] == "parameter_mismatch":
            assert np.all((errs >= 0.15 - 1e-12) & (errs <= 0.20 + 1e-12))
        else:  # none / drift / coloured_noise: close to the truth
            assert tr["nominal_gap_over_noise"] <= 0.1 + 1e-9


def test_family_b_imports_nothing_of_the_diagnosis():
    src = Path(fb.__file__).read_text()
    assert "diagnosis" not in "\n".join(
        line
        for line in src.splitlines()
        if line.lstrip().startswith(("import", "from"))
    )
    assert "jax" not in "\n".join(
        line
        for line in src.splitlines()
        if line.lstrip().startswith(("import", "from"))
    )


def _numeric_hash(folder: Path) -> str:
    """sha256 of the file names and their numbers at 10 significant digits: family A's
    `realistic` draws move in the last bit with the environment (thread pools), the
    same tree and environment give identical bytes; 10 digits see any real change."""
    h = hashlib.sha256()
    for p in sorted(Path(folder).rglob("*")):
        if not p.is_file():
            continue
        h.update(str(p.relative_to(folder)).encode())
        if p.suffix == ".csv":
            x = np.loadtxt(p, delimiter=",", skiprows=1)
            h.update(p.read_text().splitlines()[0].encode())
            h.update(" ".join(f"{v:.10g}" for v in x.ravel()).encode())
        else:
            h.update(json.dumps(_rounded(read_json(p)), sort_keys=True).encode())
    return h.hexdigest()


def _rounded(obj):
    if isinstance(obj, float):
        return f"{obj:.10g}"
    if isinstance(obj, dict):
        return {k: _rounded(v) for k, v in obj.items()}
    if isinstance(obj, list):
        return [_rounded(v) for v in obj]
    return obj


# _numeric_hash of what `hamjax blind make --family B --cases 3 --seed 22` wrote with the
# tree of commit 74d7c9d (12 classes, before friction and feedback_nonlinearity): the
# `twelve` sets must not move (a dead zone, a backlash, an output nonlinearity).
FAMILY_B_TWELVE_HASH = (
    "0be9742893a3c7c52319f94d06588dcc77507f8f5da0ac86f8565f660c428bb7"
)


def test_family_b_twelve_reproduces_the_twelve_class_sets(tmp_path):
    r = run_hamjax(
        "blind",
        "make",
        "--family",
        "B",
        "--classes",
        "twelve",
        "--cases",
        "3",
        "--seed",
        "22",
        "--out",
        str(tmp_path / "B12"),
    )
    assert r.returncode == 0, r.stderr
    assert _numeric_hash(tmp_path / "B12") == FAMILY_B_TWELVE_HASH
    assert "classes" not in read_json(tmp_path / "B12" / "truth.json")


# _numeric_hash of what `hamjax blind make --cases 3 --seed 7 --realism R` writes, taken
# with the tree of commit 7171ad5 (before family B): family A must not move. Retaken
# when family A began to draw friction and feedback_nonlinearity (issue 19): case_0001
# of seed 7 became a friction case; case_0000 and case_0002 are byte for byte those of
# commit 74d7c9d (whose tree gave the previous hashes, 02133a28... and 8c84a4b8...).
FAMILY_A_HASH = {
    "exact": "bf06669f106ca5dfaf39b209f6de8593a49b8f85f43705f99c8beb5c621ca813",
    "realistic": "5fa1e1f54707de4756d1a545408a88bf7f0d3383f757e115e24312320e4f3535",
}


@pytest.mark.parametrize("realism", ["exact", "realistic"])
def test_family_a_unchanged(realism, tmp_path):
    # the default family, and --family A named explicitly, make the same cases
    for name, family in (("A", ()), ("A2", ("--family", "A"))):
        out = tmp_path / name
        args = ("--cases", "3", "--seed", "7", "--realism", realism, "--out", str(out))
        r = run_hamjax("blind", "make", *family, *args)
        assert r.returncode == 0, r.stderr
        assert _numeric_hash(out) == FAMILY_A_HASH[realism]


def test_cli_blind_make_family_b(tmp_path):
    r = run_hamjax(
        "blind",
        "make",
        "--family",
        "B",
        "--cases",
        "2",
        "--seed",
        "4",
        "--out",
        str(tmp_path / "B"),
    )
    assert r.returncode == 0, r.stderr
    assert "family-B" in r.stdout
    truth = read_json(tmp_path / "B" / "truth.json")
    assert truth["family"] == "B" and len(truth["cases"]) == 2
    direct = fb.make_cases(4, 2, tmp_path / "direct")
    assert truth == direct
    refused = {  # options of another family: exit 2, nothing written
        "X": (("--family", "B", "--realism", "exact"), "family A only"),
        "Y": (("--classes", "twelve"), "family B only"),
    }
    for out, (opts, message) in refused.items():
        r = run_hamjax(
            "blind", "make", *opts, "--cases", "2", "--out", str(tmp_path / out)
        )
        assert r.returncode == 2 and message in r.stderr
        assert not (tmp_path / out).exists()
