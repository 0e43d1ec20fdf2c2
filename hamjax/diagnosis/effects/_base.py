"""The shape shared by every candidate effect of the sim-to-real-gap catalogue."""

from typing import ClassVar

import equinox as eqx
import numpy as np


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


class AbstractEffect(eqx.Module):
    """A candidate effect: a parametrised augmentation of the nominal model.

    Deterministic effects free some `slots` of the universal augmented model
    (`hamjax.diagnosis.augmented`); at their `neutral` values the augmented model
    is the nominal model exactly. `starts(ctx)` gives starting values (multi-start
    under `vmap`), each a `{slot: value}` dict in physical units.
    """

    name: ClassVar[str]
    slots: ClassVar[tuple[str, ...]] = ()
    deterministic: ClassVar[bool] = True

    def starts(self, ctx: StartContext) -> list[dict[str, float]]:
        return [{}]


def quantile_pair(ctx: StartContext, lo: float, hi: float) -> tuple[float, float]:
    """Nominal-u quantiles at levels `lo`, `hi` (keys of `ctx.u_quantiles`)."""
    return float(ctx.u_quantiles[lo]), float(ctx.u_quantiles[hi])


def span(ctx: StartContext) -> float:
    """Peak-to-peak input range (never 0)."""
    return max(ctx.v_max - ctx.v_min, np.finfo(float).tiny)
