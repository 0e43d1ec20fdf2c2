"""Backlash border shapes of seed 000 (Figs. 2-4, Remark 1b) for tests and studies.

Each shape is a `Backlash` over the working interval [-1, 1] in normalised
units (G(0) = 1): straight, non-smooth, non-invertible, discontinuous
(relay-like), crossing borders, superposed borders (a static map), and the
Fig. 4b composition used by `hamjax reproduce backlash-frequency`.
"""

import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

from ..._fields import float_field
from ...models import AbstractStaticNonlinearity, Backlash, Tabulated


def cycle_points(
    backlash: Backlash, levels: Float[ArrayLike, " n"]
) -> Float[Array, " m"]:
    """The $2n-2$ backlash outputs $U_i$ of the staircase (4a-b) after step (3)."""
    from ...models import apply_nonlinearity
    from ...signals.staircase import staircase_cycle_levels

    levels = jnp.asarray(levels, dtype=float)
    cycle = staircase_cycle_levels(levels)
    v = jnp.concatenate([levels[-1:], levels[:1], cycle])
    return apply_nonlinearity(backlash, v)[2:]


class Relay(AbstractStaticNonlinearity):
    """Step border: `low` for $v <$ `threshold`, `high` from `threshold` on."""

    threshold: Float[Array, ""] = float_field(kw_only=True)
    low: Float[Array, ""] = float_field(kw_only=True)
    high: Float[Array, ""] = float_field(kw_only=True)

    def __call__(self, v: Float[Array, "*shape"]) -> Float[Array, "*shape"]:
        return jnp.where(v >= self.threshold, self.high, self.low)


class Wavy(AbstractStaticNonlinearity):
    """$s v + A \\sin(\\nu v) + c$: non-invertible when $A\\nu > s$."""

    slope: Float[Array, ""] = float_field(kw_only=True)
    amplitude: Float[Array, ""] = float_field(kw_only=True)
    frequency: Float[Array, ""] = float_field(kw_only=True)
    offset: Float[Array, ""] = float_field(kw_only=True)

    def __call__(self, v: Float[Array, "*shape"]) -> Float[Array, "*shape"]:
        return (
            self.slope * v + self.amplitude * jnp.sin(self.frequency * v) + self.offset
        )


class Cubic(AbstractStaticNonlinearity):
    """$s v + c_3 v^3 + c$, the Fig. 4b static map before a straight play."""

    slope: Float[Array, ""] = float_field(kw_only=True)
    cubic: Float[Array, ""] = float_field(kw_only=True)
    offset: Float[Array, ""] = float_field(kw_only=True)

    def __call__(self, v: Float[Array, "*shape"]) -> Float[Array, "*shape"]:
        return self.slope * v + self.cubic * v**3 + self.offset


def straight(width: float = 0.4) -> Backlash:
    """Straight parallel borders $v \\mp c/2$ (the classical backlash)."""
    return Backlash.from_width(width)


def non_smooth() -> Backlash:
    """Piecewise-linear borders with kinks (Fig. 3)."""
    grid = jnp.array([-2.0, -0.6, -0.2, 0.3, 0.7, 2.0])
    base = jnp.array([-1.6, -0.9, -0.2, 0.1, 0.8, 1.6])
    return Backlash.from_table(grid, base - 0.25, base + 0.25)


def non_invertible() -> Backlash:
    """Non-monotone borders $0.8 v + 0.25 \\sin(5 v) \\mp 0.1$."""
    return Backlash(
        ascending=Wavy(slope=0.8, amplitude=0.25, frequency=5.0, offset=-0.1),
        descending=Wavy(slope=0.8, amplitude=0.25, frequency=5.0, offset=0.1),
    )


def relay(threshold: float = 0.25, low: float = -1.0, high: float = 1.0) -> Backlash:
    """Discontinuous relay-like borders: switch up at $+t$, down at $-t$ (Remark 1b)."""
    return Backlash(
        ascending=Relay(threshold=threshold, low=low, high=high),
        descending=Relay(threshold=-threshold, low=low, high=high),
    )


def crossing() -> Backlash:
    """Borders that cross at $v = 0.5$: $f_a = 1.2 v - 0.1$, $f_d = 0.8 v + 0.1$."""
    return Backlash(
        ascending=Tabulated(jnp.array([-2.0, 2.0]), jnp.array([-2.5, 2.3])),
        descending=Tabulated(jnp.array([-2.0, 2.0]), jnp.array([-1.5, 1.7])),
    )


def superposed() -> Backlash:
    """Superposed borders $f_a = f_d$: the static map $v + 0.4\\sin(3v)$ (Remark 1b)."""
    f = Wavy(slope=1.0, amplitude=0.4, frequency=3.0, offset=0.0)
    return Backlash(ascending=f, descending=f)


def composed(width: float = 0.3) -> Backlash:
    """Fig. 4b: a cubic static map followed by a straight play of total `width`."""
    return Backlash(
        ascending=Cubic(slope=0.5, cubic=0.5, offset=-width / 2),
        descending=Cubic(slope=0.5, cubic=0.5, offset=width / 2),
    )


SHAPES = {
    "straight": straight,
    "non-smooth": non_smooth,
    "non-invertible": non_invertible,
    "relay": relay,
    "crossing": crossing,
    "superposed": superposed,
    "composed": composed,
}
