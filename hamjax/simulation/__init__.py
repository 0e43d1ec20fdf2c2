"""Simulation: the one linear filter (`filters`), sampled and batched time-major
simulation of Hammerstein plants, and diffrax in continuous time.

`filters` is `hamjax._filters`, a private base module that imports nothing else
of hamjax (so `models` may use it without importing a layer above it): the
linear blocks of `hamjax.models` step and discretise with it, while the simulators below import
`hamjax.models`; they are therefore loaded on first use (PEP 562), which keeps
the two from importing each other half-way.
"""

import importlib as _importlib

from .. import _filters as filters


_LAZY = {
    "simulate_batch": ".batch",
    "simulate_diffrax": ".continuous",
    "check_stable": ".discrete",
    "linear_response": ".discrete",
    "simulate": ".discrete",
}


def __getattr__(name: str):
    if name in _LAZY:
        value = getattr(_importlib.import_module(_LAZY[name], __name__), name)
        globals()[name] = value
        return value
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def __dir__():
    return sorted(set(globals()) | set(_LAZY))


__all__ = ["filters", *_LAZY]
