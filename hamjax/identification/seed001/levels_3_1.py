"""The four interpolation levels of seed 001 and their condition (3.1).

Giri, Rochdi, Chaoui, *Recursive identification of systems with hard input
nonlinearities of known structure*, Section III.A.
"""

import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float


def check_levels(
    levels: Float[ArrayLike, " 4"], *, d_max: float | None = None
) -> Float[Array, " 4"]:
    r"""Validate the levels $(V_1, V_2, V_3, V_4)$ against (3.1),

    $$V_1 < V_2 < -D_M < 0 < D_M < V_3 < V_4,$$

    and return them as a float array. Without `d_max` only
    $V_1 < V_2 < 0 < V_3 < V_4$ is checked (the user then vouches for $D_M$).

    **Arguments:**

    - `levels`: four finite numbers (input units); must be concrete.
    - `d_max`: the known bound $D_M$ of assumption A4 (optional, $> 0$).

    **Returns:** the levels, shape `(4,)`.

    **Raises:** `ValueError` naming the violated part of (3.1) (wrong count,
    NaN/inf, duplicates, wrong order, a level on the wrong side of $\pm D_M$).
    """
    try:
        arr = np.asarray(levels, dtype=float)
    except (TypeError, ValueError):
        raise ValueError(f"levels must be four numbers; got {levels!r}") from None
    if arr.ndim != 1 or arr.shape[0] != 4:
        raise ValueError(
            f"seed 001 needs exactly four levels V1..V4 (3.1); got shape {arr.shape}"
        )
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"levels must be finite; got {arr.tolist()}")
    if np.unique(arr).shape[0] != 4:
        raise ValueError(
            f"levels must be distinct (duplicate level in {arr.tolist()}); the "
            "Lagrange polynomials (3.3) divide by V_j - V_i"
        )
    if np.any(np.diff(arr) <= 0):
        raise ValueError(
            f"levels must satisfy V1 < V2 < V3 < V4 (3.1); got {arr.tolist()}"
        )
    if not (arr[1] < 0.0 < arr[2]):
        raise ValueError(
            "levels must satisfy V1 < V2 < 0 < V3 < V4 (3.1): two negative and two "
            f"positive levels; got {arr.tolist()}"
        )
    if d_max is not None:
        d_max = float(d_max)
        if not (np.isfinite(d_max) and d_max > 0):
            raise ValueError(f"D_M must be finite and > 0; got {d_max}")
        if not (arr[1] < -d_max and d_max < arr[2]):
            raise ValueError(
                f"levels must lie outside the band [-D_M, D_M] = [{-d_max:g}, "
                f"{d_max:g}] (3.1): need V2 < -D_M and V3 > D_M; got {arr.tolist()}"
            )
    return jnp.asarray(arr)
