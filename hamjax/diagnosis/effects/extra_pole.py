r"""`extra_pole`: $G' = G\,(1-p)/(1 - p q^{-1})$, an unmodelled lag of unit static gain.

The lag's pole starts at $p = e^{-1/T}$ for time constants $T$ log-spaced about
the nominal's dominant time constant $T_d$ (`StartContext.t_dom`), from
$T_d / 4$ to $4 T_d$ (`LAG_FACTORS`), plus one sub-sample lag: with the re-fit
of the nominal's denominator free, the product of the two lags is symmetric in
their time constants, so a start on the fast side of $T_d$ stays there (a
local minimum where the extra pole mimics part of the nominal's own lag) and a
lag slower than the nominal's (a thermal sensor behind a fast plant) is reached
only from a start beyond $T_d$. With a factor of 4 between starts every lag
from $T_d / 8$ to $8 T_d$ is within a factor of 2 of one; without a stable
nominal time constant the two fixed starts 0.3 and 0.85 are used.
"""

import numpy as np

from ._base import UNIT_MAX, AbstractEffect, StartContext


FAST_POLE = 0.3  # a lag of under one sample (e^{-1/0.83})
LAG_FACTORS = (0.25, 1.0, 4.0)  # start lags as multiples of the dominant one


def lag_pole(t: float) -> float:
    """The discrete pole $e^{-1/T}$ of a lag of $T$ samples, at most where the
    slot's sigmoid is 0.995 (`UNIT_MAX` x 0.995, a lag of about 100 samples): a
    start deeper in the sigmoid's flat tail would barely move."""
    return float(min(np.exp(-1.0 / max(t, 1e-12)), 0.995 * UNIT_MAX))


class ExtraPoleEffect(AbstractEffect):
    """One extra real pole $0 \\le p < 1$ (neutral 0)."""

    name = "extra_pole"
    slots = ("pole",)
    neutral = {"pole": 0.0}
    unit_interval = ("pole",)

    def scales(self, ctx: StartContext) -> dict[str, float]:
        return {"pole": 1.0}

    def starts(self, ctx: StartContext) -> list[dict[str, float]]:
        t = ctx.t_dom
        if not (np.isfinite(t) and t > 0):
            return [{"pole": FAST_POLE}, {"pole": 0.85}]
        poles = sorted({lag_pole(f * t) for f in LAG_FACTORS} | {FAST_POLE})
        return [{"pole": p} for p in poles]
