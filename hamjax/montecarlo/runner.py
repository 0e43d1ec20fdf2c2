"""`run_monte_carlo`: R realisations of a single-realisation function, in chunks."""

from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import jax.random as jr
import jax.tree_util as jtu
import numpy as np
from jax.experimental import multihost_utils
from jaxtyping import PyTree

from .._types import Key
from ..simulation.sharding import (
    effective_chunk,
    put_indices,
    realisation_sharding,
    to_host,
)
from . import storage
from .config import MonteCarloConfig
from .progress import progress_bar
from .random import key_impl_name


@eqx.filter_jit
def _run_chunk(trial, key, indices, sharding):
    """One compiled call: realisations `indices`, split over the mesh of `sharding`."""
    indices = jax.lax.with_sharding_constraint(indices, sharding)
    # key_r = fold_in(key, r), so a realisation depends only on (key, r).
    keys = jax.vmap(lambda r: jr.fold_in(key, r))(indices)
    # A trial may supply a hand-batched `batched(keys)` (e.g. time-major scans);
    # it must equal `vmap(trial)(keys)`, which is the definition.
    batched = getattr(trial, "batched", None)
    outputs = batched(keys) if callable(batched) else eqx.filter_vmap(trial)(keys)
    return jtu.tree_map(
        lambda x: (
            jax.lax.with_sharding_constraint(x, sharding) if eqx.is_array(x) else x
        ),
        outputs,
    )


def run_monte_carlo(
    key: Key,
    trial: Callable[[Key], PyTree],
    config: MonteCarloConfig,
    *,
    out: str | Path | None = None,
    quiet: bool = False,
    metadata: dict[str, Any] | None = None,
    devices: Sequence[jax.Device] | None = None,
) -> PyTree[np.ndarray]:
    r"""Run `trial` for realisations $r = 0, \dots, R-1$ with keys `fold_in(key, r)`.

    Realisations are computed $C$ at a time by one jitted, vmapped call, compiled
    once (the last, partial chunk is padded with extra keys whose outputs are
    dropped) and sharded along the realisation axis over `devices`. Only the
    per-realisation outputs of `trial` are kept, so memory is bounded by the chunk.
    The results depend only on `key` and $r$: they are the same (to rounding) for
    any chunk size and device count.

    **Arguments:**

    - `key`: root key; realisation $r$ receives `jr.fold_in(key, r)`. Its PRNG
      implementation (`jax.random.key(seed, impl=...)`) is recorded in the
      manifest: resuming with another is refused.
    - `trial`: `trial(key_r) -> pytree of arrays`, the per-realisation summaries
      (estimates, errors). A function or an `eqx.Module` (its arrays are traced, so
      changing them does not recompile). Use the same object across calls to reuse
      the compiled chunk. If it has a method `batched(keys) -> outputs with a
      leading axis`, that is used instead of `vmap(trial)` (a faster, hand-batched
      form such as a time-major scan; it must compute the same thing).
    - `config`: a `MonteCarloConfig` (R, C, name).
    - `out`: optional folder. Each finished chunk is written there atomically
      with a `manifest.json`; calling again with the same folder resumes (finished
      chunks are read, not recomputed). A run interrupted at any point (even by
      SIGKILL) loses at most the chunk in flight.
    - `quiet`: no progress bar (there is none either when stderr is not a terminal).
    - `metadata`: JSON-able description of the study's configuration (for example
      its argparse options and `seed`), stored in the manifest and checked on resume.
    - `devices`: devices to shard over (default: all devices on all hosts).

    **Returns:** the pytree returned by `trial`, each leaf stacked along a new
    leading axis of length $R$ in realisation order, as NumPy arrays.

    **Raises:** `ValueError` if `out` holds a different run (manifest mismatch) or
    if `trial` returns something other than arrays.
    """
    if not isinstance(config, MonteCarloConfig):
        raise ValueError(
            f"config must be a MonteCarloConfig; got {type(config).__name__}"
        )
    key = jnp.asarray(key) if not isinstance(key, jax.Array) else key
    if key.shape != () and not (key.dtype == jnp.uint32 and key.shape == (2,)):
        raise ValueError(f"key must be a single PRNG key; got shape {key.shape}")
    R = config.realisations
    sharding = realisation_sharding(devices)
    n_devices = sharding.mesh.devices.size
    C = effective_chunk(config.chunk, n_devices)

    def _indices(start: int):
        # Padding keys continue past the chunk; their outputs are dropped.
        return put_indices(np.arange(start, start + C, dtype=np.uint32), sharding)

    # Same avals as the real calls, so this trace is reused by them (no retrace).
    shapes = eqx.filter_eval_shape(_run_chunk, trial, key, _indices(0), sharding)
    out_leaves, treedef = jtu.tree_flatten(shapes)
    paths = [jtu.keystr(p) for p, _ in jtu.tree_flatten_with_path(shapes)[0]]
    for path, leaf in zip(paths, out_leaves, strict=True):
        if not isinstance(leaf, jax.ShapeDtypeStruct):
            raise ValueError(
                f"trial must return a pytree of arrays; output {path or '(root)'} is "
                f"{type(leaf).__name__}"
            )
    outputs = [
        {
            "name": path or "(root)",
            "shape": list(leaf.shape[1:]),
            "dtype": str(leaf.dtype),
        }
        for path, leaf in zip(paths, out_leaves, strict=True)
    ]

    done: list[tuple[int, int]] = []
    finished: list[list[np.ndarray]] = []
    # Several processes: process 0 alone touches the folder (see _open_folder).
    writer = out is not None and jax.process_index() == 0
    if out is not None:
        out = Path(out)
        metadata = {} if metadata is None else metadata
        manifest = storage.make_manifest(
            study=config.name,
            seed=metadata.get("seed"),
            key_data=_key_data(key),
            key_impl=key_impl_name(key),
            realisations=R,
            chunk=config.chunk,
            outputs=outputs,
            config=storage.jsonable(metadata),
            n_devices=n_devices,
            n_processes=jax.process_count(),
        )
        done, finished = _open_folder(out, manifest, outputs)

    pieces: dict[int, tuple[int, list[np.ndarray]]] = {}
    with progress_bar(
        total=R,
        initial=sum(b - a for a, b in done),
        name=config.name,
        quiet=quiet or jax.process_index() != 0,
    ) as bar:
        for start, stop in _todo(done, R, C):
            result = _run_chunk(trial, key, _indices(start), sharding)
            leaves = [leaf[: stop - start] for leaf in jtu.tree_leaves(to_host(result))]
            if writer:
                storage.write_chunk(out, start, stop, leaves)
            pieces[start] = (stop, leaves)
            bar.update(stop - start)
    for (start, stop), leaves in zip(done, finished, strict=True):
        pieces[start] = (stop, leaves)

    starts = sorted(pieces)
    stacked = [
        np.concatenate([pieces[s][1][i] for s in starts], axis=0)
        for i in range(len(out_leaves))
    ]
    return jtu.tree_unflatten(treedef, stacked)


