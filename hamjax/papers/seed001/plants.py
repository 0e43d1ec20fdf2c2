"""Seed-001 test cases: the paper's plant (Section V.C) and random ones.

Not public API: generators for the tests and the Monte Carlo studies.
"""

import equinox as eqx
import jax
import jax.numpy as jnp
import jax.random as jr
from jaxtyping import Array, Float, PRNGKeyArray

from ..._linalg import polymul
from ...identification.seed001 import theta_star
from ...identification.seed001.rank_one_prop3_1 import first_largest
from ...models import DiscreteTransferFunction, Hammerstein, PiecewiseLinear


class RecursivePLCase(eqx.Module):
    """A plant $y = B/A\\,F(v)$ of seed 001 with its interpolation levels."""

    a: Float[Array, " n"]
    b: Float[Array, " n"]
    nonlinearity: PiecewiseLinear
    levels: Float[Array, " 4"]
    order: int = eqx.field(static=True)

    def plant(self, dt: float | None = None) -> Hammerstein:
        linear = DiscreteTransferFunction(
            jnp.concatenate([jnp.zeros(1), self.b]),
            jnp.concatenate([jnp.ones(1), self.a]),
            dt=dt,
        )
        return Hammerstein(self.nonlinearity, linear)

    def d(self) -> Float[Array, " 4"]:
        """Eq. (3.5) at the true $F$: $d_j = F(V_j)/V_j$."""
        return self.nonlinearity(self.levels) / self.levels

    def theta_star(self) -> Float[Array, " p"]:
        """Eq. (3.8c) in the plant's own scale."""
        return theta_star(self.a, self.b, self.d())

    def normalised_truth(self) -> dict[str, Array]:
        """The true parameters in the normalisation (3.10) of the estimates."""
        c = jnp.sign(first_largest(self.b)) / jnp.linalg.norm(self.b)
        f = self.nonlinearity
        k1, k2 = f.k1 / c, f.k2 / c
        h1, h2 = (f.l1 - f.k1 * f.d1) / c, (f.l2 - f.k2 * f.d2) / c
        return {
            "a": self.a,
            "b": self.b * c,
            "d": self.d() / c,
            "points": f(self.levels) / c,
            "k1": k1,
            "k2": k2,
            "h1": h1,
            "h2": h2,
            "d1": f.d1,
            "d2": f.d2,
            "l1": f.l1 / c,
            "l2": f.l2 / c,
        }


def paper_case() -> RecursivePLCase:
    """Section V.C: $A = 1 - 1.5 q^{-1} + 0.56 q^{-2}$, $B = q^{-1} - 2 q^{-2}$,
    $K = (1, 2)$, $D = (1, -2)$, $L = (1, -2)$, $V = (-6, -3, 3, 6)$."""
    return RecursivePLCase(
        a=jnp.array([-1.5, 0.56]),
        b=jnp.array([1.0, -2.0]),
        nonlinearity=PiecewiseLinear(k1=1.0, k2=2.0, d1=1.0, d2=-2.0, l1=1.0, l2=-2.0),
        levels=jnp.array([-6.0, -3.0, 3.0, 6.0]),
        order=2,
    )


