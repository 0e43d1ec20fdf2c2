r"""Frequency Gain Identification (FGI).

Brouri, Giri, Rochdi, Chaoui, *Frequency identification of nonparametric
Hammerstein systems with backlash nonlinearity*, Section IV, Table 2,
Proposition 2 and Remark 2.

The periodic staircase (24) visits the NBBI levels in the order of (4a-b), so the
backlash output $u$ is a periodic staircase on the same levels. It is the staircase
of the NBBI values (9)-(11) when the descending path meets $f_d$ by $v_m$; in
general `steady_cycle_values` rebuilds its steady-state period from them by the
play operator's logic (or says that it cannot). Its exact Fourier coefficients $(a_k, b_k)$ (13) and those $(\alpha_k(M),
\beta_k(M))$ (22) of the trans-period average $y_f(t, M)$ (20) of the steady-state
output give $\hat G_M(jk\omega)$ by (25)-(26), i.e.
$\hat G_M = (\alpha_k - j\beta_k)/(a_k - j b_k)$.
"""

import math
from typing import Literal

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Bool, Complex, Float, Int

from ..._results import RESULTS
from .fourier_13_22 import (
    piecewise_constant_coefficients,
    sampled_coefficients,
    segment_weights,
)


def steady_cycle_values(
    cycle_values: Float[ArrayLike, " m"],
    *,
    cycle_stderr: Float[ArrayLike, " m"] | None = None,
    z: float = 4.0,
    max_periods: int = 3,
) -> tuple[Float[Array, " m"], Bool[Array, ""]]:
    """The backlash output over one steady-state period of (24) from NBBI's points:
    `(values, ok)` with `values = cycle_values[i]` for the indices `i` of
    `steady_cycle_indices` (which see), the $W_i$ where `ok` is false."""
    w = jnp.asarray(cycle_values, dtype=float)
    index, ok, _ = steady_cycle_indices(
        w, cycle_stderr=cycle_stderr, z=z, max_periods=max_periods
    )
    return w[index], ok


