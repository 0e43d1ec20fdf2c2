r"""Nonparametric Backlash Border Identification (NBBI).

Brouri, Giri, Rochdi, Chaoui, *Frequency identification of nonparametric
Hammerstein systems with backlash nonlinearity*, Section III, Table 1,
Proposition 1 and Remark 1a.

After the initialisation step (3) the staircase (4a-b) holds each of the $2n-2$
levels $V_1, \dots, V_n, V_{n-1}, \dots, V_2$ for $N T_r$ seconds. With $G(0) = 1$
the output settles at the backlash output $U_i$ of each level, so the average
(5) of $y$ over each interval estimates a point $(V_i, U_i)$ of the limit cycle:
the first $n$ lie on the ascending path $\mathcal P_a$, the last $n-2$ (and the
two end points) on the descending path $\mathcal P_d$ (Fig. 5).
"""

import math

import equinox as eqx
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float

from ..._results import RESULTS
from ...signals._common import as_levels, samples_in


class NBBIResult(eqx.Module):
    r"""Estimated points of the backlash limit cycle (Table 1, step 3).

    - `levels`: $V_1 < \dots < V_n$.
    - `cycle_levels`, `cycle_values`: the $2n-2$ points $(V_i, \hat W_i(N))$ in the
      order of the staircase (4a-b), which is the order FGI's input (24) visits them.
    - `stderr`: standard error of each $\hat W_i$ (white-noise formula
      $\hat\sigma / \sqrt{m}$, $m$ samples averaged).
    - `uncertainty`: $\sqrt{\text{stderr}^2 + d^2}$ with $d$ the difference between
      $\hat W_i$ and the mean of the second half of its interval: an estimate of
      the transient bias of the plain average (5) added to the noise. FGI uses it
      to tell negligible harmonics of $u$ from real ones.
    - `noise_std`: $\hat\sigma$, pooled from the second half of every interval.
    - `spread`: range of the settled half-interval means (Remark 1a statistic).
    - `result`: `RESULTS.successful`, or `RESULTS.not_exciting` when the working
      interval is too narrow (Remark 1a), or `RESULTS.nonfinite`.
    """

    levels: Float[Array, " n"]
    cycle_levels: Float[Array, " m"]
    cycle_values: Float[Array, " m"]
    stderr: Float[Array, " m"]
    uncertainty: Float[Array, " m"]
    noise_std: Float[Array, ""]
    spread: Float[Array, ""]
    result: RESULTS

    @property
    def ascending(self) -> Float[Array, "n 2"]:
        """The $n$ points on $\\mathcal P_a$, $V_1$ to $V_n$."""
        n = self.levels.shape[0]
        return jnp.stack([self.levels, self.cycle_values[:n]], axis=-1)

    @property
    def descending(self) -> Float[Array, "n 2"]:
        """The $n$ points on $\\mathcal P_d$, $V_n$ down to $V_1$ (ends shared with P_a)."""
        n = self.levels.shape[0]
        # Points n..2n-2 of the staircase, then (V_1, W_1): the cycle closes at 1.
        values = jnp.concatenate([self.cycle_values[n - 1 :], self.cycle_values[:1]])
        return jnp.stack([self.levels[::-1], values], axis=-1)

    @property
    def cycle(self) -> Float[Array, "m 2"]:
        """The $2n-2$ points in staircase order (4a-b)."""
        return jnp.stack([self.cycle_levels, self.cycle_values], axis=-1)


def identify_nbbi(
    y: Float[ArrayLike, " time"],
    levels: Float[ArrayLike, " n"],
    *,
    hold: float,
    dt: float,
    start: int = 0,
    discard: float = 0.0,
    narrow_z: float = 6.0,
    throw: bool = True,
) -> NBBIResult:
    r"""Table 1, step 3: the averages (5) and the $2n-2$ border points.

    **Arguments:**

    - `y`: measured output samples $y(k\,dt)$, shape `(time,)`; the staircase (4a-b)
      starts at sample `start` (after the initialisation (3)) and lasts
      $(2n-2)\,$`hold`.
    - `levels`: $V_1 < \dots < V_n$, $n \ge 3$.
    - `hold`: $N T_r$ (s), a whole number of samples.
    - `dt`: sampling period (s).
    - `start`: index of the first staircase sample (the initialisation length).
    - `discard`: seconds discarded at the start of each interval before averaging.
      `0` is the paper's plain average (5), whose transient costs a bias
      $O(1/N)$; a `discard` of a few settling times removes it (the "settled"
      average) at the price of fewer samples.
    - `narrow_z`: Remark 1a threshold: the working interval is declared too narrow
      when the range of the settled means is below `narrow_z` standard errors of
      a difference (or below round-off for noise-free data).
    - `throw`: raise on failure; otherwise report it in `.result`.

    The average is the rectangle rule on the samples, exact for an output that has
    settled; during a transient its error is $O(dt/(N T_r))$ times the jump.

    **Returns:** an `NBBIResult`.

    **Raises:** `ValueError` for bad levels, a hold or discard that is not a whole
    number of samples, or `y` too short; at run time (with `throw=True`) an error
    naming Remark 1a when the interval is too narrow.
    """
    # Levels fix the design: concrete NumPy values (validated), constants under jit.
    as_levels(levels, minimum=3)
    levels_np = np.asarray(levels, dtype=float)
    per_level = samples_in(hold, dt, "hold N*Tr")
    skip = 0 if discard == 0 else samples_in(discard, dt, "discard")
    if skip >= per_level:
        raise ValueError(
            f"discard = {discard:g} s leaves nothing of each {hold:g} s interval to average"
        )
    if per_level < 2:
        raise ValueError("each level must be held for at least 2 samples")
    cycle = np.concatenate([levels_np, levels_np[-2:0:-1]])  # Eq. (4a-b)
    m = cycle.shape[0]
    y = jnp.asarray(y, dtype=float)
    if y.ndim != 1:
        raise ValueError(f"`y` must be 1-D (time,); got shape {y.shape}")
    if start < 0 or y.shape[0] < start + m * per_level:
        raise ValueError(
            f"`y` has {y.shape[0]} samples; the staircase needs {start} + {m} x "
            f"{per_level} = {start + m * per_level}"
        )
    return _nbbi(
        y,
        jnp.asarray(levels_np),
        jnp.asarray(cycle),
        start=int(start),
        per_level=per_level,
        skip=skip,
        narrow_z=float(narrow_z),
        throw=bool(throw),
    )


