"""Shared test helpers."""

import jax.tree_util as jtu
import numpy as np


def tree_allclose(x, y, *, rtol=1e-10, atol=1e-12) -> bool:
    """Whether two pytrees have the same structure and allclose leaves."""
    lx, tx = jtu.tree_flatten(x)
    ly, ty = jtu.tree_flatten(y)
    if tx != ty:
        return False
    return all(np.allclose(a, b, rtol=rtol, atol=atol) for a, b in zip(lx, ly))
