"""The `model.json` schema (`docs/model-json.md`): load into Modules and back."""

import os
from pathlib import Path
from typing import Any

import numpy as np

from .._errors import UserInputError
from ..models import (
    Backlash,
    ContinuousTransferFunction,
    DiscreteTransferFunction,
    Hammerstein,
    Identity,
    PiecewiseLinear,
    Scaled,
    Shifted,
    Tabulated,
)
from ..models.hammerstein import fold_output_scale
from ..models.nonlinearities.piecewise_linear import PARAMETERS as PL_PARAMETERS
from .files import read_json


_NL_KINDS = ("identity", "piecewise_linear", "tabulated", "backlash")
_LIN_KINDS = ("discrete_tf", "continuous_tf")


def _as_float(x: Any) -> float | None:
    """`x` as a finite float, or None if it is not a finite JSON number (a bool, a
    string, NaN/inf, an integer beyond the float range)."""
    if isinstance(x, bool) or not isinstance(x, int | float):
        return None
    try:
        f = float(x)
    except OverflowError:
        return None
    return f if np.isfinite(f) else None


def _number(where: str, obj: dict, key: str) -> float:
    if key not in obj:
        raise UserInputError(f"{where}: missing field {key!r}")
    f = _as_float(obj[key])
    if f is None:
        raise UserInputError(
            f"{where}: field {key!r} must be a finite number; got {_short(obj[key])}"
        )
    return f


def _short(x: Any, limit: int = 60) -> str:
    """`repr(x)` cut to `limit` characters (a message stays one readable line)."""
    text = repr(x) if not isinstance(x, int) or abs(x) < 10**50 else "a huge integer"
    return text if len(text) <= limit else text[: limit - 3] + "..."


def _numbers(where: str, obj: dict, key: str, *, min_len: int = 1) -> np.ndarray:
    if key not in obj:
        raise UserInputError(f"{where}: missing field {key!r}")
    x = obj[key]
    if not isinstance(x, list) or not all(
        isinstance(e, int | float) and not isinstance(e, bool) for e in x
    ):
        raise UserInputError(
            f"{where}: field {key!r} must be a list of numbers; got {_short(x)}"
        )
    values = [_as_float(e) for e in x]
    if any(f is None for f in values):
        raise UserInputError(f"{where}: field {key!r} has non-finite numbers")
    arr = np.asarray(values, dtype=float)
    if arr.shape[0] < min_len:
        raise UserInputError(f"{where}: field {key!r} needs at least {min_len} numbers")
    return arr


def _kind(where: str, obj: Any, allowed: tuple[str, ...]) -> str:
    if not isinstance(obj, dict):
        raise UserInputError(f"{where}: must be a JSON object")
    kind = obj.get("kind")
    if kind not in allowed:
        raise UserInputError(
            f"{where}: unknown kind {_short(kind)} (expected one of {', '.join(allowed)})"
        )
    return kind


def nonlinearity_from_dict(obj: dict, where: str = "nonlinearity"):
    """Build a nonlinearity Module from its `model.json` dict."""
    kind = _kind(where, obj, _NL_KINDS)
    try:
        if kind == "identity":
            return Identity()
        if kind == "piecewise_linear":
            p = {k: _number(where, obj, k) for k in PL_PARAMETERS}
            return PiecewiseLinear(**p)
        if kind == "tabulated":
            return Tabulated(
                _numbers(where, obj, "v", min_len=2),
                _numbers(where, obj, "u", min_len=2),
            )
        v = _numbers(where, obj, "v", min_len=2)
        return Backlash.from_table(
            v,
            _numbers(where, obj, "ascending", min_len=2),
            _numbers(where, obj, "descending", min_len=2),
        )
    except ValueError as err:
        if isinstance(err, UserInputError):
            raise
        raise UserInputError(f"{where}: {err}") from None


def linear_from_dict(obj: dict, where: str = "linear"):
    """Build a linear block from its `model.json` dict; returns `(block, dt or None)`."""
    kind = _kind(where, obj, _LIN_KINDS)
    try:
        if kind == "discrete_tf":
            dt = _number(where, obj, "dt") if "dt" in obj else None
            return DiscreteTransferFunction(
                _numbers(where, obj, "b"), _numbers(where, obj, "a"), dt
            ), dt
        return ContinuousTransferFunction(
            _numbers(where, obj, "num"), _numbers(where, obj, "den")
        ), None
    except ValueError as err:
        if isinstance(err, UserInputError):
            raise
        raise UserInputError(f"{where}: {err}") from None


def load_model(source: str | os.PathLike | dict) -> tuple[Hammerstein, float | None]:
    """Read a nominal model (a `model.json` path or its parsed dict).

    **Returns:** `(plant, dt)` where `dt` is the discrete block's sampling period
    (None for a continuous block, whose `dt` comes from the data).

    **Raises:** `UserInputError` naming the file and the field at fault.
    """
    if isinstance(source, dict):
        obj, name = source, "model"
    else:
        obj, name = read_json(source), str(Path(source))
    for key in ("nonlinearity", "linear"):
        if key not in obj:
            raise UserInputError(f"{name}: missing {key!r}")
    nl = nonlinearity_from_dict(obj["nonlinearity"], f"{name}: nonlinearity")
    lin, dt = linear_from_dict(obj["linear"], f"{name}: linear")
    return Hammerstein(nl, lin), dt


MAX_INTEGRATORS = 2  # a position axis driven by a force is a double integrator


