r"""Seed 000 refinement: $G(jk\omega)$ at the FGI harmonics jointly with the $U_i$.

Brouri, Giri, Rochdi, Chaoui, *Frequency identification of nonparametric
Hammerstein systems with backlash nonlinearity*, Tables 1-2, eqs. (5), (13), (22),
(25)-(26).

One likelihood holds both records. In the NBBI record (3), (4a-b) the output
settles at $G(0) U_i$ in each hold; the first `settle` samples of each hold (the
transient, which a nonparametric $G$ cannot describe) are left out. In the FGI
record (24), after its transient periods, $u$ is the $T$-periodic staircase of the
$U_i$ with Fourier coefficients $c_k = a_k - j b_k = \sum_i U_i e_{ki}$ (13), so
the steady-state output is

$$y(t) = G(0)\,\frac{a_0}{2} + \sum_k \mathrm{Re}\big(G(jk\omega)\, c_k\,
e^{jk\omega t}\big),$$

kept to the harmonics that FGI keeps (Remark 2b). Where the input reverses before
the descending path meets $f_d$, the periodic $u$ is not the NBBI staircase but a
selection $U_{\pi(j)}$ of its values (`steady_cycle_indices`, the play operator's
rule): `fgi_cycle` holds $\pi$, decided once from the closed form. The harmonics
left out are orthogonal to the kept ones over whole periods of uniform samples, so they do not
bias the fit; they only add to its residual (hence `replicate_noise_variance`).
"""

import math
from collections.abc import Sequence

import equinox as eqx
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Bool, Complex, Float

from .._types import Params, Signal
from ..identification.seed000.fourier_13_22 import segment_weights
from ._parametrisation import AbstractParametrisation


class FGIBlock(eqx.Module):
    """One FGI frequency block of the record (24).

    - `period_samples`: $P = T/dt$, a multiple of $2n-2$.
    - `periods`: $M$, the whole periods fitted (those averaged by (20)).
    - `start`: index in the FGI record of the first fitted sample (a period start).
    - `harmonics`: the $k$ whose $G(jk\\omega)$ is estimated (FGI's kept ones).
    """

    period_samples: int = eqx.field(static=True)
    periods: int = eqx.field(static=True)
    start: int = eqx.field(static=True)
    harmonics: tuple[int, ...] = eqx.field(static=True)

    def __check_init__(self):
        if self.periods < 1:
            raise ValueError(f"periods must be >= 1; got {self.periods}")
        if self.start < 0:
            raise ValueError(f"start must be >= 0; got {self.start}")
        if not self.harmonics:
            raise ValueError("an FGI block needs at least one harmonic k >= 1")
        if any(k < 1 or 2 * k >= self.period_samples for k in self.harmonics):
            raise ValueError(
                f"harmonics must satisfy 1 <= k < P/2 = {self.period_samples / 2:g}; "
                f"got {self.harmonics}"
            )
        if len(set(self.harmonics)) != len(self.harmonics):
            raise ValueError(f"harmonics must be distinct; got {self.harmonics}")


