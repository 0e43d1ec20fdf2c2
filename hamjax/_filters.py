r"""The one linear filter of hamjax: the controllable canonical form, the exact
zero-order hold (matrix exponential) and direct form II transposed.

Each is written once, traceable in `jax.numpy`; `xp=numpy` (or the `_numpy` twin)
is the same computation on the host, kept only where a measured reason (given
beside it) needs it, and tested equal to the JAX path. The linear blocks of
`hamjax.models` step and discretise with these, and so do the diagnosis's
augmented model and its host-side nominal responses.

This module imports no other part of hamjax: `hamjax.models` imports it.
"""

from collections.abc import Callable

import jax.lax as lax
import jax.numpy as jnp
import jax.scipy.linalg as jsl
import numpy as np
from jaxtyping import Array, Float


def outer(
    coefficients: Float[Array, " n"], u: Float[Array, "*batch"]
) -> Float[Array, " n *batch"]:
    """$c_i u$ for every coefficient $c_i$: the state axis first, then the batch
    axes of `u` (none: the plain product)."""
    u = jnp.asarray(u)
    if u.ndim == 0:
        return coefficients * u
    return coefficients[(slice(None),) + (None,) * u.ndim] * u[None]


def companion(num, den, *, xp=jnp) -> tuple[Array, Array, Array, Array]:
    r"""Controllable canonical form `(A, B, C, D)` of the proper $\text{num}/\text{den}$
    (highest power first), the `scipy.signal.tf2ss` one: $A$ has $-\text{den}_{1:}$
    (made monic) in its first row and ones below the diagonal, $B = e_1$,
    $C = \text{num}_{1:} - \text{den}_{1:} d$, $D = d$ (`num` zero-padded in front
    to the length of `den`). `xp=numpy` on the host."""
    den, num = xp.asarray(den, dtype=float), xp.asarray(num, dtype=float)
    n = den.shape[0] - 1
    num = xp.concatenate([xp.zeros(n + 1 - num.shape[0]), num]) / den[0]
    den = den / den[0]
    d = num[0]
    if n == 0:  # a static gain
        return (
            xp.zeros((0, 0)),
            xp.zeros((0, 1)),
            xp.zeros((1, 0)),
            xp.reshape(d, (1, 1)),
        )
    A = xp.concatenate([-den[1:][None, :], xp.eye(n - 1, n)], axis=0)
    B = xp.eye(n, 1)
    C = (num[1:] - den[1:] * d)[None, :]
    return A, B, C, xp.reshape(d, (1, 1))


def expm_taylor(
    M: Float[Array, "n n"], *, squarings: int = 12, order: int = 10
) -> Float[Array, "n n"]:
    r"""Matrix exponential by a fixed Taylor series of $M / 2^s$ and $s$ squarings.

    No data-dependent branches, so it compiles small under `vmap`/`jvp`; exact to
    rounding for $\|M\| \lesssim 10^3$ (7e-13 relative to
    `jax.scipy.linalg.expm` on 5x5 normal matrices, the 12 fixed squarings
    multiplying the series' rounding). Measured by `benchmarks/expm_choice.py`
    (this shared 2-core machine, batch 512): under `jit(vmap(jvp))` on the
    diagnosis's 5x5 matrices it compiles in 1.3-2.5 s against 7.3-7.7 s for
    `jax.scipy.linalg.expm` (Padé with a branch on the norm, every branch computed
    under `vmap`) and runs in 40-45 ms against 19-65 ms (noisy): the augmented
    model's choice (`zoh(..., expm=expm_taylor)`), inside every Levenberg-Marquardt
    step. It is not `zoh`'s default: the fixed squarings leave rounding noise of
    ~1e-12 that a central difference with step 1e-6 turns into 6.5e-6 relative
    error (`test_grad_wrt_continuous_num_den` failed with it); Padé scales by the
    norm and is exact to rounding. Not jitted, so the augmented model's traced
    program is the one it had (called eagerly, its loops compile on every call:
    0.6 s each, measured; jitted, 0.007 ms).
    """
    A = M / 2.0**squarings

    def taylor(k, carry):  # term_k = term_{k-1} A / k
        term, E = carry
        term = term @ A / k.astype(M.dtype)
        return term, E + term

    eye = jnp.eye(M.shape[0], dtype=M.dtype)
    # Loops rather than unrolled products: the same arithmetic, a fraction of the
    # compiled program (this sits inside every Levenberg-Marquardt step).
    _, E = lax.fori_loop(1, order + 1, taylor, (eye, eye))
    return lax.fori_loop(0, squarings, lambda _, E: E @ E, E)


def zoh(
    A: Float[Array, "n n"],
    B: Float[Array, "n 1"],
    dt,
    *,
    xp=jnp,
    expm: Callable[[Array], Array] = jsl.expm,
) -> tuple[Float[Array, "n n"], Float[Array, "n 1"]]:
    r"""Exact zero-order hold of $\dot x = A x + B u$ at sampling period `dt`:
    $\exp\begin{pmatrix} A\,dt & B\,dt \\ 0 & 0 \end{pmatrix} =
    \begin{pmatrix} A_d & B_d \\ 0 & 1 \end{pmatrix}$.

    `expm`: the matrix exponential (traced; `expm_taylor` compiles smaller under
    `vmap`). `xp=numpy` runs `scipy.linalg.expm` on the host: the diagnosis
    discretises every continuous nominal once per case, and the JAX form compiled
    anew for each (~1 s per continuous case, measured when the twin was written)."""
    n = A.shape[0]
    if xp is np:
        import scipy.linalg  # not at import: `hamjax.models` imports this module

        M = np.zeros((n + 1, n + 1))
        M[:n, :n], M[:n, n:] = A * dt, B * dt
        E = scipy.linalg.expm(M)
    else:
        M = jnp.zeros((n + 1, n + 1), jnp.result_type(A, B, dt))
        E = expm(M.at[:n, :n].set(A * dt).at[:n, n:].set(B * dt))
    return E[:n, :n], E[:n, n:]


