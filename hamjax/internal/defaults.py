"""The built-in default plants of the demo and the examples (not public API)."""

import jax.numpy as jnp

from .. import models as hm


def seed000_border_shapes() -> hm.Backlash:
    """A backlash with curved, non-straight borders (seed 000 Fig. 4b kind): a
    straight play of width 0.6 after a static cubic-like map, tabulated."""
    grid = jnp.linspace(-3.0, 3.0, 121)
    shape = grid + 0.15 * grid**3 / 3
    return hm.Backlash.from_table(grid, shape - 0.35, shape + 0.35)


def seed000_plant():
    """Seed 000 Fig. 6: $G(s) = (s-10)/(s+1)^2$ with a curved backlash, normalised
    to $G(0) = 1$ by $(kF, G/k)$; levels for $n = 4$, `dt`, hold $N T_r$."""
    G = hm.ContinuousTransferFunction(
        jnp.array([1.0, -10.0]), jnp.array([1.0, 2.0, 1.0])
    )
    plant = hm.normalise_static_gain(hm.Hammerstein(seed000_border_shapes(), G))
    levels = jnp.array([-2.0, -0.7, 0.7, 2.0])
    return plant, levels, 0.02, 20.0


def seed001_plant():
    """Seed 001 Section V.C (`recursive_pl_plants.paper_case`) as `(plant, levels,
    order)`: $A = 1 - 1.5q^{-1} + 0.56q^{-2}$, $B = q^{-1} - 2q^{-2}$,
    $K_1 = 1, K_2 = 2, D_1 = 1, D_2 = -2, L_1 = 1, L_2 = -2$, $V = (-6, -3, 3, 6)$,
    with `dt = 1`."""
    from .recursive_pl_plants import paper_case

    c = paper_case()
    G = hm.DiscreteTransferFunction(
        jnp.concatenate([jnp.zeros(1), c.b]),
        jnp.concatenate([jnp.ones(1), c.a]),
        dt=1.0,
    )
    return hm.Hammerstein(c.nonlinearity, G), c.levels, c.order