def _open_folder(
    out: Path, manifest: dict, outputs: list[dict]
) -> tuple[list[tuple[int, int]], list[list[np.ndarray]]]:
    """Finished ranges of `out` and their outputs. With several processes, process
    0 opens the folder and broadcasts both, so that every process computes the
    same chunks and only process 0's machine needs the folder."""
    if jax.process_count() == 1:
        done = storage.open_folder(out, manifest)
        return done, [storage.read_chunk(out, a, b, outputs) for a, b in done]
    error, done, finished = "", [], []
    if jax.process_index() == 0:
        try:
            done = storage.open_folder(out, manifest)
            finished = [storage.read_chunk(out, a, b, outputs) for a, b in done]
        except (OSError, ValueError) as err:
            error = str(err)
    failed, n_done = multihost_utils.broadcast_one_to_all(
        np.array([bool(error), len(done)], np.int64)
    )
    if failed:
        raise ValueError(error or "process 0 could not open the output folder")
    ranges = np.zeros((int(n_done), 2), np.int64)
    if done:
        ranges[:] = done
    ranges = multihost_utils.broadcast_one_to_all(ranges)
    done = [(int(a), int(b)) for a, b in ranges]
    if jax.process_index() != 0:
        finished = [
            [np.zeros((b - a, *o["shape"]), o["dtype"]) for o in outputs]
            for a, b in done
        ]
    finished = [multihost_utils.broadcast_one_to_all(f) for f in finished]
    return done, [[np.asarray(x) for x in f] for f in finished]


def _todo(done: list[tuple[int, int]], R: int, C: int) -> list[tuple[int, int]]:
    """Chunks of at most `C` covering the realisations not in `done`."""
    todo, r = [], 0
    for start, stop in [*done, (R, R)]:
        while r < start:
            todo.append((r, min(r + C, start)))
            r = todo[-1][1]
        r = max(r, stop)
    return todo


def _key_data(key) -> list:
    data = jr.key_data(key) if jnp.issubdtype(key.dtype, jax.dtypes.prng_key) else key
    return np.asarray(data).tolist()