def steady_cycle_indices(
    cycle_values: Float[ArrayLike, " m"],
    *,
    cycle_stderr: Float[ArrayLike, " m"] | None = None,
    z: float = 4.0,
    max_periods: int = 3,
) -> tuple[Int[Array, " m"], Bool[Array, ""], Int[Array, ""]]:
    r"""Which of NBBI's points the backlash output takes on each segment of one
    steady-state period of (24).

    NBBI measures the first cycle $W_1..W_{2n-2}$ after (3), which leaves point 1 on
    $f_d(v_m)$ (Fig. 5). In the periodic regime of (24) the input falls from $V_2$
    to $V_1$ at each period start: if the descending path has met $f_d$ by then, or
    if $f_d(v_m) = W_1$ lies below the output at $V_2$, the point returns to
    $(V_1, W_1)$ and the cycle repeats ($u$ is the staircase of the $W_i$).
    Otherwise the input reverses before the output reaches the border: $u$ stays
    at its value at $V_2$ (the inner, horizontal segment) and the next period
    differs from the first. The periods are then rebuilt by the play operator's
    rules (seed 000, Section II; `hamjax.models.Backlash`): a step in the
    direction of the last move follows that border; otherwise the point moves onto
    the border $f$ of the new direction iff $f(V) \ge u$ rising ($\le u$ falling),
    else stays. The borders are known at the levels where the first cycle moved
    ($f = W_i$); where it did not, only the side of $W_{i-1}$ they lie on is known,
    which decides the step when $u$ is beyond $W_{i-1}$ on the same side. The
    orientation (a gain $k < 0$ after $(kF, G/k)$ flips it) is that of the first
    move of the ascending path.

    **Arguments:**

    - `cycle_values`: the $W_i$ in staircase order (NBBI's `cycle_values`).
    - `cycle_stderr`: their standard errors; two values within `z` standard errors
      of a difference are equal (no move). Without it, equal to 1e-9 relative.
    - `max_periods`: periods after the first tried before giving up.

    **Returns:** `(index, ok, first)`: $u = W_{\mathrm{index}_j}$ on segment $j$ of
    one steady-state period (staircase order; every value of $u$ is one of the
    $W_i$, so $u$ is a selection of them, differentiable in them), whether it
    could be rebuilt (`ok`; `index` is $0..m-1$ where not), and the first period
    of (24) after (3) that is steady (0: the first, which is NBBI's cycle).
    """
    w = jnp.asarray(cycle_values, dtype=float)
    m = w.shape[0]
    n = m // 2 + 1
    tol = 1e-9 * jnp.max(jnp.abs(w))
    if cycle_stderr is not None:
        tol = tol + z * math.sqrt(2.0) * jnp.max(jnp.asarray(cycle_stderr, float))
    rising = (jnp.arange(m) > 0) & (jnp.arange(m) < n)
    same = rising == jnp.roll(rising, 1)
    w_prev = jnp.roll(w, 1)  # W_{j-1}, cyclically
    moved = jnp.abs(w - w_prev) > tol

    # Period 1: the border of step j's direction is known at V_j (= W_j) iff the
    # step moved (W_j != W_{j-1}) or followed that border from V_{j-1}; step 0
    # (v_M to v_m in (3)) put point 1 on f_d(v_m).
    def _known(prev, xs):
        mv, sm = xs
        k = mv | (prev & sm)
        return k, k

    _, known = jax.lax.scan(_known, jnp.asarray(True), (moved[1:], same[1:]))
    known = jnp.concatenate([jnp.ones(1, bool), known])
    # Orientation: sign of the first move of the ascending path (+1 if none).
    up = moved & rising
    sign = jnp.where(jnp.any(up), jnp.sign((w - w_prev)[jnp.argmax(up)]), 1.0)
    d = jnp.where(rising, sign, -sign)  # d*(f - u) >= 0: the border is reached

    def _step(carry, xs):
        x, xi, on, matched, fail = carry
        w_j, w_jm1, j, known_j, same_j, d_j, prev_u, prev_i, prev_on = xs
        follow = on & same_j
        onto = d_j * (w_j - x) >= -tol
        # Border unknown at V_j: period 1 stayed at W_{j-1} off it, so
        # d*f(V_j) < d*W_{j-1}; u stays if d*u >= d*W_{j-1}, else it is unknown.
        stays = d_j * (x - w_jm1) >= -tol
        take = known_j & (follow | onto)
        unknown = ~known_j & (follow | ~stays)
        u = jnp.where(matched, prev_u, jnp.where(take, w_j, x))
        ui = jnp.where(matched, prev_i, jnp.where(take, j, xi))
        on = jnp.where(matched, prev_on, take)
        fail = fail | (~matched & unknown)
        matched = matched | ((jnp.abs(u - prev_u) <= tol) & (on == prev_on))
        return (u, ui, on, matched, fail), (ui, on, matched)

    steps = jnp.arange(m)

    def _period(carry, period):
        prev_u, prev_i, prev_on, ok, broken, steady, first = carry
        init = (
            prev_u[m - 1],
            prev_i[m - 1],
            prev_on[m - 1],
            jnp.asarray(False),
            jnp.asarray(False),
        )
        xs = (w, w_prev, steps, known, same, d, prev_u, prev_i, prev_on)
        (_, _, _, matched, fail), (uis, ons, hist) = jax.lax.scan(_step, init, xs)
        broken = broken | fail  # a step undecided: later periods are unknown too
        newly = matched & ~broken & ~ok
        # The state at the first matched step repeats the last period's there, so
        # this period is steady throughout (and the last one too if at step 0).
        steady = jnp.where(newly, uis, steady)
        first = jnp.where(newly, jnp.where(hist[0], period - 1, period), first)
        return (w[uis], uis, ons, ok | newly, broken, steady, first), None

    false = jnp.asarray(False)
    init = (w, steps, known, false, false, steps, jnp.asarray(0))
    periods = jnp.arange(1, max_periods + 1)
    (_, _, _, ok, _, steady, first), _ = jax.lax.scan(_period, init, periods)
    return steady, ok, first


