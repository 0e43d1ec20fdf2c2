"""The shape shared by every candidate effect of the sim-to-real-gap catalogue."""

from collections.abc import Callable
from typing import ClassVar

import equinox as eqx
import numpy as np
from jaxtyping import Array, Float


# The physical value of a slot by name (`augmented.named`; a dict's `__getitem__`
# does too): what an effect's formula reads its parameters from.
SlotValues = Callable[[str], Float[Array, ""]]


class StartContext(eqx.Module):
    """Case statistics (NumPy, computed once per case) used to place starting values."""

    v_min: float
    v_max: float
    v_absmax: float
    max_step: float  # largest |v[k] - v[k-1]|
    dt: float
    u_quantiles: dict  # quantile level -> value of the nominal u = F(v)
    u_std: float
    w_quantiles: dict  # quantile level -> value of the nominal output w
    dw_half: float  # half range of the nominal output's rate dw/dt (2 %/98 % rule)
    # (S, J, re-fit start, jump slot) of the stick-slip variants that fit the
    # estimation record best on a grid (`layout.stick_slip_profile`), best first;
    # empty when not computed
    stick_slip: tuple = ()
    # the nominal linear block's slowest time constant in samples
    # (`time_delay.dominant_time_constant`; inf when not stable, 0 without a pole)
    t_dom: float = float("inf")
    # the nominal is hamjax's own linear fit (`nominal_fit`, no model.json) with a
    # discrete block: a start may then re-fit its whole linear block (`REFIT_LINEAR`)
    refit_linear: bool = False


class AbstractEffect(eqx.Module):
    r"""A candidate effect: a parametrised augmentation of the nominal model.

    A deterministic effect owns some `slots` of the universal augmented model
    (`hamjax.diagnosis.augmented`), and everything about them:

    - `neutral[slot]`: the physical value at which the effect vanishes (the
      augmented model is then the nominal model exactly);
    - `positive`: slots whose physical value is $|raw|$ (widths, rates);
    - `unit_interval`: slots whose physical value is $0.995\,\sigma(raw)$, in
      $[0, 1)$ (a pole), see `unit_raw` and `UNIT_MAX`;
    - `scales(ctx)`: the step of one unit of the fitted parameter, per slot;
    - `starts(ctx)`: starting values (multi-start under `vmap`), each a
      `{slot: value}` dict in physical units; the key `FLIP_SIGN` (not a slot)
      starts the re-fitted nominal model with its output negated (the sign of
      $G F$ flipped: the gain, the slopes and levels of a piecewise-linear map, or
      a table's output scale), for an effect that hides the sign; the key
      `REFIT_LINEAR` (not a slot; offered only where `ctx.refit_linear`) re-fits
      the whole discrete linear block, numerator included (`db0..`), with the
      static gain and map held at nominal, or with the key `IDENTITY_MAP` too,
      a piecewise-linear map held at the identity.
    """

    name: ClassVar[str]
    slots: ClassVar[tuple[str, ...]] = ()
    neutral: ClassVar[dict[str, float]] = {}
    positive: ClassVar[tuple[str, ...]] = ()
    unit_interval: ClassVar[tuple[str, ...]] = ()
    # slots that extend the effect's simpler form (neutral there): a row freeing
    # one stands for the class only if the likelihood ratio over the class's best
    # simpler row is significant (`layout.best_row_per_class`)
    extension: ClassVar[tuple[str, ...]] = ()
    # slots of another form of the effect than the contract's (a play on the
    # output of G, not on v): a row freeing one stands for the class only if it
    # beats the class's best row of the contract's form on the estimation SSE and
    # on the validation SSE (`layout.best_row_per_class`; not nested, so no
    # likelihood ratio: the two have the same number of parameters)
    alternative: ClassVar[tuple[str, ...]] = ()
    # slots that are a level (an offset) beside the effect, not the effect: the
    # linear twin of a `REFIT_LINEAR` row keeps them free (`layout.LINEAR_TWIN`)
    level: ClassVar[tuple[str, ...]] = ()
    deterministic: ClassVar[bool] = True

    def scales(self, ctx: StartContext) -> dict[str, float]:
        return {}

    def starts(self, ctx: StartContext) -> list[dict[str, float]]:
        return [{}]


FLIP_SIGN = "flip_sign"  # a start key: the nominal re-fit starts with -G F
# a start key: the row re-fits numerator and denominator of the nominal's own fit
REFIT_LINEAR = "refit_linear"
# a start key beside `REFIT_LINEAR`: the nominal's piecewise-linear map held at the
# identity (the stick-slip profile's point scored without the map, whose dead band
# a fitted nominal took from the valve: `layout.stick_slip_profile`)
IDENTITY_MAP = "identity_map"

UNIT_MAX = 0.995  # a unit-interval slot is 0.995 * sigmoid(raw): inside [0, 1), smooth


def unit_raw(value: float) -> float:
    """The raw value of a unit-interval slot at physical `value` (inverse sigmoid)."""
    x = min(max(value / UNIT_MAX, 1e-6), 1 - 1e-6)
    return float(np.log(x / (1 - x)))


def quantile_pair(ctx: StartContext, lo: float, hi: float) -> tuple[float, float]:
    """Nominal-u quantiles at levels `lo`, `hi` (keys of `ctx.u_quantiles`)."""
    return float(ctx.u_quantiles[lo]), float(ctx.u_quantiles[hi])


def span(ctx: StartContext) -> float:
    """Peak-to-peak input range (never 0)."""
    return max(ctx.v_max - ctx.v_min, np.finfo(float).tiny)


def scale_span(ctx: StartContext) -> float:
    """Peak-to-peak input range floored at 1e-12: the unit of the input slots'
    scales (and of the nominal map's offsets)."""
    return max(ctx.v_max - ctx.v_min, 1e-12)


def output_half_range(ctx: StartContext) -> float:
    r"""Half the range of the nominal output, $\max(|w_{0.98}|, |w_{0.02}|)$ (never
    0): the unit of the output-map slots."""
    wq = ctx.w_quantiles
    return max(abs(wq[0.98]), abs(wq[0.02]), 1e-12)
