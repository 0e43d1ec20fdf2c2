"""Seed 000 refinement: the backlash cycle points $U_i$ and a parametric $G(s)$.

Brouri, Giri, Rochdi, Chaoui, *Frequency identification of nonparametric
Hammerstein systems with backlash nonlinearity*, Table 1 and Section III.

A staircase that visits only the levels $V_1 < \\dots < V_n$ (the initialisation
(3), the NBBI input (4a-b), the periodic input (24)) drives the backlash
working point through the $2n-2$ positions of Fig. 5: $V_1$, then $V_2..V_n$
arriving from below (on $\\mathcal P_a$), then $V_{n-1}..V_2$ arriving from above
(on $\\mathcal P_d$). Whatever the borders, $u$ is constant at each position, so
$u$ is a table of $2n-2$ values indexed by (level, direction of arrival); the
first hold, reached from rest, has its own (nuisance) value. $G(s)$ has
user-given orders with $G(0) = 1$ (Section II), simulated by the exact ZOH.
"""

import equinox as eqx
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Bool, Float, Int

from .._types import Params, Signal
from ..models import ContinuousTransferFunction
from ._parametrisation import AbstractParametrisation


def cycle_positions(
    v: np.ndarray, levels: np.ndarray, *, atol: float = 1e-9
) -> np.ndarray:
    """Per sample, 0 for the first hold and $1 + $ the cycle position of Fig. 5
    (0: $V_1$; $1..n-1$: $V_2..V_n$ rising; $n..2n-3$: $V_{n-1}..V_2$ falling).

    **Raises:** `ValueError` if `v` takes a value that is not one of `levels`.
    """
    v = np.asarray(v, dtype=float)
    levels = np.asarray(levels, dtype=float)
    n = levels.shape[0]
    if n < 3:
        raise ValueError(f"need at least 3 levels V1..Vn; got {n}")
    dist = np.abs(v[:, None] - levels[None, :])
    level = np.argmin(dist, axis=1)
    bad = dist[np.arange(v.shape[0]), level] > atol * max(1.0, np.max(np.abs(levels)))
    if np.any(bad):
        k = int(np.argmax(bad))
        raise ValueError(
            f"input sample {k} (v = {v[k]:g}) is not one of the staircase levels "
            f"{levels.tolist()}"
        )
    out = np.zeros(v.shape[0], dtype=np.int64)
    change = np.flatnonzero(np.diff(level)) + 1
    starts = np.concatenate([[0], change])
    ends = np.concatenate([change, [v.shape[0]]])
    for r in range(1, starts.shape[0]):
        i = level[starts[r]]
        rising = i > level[starts[r - 1]]
        if i == 0:
            pos = 0
        elif i == n - 1 or rising:
            pos = i
        else:
            pos = 2 * n - 2 - i
        out[starts[r] : ends[r]] = pos + 1
    return out


class BacklashPathParametrisation(AbstractParametrisation):
    """$\\theta = (U_1..U_{2n-2}, \\alpha_1..\\alpha_p, \\beta_0..\\beta_{m-1}, u_0)$ with

    $$G(s) = \\frac{\\beta_0 s^m + \\dots + \\beta_{m-1} s + \\alpha_p}
    {s^p + \\alpha_1 s^{p-1} + \\dots + \\alpha_p},\\qquad G(0) = 1,$$

    $U$ the cycle values in the order of (4a-b) and $u_0$ the value of the first
    hold. Reported (`to_physical`) is $\\theta$ itself.

    **Arguments:**

    - `positions`: per-sample index from `cycle_positions(v, levels)`.
    - `n_levels`: $n$.
    - `den_order`, `num_order`: $p \\ge 1$ and $0 \\le m \\le p$.
    - `dt`: sampling period (s).
    """

    positions: Int[Array, " time"]
    n_levels: int = eqx.field(static=True)
    den_order: int = eqx.field(static=True)
    num_order: int = eqx.field(static=True)
    dt: float = eqx.field(static=True)

    def __init__(
        self,
        positions: Int[ArrayLike, " time"],
        *,
        n_levels: int,
        den_order: int,
        num_order: int,
        dt: float,
    ):
        self.positions = jnp.asarray(positions)
        self.n_levels = int(n_levels)
        self.den_order = int(den_order)
        self.num_order = int(num_order)
        self.dt = float(dt)

    def __check_init__(self):
        if self.n_levels < 3:
            raise ValueError(f"need n_levels >= 3; got {self.n_levels}")
        if self.den_order < 1 or not 0 <= self.num_order <= self.den_order:
            raise ValueError(
                "G(s) orders must satisfy den_order >= 1 and 0 <= num_order <= "
                f"den_order; got den_order={self.den_order}, num_order={self.num_order}"
            )
        if not self.dt > 0:
            raise ValueError(f"sampling period dt must be > 0; got {self.dt}")

    @classmethod
    def from_design(
        cls, v, levels, *, den_order: int, num_order: int, dt: float
    ) -> "BacklashPathParametrisation":
        """From the input samples and the staircase levels (checked to match)."""
        levels = np.asarray(levels, dtype=float)
        return cls(
            cycle_positions(np.asarray(v), levels),
            n_levels=levels.shape[0],
            den_order=den_order,
            num_order=num_order,
            dt=dt,
        )

    @property
    def n_cycle(self) -> int:
        return 2 * self.n_levels - 2

    @property
    def names(self) -> tuple[str, ...]:
        return (
            tuple(f"U{i + 1}" for i in range(self.n_cycle))
            + tuple(f"den{i + 1}" for i in range(self.den_order))
            + tuple(f"num{i}" for i in range(self.num_order))
            + ("u_initial",)
        )

    def transfer_function(self, theta: Params) -> ContinuousTransferFunction:
        """$G(s)$ with $G(0) = 1$ built from $\\theta$."""
        c, p, m = self.n_cycle, self.den_order, self.num_order
        alpha = theta[c : c + p]
        beta = theta[c + p : c + p + m]
        den = jnp.concatenate([jnp.ones(1), alpha])
        num = jnp.concatenate([beta, alpha[-1:]])  # G(0) = 1 (Section II)
        return ContinuousTransferFunction(num, den)

    def internal_signal(self, theta: Params) -> Signal:
        """$u$ per sample: the cycle value of each hold (Fig. 5)."""
        c = self.n_cycle
        table = jnp.concatenate([theta[-1:], theta[:c]])
        return table[self.positions]

    def predict(self, theta: Params, v: Signal) -> Signal:
        del v  # the hold positions, fixed by the design, carry all of v
        G = self.transfer_function(theta)
        return G.discretise(self.dt).response(self.internal_signal(theta))

    def to_physical(self, theta: Params) -> Float[Array, " n_physical"]:
        return theta

    def from_physical(self, physical: Float[Array, " n_physical"]) -> Params:
        return jnp.asarray(physical, dtype=float)

    def is_valid(self, theta: Params) -> Bool[Array, ""]:
        stable = self.transfer_function(theta).stable()
        return stable & jnp.all(jnp.isfinite(theta))

    def paths(self, theta: Params) -> tuple[Array, Array]:
        """`(ascending, descending)` $U$ values: $V_1..V_n$ on $\\mathcal P_a$ and
        $V_n..V_1$ on $\\mathcal P_d$ (both include the shared end points)."""
        n, c = self.n_levels, theta[: self.n_cycle]
        ascending = c[:n]
        descending = jnp.concatenate([c[n - 1 :], c[:1]])
        return ascending, descending
