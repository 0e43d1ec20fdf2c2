r"""The experiment designs of seed 000, each owning its rules (one place for each).

- `FGIDesign`: Table 2's periodic staircase (24) at one frequency: the period
  rounded to a whole number of samples that is a multiple of $2n-2$ (Remark 2a,
  `fgi_period_samples`), the transient periods that let $G$ settle before the
  $M$ averaged ones, and where the averaging starts.
"""

import math

import equinox as eqx
import jax.numpy as jnp

from .._types import Signal, Times
from .staircase import fgi_period_samples, periodic_staircase


class FGIDesign(eqx.Module):
    """One FGI experiment (Table 2, input (24)) at the base frequency `omega`.

    Build it with `FGIDesign.settling(...)` from a settling time; `input()` is the
    staircase, `start(offset)` the first averaged sample when the staircase follows
    `offset` samples (e.g. the initialisation (3)), `identify_kwargs(offset)` the
    matching `identify_fgi` options.
    """

    levels: tuple[float, ...] = eqx.field(static=True)
    dt: float = eqx.field(static=True)
    omega: float = eqx.field(static=True)  # the base frequency used (rounded)
    period_samples: int = eqx.field(static=True)
    transient_periods: int = eqx.field(static=True)
    periods: int = eqx.field(static=True)  # M, the periods averaged

    @classmethod
    def settling(
        cls, levels, *, omega: float, dt: float, periods: int, settle: float
    ) -> "FGIDesign":
        """The design whose transient lasts at least `settle` seconds (whole
        periods): Table 2 averages only periods in steady state."""
        period_samples, used = fgi_period_samples(float(omega), dt, len(levels))
        transient = math.ceil(settle / (period_samples * dt))
        return cls(
            tuple(float(x) for x in levels),
            float(dt),
            used,
            period_samples,
            transient,
            int(periods),
        )

    @property
    def total_periods(self) -> int:
        return self.transient_periods + self.periods

    def input(self) -> tuple[Times, Signal]:
        """$(t, v)$ of (24): the transient and the averaged periods."""
        return periodic_staircase(
            jnp.asarray(self.levels),
            period_samples=self.period_samples,
            periods=self.total_periods,
            dt=self.dt,
        )

    def start(self, offset: int = 0) -> int:
        """Index of the first averaged sample, the staircase following `offset`."""
        return int(offset) + self.transient_periods * self.period_samples

    def identify_kwargs(self, offset: int = 0) -> dict:
        """`period_samples`, `periods`, `dt`, `start` of `identify_fgi`."""
        return dict(
            period_samples=self.period_samples,
            periods=self.periods,
            dt=self.dt,
            start=self.start(offset),
        )
