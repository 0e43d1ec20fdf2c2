"""benchmarks/scipy_reference_diagnosis.py: issue 7's scipy baseline diagnosis.

Neutral effect parameters reproduce the nominal simulation exactly, the reference
names the effect on noise-free cases built here with plain NumPy/SciPy, and the
study runs end to end on a tiny `hamjax blind make` set.
"""

import json
import sys

import numpy as np
import pytest
from helpers import benchmark_module, reference_backlash, reference_zoh
from scipy import signal

from hamjax.cli.main import main as hamjax_main


@pytest.fixture(scope="module")
def ref():
    # the process pool pickles its functions by name
    module = benchmark_module("scipy_reference_diagnosis", register=True)
    yield module
    sys.modules.pop("scipy_reference_diagnosis", None)


DT = 0.05
PWL = {"kind": "piecewise_linear", "k1": 1.2, "k2": 0.9, "d1": 0.1, "d2": -0.05}
PWL |= {"l1": 0.05, "l2": -0.02}
DISCRETE = {
    "kind": "discrete_tf",
    "b": [0.0, 0.2, 0.1],
    "a": [1.0, -1.2, 0.5],
    "dt": DT,
}
CONTINUOUS = {"kind": "continuous_tf", "num": [2.0], "den": [1.0, 1.6, 2.0]}
TABLE = {"kind": "tabulated", "v": [-1.0, -0.2, 0.3, 1.0], "u": [-0.8, 0.0, 0.1, 1.1]}
MODELS = {
    "discrete_pwl": {"nonlinearity": PWL, "linear": DISCRETE},
    "continuous_tabulated": {"nonlinearity": TABLE, "linear": CONTINUOUS},
    "continuous_identity": {"nonlinearity": {"kind": "identity"}, "linear": CONTINUOUS},
}