INTEGRATOR_ROUNDING = 1e-9  # a pole this close to z = 1 (or s = 0) is one, to rounding


def _integrator_poles(
    linear, tolerance: float = INTEGRATOR_ROUNDING
) -> tuple[np.ndarray, np.ndarray]:
    """`(at, inside)` over the poles of `linear`: at an integrator (z = 1 for a
    discrete block, s = 0 for a continuous one, within `tolerance`: for a
    continuous one times the largest pole's modulus where that exceeds 1),
    strictly stable."""
    poles = np.asarray(linear.poles(), complex)
    if isinstance(linear, ContinuousTransferFunction):
        scale = max(float(np.max(np.abs(poles))) if poles.size else 1.0, 1.0)
        return np.abs(poles) <= tolerance * scale, poles.real < 0
    return np.abs(poles - 1.0) <= tolerance, np.abs(poles) < 1.0


def integrators(linear, *, tolerance: float = INTEGRATOR_ROUNDING) -> int:
    """How many poles of `linear` are integrators (`_integrator_poles`): to
    rounding by default; a fit's pole near 1 is judged at a looser `tolerance`
    (`diagnosis.layout.INTEGRATOR_TOLERANCE`)."""
    return int(np.sum(_integrator_poles(linear, tolerance)[0]))


def integrating_only(linear) -> bool:
    """Whether every pole of `linear` is stable except at most `MAX_INTEGRATORS`
    integrators (z = 1 for a discrete block, s = 0 for a continuous one, to
    rounding): a level loop or a position axis, which simulates from rest on a
    finite record though it is not asymptotically stable."""
    at, inside = _integrator_poles(linear)
    return bool(np.all(at | inside) and np.sum(at) <= MAX_INTEGRATORS)


def require_stable(
    plant: Hammerstein, name: str | os.PathLike, *, integrating: bool = False
) -> None:
    """Refuse a plant whose linear block is unstable, before anything simulates it:
    the check `hamjax.simulation.simulate` makes (`simulation.check_stable`), as a
    `UserInputError` naming the file `name`. `integrating=True` also accepts
    integrators (`integrating_only`), for callers that simulate them (the
    diagnosis)."""
    from ..simulation import check_stable

    if integrating and integrating_only(plant.linear):
        return
    try:
        check_stable(plant.linear, "the plant's linear block")
    except ValueError as err:
        raise UserInputError(f"{name}: {err}") from None


def _static_to_dict(nl) -> dict:
    if isinstance(nl, Identity):
        return {"kind": "identity"}
    if isinstance(nl, PiecewiseLinear):
        return {
            "kind": "piecewise_linear",
            **{k: float(getattr(nl, k)) for k in PL_PARAMETERS},
        }
    if isinstance(nl, Tabulated):
        return {
            "kind": "tabulated",
            "v": np.asarray(nl.v).tolist(),
            "u": np.asarray(nl.u).tolist(),
        }
    raise ValueError(f"{type(nl).__name__} has no model.json form")


def model_to_dict(plant: Hammerstein, dt: float | None = None, *, grid=None) -> dict:
    """The `model.json` dict of `plant`. A backlash whose borders are not tables is
    tabulated on `grid` (required then); scaled/shifted maps are tabulated likewise.

    A backlash with its output scaled by $k$ (`OutputScaled`, seed 000's $kF$ when
    $G(0) < 0$) has no form of its own in the contract: it is written as the
    unscaled backlash before $kG$, the same plant from input to output.
    """
    plant = fold_output_scale(plant)
    nl = plant.nonlinearity
    if isinstance(nl, Backlash):
        asc, desc = nl.ascending, nl.descending
        if (
            isinstance(asc, Tabulated)
            and isinstance(desc, Tabulated)
            and np.array_equal(asc.v, desc.v)
        ):
            grid_, a_vals, d_vals = (
                np.asarray(asc.v),
                np.asarray(asc.u),
                np.asarray(desc.u),
            )
        elif grid is None:
            raise ValueError("a backlash with non-tabulated borders needs `grid`")
        else:
            grid_ = np.asarray(grid, float)
            a_vals, d_vals = np.asarray(asc(grid_)), np.asarray(desc(grid_))
        nl_dict = {
            "kind": "backlash",
            "v": grid_.tolist(),
            "ascending": a_vals.tolist(),
            "descending": d_vals.tolist(),
        }
    elif isinstance(nl, Scaled | Shifted):
        if grid is None:
            raise ValueError(f"a {type(nl).__name__} map needs `grid` to be tabulated")
        grid_ = np.asarray(grid, float)
        nl_dict = {
            "kind": "tabulated",
            "v": grid_.tolist(),
            "u": np.asarray(nl(grid_)).tolist(),
        }
    else:
        nl_dict = _static_to_dict(nl)
    lin = plant.linear
    if isinstance(lin, DiscreteTransferFunction):
        lin_dict = {
            "kind": "discrete_tf",
            "b": np.asarray(lin.b).tolist(),
            "a": np.asarray(lin.a).tolist(),
        }
        dt = lin.dt if dt is None else dt
        if dt is not None:
            lin_dict["dt"] = float(dt)
    elif isinstance(lin, ContinuousTransferFunction):
        lin_dict = {
            "kind": "continuous_tf",
            "num": np.asarray(lin.num).tolist(),
            "den": np.asarray(lin.den).tolist(),
        }
    else:
        raise ValueError(f"{type(lin).__name__} has no model.json form")
    return {"nonlinearity": nl_dict, "linear": lin_dict}