def zoh_tf(
    num, den, dt, *, xp=jnp, expm: Callable[[Array], Array] = jsl.expm
) -> tuple[Array, Array, Array, Array]:
    """The state space `(A_d, B_d, C, D)` of the proper continuous $\\text{num}/
    \\text{den}$ held over each sample: `zoh` of its `companion` form."""
    A, B, C, D = companion(num, den, xp=xp)
    Ad, Bd = zoh(A, B, dt, xp=xp, expm=expm)
    return Ad, Bd, C, D


def df2t_step(
    b: Float[Array, " n1"], a: Float[Array, " n1"], z: Float[Array, " n *batch"], u
) -> tuple[Float[Array, " n *batch"], Float[Array, "*batch"]]:
    r"""One sample of direct form II transposed for `b`, `a` of equal length
    (`a[0] = 1`) at the input sample `u`: $y_k = b_0 u_k + z_0$, then
    $z \leftarrow$ (z shifted up) $+ b_{1:} u_k - a_{1:} y_k$. `u` may carry batch
    axes (the state has them after its own). A length-1 `b` is a static gain (the
    state stays at zero)."""
    if b.shape[0] == 1:
        return z, b[0] * u
    y = b[0] * u + z[0]
    shifted = jnp.concatenate([z[1:], jnp.zeros_like(z[:1])], axis=0)
    return shifted + outer(b[1:], u) - outer(a[1:], y), y


def filter_scan(
    b: Float[Array, " n1"],
    a: Float[Array, " n1"],
    u: Float[Array, " time *batch"],
    z: Float[Array, " n *batch"],
) -> tuple[Float[Array, " n *batch"], Float[Array, " time *batch"]]:
    """Direct form II transposed over `u` from state `z`: `(z_end, y)`. From
    `z = 0` this is `scipy.signal.lfilter(b, a, u)`; chaining the state over
    consecutive blocks of `u` gives the output of one call on the whole record."""
    return lax.scan(lambda z, uk: df2t_step(b, a, z, uk), z, u)


def lfilter_numpy(b: np.ndarray, a: np.ndarray, u: np.ndarray) -> np.ndarray:
    """`filter_scan` from rest on the host, for `a[0] == 1` and `b`, `a` of equal
    length, along the last axis of `u`: `scipy.signal.lfilter`, whose loop is
    `df2t_step` in C (the same operations in the same order: equal to rounding,
    tested). A loop on Python floats once ran the 1-D records, to save the
    import of `scipy.signal` (~0.5 s); a diagnosis imports it anyway, and the
    loop took 0.8 ms a record of 3000 samples against 15 us (80 control loops:
    2900 calls, 4 s holding the GIL)."""
    from scipy import signal

    u = np.asarray(u, float)
    return signal.lfilter(np.asarray(b, float), np.asarray(a, float), u, axis=-1)


STATE_BLOCK = 64  # samples a block of `state_space_numpy`


def state_space_numpy(A, B, C, D, u: np.ndarray) -> np.ndarray:
    r"""The response from rest of the single-input single-output discrete state
    space $x_{k+1} = A x_k + B u_k$, $y_k = C x_k + D u_k$ to the samples `u`
    (last axis), on the host in blocks of $L$ = `STATE_BLOCK` samples: within a
    block $y_{bL+i} = C A^i x_{bL} + \sum_{j \le i} h_{i-j} u_{bL+j}$ ($h_0 = D$,
    $h_i = C A^{i-1} B$), and $x_{(b+1)L} = A^L x_{bL} + \sum_j A^{L-1-j} B
    u_{bL+j}$: the same sums as the step-by-step recursion (the state the scan
    of the simulator carries), in matrix products, with a loop of one step a
    block (a loop of one step a sample took 6.5 ms a record of 2500 samples,
    run three times a diagnosed case). Equal to the recursion to rounding,
    tested; a block with no state (a static gain) is $D u$."""
    A, B, C, D = (np.asarray(x, float) for x in (A, B, C, D))
    u = np.asarray(u, float)
    d = float(D.reshape(-1)[0])
    n_x = A.shape[0]
    if n_x == 0:
        return d * u
    L, n = STATE_BLOCK, u.shape[-1]
    nb = -(-n // L)
    U = np.concatenate([u, np.zeros(u.shape[:-1] + (nb * L - n,))], axis=-1)
    U = U.reshape(u.shape[:-1] + (nb, L))
    powers = [np.eye(n_x)]  # A^0 .. A^L
    for _ in range(L):
        powers.append(A @ powers[-1])
    observe = np.stack([C[0] @ P for P in powers[:L]])  # (L, n_x): C A^i
    h = np.r_[d, observe[: L - 1] @ B[:, 0]]  # Markov parameters h_0 .. h_{L-1}
    lag = np.arange(L)[:, None] - np.arange(L)[None, :]
    toeplitz = np.where(lag >= 0, h[np.clip(lag, 0, L - 1)], 0.0)  # (L, L)
    drive = np.stack([P @ B[:, 0] for P in powers[L - 1 :: -1]], 1)  # A^{L-1-j} B
    x = np.zeros(u.shape[:-1] + (n_x,))
    starts = np.empty(u.shape[:-1] + (nb, n_x))
    for b in range(nb):
        starts[..., b, :] = x
        x = x @ powers[L].T + U[..., b, :] @ drive.T
    Y = U @ toeplitz.T + starts @ observe.T
    return Y.reshape(u.shape[:-1] + (nb * L,))[..., :n]
