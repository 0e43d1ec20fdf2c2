"""Seed 001 refinement for inputs that cross the breakpoints: $a$, $b$ and the
map's $k_1, k_2, d_1, d_2, l_1, l_2$ directly (Fig. 2, signed convention).

Giri, Rochdi, Chaoui, *Recursive identification of systems with hard input
nonlinearities of known structure*, Eq. (2.1) and Fig. 2.

The map jumps (preload $l_j \\ne 0$) or kinks at $d_1, d_2$, so the output-error
cost is not differentiable there: `refine` first fits a smoothed map, in which
the switches $\\mathbb 1[v > d_1]$, $\\mathbb 1[v < d_2]$ become logistic
functions of width $\\varepsilon$, for a decreasing sequence of $\\varepsilon$,
then the exact map, which fixes the optimum.

With a preload, a finite record identifies $d_j$ only to the gap between the
input values on either side of it (inside that gap only $h_j = l_j - k_j d_j$
enters the output); the Cramér-Rao bound is then reported for
$(a, b, k_1, k_2, h_1, h_2)$ (pass `physical=parametrisation.regular_physical`
to `cramer_rao_bound`); for $d_j, l_j$ it is NaN.
"""

import jax
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Bool, Float

from .._checks import concrete
from .._types import Params, Signal
from ..models.nonlinearities.piecewise_linear import (
    PARAMETERS as PL_PARAMETERS,
    piecewise_linear_map,
)
from ._discrete import (
    AbstractDiscreteParametrisation,
    discrete_response,
    discrete_stable,
)
from .normalisation import normalise_b, sphere_coordinates, sphere_point


def smoothed_piecewise_linear(
    params: Float[Array, " 6"], v: Signal, width: Float[ArrayLike, ""] | None
) -> Signal:
    """Fig. 2's map with its switches smoothed over `width` (exact for `None`)."""
    if width is None:
        return piecewise_linear_map(v, *params)
    k1, k2, d1, d2, l1, l2 = params
    upper = k1 * (v - d1) + l1
    lower = k2 * (v - d2) + l2
    return (
        jax.nn.sigmoid((v - d1) / width) * upper
        + jax.nn.sigmoid((d2 - v) / width) * lower
    )


