r"""The backlash operator of seed 000 with arbitrary-shape borders.

Brouri, Giri, Rochdi, Chaoui, *Frequency identification of nonparametric
Hammerstein systems with backlash nonlinearity*, Section II and Remark 1.
"""

from typing import NamedTuple

import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Bool, Float

from ..._checks import concrete
from ._base import AbstractHysteresisNonlinearity, AbstractStaticNonlinearity
from .tabulated import Tabulated


class BacklashState(NamedTuple):
    """Where the working point is: last input, output, and which borders it is on."""

    v_prev: Float[Array, ""]
    u: Float[Array, ""]
    on_ascending: Bool[Array, ""]
    on_descending: Bool[Array, ""]


class Backlash(AbstractHysteresisNonlinearity):
    r"""Backlash with ascending border $f_a$ and descending border $f_d$.

    The working point $(v, u)$ moves as follows (seed 000, Section II):

    - while $v$ rises and the point is on the ascending border, $u = f_a(v)$,
      even where $f_a$ is non-monotone or discontinuous; likewise on $f_d$ while
      $v$ falls;
    - after a reversal (or from any point off a border) $u$ stays constant: the
      point moves horizontally until it meets the border of the new direction,
      i.e. until $f_a(v) \ge u$ when rising ($f_d(v) \le u$ when falling), and
      from then on follows that border;
    - while $v$ does not change, nothing moves.

    The operator only sees samples. A jump from $v_{k-1}$ to $v_k$ is one move
    in its direction, and the border test is made at $v_k$ only: the border
    between the samples is not examined. For piecewise-constant inputs (the
    staircases of seed 000) this is exactly the paper's behaviour whenever the
    border reached at each new level is the one of (9); for sampled continuous
    inputs it is exact up to the sampling of the borders.

    Superposed borders ($f_a = f_d = f$, even non-monotone) give exactly the
    static map $u = f(v)$ (Remark 1b): the point is then on both borders. Where
    borders cross ($f_a > f_d$) the point follows the border of the current
    direction. The initial working point is $u_0$ (by default the centre of the
    play, $(f_a(v_0) + f_d(v_0))/2$).

    ```python
    >>> bl = Backlash.from_width(1.0)   # f_a(v) = v - 0.5, f_d(v) = v + 0.5
    >>> apply_nonlinearity(bl, jnp.array([0.0, 1.0, 2.0, 1.5, 1.0, 0.0]))
    Array([0. , 0.5, 1.5, 1.5, 1.5, 0.5], dtype=float64)
    ```
    """

    ascending: AbstractStaticNonlinearity
    descending: AbstractStaticNonlinearity
    u0: Float[Array, ""] | None = None

    def __check_init__(self):
        for name in ("ascending", "descending"):
            if not isinstance(getattr(self, name), AbstractStaticNonlinearity):
                raise TypeError(
                    f"Backlash.{name} must be a static nonlinearity (e.g. Tabulated); "
                    f"got {type(getattr(self, name)).__name__}"
                )

    @classmethod
    def from_width(
        cls, width: Float[ArrayLike, ""], *, u0: Float[ArrayLike, ""] | None = None
    ) -> "Backlash":
        """Straight-line play of total width `width`: $f_a = v - c/2$, $f_d = v + c/2$."""
        from .shifted import Shifted

        c = jnp.asarray(width, dtype=float)
        value = concrete(c)
        if value is not None and value < 0:
            raise ValueError(f"backlash width must be >= 0; got {float(value)}")
        return cls(
            ascending=Shifted(offset=-c / 2),
            descending=Shifted(offset=c / 2),
            u0=None if u0 is None else jnp.asarray(u0, dtype=float),
        )

    @classmethod
    def from_table(
        cls,
        v: Float[ArrayLike, " grid"],
        ascending: Float[ArrayLike, " grid"],
        descending: Float[ArrayLike, " grid"],
        *,
        u0: Float[ArrayLike, ""] | None = None,
    ) -> "Backlash":
        """Borders tabulated on a common grid (the `model.json` form)."""
        return cls(
            ascending=Tabulated(v, ascending),
            descending=Tabulated(v, descending),
            u0=None if u0 is None else jnp.asarray(u0, dtype=float),
        )

    def init(self, v0: Float[Array, ""]) -> BacklashState:
        v0 = jnp.asarray(v0, dtype=float)
        fa, fd = self.ascending(v0), self.descending(v0)
        u = (fa + fd) / 2 if self.u0 is None else jnp.asarray(self.u0, dtype=float)
        return BacklashState(v0, u, u == fa, u == fd)

    def step(
        self, state: BacklashState, v: Float[Array, ""]
    ) -> tuple[BacklashState, Float[Array, ""]]:
        v_prev, u, on_asc, on_desc = state
        fa, fd = self.ascending(v), self.descending(v)
        rising, falling = v > v_prev, v < v_prev
        # Rising: follow f_a once on it; a horizontal move meets f_a when f_a >= u.
        take_a = rising & (on_asc | (fa >= u))
        take_d = falling & (on_desc | (fd <= u))
        u_new = jnp.where(take_a, fa, jnp.where(take_d, fd, u))
        # Membership is re-evaluated from values so that superposed borders keep
        # the point on both (the static map of Remark 1b).
        moved = rising | falling
        on_asc_new: Bool[Array, ""] = jnp.where(moved, take_a | (u_new == fa), on_asc)
        on_desc_new: Bool[Array, ""] = jnp.where(moved, take_d | (u_new == fd), on_desc)
        return BacklashState(v, u_new, on_asc_new, on_desc_new), u_new
