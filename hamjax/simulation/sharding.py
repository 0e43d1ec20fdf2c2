"""Sharding of the realisation axis over every device JAX sees."""

import math

import jax
import jax.tree_util as jtu
import numpy as np
from jax.experimental import multihost_utils
from jax.sharding import Mesh, NamedSharding, PartitionSpec


AXIS = "realisations"


def realisation_sharding(devices=None) -> NamedSharding:
    """A 1-D mesh over `devices` (default: all, on every host) split along realisations."""
    devices = jax.devices() if devices is None else list(devices)
    if len(devices) == 0:
        raise ValueError("need at least one device to run on")
    mesh = Mesh(np.asarray(devices), (AXIS,))
    return NamedSharding(mesh, PartitionSpec(AXIS))


def effective_chunk(chunk: int, n_devices: int) -> int:
    """`chunk` rounded up to a multiple of `n_devices` (each device gets a slice)."""
    return int(math.ceil(chunk / n_devices) * n_devices)


def put_indices(indices: np.ndarray, sharding: NamedSharding) -> jax.Array:
    """Place the host array `indices` on the mesh, split along its first axis.

    Built from a callback, so it also works when the mesh spans several hosts
    (each host supplies only its own devices' slices).
    """
    return jax.make_array_from_callback(
        indices.shape, sharding, lambda index: indices[index]
    )


def to_host(tree):
    """Pytree of (possibly multi-host) sharded arrays -> pytree of NumPy arrays."""
    if jax.process_count() > 1:
        return multihost_utils.process_allgather(tree, tiled=True)
    return jtu.tree_map(np.asarray, tree)
