r"""Time-major batched simulation: the fast form of `hamjax.simulate` for many inputs.

`vmap` of a per-realisation `lax.scan` is correct but slow on CPU; the forms here
scan over time once, with the realisations as the vector axis inside the scan body
(input `(time, batch)`), step the nonlinearity and the linear block together, and
take a static `unroll`. `simulate_time_major` returns the outputs (it is what
`hamjax.simulate_batch` runs); `output_summary_time_major` keeps only running
summaries in the carry; `output_summary_drawn` also draws its input block by block
inside the scan (`hamjax.montecarlo.random`), so no input is stored; `scan_blocks`
is that block-by-block scan for any step. All equal `hamjax.simulate` (tested),
which remains the definition. Seed 001's (4.1) has its time-major forms (outputs
given, or their noise drawn inside the scan) beside the reference, in
`identification/seed001/normalised_gradient_4_1.py`.
"""

from collections.abc import Callable

import equinox as eqx
import jax
import jax.lax as lax
import jax.numpy as jnp
from jaxtyping import Array, Float, PyTree, UInt

from .._checks import concrete
from ..models import (
    AbstractHysteresisNonlinearity,
    AbstractStaticNonlinearity,
    Backlash,
    DiscreteStateSpace,
    DiscreteTransferFunction,
    Hammerstein,
    Identity,
    Shifted,
)
from .discrete import discrete_block


class _Stepper(eqx.Module):
    r"""One sample of a plant for a batch: `state = init(v0)`, `step(state, v_k)`.

    A straight-line backlash (`play`, see `is_play_operator`) is stepped as the
    play operator $u_k = \min(\max(u_{k-1}, f_a(v_k)), f_d(v_k))$, which equals
    `Backlash.step` exactly there and needs no direction flags: about a third of
    the operations and buffers of the general step in each sample of the scan."""

    plant: Hammerstein
    linear: DiscreteTransferFunction | DiscreteStateSpace
    play: bool = eqx.field(static=True, default=False)

    def init(self, v0: Float[Array, " batch"]):
        nl = self.plant.nonlinearity
        if self.play:  # the centre of the play, as in Backlash.init
            s0 = (nl.ascending(v0) + nl.descending(v0)) / 2
        elif isinstance(nl, AbstractHysteresisNonlinearity):
            s0 = jax.vmap(nl.init)(v0)
        else:
            s0 = None
        return s0, self.linear.zero_state(v0)

    def step(self, state, vk: Float[Array, " batch"]):
        s, z = state
        nl = self.plant.nonlinearity
        if self.play:
            s = u = jnp.minimum(jnp.maximum(s, nl.ascending(vk)), nl.descending(vk))
        elif isinstance(nl, AbstractHysteresisNonlinearity):
            s, u = jax.vmap(nl.step)(s, vk)
        else:
            u = nl(vk)
        z, y = self.linear.step(z, u)  # the block's own step, batched
        return (s, z), y


def is_play_operator(nl) -> bool:
    r"""Whether `nl` is a backlash with straight borders $f_a = v + o_a$,
    $f_d = v + o_d$ of concrete offsets $o_a \le o_d$ starting at the centre of
    the play (`Backlash.from_width` with concrete width and no `u0`).

    There `Backlash.step` is the play operator: the working point stays in the
    band $[f_a(v_{k-1}), f_d(v_{k-1})]$ (it starts at its centre), rounding keeps
    $v \mapsto v + o$ non-decreasing, so when $v$ rises $f_a(v_k) \ge f_a(v_{k-1})
    \ge u$ whenever the point is on $f_a$ (the flag adds nothing to $f_a \ge u$)
    and $u \le f_d(v_{k-1}) \le f_d(v_k)$: the step is $\max(u, f_a(v_k))$;
    likewise $\min(u, f_d(v_k))$ when it falls, and $u$ is unchanged otherwise.
    All three are $\min(\max(u, f_a(v_k)), f_d(v_k))$ (tested bit for bit)."""
    if not isinstance(nl, Backlash) or nl.u0 is not None:
        return False
    borders = (nl.ascending, nl.descending)
    if not all(
        isinstance(b, Shifted) and isinstance(b.inner, Identity) for b in borders
    ):
        return False
    lo, hi = (concrete(b.offset) for b in borders)
    return lo is not None and hi is not None and bool(lo <= hi)