@eqx.filter_jit
def _nbbi(y, levels, cycle, *, start, per_level, skip, narrow_z, throw) -> NBBIResult:
    """The numerics of `identify_nbbi` (validated arguments), compiled once per design."""
    m = cycle.shape[0]
    blocks = y[start : start + m * per_level].reshape(m, per_level)
    # Eq. (5): the mean over [i N Tr, (i+1) N Tr), optionally after the transient.
    used = blocks[:, skip:]
    values = jnp.mean(used, axis=1)

    # Remark 1a: on settled halves, a too-narrow interval leaves y constant.
    half = blocks[:, per_level // 2 :]
    half_means = jnp.mean(half, axis=1)
    resid = half - half_means[:, None]
    dof = m * (half.shape[1] - 1)
    noise_std = jnp.sqrt(jnp.sum(resid**2) / max(dof, 1))
    stderr = jnp.full((m,), noise_std / math.sqrt(used.shape[1]))
    uncertainty = jnp.sqrt(stderr**2 + (values - half_means) ** 2)
    spread = jnp.max(half_means) - jnp.min(half_means)
    scale = jnp.max(jnp.abs(half_means))
    threshold = jnp.maximum(
        narrow_z * noise_std * math.sqrt(2.0 / half.shape[1]), 1e-9 * (1.0 + scale)
    )
    result = RESULTS.where(
        jnp.all(jnp.isfinite(values)),
        RESULTS.where(spread > threshold, RESULTS.successful, RESULTS.not_exciting),
        RESULTS.nonfinite,
    )
    if throw:
        values = result.error_if(values, result != RESULTS.successful)
    return NBBIResult(
        levels=levels,
        cycle_levels=cycle,
        cycle_values=values,
        stderr=stderr,
        uncertainty=uncertainty,
        noise_std=noise_std,
        spread=spread,
        result=result,
    )


def check_assumptions(linear, *, atol: float = 1e-9) -> None:
    """Section II's assumptions on $G$: asymptotically stable, $G(0) = 1$.

    **Raises:** `ValueError` if $G$ is unstable, if $G(0) = 0$ (no normalisation
    exists: a derivative system), or if $G(0) \ne 1$ (normalise first with
    `hamjax.normalise_static_gain`).
    """
    if not linear.is_stable():
        poles = ", ".join(f"{p:.4g}" for p in np.atleast_1d(linear.poles()))
        raise ValueError(
            f"G must be asymptotically stable (seed 000, Section II); poles {poles}"
        )
    gain = float(linear.static_gain())
    if abs(gain) <= atol:
        raise ValueError(
            "G(0) = 0: the static gain must be nonzero for the (kF, G/k) normalisation "
            "(seed 000, Section II)"
        )
    if abs(gain - 1.0) > atol:
        raise ValueError(
            f"G(0) = {gain:g}, not 1: normalise with hamjax.normalise_static_gain first"
        )


def narrow_message(res: NBBIResult) -> str:
    """A one-line explanation of a failed NBBI result, for the CLI."""
    code = np.asarray(res.result._value)
    if code == RESULTS.not_exciting._value:
        return (
            "the working interval [V1, Vn] is too narrow (Remark 1a): the output stays "
            f"constant (range of settled means {float(res.spread):.3g} is within noise "
            f"{float(res.noise_std):.3g}); the working point never reaches a border - "
            "widen the levels"
        )
    return "the border-point estimates are not finite (NaN or inf in the data)"
