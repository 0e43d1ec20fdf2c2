"""The file contracts: signal CSVs and model.json (contracts/gap-case.md)."""

import json

import jax.numpy as jnp
import numpy as np
import pytest
from scipy import signal

import hamjax as hj
from hamjax._errors import UserInputError
from hamjax.io import (
    load_model,
    model_to_dict,
    read_csv,
    read_json,
    write_csv,
    write_json,
)


def _write(path, text):
    path.write_text(text)
    return path


def test_csv_round_trip_is_exact(tmp_path):
    rng = np.random.default_rng(0)
    cols = {
        "t": np.arange(50) * 0.1,
        "v": rng.normal(size=50),
        "y": rng.normal(size=50),
    }
    write_csv(tmp_path / "d.csv", cols)
    back = read_csv(tmp_path / "d.csv")
    for k in cols:
        np.testing.assert_array_equal(back[k], cols[k])  # %.17g round-trips float64


def test_csv_extra_columns_are_kept_and_ignored(tmp_path):
    p = _write(tmp_path / "d.csv", "t,v,y,z\n0,1,2,3\n1,1,2,3\n")
    assert set(read_csv(p)) == {"t", "v", "y", "z"}


@pytest.mark.parametrize(
    "text, match",
    [
        ("t,v\n0,1\n1,2\n", "missing column.*y"),
        ("t,v,y\n0,1,nan\n1,2,3\n", "column y has NaN"),
        ("t,v,y\n0,1,inf\n1,2,3\n", "column y has inf"),
        ("t,v,y\n0,1,2\n1,2,3\n3,1,1\n", "not uniformly sampled"),
        ("t,v,y\n0,1,2\n0,2,3\n", "strictly increasing"),
        ("t,v,y\n0,1,x\n1,2,3\n", "line 2: malformed number .x."),
        ("t,v,y\n0,1,2\n", "at least 2 rows"),
        ("", "empty file"),
    ],
)
def test_csv_errors_name_the_file_and_the_problem(tmp_path, text, match):
    p = _write(tmp_path / "bad.csv", text)
    with pytest.raises(UserInputError, match=match) as info:
        read_csv(p)
    assert "bad.csv" in str(info.value)


def test_json_round_trip_and_nan_to_null(tmp_path):
    write_json(tmp_path / "r.json", {"a": np.array([1.0, 2.0]), "b": float("nan")})
    assert read_json(tmp_path / "r.json") == {"a": [1.0, 2.0], "b": None}
    _write(tmp_path / "bad.json", "{not json")
    with pytest.raises(UserInputError, match="bad.json: not valid JSON"):
        read_json(tmp_path / "bad.json")


MODELS = [
    {
        "nonlinearity": {
            "kind": "piecewise_linear",
            "k1": 1.0,
            "k2": 2.0,
            "d1": 1.0,
            "d2": -2.0,
            "l1": 1.0,
            "l2": -2.0,
        },
        "linear": {
            "kind": "discrete_tf",
            "b": [0.0, 1.0, -2.0],
            "a": [1.0, -1.5, 0.56],
            "dt": 1.0,
        },
    },
    {
        "nonlinearity": {
            "kind": "tabulated",
            "v": [-1.0, 0.0, 2.0],
            "u": [-2.0, 0.0, 1.0],
        },
        "linear": {"kind": "continuous_tf", "num": [1.0], "den": [0.25, 1.0, 1.0]},
    },
    {
        "nonlinearity": {
            "kind": "backlash",
            "v": [-2.0, 2.0],
            "ascending": [-2.2, 1.8],
            "descending": [-1.8, 2.2],
        },
        "linear": {"kind": "discrete_tf", "b": [0.0, 0.3], "a": [1.0, -0.7], "dt": 0.1},
    },
    {
        "nonlinearity": {"kind": "identity"},
        "linear": {"kind": "discrete_tf", "b": [0.5], "a": [1.0]},
    },
]


@pytest.mark.parametrize("model", MODELS)
def test_model_json_round_trip(model):
    plant, dt = load_model(model)
    assert model_to_dict(plant, dt) == model


def test_loaded_model_simulates_like_scipy():
    # The contract's piecewise-linear map and B/A, against lfilter on a numpy map.
    plant, _ = load_model(MODELS[0])
    v = np.random.default_rng(1).uniform(-8, 8, 200)
    F = np.where(v > 1, (v - 1) + 1, np.where(v < -2, 2 * (v + 2) - 2, 0.0))
    want = signal.lfilter([0, 1.0, -2.0], [1, -1.5, 0.56], F)
    # fixed rng(1): the same input each run; outputs are O(100) (static gain -16.7)
    np.testing.assert_allclose(
        hj.simulate(plant, jnp.asarray(v)), want, rtol=1e-12, atol=1e-12
    )