class FGIResult(eqx.Module):
    r"""$\hat G_M(jk\omega)$ at the candidate harmonics $k = 1..K$ of one $\omega$.

    - `omega`: the fundamental $\omega = 2\pi/T$ actually used (rad/s).
    - `harmonics`: $k = 1..K$.
    - `g`: $\hat G_M(jk\omega)$ (NaN where not kept).
    - `keep`: harmonics kept by Remark 2b's Parseval rule and not negligible.
    - `order`: Parseval's $p$ (Remark 2b).
    - `cycle_values`: $u$ over one steady-state period (`steady_cycle_values` of
      the NBBI points given).
    - `a`, `b`: Eq. (13) of the reconstructed $u$; `alpha`, `beta`: Eq. (22).
    - `result`: `RESULTS.successful`, `not_exciting` (no harmonic kept),
      `cycle_not_rebuilt` (`steady_cycle_values` cannot rebuild $u$) or
      `nonfinite`.
    """

    omega: Float[Array, ""]
    harmonics: Int[Array, " k"]
    g: Complex[Array, " k"]
    keep: Bool[Array, " k"]
    order: Int[Array, ""]
    cycle_values: Float[Array, " m"]
    a: Float[Array, " k"]
    b: Float[Array, " k"]
    alpha: Float[Array, " k"]
    beta: Float[Array, " k"]
    result: RESULTS

    def frequency_response(self) -> list[dict]:
        """The kept entries as `{omega, k, base_omega, re, im}` (the contract)."""
        w = float(self.omega)
        out = []
        for k, g, keep in zip(self.harmonics, self.g, self.keep, strict=True):
            if bool(keep):
                out.append(
                    {
                        "omega": int(k) * w,
                        "k": int(k),
                        "base_omega": w,
                        "re": float(jnp.real(g)),
                        "im": float(jnp.imag(g)),
                    }
                )
        return out


def trans_period_average(
    y: Float[Array, " time"], *, start: int, period_samples: int, periods: int
) -> Float[Array, " period"]:
    """Eq. (20): $y_f(t, M) = \\frac1M \\sum_{i=1}^M y(t + (i-1)T)$ on one period."""
    end = start + periods * period_samples
    if start < 0 or end > y.shape[0]:
        raise ValueError(
            f"`y` has {y.shape[0]} samples; {periods} periods of {period_samples} "
            f"from sample {start} need {end}"
        )
    return jnp.mean(y[start:end].reshape(periods, period_samples), axis=0)


