"""`extra_pole`: $G' = G\\,(1-p)/(1 - p q^{-1})$, an unmodelled lag of unit static gain."""

from ._base import AbstractEffect, StartContext


class ExtraPoleEffect(AbstractEffect):
    """One extra real pole $0 \\le p < 1$ (neutral 0)."""

    name = "extra_pole"
    slots = ("pole",)
    neutral = {"pole": 0.0}
    unit_interval = ("pole",)

    def scales(self, ctx: StartContext) -> dict[str, float]:
        return {"pole": 1.0}

    def starts(self, ctx: StartContext) -> list[dict[str, float]]:
        return [{"pole": 0.3}, {"pole": 0.85}]
