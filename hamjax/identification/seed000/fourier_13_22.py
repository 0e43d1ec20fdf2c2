r"""Exact Fourier coefficients of periodic piecewise-constant signals.

Seed 000 (Brouri, Giri, Rochdi, Chaoui), eqs. (13) and (22). With the complex
coefficient $c_k = a_k - j b_k = \frac{2}{T}\int_0^T x(t) e^{-jk\omega t}\,dt$, a
signal equal to $x_i$ on $[t_i, t_{i+1})$ has, for $k \ge 1$,

$$c_k = \frac{2}{T} \sum_i x_i \frac{e^{-jk\omega t_i} - e^{-jk\omega t_{i+1}}}{jk\omega},$$

and $c_0 = a_0 = \frac{2}{T}\sum_i x_i (t_{i+1} - t_i)$.
"""

from typing import Literal

import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Complex, Float, Int


def segment_weights(
    edges: Float[ArrayLike, " m_plus_1"],
    omega: float | Float[ArrayLike, ""],
    harmonics: Int[ArrayLike, " k"],
) -> Complex[Array, "k m"]:
    r"""$e_{ki}$ with $c_k = \sum_i x_i e_{ki}$ for segments $[t_i, t_{i+1})$ (Eq. (13)).

    `edges` are $t_0 = 0 < t_1 < \dots < t_m = T$ with $T = 2\pi/\omega$.
    """
    edges = jnp.asarray(edges, dtype=float)
    omega = jnp.asarray(omega, dtype=float)
    period = edges[-1] - edges[0]
    k = jnp.asarray(harmonics)[:, None].astype(float)
    t0, t1 = edges[None, :-1], edges[None, 1:]
    kw = k * omega
    safe = jnp.where(kw == 0, 1.0, kw)
    # exp(-j k w t0) - exp(-j k w t1) over j k w; the k = 0 limit is the segment length.
    diff = jnp.exp(-1j * kw * t0) - jnp.exp(-1j * kw * t1)
    integral = jnp.where(kw == 0, (t1 - t0) + 0j, diff / (1j * safe))
    return (2.0 / period) * integral


def piecewise_constant_coefficients(
    values: Float[ArrayLike, " m"],
    edges: Float[ArrayLike, " m_plus_1"],
    omega: float | Float[ArrayLike, ""],
    harmonics: Int[ArrayLike, " k"],
) -> tuple[Float[Array, " k"], Float[Array, " k"]]:
    r"""Exact $(a_k, b_k)$ of Eq. (13) for a $T$-periodic piecewise-constant signal.

    **Arguments:**

    - `values`: $x_i$, the value on segment $i$, shape `(m,)`.
    - `edges`: segment boundaries $0 = t_0 < \dots < t_m = T$ (s), shape `(m+1,)`.
    - `omega`: fundamental $\omega = 2\pi/T$ (rad/s).
    - `harmonics`: the $k$ wanted (integers $\ge 0$).

    **Returns:** `(a, b)`, each of shape `(k,)`; $b_0 = 0$.
    """
    values = jnp.asarray(values, dtype=float)
    c = segment_weights(edges, omega, harmonics) @ values
    return jnp.real(c), -jnp.imag(c)


def sampled_coefficients(
    samples: Float[Array, " period"],
    harmonics: Int[ArrayLike, " k"],
    *,
    quadrature: Literal["hold", "rectangle"] = "hold",
) -> tuple[Float[Array, " k"], Float[Array, " k"]]:
    r"""$(\alpha_k, \beta_k)$ of Eq. (22) from one period of uniform samples.

    With `quadrature="hold"` (the ZOH convention) sample $y_j$ is held on
    $[j\,dt, (j+1)\,dt)$ and the integral (22) of that staircase is taken exactly:
    $c_k = \frac{2}{P}\,\mathrm{DFT}_k(y)\, e^{-j\theta/2}\,\mathrm{sinc}(\theta/2)$ with
    $\theta = k\omega\,dt = 2\pi k/P$. For a smooth $y$ this is the coefficient of
    $y$ delayed by $dt/2$ and low-passed: a relative error of about $k\omega\,dt/2$
    (phase) plus $(k\omega\,dt)^2/24$ (gain). With `"rectangle"` the periodic
    rectangle rule $\frac{2}{P}\mathrm{DFT}_k$ is used, whose only error is the
    aliasing of harmonics $k \pm P, k \pm 2P, \dots$.

    **Arguments:**

    - `samples`: $y_f(j\,dt)$, $j = 0..P-1$, one period of $P$ samples.
    - `harmonics`: integers $0 \le k < P/2$.

    **Returns:** `(alpha, beta)`, each of shape `(k,)`.
    """
    samples = jnp.asarray(samples, dtype=float)
    n = samples.shape[0]
    k = jnp.asarray(harmonics)
    dft = jnp.fft.rfft(samples)[k]
    c = (2.0 / n) * dft
    if quadrature == "hold":
        theta = 2 * jnp.pi * k.astype(float) / n
        safe = jnp.where(theta == 0, 1.0, theta)
        hold = jnp.where(theta == 0, 1.0 + 0j, (1 - jnp.exp(-1j * theta)) / (1j * safe))
        c = c * hold
    elif quadrature != "rectangle":
        raise ValueError(
            f"quadrature must be 'hold' or 'rectangle'; got {quadrature!r}"
        )
    return jnp.real(c), -jnp.imag(c)
