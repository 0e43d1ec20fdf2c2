"""benchmarks/decision_replay.py: the rule replayed on captured fits gives the
diagnosis's own names (fixed keys, one batched call)."""

import json
import pickle

import jax.random as jr
from helpers import benchmark_module

from hamjax.diagnosis.diagnose import diagnose_many
from hamjax.papers.gap.blind import calibration
from hamjax.papers.gap.demo_cases import tiny_case


def test_the_replayed_rule_names_what_the_diagnosis_named(tmp_path, capsys):
    replay = benchmark_module("decision_replay")
    effects = ("saturation", "none")
    items = [tiny_case(jr.key(70 + i), e) for i, e in enumerate(effects)]
    kept = replay.capture(items, [False, False])
    diagnoses = diagnose_many(items)
    direct = [d.effect for d in diagnoses]
    assert [k[2] for k in kept] == direct
    # the pickle as `capture` writes it: truth, prepared rows, fits, name
    store = {
        f"case_{i}": ({"effect": e}, *k)
        for i, (e, k) in enumerate(zip(effects, kept, strict=True))
    }
    path = tmp_path / "fits.pkl"
    path.write_bytes(pickle.dumps(store))
    named, line = replay._score(path, "cascade")
    assert list(named.values()) == direct
    right = sum(n == e for n, e in zip(direct, effects, strict=True))
    assert line.startswith(f"fits.pkl: accuracy {right / 2:.3f} ({right} of 2)")
    # the calibration of the probabilities the diagnosis itself stated
    ece = calibration(
        [d.probabilities[d.effect] for d in diagnoses],
        [n == e for n, e in zip(direct, effects, strict=True)],
    )["ece"]
    assert f", ECE {ece:.3f}" in line
    # a names file written earlier: the changed cases are listed
    before = tmp_path / "before.json"
    names = {"fits.pkl": {"case_0": "drift", "case_1": direct[1]}}
    before.write_text(json.dumps(names))
    replay.main(["score", str(path), "--against", str(before)])
    out = capsys.readouterr().out
    assert f"case_0: drift -> {direct[0]}" in out and "case_1:" not in out


def test_the_fits_report_counts_what_was_made_so(tmp_path):
    """`fits`: on a coloured-noise case (fitted by prediction error), a nesting
    row set above the re-fit, a prediction-error row given an unstable linear
    part and a re-fit made to validate worse than the nominal are each counted
    once more than on the fits as captured (the last two: at most once, the
    case is one)."""
    import numpy as np

    from hamjax.diagnosis.augmented import n_max_of, slot_names
    from hamjax.diagnosis.layout import n_beyond
    from hamjax.diagnosis.schedule import leading_rows
    from hamjax.papers.gap.demo_cases import coloured_case

    replay = benchmark_module("decision_replay")
    ((prep, fit, name),) = replay.capture(
        [coloured_case(jr.key(4), pole=0.95, std=0.05)], [False]
    )
    path = tmp_path / "fits.pkl"

    def report(fit):
        path.write_bytes(
            pickle.dumps({"case_0": ({"effect": "none"}, prep, fit, name)})
        )
        line = replay._fits_report(path)
        above, nesting = (
            int(x) for x in line.split("re-fit ")[1].split(" (")[0].split(" of ")
        )
        unstable = int(line.split("1 + 1e-6 ")[1].split(",")[0].split(";")[0])
        worse = int(line.split("than the nominal ")[1].split(" ")[0])
        return above, nesting, unstable, worse

    white = fit["whitened"]
    above, nesting, _, _ = report(fit)
    refit = leading_rows(prep, fit)[2]
    k = next(
        k
        for k in white["rows"]
        if k != refit
        and n_beyond(prep, refit, k) == 0
        and n_beyond(prep, k, refit) > 0
        and white["sse_est"][k] <= white["sse_est"][refit]
    )
    doctored = {key: np.copy(v) for key, v in white.items()}
    doctored["sse_est"][k] = 2 * white["sse_est"][refit]
    # the nominal's denominator moved to a pole pair at 1.01 in row k
    names = slot_names(n_max_of(prep.arrays.anchor.shape[0]))
    a = np.real(np.poly([1.01 + 0.05j, 1.01 - 0.05j]))
    for i in (1, 2):
        doctored["params"][k][names.index(f"den{i}")] = a[i]
    y_val = np.copy(fit["y_val"])
    y_val[refit] += 10.0 * np.std(np.asarray(prep.arrays.y_val))
    got = report(dict(fit, whitened=doctored, y_val=y_val))
    assert got == (above + 1, nesting, 1, 1)
    assert "1 fitted by prediction error" in replay._fits_report(path)
