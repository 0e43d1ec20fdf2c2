"""Simulation: the one linear filter (`filters`, i.e. `hamjax._filters`, a private
base module because the linear blocks of `hamjax.models` step and discretise with
it), sampled and batched time-major simulation of Hammerstein plants, and diffrax
in continuous time."""

from .. import _filters as filters  # noqa: F401 (re-exported: simulation.filters)
from .batch import simulate_batch as simulate_batch
from .continuous import simulate_diffrax as simulate_diffrax
from .discrete import (
    check_stable as check_stable,
    linear_response as linear_response,
    simulate as simulate,
)