def staircase(seed, n=600, hold=4, amplitude=1.0):
    rng = np.random.default_rng(seed)
    levels = rng.uniform(-amplitude, amplitude, n // hold + 1)
    return np.repeat(levels, hold)[:n]


def pwl(v):
    return np.where(
        v > 0.1,
        1.2 * (v - 0.1) + 0.05,
        np.where(v < -0.05, 0.9 * (v + 0.05) - 0.02, 0.0),
    )


@pytest.mark.parametrize("name", sorted(MODELS))
def test_neutral_effect_parameters_reproduce_the_nominal(ref, name):
    plant = ref.Plant(MODELS[name], DT)
    v = staircase(0) + 0.05 * np.sin(np.arange(600) * 0.3)
    y0 = plant.simulate(plant.theta0, v)
    # the nominal itself, computed independently
    if name == "discrete_pwl":
        expected = signal.lfilter(DISCRETE["b"], DISCRETE["a"], pwl(v))
    elif name == "continuous_tabulated":
        expected = reference_zoh(
            [2.0], [1.0, 1.6, 2.0], np.interp(v, TABLE["v"], TABLE["u"]), DT
        )
    else:
        expected = reference_zoh([2.0], [1.0, 1.6, 2.0], v, DT)
    np.testing.assert_allclose(y0, expected, rtol=0, atol=1e-12)
    assert np.ptp(y0) > 0.1
    moves = {"time_delay": [3.0], "output_cubic": [0.3, 0.2]}
    for effect in (*ref.STRUCTURAL[:-1], "output_cubic", "output_clip"):
        if effect in moves:
            moved = np.asarray(moves[effect])
        else:  # the fit's first start
            moved = np.asarray(ref.effect_setup(effect, v, v, y0, DT)[0][0])
        y = plant.simulate(plant.theta0, v, effect, ref.neutral(effect, moved))
        np.testing.assert_allclose(y, y0, rtol=0, atol=1e-12, err_msg=effect)
        # and a non-neutral value does change the output (the effect is wired in)
        assert (
            np.max(np.abs(plant.simulate(plant.theta0, v, effect, moved) - y0)) > 1e-3
        ), effect
    r = np.random.default_rng(1).standard_normal(200)
    np.testing.assert_array_equal(ref.smoother_error(r, 0.0), r)
    np.testing.assert_array_equal(ref.ar1_error(r, 0.0), r)


def test_memory_operators_match_independent_references(ref):
    v = staircase(2, n=300) + 0.1 * np.sin(np.arange(300) * 0.2)
    expected = reference_backlash(v, lambda x: x - 0.2, lambda x: x + 0.2, v[0])
    np.testing.assert_allclose(ref.play(v, 0.4), expected, rtol=0, atol=1e-15)
    grid = np.linspace(-2, 2, 41)
    bl = ref.tabulated_backlash(v, grid, grid - 0.2, grid + 0.2)
    np.testing.assert_allclose(bl, expected, rtol=0, atol=1e-12)
    static = ref.tabulated_backlash(v, grid, grid**3, grid**3)  # superposed borders
    np.testing.assert_allclose(static, np.interp(v, grid, grid**3), rtol=0, atol=1e-12)
    limited = ref.rate_limit(v, 0.05)
    assert np.max(np.abs(np.diff(limited))) <= 0.05 + 1e-12
    assert limited[0] == v[0]


def test_a_trial_point_the_simulator_cannot_take_is_a_bad_point(ref):
    # a continuous block at NaN parameters makes the matrix exponential raise; the
    # fit treats that point as it treats an unstable one (a large residual) and
    # ends at the start, instead of stopping the whole study (seen on family B)
    plant = ref.Plant(MODELS["continuous_identity"], DT)
    v = staircase(4)
    y = plant.simulate(plant.theta0, v)
    with pytest.raises((np.linalg.LinAlgError, ValueError)):
        plant.simulate(np.full_like(plant.theta0, np.nan), v)

    class Failing:  # the plant, failing away from its start
        lower, upper = plant.lower, plant.upper

        def simulate(self, theta, v, effect="none", p=()):
            if not np.array_equal(theta, plant.theta0):
                raise np.linalg.LinAlgError("Array must not contain infs or NaNs")
            return plant.simulate(theta, v, effect, p)

    theta, _, sse = ref.fit(Failing(), v, y + 0.01, "none", plant.theta0, [[]], [], [])
    np.testing.assert_array_equal(theta, plant.theta0)
    assert sse == pytest.approx(0.01**2 * len(v))


def _simulate_truth(effect, v):
    """Noise-free plant output with the effect applied, written independently."""
    if effect == "saturation":
        u = np.clip(pwl(v), -0.4, 0.5)
        return signal.lfilter(DISCRETE["b"], DISCRETE["a"], u)
    # backlash of width 0.3 in front of an identity map and the continuous plant
    return reference_zoh(
        [2.0],
        [1.0, 1.6, 2.0],
        reference_backlash(v, lambda x: x - 0.15, lambda x: x + 0.15, v[0]),
        DT,
    )


@pytest.mark.parametrize(
    "effect, model",
    [("saturation", "discrete_pwl"), ("backlash", "continuous_identity")],
)
def test_reference_names_the_effect_on_a_noise_free_case(ref, effect, model):
    ve, vv = staircase(10), staircase(11)
    est = {"v": ve, "y": _simulate_truth(effect, ve)}
    val = {"v": vv, "y": _simulate_truth(effect, vv)}
    result = ref.diagnose(est, val, DT, MODELS[model])
    assert result["effect"] == effect, result["ranking"][:3]
    assert result["gap_after"] < 0.1 * result["gap_before"]
    assert {r["effect"] for r in result["ranking"]} >= set(ref.EFFECTS) - {"dead_zone"}


def test_study_runs_end_to_end_and_fails_cleanly(ref, tmp_path, capsys):
    bench = tmp_path / "bench"
    assert (
        hamjax_main(
            ["blind", "make", "--cases", "2", "--seed", "1", "--out", str(bench)]
        )
        == 0
    )
    out = tmp_path / "out"
    argv = ["--cases", str(bench), "--limit", "2", "--skip-hamjax", "--out", str(out)]
    assert ref.main(argv) == 0
    summary = json.loads((out / "scipy_reference.json").read_text())
    assert summary["n_cases"] == 2 and summary["hamjax"] is None
    assert 0.0 <= summary["scipy"]["accuracy"] <= 1.0
    assert summary["scipy"]["s_per_case"] > 0
    assert sum(sum(row.values()) for row in summary["scipy"]["confusion"].values()) == 2
    assert summary["machine"]["cores_available"] >= 1
    for case in ("case_0000", "case_0001"):
        d = json.loads((out / "scipy" / case / "diagnosis.json").read_text())
        assert d["effect"] in ref.EFFECTS
        assert d["gap_after"] <= d["gap_before"] + 1e-12
        assert d["ranking"][0]["effect"] == d["effect"]
    capsys.readouterr()
    assert ref.main(["--cases", str(tmp_path / "missing"), "--skip-hamjax"]) == 2
    err = capsys.readouterr().err
    assert (
        err.startswith("error:")
        and "missing" in err
        and len(err.strip().splitlines()) == 1
    )