def identify_fgi(
    y: Float[ArrayLike, " time"],
    cycle_values: Float[ArrayLike, " m"],
    *,
    period_samples: int,
    periods: int,
    dt: float,
    start: int = 0,
    epsilon: float = 0.05,
    max_harmonic: int = 64,
    cycle_stderr: Float[ArrayLike, " m"] | None = None,
    z: float = 4.0,
    rtol: float = 1e-10,
    quadrature: Literal["hold", "rectangle"] = "rectangle",
    throw: bool = True,
) -> FGIResult:
    r"""Table 2, step 3: $\hat G_M(jk\omega)$ from the steady-state output.

    **Arguments:**

    - `y`: output samples, shape `(time,)`; the $M$ averaged periods start at sample
      `start`, which must be a period boundary of the input (24) (i.e. after the
      initialisation and the discarded transient periods).
    - `cycle_values`: $U_1..U_{2n-2}$ of (9) in staircase order (NBBI's
      `cycle_values`), so $u = U_i$ on $[(i-1)\tau, i\tau)$ (11) in the first
      period; the steady-state $u$ is rebuilt from them (`steady_cycle_values`).
    - `period_samples`: $T/dt$, a multiple of $2n-2$ (see `fgi_period_samples`).
    - `periods`: $M$ of (20).
    - `dt`: sampling period (s).
    - `epsilon`: Remark 2b: keep $k \le p$, the smallest $p$ whose partial Parseval
      sum (27) reaches $(1-\varepsilon)$ of the power of $u$.
    - `max_harmonic`: the largest $k$ considered (also capped below $P/2$).
    - `cycle_stderr`: standard errors of the $U_i$ (NBBI's `stderr`); a harmonic
      whose $|a_k - j b_k|$ is within `z` standard errors of 0 is negligible, and
      two $U_i$ within `z` standard errors of a difference are equal when $u$ is
      rebuilt.
    - `rtol`: a harmonic whose power is below `rtol` times that of $u$ is
      negligible (round-off: e.g. even harmonics of a half-wave antisymmetric
      cycle). Negligible harmonics are dropped, never divided by.
    - `quadrature`: how (22) integrates the samples, see `sampled_coefficients`:
      `"rectangle"` (default: the periodic rectangle rule on the samples of the
      continuous $y$, aliasing error only) or `"hold"` ($y$ held over each
      sample, relative error about $k\omega\,dt/2$).
    - `throw`: raise on failure; otherwise report it in `.result`.

    **Returns:** an `FGIResult`.
    """
    m = jnp.asarray(cycle_values).shape[0]
    if m < 4 or m % 2:
        raise ValueError(f"need the 2n-2 >= 4 cycle values of NBBI; got {m}")
    if period_samples < m or period_samples % m:
        raise ValueError(
            f"period of {period_samples} samples must be a positive multiple of "
            f"2n-2 = {m} (fewer than 2n-2 samples per period: omega too high for dt)"
        )
    if periods < 1:
        raise ValueError(f"periods M must be >= 1; got {periods}")
    if not (math.isfinite(dt) and dt > 0):
        raise ValueError(f"sampling period dt must be > 0; got {dt}")
    if not 0 < epsilon < 1:
        raise ValueError(f"epsilon must be in (0, 1); got {epsilon}")
    n_harm = min(max_harmonic, (period_samples - 1) // 2)
    if n_harm < 1:
        raise ValueError(
            f"a period of {period_samples} samples resolves no harmonic; lower omega"
        )
    return _fgi(
        jnp.asarray(y, dtype=float),
        jnp.asarray(cycle_values, dtype=float),
        None if cycle_stderr is None else jnp.asarray(cycle_stderr, dtype=float),
        period_samples=int(period_samples),
        periods=int(periods),
        dt=float(dt),
        start=int(start),
        epsilon=float(epsilon),
        n_harm=int(n_harm),
        z=float(z),
        rtol=float(rtol),
        quadrature=quadrature,
        throw=bool(throw),
    )


@eqx.filter_jit
def _fgi(
    y,
    values,
    cycle_stderr,
    *,
    period_samples,
    periods,
    dt,
    start,
    epsilon,
    n_harm,
    z,
    rtol,
    quadrature,
    throw,
) -> FGIResult:
    """The numerics of `identify_fgi` (validated arguments), compiled once per design."""
    m = values.shape[0]
    values, rebuilt = steady_cycle_values(values, cycle_stderr=cycle_stderr, z=z)
    period = period_samples * dt
    omega = 2 * math.pi / period
    k = jnp.arange(1, n_harm + 1)
    edges = jnp.arange(m + 1, dtype=float) * (period / m)

    # Eq. (9)-(11), (13): u is the staircase of the U_i, its coefficients exact.
    a, b = piecewise_constant_coefficients(values, edges, omega, k)
    a0 = 2 * jnp.mean(values)
    power = jnp.mean(values**2)  # (1/T) int u^2: equal segments tau
    # Eq. (27), Remark 2b: the smallest p with a0^2/4 + sum_{k<=p} (.)/2 >= (1-eps) P.
    partial = a0**2 / 4 + jnp.cumsum((a**2 + b**2) / 2)
    reached = partial >= (1 - epsilon) * power
    order = jnp.where(jnp.any(reached), jnp.argmax(reached) + 1, n_harm)
    c2 = a**2 + b**2
    negligible = c2 / 2 <= rtol * power
    if cycle_stderr is not None:
        # Var of c_k from independent errors in the U_i (c_k is linear in them).
        weights = segment_weights(edges, omega, k)
        sd2 = cycle_stderr**2
        var = jnp.abs(weights) ** 2 @ sd2
        negligible = negligible | (c2 <= z**2 * var)
    keep = (k <= order) & ~negligible

    # Eq. (20), (22): trans-period average and its Fourier coefficients.
    y_f = trans_period_average(
        y, start=start, period_samples=period_samples, periods=periods
    )
    alpha, beta = sampled_coefficients(y_f, k, quadrature=quadrature)

    # Eq. (25)-(26): modulus and phase; the same as (alpha - j beta)/(a - j b).
    safe_c = jnp.where(keep, jnp.sqrt(c2), 1.0)
    r_y = jnp.sqrt(alpha**2 + beta**2)
    safe_r = jnp.where(r_y > 0, r_y, 1.0)
    modulus = r_y / safe_c
    cos_phase = (a * alpha + b * beta) / (safe_c * safe_r)
    sin_phase = (b * alpha - a * beta) / (safe_c * safe_r)
    g = modulus * (cos_phase + 1j * sin_phase)
    g = jnp.where(keep, g, jnp.nan + 0j)

    finite = jnp.all(jnp.where(keep, jnp.isfinite(jnp.abs(g)), True))
    result = RESULTS.where(
        finite,
        RESULTS.where(
            rebuilt,
            RESULTS.where(jnp.any(keep), RESULTS.successful, RESULTS.not_exciting),
            RESULTS.cycle_not_rebuilt,
        ),
        RESULTS.nonfinite,
    )
    if throw:
        g = result.error_if(g, result != RESULTS.successful)
    return FGIResult(
        omega=jnp.asarray(omega),
        harmonics=k,
        g=g,
        keep=keep,
        order=jnp.asarray(order),
        cycle_values=values,
        a=a,
        b=b,
        alpha=alpha,
        beta=beta,
        result=result,
    )