def stepper(plant: Hammerstein, *, dt: float | None = None) -> _Stepper:
    """The batched one-sample step of `plant`; a continuous linear block is
    discretised by zero-order hold at `dt`, as in `hamjax.simulate`."""
    if not isinstance(plant, Hammerstein):
        raise ValueError(f"plant must be a Hammerstein; got {type(plant).__name__}")
    nl, linear = plant.nonlinearity, plant.linear
    if not isinstance(nl, AbstractStaticNonlinearity | AbstractHysteresisNonlinearity):
        raise TypeError(f"expected a hamjax nonlinearity; got {type(nl).__name__}")
    return _Stepper(plant, discrete_block(linear, dt=dt), is_play_operator(nl))


def simulate_time_major(
    plant: Hammerstein,
    v: Float[Array, "time batch"],
    *,
    dt: float | None = None,
    unroll: int = 1,
) -> Float[Array, "time batch"]:
    """Noise-free outputs of `plant` for a batch of inputs stored time-major."""
    check_unroll(unroll)
    if v.ndim != 2:
        raise ValueError(f"v must be (time, batch); got shape {v.shape}")
    st = stepper(plant, dt=dt)
    _, w = lax.scan(lambda c, vk: st.step(c, vk), st.init(v[0]), v, unroll=unroll)
    return w


