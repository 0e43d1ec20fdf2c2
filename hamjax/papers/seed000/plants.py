"""Seed 000's example plants: the Fig. 6 plant and a curved backlash (the demo's and
the studies' defaults)."""

import jax.numpy as jnp

from ... import models as hm


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