class PiecewiseLinearParametrisation(AbstractDiscreteParametrisation):
    """$\\theta = (a_1..a_n, \\delta_1..\\delta_{n-1}, k_1, k_2, d_1, d_2, l_1, l_2)$,
    $\\delta$ a chart of $\\sum b_i^2 = 1$ at `b_ref` (Eq. (3.10)).

    Reported: $(a, b, k_1, k_2, d_1, d_2, l_1, l_2)$, with $b$, $k_j$, $l_j$ in
    the normalisation (3.10) ($d_j$ are abscissas and do not scale).

    **Arguments:**

    - `b_ref`: point of the chart (normalised here), e.g. the initial $b$.
    - `smoothing`: width $\\varepsilon > 0$ of the smoothed switches (`None`: the
      exact map).
    """

    b_ref: Float[Array, " n"]
    smoothing: Float[Array, ""] | None

    def __init__(
        self,
        b_ref: Float[ArrayLike, " n"],
        smoothing: Float[ArrayLike, ""] | None = None,
    ):
        self.b_ref = normalise_b(jnp.asarray(b_ref, dtype=float))[0]
        self.smoothing = None if smoothing is None else jnp.asarray(smoothing, float)

    def __check_init__(self):
        if self.b_ref.ndim != 1 or self.b_ref.shape[0] < 1:
            raise ValueError(f"b_ref must be 1-D and non-empty; got {self.b_ref.shape}")
        if self.smoothing is not None:
            width = concrete(self.smoothing)
            if width is not None and not width > 0:
                raise ValueError(f"smoothing width must be > 0; got {float(width)}")

    def with_smoothing(self, width) -> "PiecewiseLinearParametrisation":
        """The same structure with the switches smoothed over `width`."""
        return PiecewiseLinearParametrisation(self.b_ref, width)

    @property
    def names(self) -> tuple[str, ...]:
        return self._ab_names() + PL_PARAMETERS

    def predict(self, theta: Params, v: Signal) -> Signal:
        a, delta, m = self._split(theta)
        b = sphere_point(self.b_ref, delta)
        u = smoothed_piecewise_linear(m, v, self.smoothing)  # Eq. (2.1b)
        return discrete_response(a, b, u)  # Eq. (2.1a)

    def to_physical(self, theta: Params) -> Float[Array, " n_physical"]:
        a, delta, m = self._split(theta)
        b, g = normalise_b(sphere_point(self.b_ref, delta))
        scale = jnp.array([g, g, 1.0, 1.0, g, g])
        return jnp.concatenate([a, b, m * scale])

    def from_physical(self, physical: Float[Array, " n_physical"]) -> Params:
        n = self.order
        a, b, m = physical[:n], physical[n : 2 * n], physical[2 * n :]
        g = jnp.linalg.norm(b) * jnp.where(jnp.dot(b, self.b_ref) < 0, -1.0, 1.0)
        scale = jnp.array([g, g, 1.0, 1.0, g, g])
        return jnp.concatenate([a, sphere_coordinates(self.b_ref, b / g), m * scale])

    def regular_physical(self, theta: Params) -> Float[Array, " n_regular"]:
        """$(a, b, k_1, k_2, h_1, h_2)$, $h_j = l_j - k_j d_j$ (Eq. (3.15)-(3.16)):
        the parameters that stay regular when a preload makes $d_j$ a jump."""
        phys = self.to_physical(theta)
        n = self.order
        k1, k2, d1, d2, l1, l2 = phys[2 * n :]
        h = jnp.stack([l1 - k1 * d1, l2 - k2 * d2])
        return jnp.concatenate([phys[: 2 * n + 2], h])

    def place_breakpoints(self, theta: Params, v: Signal, y: Signal) -> Params:
        """Each $d_j$ moved to the midpoint of the gap between input values that
        gives the exact map the lowest residual, among its own gap and the two
        next to it, with $h_j = l_j - k_j d_j$ kept (`refine` calls it before the
        exact stage). The exact cost is flat in $d_j$ inside a gap and jumps at an
        input value, where the last smoothed stage may leave $d_j$: the exact
        stage cannot move it across."""
        s = jnp.sort(v)
        n0 = 2 * self.order - 1
        exact = self.with_smoothing(None) if self.smoothing is not None else self

        def rss(th):
            return jnp.sum((y - exact.predict(th, v)) ** 2)

        def mid(lo, hi):  # midpoint of the gap (s[lo], s[hi]), clipped to the data
            lo, hi = jnp.clip(lo, 0, s.shape[0] - 1), jnp.clip(hi, 0, s.shape[0] - 1)
            return (s[lo] + s[hi]) / 2

        for j in range(2):
            d, k = theta[n0 + 2 + j], theta[n0 + j]
            i = jnp.searchsorted(s, d, side="left")  # s[i-1] < d <= s[i]
            above = jnp.searchsorted(s, s[jnp.minimum(i, s.shape[0] - 1)], "right")
            below = jnp.searchsorted(s, s[jnp.maximum(i - 1, 0)], "left") - 1
            candidates = jnp.stack([mid(i - 1, i), mid(i, above), mid(below, i - 1)])
            # d_j -> c with l_j -> l_j + k_j (c - d_j): the same h_j.
            shift = jnp.zeros_like(theta).at[n0 + 2 + j].set(1.0).at[n0 + 4 + j].set(k)
            trials = theta[None, :] + (candidates - d)[:, None] * shift[None, :]
            theta = trials[jnp.argmin(jax.vmap(rss)(trials))]
        return theta

    def is_valid(self, theta: Params) -> Bool[Array, ""]:
        a, _, m = self._split(theta)
        # Fig. 2 needs d2 <= 0 <= d1.
        return discrete_stable(a) & (m[2] >= 0) & (m[3] <= 0)