def simulate_batch_major(
    plant: Hammerstein,
    V: Float[Array, "batch time"],
    *,
    dt: float | None = None,
    block: int = 20,
    unroll: int = 1,
) -> Float[Array, "batch time"]:
    """`simulate_time_major` for inputs stored `(batch, time)`, without transposing
    the whole batch: blocks of `block` samples are transposed in cache, scanned, and
    their outputs written over the inputs they came from, in one buffer (no second
    `(batch, time)` array to fill; a length that is not a multiple of `block`
    still costs the padded copy and the final slice). With blocks of 20 this is
    1.5x the earlier
    form (a fresh output array, blocks of 50): 239 -> 360 M realisation-samples/s
    on workload 1 of `benchmarks/benchmark_throughput.py`, 2 cores."""
    check_unroll(unroll)
    if V.ndim != 2:
        raise ValueError(f"V must be (batch, time); got shape {V.shape}")
    st = stepper(plant, dt=dt)
    batch, T = V.shape
    K = max(1, min(block, T))
    nb = -(-T // K)
    # Zeros after the end: the response is causal, so the outputs kept are unchanged.
    Vb = jnp.pad(V, ((0, 0), (0, nb * K - T))).reshape(batch, nb, K)

    def outer(carry, b):
        # block b of `buf` is still input when it is read, then becomes output
        state, buf = carry
        v = lax.dynamic_index_in_dim(buf, b, axis=1, keepdims=False).T
        state, w = lax.scan(
            lambda c, vk: st.step(c, vk), state, v, unroll=min(unroll, K)
        )
        return (state, lax.dynamic_update_index_in_dim(buf, w.T, b, axis=1)), None

    (_, out), _ = lax.scan(outer, (st.init(V[:, 0]), Vb), jnp.arange(nb))
    return out.reshape(batch, nb * K)[:, :T]


def output_summary(
    plant: Hammerstein, v: Float[Array, " time"], *, unroll: int = 1
) -> dict[str, Float[Array, ""]]:
    r"""Mean, RMS and max $|w|$ of the noise-free output $w$ of `plant` driven by `v`.

    One `lax.scan` that steps the nonlinearity and the linear block (direct form II
    transposed) together, so no signal is stored; equals the summaries of
    `hamjax.simulate(plant, v)`.
    """
    return jax.tree.map(
        lambda x: x[0], output_summary_time_major(plant, v[:, None], unroll=unroll)
    )


def _summary_step(st: _Stepper):
    def step(carry, vk):
        state, total, squares, peak = carry
        state, y = st.step(state, vk)
        return (state, total + y, squares + y * y, jnp.maximum(peak, jnp.abs(y))), None

    return step


def _summaries(total, squares, peak, T: int) -> dict[str, Array]:
    return {"mean": total / T, "rms": jnp.sqrt(squares / T), "max_abs": peak}


def output_summary_time_major(
    plant: Hammerstein, v: Float[Array, "time batch"], *, unroll: int = 1
) -> dict[str, Float[Array, " batch"]]:
    """`output_summary` for a batch of inputs stored time-major, `(time, batch)`."""
    st = _discrete_stepper(plant)
    check_unroll(unroll)
    if v.ndim != 2:
        raise ValueError(f"v must be (time, batch); got shape {v.shape}")
    zeros = jnp.zeros(v.shape[1], v.dtype)
    init = (st.init(v[0]), zeros, zeros, zeros)
    (_, total, squares, peak), _ = lax.scan(_summary_step(st), init, v, unroll=unroll)
    return _summaries(total, squares, peak, v.shape[0])


def output_summary_drawn(
    plant: Hammerstein,
    draw: Callable[[UInt[Array, ""]], Float[Array, "block batch"]],
    *,
    n_samples: int,
    block: int,
    unroll: int = 1,
) -> dict[str, Float[Array, " batch"]]:
    """`output_summary_time_major` of the input whose samples $[bK, (b+1)K)$ are
    `draw(b)` ($K$ = `block`), drawn inside the scan: memory $O$(`block` x batch)."""
    st = _discrete_stepper(plant)
    check_unroll(unroll)

    def init(v0):
        zeros = jnp.zeros(v0.shape[1], v0.dtype)
        return (st.init(v0[0]), zeros, zeros, zeros)

    _, total, squares, peak = scan_blocks(
        _summary_step(st), init, draw, n_samples=n_samples, block=block, unroll=unroll
    )
    return _summaries(total, squares, peak, n_samples)


def scan_blocks(
    step: Callable,
    init: Callable,
    block_xs: Callable[[UInt[Array, ""]], PyTree],
    *,
    n_samples: int,
    block: int,
    unroll: int = 1,
):
    """The final carry of `lax.scan(step, init(block_xs(0)), xs)` over `n_samples`
    samples whose `xs` for samples $[bK, (b+1)K)$ are `block_xs(b)` (a pytree with
    leading axis $K$ = `block`), each block made inside the scan: only one block of
    `xs` ever exists (the last one is cut to the samples left)."""
    check_unroll(unroll)
    if block < 1 or n_samples < 1:
        raise ValueError(f"need block, n_samples >= 1; got {block}, {n_samples}")
    n_full, rest = divmod(n_samples, block)

    def run_block(carry, xs, size):
        xs = jax.tree.map(lambda x: x[:size], xs)
        carry, _ = lax.scan(step, carry, xs, unroll=min(unroll, size))
        return carry

    xs0 = block_xs(jnp.uint32(0))
    carry = run_block(init(xs0), xs0, min(block, n_samples))
    if n_full > 1:
        carry, _ = lax.scan(
            lambda c, b: (run_block(c, block_xs(b), block), None),
            carry,
            jnp.arange(1, n_full, dtype=jnp.uint32),
        )
    if rest and n_full >= 1:
        carry = run_block(carry, block_xs(jnp.uint32(n_full)), rest)
    return carry


def _discrete_stepper(plant: Hammerstein) -> _Stepper:
    if isinstance(plant, Hammerstein) and not isinstance(
        plant.linear, DiscreteTransferFunction | DiscreteStateSpace
    ):
        raise ValueError(
            "the fused simulation needs a discrete linear block; got "
            f"{type(plant.linear).__name__} (discretise it first)"
        )
    return stepper(plant)


def check_unroll(unroll) -> None:
    """`unroll` of a time-major scan: an integer >= 1 (`ValueError` otherwise)."""
    if isinstance(unroll, bool) or not isinstance(unroll, int) or unroll < 1:
        raise ValueError(f"unroll must be an integer >= 1; got {unroll!r}")
