"""Adapters of the measured datasets in `../shared/data/real/` (skipped without it)."""

import numpy as np
import pytest

from hamjax.diagnosis.case import read_case
from hamjax.papers.gap.real_data import from_rest, real_cases, write_real_cases


EXPECTED = (
    "cascaded_tanks",
    "ced_prbs",
    "emps",
    "silverbox",
    "ball_beam",
    "heat_exchanger",
    "robot_arm",
    "f16_level3_to_2",
    "hsm150_pos",
    "hsm150_neg",
    "hsm150_pos_to_neg",
)


@pytest.fixture(scope="module")
def cases():
    from conftest import SHARED

    if not (SHARED / "data" / "real").is_dir():
        pytest.skip("../shared/data/real is not beside this clone")
    return real_cases(SHARED / "data" / "real", stiction_loops=3)


def test_every_usable_dataset_is_adapted(cases):
    for name in EXPECTED:
        est, val, note = cases[name]
        assert note
        for rec in (est, val):
            assert rec["v"].shape == rec["y"].shape == rec["t"].shape
            assert rec["v"].shape[0] >= 200
            assert np.all(np.isfinite(rec["v"])) and np.all(np.isfinite(rec["y"]))
            assert np.ptp(rec["v"]) > 0  # something to identify
        np.testing.assert_allclose(np.diff(est["t"]), np.diff(est["t"])[0])
        assert np.isclose(est["t"][1], val["t"][1])
    assert sum(name.startswith("stiction_") for name in cases) == 3


def test_f16_record_is_the_2_to_15_hz_multisine(cases):
    # The benchmark's excitation spans 2-15 Hz: after block-averaging 400 Hz by 8,
    # the force must keep nearly all of its power there (an off-by-one column or a
    # wrong decimation would not).
    est, _, _ = cases["f16_level3_to_2"]
    dt = est["t"][1]
    f = np.fft.rfftfreq(est["v"].shape[0], dt)
    p = np.abs(np.fft.rfft(est["v"] - est["v"].mean())) ** 2
    band = (f >= 1.9) & (f <= 15.1)
    assert p[band].sum() / p.sum() > 0.95


def test_hsm150_starts_at_rest_and_steps_once(cases, tmp_path):
    est, val, _ = cases["hsm150_pos"]
    for rec in (est, val):
        assert abs(rec["y"][0]) < 1e-3 * np.std(rec["y"])
        assert np.unique(rec["v"]).shape[0] == 2  # operating point, then the step
    write_real_cases(_shared_real(), tmp_path, stiction_loops=0)
    hsm = read_case(tmp_path / "hsm150_pos")
    assert from_rest(est, val)  # decided from the records, not the name
    # uncentred; fixed data (no key), and the only error is the write/read round trip
    np.testing.assert_allclose(hsm.estimation["y"], est["y"], rtol=1e-12)
    tanks = read_case(tmp_path / "cascaded_tanks")
    assert abs(np.mean(tanks.estimation["y"])) < 1e-9 * np.ptp(tanks.estimation["y"])


def _shared_real():
    from conftest import SHARED

    return SHARED / "data" / "real"


def test_ced_estimates_on_the_larger_prbs_and_validates_on_the_smaller(cases):
    # SOURCE.md: record 2 is the +-1.5 PRBS, record 1 the +-1.0 one; the sensor
    # is sign-blind, so every output sample is >= 0
    est, val, _ = cases["ced_prbs"]
    np.testing.assert_allclose(np.max(np.abs(est["v"])), 1.5, rtol=0.02)
    np.testing.assert_allclose(np.max(np.abs(val["v"])), 1.0, rtol=0.02)
    assert est["v"].shape[0] == val["v"].shape[0] == 500
    assert np.min(est["y"]) >= 0 and np.min(val["y"]) >= 0


def test_silverbox_splits_the_multisine_part_75_25(cases):
    est, val, _ = cases["silverbox"]
    n = 127400 - 40650
    assert est["v"].shape[0] == (3 * n) // 4
    assert est["v"].shape[0] + val["v"].shape[0] == n


def test_from_rest_is_read_off_the_records():
    t = np.arange(100.0)
    step = np.where(t < 10, 0.0, 1.0 - np.exp(-(t - 10) / 5))
    at_rest = {"t": t, "v": np.where(t < 10, 0.3, 0.6), "y": step}
    moving = {"t": t, "v": at_rest["v"], "y": step + 0.2}
    assert from_rest(at_rest, at_rest)
    # either record not starting at zero output: centred
    assert not from_rest(at_rest, moving) and not from_rest(moving, at_rest)
