"""benchmarks/compare_revisions.py: two trees' JSON compared number by number."""

from helpers import benchmark_module


def test_numbers_within_tolerance_are_equal_and_timings_are_ignored():
    cmp = benchmark_module("compare_revisions")
    old = {"a": [1.0, 2.0], "b": {"c": 3.0, "seconds_per_case": 1.0}, "n": 4}
    new = {
        "a": [1.0, 2.0 * (1 + 1e-12)],
        "b": {"c": 3.0, "seconds_per_case": 9.0},
        "n": 4,
    }
    assert cmp._differences(old, new, 1e-9) == []


def test_a_changed_number_a_missing_key_and_nan_are_reported():
    cmp = benchmark_module("compare_revisions")
    old = {"a": [1.0, 2.0], "x": 1.0, "nan": float("nan"), "flag": True}
    new = {"a": [1.0, 2.1], "nan": float("nan"), "flag": False}
    diffs = cmp._differences(old, new, 1e-9)
    assert any(d.startswith("/x: only in one") for d in diffs)
    assert any(d.startswith("/a[1]:") for d in diffs)
    assert any(d.startswith("/flag:") for d in diffs)
    assert not any(d.startswith("/nan") for d in diffs)  # NaN equals NaN here
