"""`extra_pole`: $G' = G\\,(1-p)/(1 - p q^{-1})$, an unmodelled lag of unit static gain."""

from jaxtyping import Array, Float

from ._base import AbstractEffect, StartContext


def lag_step(
    z_prev: Float[Array, ""], u: Float[Array, ""], pole: Float[Array, ""]
) -> Float[Array, ""]:
    """$z_k = p z_{k-1} + (1 - p) u_k$ from rest; $p = 0$ gives $z_k = u_k$."""
    return pole * z_prev + (1 - pole) * u


class ExtraPoleEffect(AbstractEffect):
    """One extra real pole $0 \\le p < 1$ (neutral 0)."""

    name = "extra_pole"
    slots = ("pole",)

    def starts(self, ctx: StartContext) -> list[dict[str, float]]:
        return [{"pole": 0.3}, {"pole": 0.85}]