@pytest.mark.parametrize(
    "change, match",
    [
        ({"nonlinearity": {"kind": "spline"}}, "unknown kind 'spline'"),
        (
            {"linear": {"kind": "discrete_tf", "b": [1.0], "a": [2.0, 1.0]}},
            "a\\[0\\] must be 1",
        ),
        (
            {"linear": {"kind": "discrete_tf", "b": "x", "a": [1.0]}},
            "'b' must be a list",
        ),
        (
            {
                "linear": {
                    "kind": "continuous_tf",
                    "num": [1.0, 1.0, 1.0],
                    "den": [1.0, 1.0],
                }
            },
            "proper",
        ),
        (
            {
                "nonlinearity": {
                    "kind": "piecewise_linear",
                    "k1": 1.0,
                    "k2": 1.0,
                    "d1": -1.0,
                    "d2": 0.0,
                    "l1": 0.0,
                    "l2": 0.0,
                }
            },
            "d2 <= 0 <= d1",
        ),
        (
            {"nonlinearity": {"kind": "piecewise_linear", "k1": "one"}},
            "'k1' must be a finite",
        ),
        (
            {"nonlinearity": {"kind": "tabulated", "v": [0.0, 0.0], "u": [1.0, 2.0]}},
            "strictly increasing",
        ),
    ],
)
def test_malformed_model_json_is_a_clear_error(tmp_path, change, match):
    model = {**MODELS[0], **change}
    path = tmp_path / "model.json"
    path.write_text(json.dumps(model))
    with pytest.raises(UserInputError, match=match) as info:
        load_model(path)
    assert "model.json" in str(info.value)


def test_a_backlash_with_a_negative_output_gain_round_trips(tmp_path):
    # Seed 000's (kF, G/k) with G(0) < 0 gives OutputScaled(backlash, k < 0): it is
    # written as the unscaled backlash before kG, which simulates the same output.
    import jax.numpy as jnp

    import hamjax as hj
    from hamjax.io import load_model, model_to_dict, write_json
    from hamjax.papers.seed000.plants import seed000_plant

    plant, levels, dt, hold = seed000_plant()
    assert isinstance(plant.nonlinearity, hj.OutputScaled)
    assert float(plant.nonlinearity.gain) < 0
    d = model_to_dict(plant, dt)
    assert d["nonlinearity"]["kind"] == "backlash"
    write_json(tmp_path / "model.json", d)
    back, _ = load_model(tmp_path / "model.json")
    _, v0 = hj.initialisation_step(levels, duration=hold / 4, dt=dt)
    _, v1 = hj.nbbi_staircase(levels, hold=hold / 4, dt=dt)
    v = jnp.concatenate([v0, v1])
    w, w_back = hj.simulate(plant, v, dt=dt), hj.simulate(back, v, dt=dt)
    scale = float(jnp.max(jnp.abs(w)))
    # tables of 121 points reproduce the tabulated borders exactly; the rest is
    # rounding of the ZOH of kG against G followed by k (a few ulps of |w|)
    assert float(jnp.max(jnp.abs(w - w_back))) <= 1e-12 * scale


def test_integrators_are_accepted_only_where_asked():
    from hamjax.io import require_stable
    from hamjax.io.model_json import integrating_only

    dt = 0.1
    axis = hj.DiscreteTransferFunction([0.0, 0.1], np.convolve([1, -0.5], [1, -1]), dt)
    double = hj.ContinuousTransferFunction([1.0], [2.0, 0.0, 0.0])
    unstable = hj.DiscreteTransferFunction([0.0, 0.1], [1.0, -1.01], dt)
    three = hj.DiscreteTransferFunction([0.0, 0.1], np.poly([1.0, 1.0, 1.0]), dt)
    assert integrating_only(axis) and integrating_only(double)
    assert not integrating_only(unstable) and not integrating_only(three)
    plant = hj.Hammerstein(hj.Identity(), axis)
    require_stable(plant, "model.json", integrating=True)
    with pytest.raises(UserInputError, match="model.json: .*unstable"):
        require_stable(plant, "model.json")
    with pytest.raises(UserInputError, match="unstable"):
        require_stable(hj.Hammerstein(hj.Identity(), unstable), "m", integrating=True)


def test_integrators_counted_to_a_tolerance():
    # a pole at 1 to rounding (the default: 1e-9) is an integrator; a fitted
    # pole 1e-7 from 1 is one only at a looser tolerance (1e-6, as the
    # stick-slip profile asks); a continuous block's pole at s = 0 relative to
    # its largest pole
    from hamjax.io.model_json import integrators

    dt = 0.1
    exact = hj.DiscreteTransferFunction([0.0, 0.1], np.poly([1.0, 0.5]), dt)
    near = hj.DiscreteTransferFunction([0.0, 0.1], np.poly([1.0 - 1e-7, 0.5]), dt)
    assert integrators(exact) == 1 and integrators(near) == 0
    assert integrators(near, tolerance=1e-6) == 1
    assert integrators(near, tolerance=1e-8) == 0
    double = hj.ContinuousTransferFunction([1.0], np.poly([0.0, 0.0, -100.0]))
    assert integrators(double) == 2
    slow = hj.ContinuousTransferFunction([1.0], np.poly([-1e-5, -100.0]))
    assert integrators(slow) == 0 and integrators(slow, tolerance=1e-6) == 1