class FGIFrequencyParametrisation(AbstractParametrisation):
    r"""$\theta = (U_1..U_{2n-2}, \mathrm{Re}\,G_1, \mathrm{Im}\,G_1, \dots)$ with
    $G_j = G(jk\omega)$ for each block and kept harmonic in turn.

    The normalisation $G(0) = 1$ (Section II) is a constraint eliminated here:
    $G(0)$ is not a parameter, the NBBI levels are $U_i$ and the FGI mean is
    $a_0/2 = \frac{1}{2n-2}\sum_i U_i$ (equal segments $\tau$). Reported
    (`to_physical`) is $\theta$ itself.

    `predict(theta, v)` ignores `v` (the design fixes where each sample lies) and
    returns the fitted samples in the order of `select`: the settled NBBI samples,
    then each block's $M P$ samples.

    **Arguments:**

    - `n_levels`: $n$.
    - `nbbi_start`: index of the first staircase sample of the NBBI record (after
      the initialisation (3)).
    - `hold_samples`: $N T_r/dt$.
    - `settle_samples`: samples left out at the start of each hold.
    - `blocks`: the `FGIBlock`s.
    - `dt`: sampling period (s) of the FGI record.
    - `fgi_cycle`: $\pi$, the index of the $U_i$ that $u$ takes on each segment of
      the FGI period (`steady_cycle_indices`); default $0..2n-3$, the NBBI
      staircase itself.
    - `average_replicates`: fit the sufficient statistics instead of the samples:
      each hold's mean of its $N_s$ settled samples and each block's trans-period
      average (20) over its $M$ periods, weighted by $\sqrt{N_s}$ and $\sqrt{M}$.
      Since $\sum_j (y_j - \mu)^2 = \sum_j (y_j - \bar y)^2 + n(\bar y - \mu)^2$,
      the criterion differs from the per-sample one by a constant, so the estimate
      and the Fisher information $J^\top J/\sigma^2$ are the same, at a cost of
      $2n-2 + \sum P$ residuals instead of $(2n-2)N_s + \sum MP$.
    """

    weights: tuple[Complex[Array, "k m"], ...]
    phasors: tuple[Complex[Array, "period k"], ...]
    n_levels: int = eqx.field(static=True)
    nbbi_start: int = eqx.field(static=True)
    hold_samples: int = eqx.field(static=True)
    settle_samples: int = eqx.field(static=True)
    blocks: tuple[FGIBlock, ...] = eqx.field(static=True)
    dt: float = eqx.field(static=True)
    fgi_cycle: tuple[int, ...] = eqx.field(static=True)
    average_replicates: bool = eqx.field(static=True)

    def __init__(
        self,
        *,
        n_levels: int,
        nbbi_start: int,
        hold_samples: int,
        settle_samples: int,
        blocks: Sequence[FGIBlock],
        dt: float,
        fgi_cycle: Sequence[int] | None = None,
        average_replicates: bool = True,
    ):
        self.n_levels = int(n_levels)
        self.nbbi_start = int(nbbi_start)
        self.hold_samples = int(hold_samples)
        self.settle_samples = int(settle_samples)
        self.blocks = tuple(blocks)
        self.dt = float(dt)
        self.average_replicates = bool(average_replicates)
        m = 2 * self.n_levels - 2
        self.fgi_cycle = tuple(
            range(m) if fgi_cycle is None else (int(i) for i in fgi_cycle)
        )
        weights, phasors = [], []
        for b in self.blocks:
            k = np.asarray(b.harmonics)
            # Eq. (13) on the grid of (24): segment i is [i tau, (i+1) tau), tau = T/m;
            # in units of T, so that omega = 2 pi.
            weights.append(segment_weights(jnp.arange(m + 1) / m, 2 * math.pi, k))
            j = np.arange(b.period_samples)[:, None]
            phasors.append(
                jnp.asarray(np.exp(2j * np.pi * k[None, :] * j / b.period_samples))
            )
        self.weights = tuple(weights)
        self.phasors = tuple(phasors)

    def __check_init__(self):
        if self.n_levels < 3:
            raise ValueError(f"need n_levels >= 3; got {self.n_levels}")
        if self.nbbi_start < 0:
            raise ValueError(f"nbbi_start must be >= 0; got {self.nbbi_start}")
        if not 0 <= self.settle_samples < self.hold_samples:
            raise ValueError(
                f"settle_samples must be in [0, hold_samples = {self.hold_samples}); "
                f"got {self.settle_samples}"
            )
        if not self.blocks:
            raise ValueError("need at least one FGI block")
        m = 2 * self.n_levels - 2
        for b in self.blocks:
            if b.period_samples % m:
                raise ValueError(
                    f"period of {b.period_samples} samples must be a multiple of "
                    f"2n-2 = {m}"
                )
        if not self.dt > 0:
            raise ValueError(f"sampling period dt must be > 0; got {self.dt}")
        if len(self.fgi_cycle) != m or not all(0 <= i < m for i in self.fgi_cycle):
            raise ValueError(
                f"fgi_cycle must hold 2n-2 = {m} indices in [0, {m}); got "
                f"{self.fgi_cycle}"
            )

    @property
    def n_cycle(self) -> int:
        return 2 * self.n_levels - 2

    @property
    def omegas(self) -> tuple[float, ...]:
        """The fundamental $\\omega = 2\\pi/(P\\,dt)$ of each block (rad/s)."""
        return tuple(2 * math.pi / (b.period_samples * self.dt) for b in self.blocks)

    @property
    def harmonic_list(self) -> tuple[tuple[int, float, int], ...]:
        """`(block, omega, k)` of each estimated $G(jk\\omega)$, in $\\theta$ order."""
        return tuple(
            (i, w, k)
            for i, (b, w) in enumerate(zip(self.blocks, self.omegas, strict=True))
            for k in b.harmonics
        )

    @property
    def names(self) -> tuple[str, ...]:
        out = [f"U{i + 1}" for i in range(self.n_cycle)]
        for _, w, k in self.harmonic_list:
            out += [f"re G({k}x{w:.4g})", f"im G({k}x{w:.4g})"]
        return tuple(out)

    @property
    def n_samples(self) -> int:
        """Length of `select`'s output and of `predict`'s."""
        if self.average_replicates:
            return self.n_cycle + sum(b.period_samples for b in self.blocks)
        return self.n_record_samples

    @property
    def n_record_samples(self) -> int:
        """Samples of the two records that enter the fit (averaged or not)."""
        per = self.hold_samples - self.settle_samples
        return self.n_cycle * per + sum(
            b.periods * b.period_samples for b in self.blocks
        )

    def nbbi_indices(self) -> np.ndarray:
        """Indices in the NBBI record of the settled samples, hold by hold (4a-b)."""
        per = self.hold_samples
        first = self.nbbi_start + per * np.arange(self.n_cycle)[:, None]
        return (first + np.arange(self.settle_samples, per)[None, :]).reshape(-1)

    def select(
        self, y_nbbi: Float[ArrayLike, " time_nbbi"], y_fgi: Float[ArrayLike, " time"]
    ) -> Signal:
        """The data fitted from both records, in `predict`'s order: the samples,
        or their weighted averages (`average_replicates`).

        **Raises:** `ValueError` if a record is too short for the design.
        """
        holds, periods = self._replicates(y_nbbi, y_fgi)
        if not self.average_replicates:
            return jnp.concatenate(
                [holds.reshape(-1), *(r.reshape(-1) for r in periods)]
            )
        parts = [math.sqrt(holds.shape[1]) * jnp.mean(holds, axis=1)]
        for r in periods:
            parts.append(math.sqrt(r.shape[0]) * jnp.mean(r, axis=0))  # Eq. (20)
        return jnp.concatenate(parts)

    def _replicates(self, y_nbbi, y_fgi):
        """Settled samples `(holds, per)` and, per block, `(periods, period)`."""
        y_nbbi = jnp.asarray(y_nbbi, dtype=float)
        y_fgi = jnp.asarray(y_fgi, dtype=float)
        need = self.nbbi_start + self.n_cycle * self.hold_samples
        if y_nbbi.ndim != 1 or y_nbbi.shape[0] < need:
            raise ValueError(
                f"the NBBI record has shape {y_nbbi.shape}; the staircase needs {need} "
                "samples"
            )
        holds = y_nbbi[self.nbbi_indices()].reshape(self.n_cycle, -1)
        periods = []
        for b in self.blocks:
            end = b.start + b.periods * b.period_samples
            if y_fgi.ndim != 1 or y_fgi.shape[0] < end:
                raise ValueError(
                    f"the FGI record has shape {y_fgi.shape}; the block at sample "
                    f"{b.start} needs {end} samples"
                )
            periods.append(y_fgi[b.start : end].reshape(b.periods, b.period_samples))
        return holds, periods

    def _split(self, theta: Params):
        m = self.n_cycle
        u = theta[:m]
        g, off = [], m
        for b in self.blocks:
            n = len(b.harmonics)
            pairs = theta[off : off + 2 * n]
            g.append(pairs[0::2] + 1j * pairs[1::2])
            off += 2 * n
        return u, g

    def predict(self, theta: Params, v: Signal) -> Signal:
        del v  # the design fixes where each fitted sample lies
        u, g = self._split(theta)
        per = self.hold_samples - self.settle_samples
        avg = self.average_replicates
        # Eq. (5) in steady state with G(0) = 1: y = U_i in hold i.
        parts = [math.sqrt(per) * u if avg else jnp.repeat(u, per)]
        us = u[jnp.asarray(self.fgi_cycle)]  # the periodic u of (24)
        mean = jnp.mean(us)  # G(0) a_0 / 2 with G(0) = 1, equal segments
        uc = us.astype(jnp.complex128)
        for b, W, E, gb in zip(self.blocks, self.weights, self.phasors, g, strict=True):
            c = W @ uc  # Eq. (13): c_k = a_k - j b_k of the staircase of the U_i
            one = mean + jnp.real(E @ (gb * c))  # steady state, cf. (22)-(26)
            parts.append(
                math.sqrt(b.periods) * one if avg else jnp.tile(one, b.periods)
            )
        return jnp.concatenate(parts)

    def to_physical(self, theta: Params) -> Float[Array, " n_physical"]:
        return theta

    def from_physical(self, physical: Float[Array, " n_physical"]) -> Params:
        return jnp.asarray(physical, dtype=float)

    def pack(
        self, cycle_values: Float[ArrayLike, " m"], g: Sequence[ArrayLike]
    ) -> Params:
        """$\\theta$ from the $U_i$ and, per block, $G(jk\\omega)$ at its harmonics."""
        cycle_values = jnp.asarray(cycle_values, dtype=float)
        if cycle_values.shape != (self.n_cycle,):
            raise ValueError(
                f"need the 2n-2 = {self.n_cycle} cycle values; got shape "
                f"{cycle_values.shape}"
            )
        if len(g) != len(self.blocks):
            raise ValueError(f"need one G array per block ({len(self.blocks)})")
        parts = [cycle_values]
        for b, gb in zip(self.blocks, g, strict=True):
            gb = jnp.asarray(gb)
            if gb.shape != (len(b.harmonics),):
                raise ValueError(
                    f"block with harmonics {b.harmonics}: G of shape {gb.shape}"
                )
            parts.append(jnp.stack([jnp.real(gb), jnp.imag(gb)], axis=-1).reshape(-1))
        return jnp.concatenate([jnp.asarray(x, dtype=float) for x in parts])

    def is_valid(self, theta: Params) -> Bool[Array, ""]:
        return jnp.all(jnp.isfinite(theta))

    def initial_theta(
        self, y_nbbi: Float[ArrayLike, " time_nbbi"], y_fgi: Float[ArrayLike, " time"]
    ) -> Params:
        """A start from the fitted data alone: $U_i$ the mean of the settled samples
        of hold $i$ (NBBI's settled average (5)), then $G(jk\\omega) = (\\alpha_k -
        j\\beta_k)/(a_k - j b_k)$ (25)-(26) with (22) on the trans-period average
        (20) and (13) of those $U_i$ (through `fgi_cycle`). Free of the plain
        average's transient bias, so the fit needs a few steps only.
        """
        _, periods = self._replicates(y_nbbi, y_fgi)
        u, _ = self.settled_cycle(y_nbbi, y_fgi)
        uc = u[jnp.asarray(self.fgi_cycle)].astype(jnp.complex128)
        g = []
        for r, W, E in zip(periods, self.weights, self.phasors, strict=True):
            y_f = jnp.mean(r, axis=0).astype(jnp.complex128)  # Eq. (20)
            coeff = (2.0 / r.shape[1]) * (jnp.conj(E).T @ y_f)  # Eq. (22), rectangle
            g.append(coeff / (W @ uc))  # Eq. (25)-(26)
        return self.pack(u, g)

    def settled_cycle(
        self, y_nbbi: Float[ArrayLike, " time_nbbi"], y_fgi: Float[ArrayLike, " time"]
    ) -> tuple[Float[Array, " m"], Float[Array, " m"]]:
        """The settled average (5) of each hold, $\\bar y_i$ over its $N_s$ settled
        samples, and its standard error $\\hat\\sigma/\\sqrt{N_s}$
        (`replicate_noise_variance`)."""
        holds, _ = self._replicates(y_nbbi, y_fgi)
        se = jnp.sqrt(self.replicate_noise_variance(y_nbbi, y_fgi) / holds.shape[1])
        return jnp.mean(holds, axis=1), jnp.full(holds.shape[0], se)

    def replicate_noise_variance(
        self, y_nbbi: Float[ArrayLike, " time_nbbi"], y_fgi: Float[ArrayLike, " time"]
    ) -> Float[Array, ""]:
        """$\\hat\\sigma^2$ from the replicates alone (model-free, white noise): the
        spread of the settled NBBI samples about their hold means and of the FGI
        periods about their average (20), pooled. Unlike rss/(N-p), it is not
        inflated by the harmonics the model leaves out.
        """
        holds, periods = self._replicates(y_nbbi, y_fgi)
        ss = jnp.sum((holds - jnp.mean(holds, axis=1, keepdims=True)) ** 2)
        dof = holds.shape[0] * (holds.shape[1] - 1)
        for r in periods:
            ss = ss + jnp.sum((r - jnp.mean(r, axis=0, keepdims=True)) ** 2)
            dof += (r.shape[0] - 1) * r.shape[1]
        return ss / max(dof, 1)
