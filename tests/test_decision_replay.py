"""benchmarks/decision_replay.py: the rule replayed on captured fits gives the
diagnosis's own names (fixed keys, one batched call)."""

import json
import pickle

import jax.random as jr
from helpers import benchmark_module

from hamjax.diagnosis.diagnose import diagnose_many
from hamjax.papers.gap.demo_cases import tiny_case


def test_the_replayed_rule_names_what_the_diagnosis_named(tmp_path, capsys):
    replay = benchmark_module("decision_replay")
    effects = ("saturation", "none")
    items = [tiny_case(jr.key(70 + i), e) for i, e in enumerate(effects)]
    kept = replay.capture(items, [False, False])
    direct = [d.effect for d in diagnose_many(items)]
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
    # a names file written earlier: the changed cases are listed
    before = tmp_path / "before.json"
    names = {"fits.pkl": {"case_0": "drift", "case_1": direct[1]}}
    before.write_text(json.dumps(names))
    replay.main(["score", str(path), "--against", str(before)])
    out = capsys.readouterr().out
    assert f"case_0: drift -> {direct[0]}" in out and "case_1:" not in out