def random_denominator(
    key: PRNGKeyArray, order: int, *, max_radius: float = 0.9
) -> Float[Array, " n"]:
    """$(a_1..a_n)$ of a random stable monic $A$: pole pairs (complex or two real)
    and, for odd $n$, one real pole, all of modulus below `max_radius`."""
    # One draw for everything: many small jr calls make slow-compiling graphs.
    u = jr.uniform(key, (5 * (order // 2) + 1,))
    poly = jnp.ones(1)
    for i in range(order // 2):
        ur, ut, uc, u1, u2 = u[5 * i : 5 * i + 5]
        r = 0.1 + (max_radius - 0.1) * ur
        angle = 0.2 + (jnp.pi - 0.4) * ut
        p1, p2 = max_radius * (2 * u1 - 1), max_radius * (2 * u2 - 1)
        complex_quad = jnp.stack([1.0, -2 * r * jnp.cos(angle), r**2])
        real_quad = jnp.stack([1.0, -(p1 + p2), p1 * p2])
        quad = jnp.where(uc < 0.5, complex_quad, real_quad)
        poly = polymul(poly, quad)
    if order % 2:
        p = max_radius * (2 * u[-1] - 1)
        poly = polymul(poly, jnp.stack([1.0, -p]))
    return poly[1:]


def random_nonlinearity(
    key: PRNGKeyArray, structure: str, *, d_max: float = 1.0
) -> PiecewiseLinear:
    """A random `PiecewiseLinear` of the named structure with dead zones below
    $0.9 D_M$: `"dead-zone"` ($L = 0$), `"preload"` ($D = 0$), `"symmetric"`
    ($D_1 = -D_2$, $L_1 = -L_2$, $K_1 \\ne K_2$) or `"general"`."""
    u = jr.uniform(key, (7,))
    k = 0.5 + 1.5 * u[0:2]
    dz = (0.05 + 0.85 * u[2:4]) * d_max
    load = 0.2 + 1.8 * u[4:6]
    if structure == "dead-zone":
        return PiecewiseLinear(k1=k[0], k2=k[1], d1=dz[0], d2=-dz[1])
    if structure == "preload":
        return PiecewiseLinear(k1=k[0], k2=k[1], l1=load[0], l2=-load[1])
    if structure == "symmetric":
        # Keep |K2 - K1| >= 0.3 so (3.18c) is well conditioned.
        k2 = k[0] + jnp.where(u[6] < 0.5, 1.0, -1.0) * (0.3 + k[1] / 2)
        k2 = jnp.where(k2 > 0.1, k2, k[0] + 0.3 + k[1] / 2)
        return PiecewiseLinear(
            k1=k[0], k2=k2, d1=dz[0], d2=-dz[0], l1=load[0], l2=-load[0]
        )
    if structure == "general":
        return PiecewiseLinear(
            k1=k[0], k2=k[1], d1=dz[0], d2=-dz[1], l1=load[0], l2=-load[1]
        )
    raise ValueError(f"unknown structure {structure!r}")


def random_levels(key: PRNGKeyArray, *, d_max: float = 1.0) -> Float[Array, " 4"]:
    """Levels satisfying (3.1) for $D_M$ = `d_max`: $|V_{2,3}| - D_M \\in (0.3, 2)$
    and gaps $|V_1 - V_2|, |V_4 - V_3| \\in (0.5, 3)$."""
    u = jr.uniform(key, (4,))
    inner = d_max + 0.3 + 1.7 * u[0:2]
    gap = 0.5 + 2.5 * u[2:4]
    return jnp.stack([-inner[0] - gap[0], -inner[0], inner[1], inner[1] + gap[1]])


def random_case(
    key: PRNGKeyArray, order: int, structure: str = "general", *, d_max: float = 1.0
) -> RecursivePLCase:
    """A random stable order-`order` plant, nonlinearity and levels; $\\|b\\| = 1$."""
    a_key, b_key, f_key, v_key = jr.split(key, 4)
    b = jr.normal(b_key, (order,))
    b = b / jnp.linalg.norm(b)
    return RecursivePLCase(
        a=random_denominator(a_key, order),
        b=b,
        nonlinearity=random_nonlinearity(f_key, structure, d_max=d_max),
        levels=random_levels(v_key, d_max=d_max),
        order=order,
    )


def pe_input(
    levels: Float[Array, " 4"], order: int, periods: int
) -> Float[Array, " time"]:
    """(5.1) as a traceable function of the levels (`hamjax.pe_impulse_sequence`
    needs concrete levels): period $7n$, $V_1$ at $2n$, $V_j$ at $(2+j)n$."""
    n = order
    one = jnp.zeros(7 * n, dtype=levels.dtype)
    one = one.at[2 * n].set(levels[0])
    for j in (2, 3, 4):
        one = one.at[(2 + j) * n].set(levels[j - 1])
    return jnp.tile(one, periods)


def random_dead_zone_or_preload(key: PRNGKeyArray, order: int) -> tuple:
    """A random case whose map is a dead zone or a preload (a fair coin), and
    whether it is the dead zone."""
    case_key, coin_key = jr.split(key)
    is_dead_zone = jr.bernoulli(coin_key)
    dz = random_case(case_key, order, "dead-zone")
    pl = random_case(case_key, order, "preload")
    case = jax.tree_util.tree_map(lambda x, y: jnp.where(is_dead_zone, x, y), dz, pl)
    return case, is_dead_zone


def seed001_plant():
    """Seed 001 Section V.C (`paper_case`) as `(plant, levels,
    order)`: $A = 1 - 1.5q^{-1} + 0.56q^{-2}$, $B = q^{-1} - 2q^{-2}$,
    $K_1 = 1, K_2 = 2, D_1 = 1, D_2 = -2, L_1 = 1, L_2 = -2$, $V = (-6, -3, 3, 6)$,
    with `dt = 1`."""
    c = paper_case()
    return c.plant(dt=1.0), c.levels, c.order
