"""Continuous-time simulation by diffrax, for arbitrary inputs and for gradients."""

from typing import Literal

import jax.numpy as jnp
from jaxtyping import Array, Float

from .._checks import check_finite, check_strictly_increasing
from .._types import Signal
from ..models import ContinuousTransferFunction, Hammerstein, apply_nonlinearity


def simulate_diffrax(
    plant: Hammerstein | ContinuousTransferFunction,
    t: Float[Array, " time"],
    v: Float[Array, " time"],
    *,
    interpolation: Literal["hold", "linear"] = "hold",
    rtol: float = 1e-10,
    atol: float = 1e-12,
    max_steps: int | None = None,
) -> Signal:
    """Solve $\\dot x = A x + B u(t)$, $y = C x + D u$ with diffrax, from rest.

    The nonlinearity acts on the samples of `v`; $u(t)$ between samples is held
    (`"hold"`, the zero-order hold: the solver is told about every jump) or
    linearly interpolated (`"linear"`). With `"hold"` this cross-checks the exact
    ZOH path of `simulate` to the solver tolerance.

    **Arguments:**

    - `plant`: a Hammerstein plant with a `ContinuousTransferFunction`, or the
      linear block alone (then `v` is its input $u$).
    - `t`: strictly increasing sample times, shape `(time,)`.
    - `v`: input samples at `t`.

    **Returns:** $y(t_k)$, shape `(time,)`.

    **Raises:** `ValueError` if `t` and `v` differ in shape, hold NaN/inf, or `t`
    is not strictly increasing (values checked when concrete).
    """
    v = jnp.asarray(v, dtype=float)
    t = jnp.asarray(t, dtype=float)
    if t.shape != v.shape or t.ndim != 1:
        raise ValueError(
            f"`t` and `v` must be 1-D of equal length; got {t.shape}, {v.shape}"
        )
    check_finite("input `v`", v)
    check_finite("sample times `t`", t)
    check_strictly_increasing("sample times `t`", t)
    if isinstance(plant, Hammerstein):
        linear = plant.linear
        u = apply_nonlinearity(plant.nonlinearity, v)
    else:
        linear, u = plant, v
    if not isinstance(linear, ContinuousTransferFunction):
        raise TypeError("simulate_diffrax needs a ContinuousTransferFunction")
    import diffrax  # here, not at import: it adds ~0.6 s to every `hamjax` command

    A, B, C, D = linear.state_space()
    n = A.shape[0]
    if n == 0:
        return D[0, 0] * u
    if interpolation == "hold":
        # Right-continuous: u(t) = u_k on [t_k, t_{k+1}).
        def control(s):
            k = jnp.clip(jnp.searchsorted(t, s, side="right") - 1, 0, t.shape[0] - 1)
            return u[k]

        controller = diffrax.ClipStepSizeController(
            diffrax.PIDController(rtol=rtol, atol=atol), jump_ts=t
        )
    elif interpolation == "linear":
        control = diffrax.LinearInterpolation(ts=t, ys=u).evaluate
        controller = diffrax.ClipStepSizeController(
            diffrax.PIDController(rtol=rtol, atol=atol), step_ts=t
        )
    else:
        raise ValueError(
            f"interpolation must be 'hold' or 'linear'; got {interpolation!r}"
        )

    def vector_field(s, x, args):
        return A @ x + B[:, 0] * control(s)

    sol = diffrax.diffeqsolve(
        diffrax.ODETerm(vector_field),
        diffrax.Tsit5(),
        t0=t[0],
        t1=t[-1],
        dt0=None,
        y0=jnp.zeros(n),
        saveat=diffrax.SaveAt(ts=t),
        stepsize_controller=controller,
        max_steps=max_steps if max_steps is not None else 64 * t.shape[0] + 4096,
    )
    return sol.ys @ C[0] + D[0, 0] * u
