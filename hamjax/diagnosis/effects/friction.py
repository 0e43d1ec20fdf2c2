r"""`friction`: a force opposing the motion of the output, fed back to the input of
$G$: $u' = F(v) - f(s)$, $f(s) = c\,\tanh(s/\varepsilon)$ (a smooth Coulomb law),
with $s$ the velocity of the output.

Two slots, one per reading of "velocity" (a row frees one of them):

- `fric_w`: $s = w$ (the output *is* a velocity);
- `fric_dw`: $s = dw/dt$ (the output is a position).

In discrete time the force acts on the velocity over the step it drives
($w_{k+1}$, or $(w_{k+1} - w_k)/dt$), solved implicitly for the input
(`augmented.feedback_scan`): with $c\,\mathrm{sign}$ this is the stick-slip
discretisation (the velocity stays 0 while the drive is below $c$), where an
explicit one (the velocity of the step before) chatters about 0.

**The smoothing width.** $\varepsilon = 10^{-3} V$, with $V$ the velocity scale of
the nominal output (`output_half_range` for $s = w$, the same 2 %/98 % quantile
rule on $\Delta w/dt$ for $s = dw/dt$). For $s$ spread evenly over $[-V, V]$ the
mean square of $c\,(\mathrm{sign}(s) - \tanh(s/\varepsilon))$ is
$c^2 (\varepsilon/V)\int_0^\infty (1 - \tanh t)^2\,dt = c^2 (2\ln 2 - 1)\,\varepsilon/V$,
so this width misses a textbook Coulomb law $c\,\mathrm{sign}(s)$ by
$0.020\,c$ in RMS (2 % of the effect) while keeping $f$ differentiable. The
implicit step keeps so steep a law well conditioned ($\partial_u$ of the
equation is $\ge 1$); an explicit one (the force from the previous step's
velocity) chattered about zero velocity with a gain $c/\varepsilon$ and made a
fit's SSE depend on rounding (83 % apart between one and two devices after 6
steps, `tests/diagnosis/test_diagnosis_fit.py`).
"""

import jax.numpy as jnp
from jaxtyping import Array, Float

from ._base import AbstractEffect, StartContext


EPS_FRACTION = 1e-3  # epsilon / velocity scale (module docstring)


def friction_force(
    v_w: Float[Array, ""],
    v_dw: Float[Array, ""],
    c_w: Float[Array, ""],
    c_dw: Float[Array, ""],
    eps_w: Float[Array, ""],
    eps_dw: Float[Array, ""],
) -> Float[Array, ""]:
    r"""$f = c_w \tanh(v_w/\varepsilon_w) + c_{dw}\tanh(v_{dw}/\varepsilon_{dw})$ with
    $v_w$ the output and $v_{dw}$ its rate over the step: exactly 0 at the neutral
    $c_w = c_{dw} = 0$."""
    return c_w * jnp.tanh(v_w / eps_w) + c_dw * jnp.tanh(v_dw / eps_dw)


class FrictionEffect(AbstractEffect):
    """Coulomb friction $c \\ge 0$ on the output (`fric_w`) or on its derivative
    (`fric_dw`); neutral 0."""

    name = "friction"
    slots = ("fric_w", "fric_dw")
    neutral = {"fric_w": 0.0, "fric_dw": 0.0}
    positive = ("fric_w", "fric_dw")

    def scales(self, ctx: StartContext) -> dict[str, float]:
        return {"fric_w": 0.1 * ctx.u_std, "fric_dw": 0.1 * ctx.u_std}

    def starts(self, ctx: StartContext) -> list[dict[str, float]]:
        c = 0.1 * ctx.u_std
        return [{"fric_w": c}, {"fric_dw": c}]

    def velocity(self, free: set[str]) -> str:
        """Which velocity a row freeing `free` used: "output" ($s = w$) or
        "derivative" ($s = dw/dt$)."""
        return "derivative" if "fric_dw" in free else "output"
