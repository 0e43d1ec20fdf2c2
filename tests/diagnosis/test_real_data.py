"""Adapters of the measured datasets in `../shared/data/real/` (skipped without it)."""

import numpy as np
import pytest

from hamjax.diagnosis.case import read_case
from hamjax.diagnosis.real_data import FROM_REST, real_cases, write_real_cases


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
    assert "hsm150_pos".startswith(FROM_REST)
    # uncentred; fixed data (no key), and the only error is the write/read round trip
    np.testing.assert_allclose(hsm.estimation["y"], est["y"], rtol=1e-12)
    tanks = read_case(tmp_path / "cascaded_tanks")
    assert abs(np.mean(tanks.estimation["y"])) < 1e-9 * np.ptp(tanks.estimation["y"])


def _shared_real():
    from conftest import SHARED

    return SHARED / "data" / "real"
