"""Value checks shared by the models: ValueError when values are concrete."""

import jax
import numpy as np


def concrete(x) -> np.ndarray | None:
    """`x` as a NumPy array if it is known at trace time, else None (a tracer)."""
    if isinstance(x, jax.core.Tracer):
        return None
    try:
        return np.asarray(x)
    except (TypeError, jax.errors.ConcretizationTypeError):
        return None


def check_finite(name: str, x) -> None:
    """Raise `ValueError` naming `name` if a concrete `x` holds NaN or inf."""
    value = concrete(x)
    if value is not None and not np.all(np.isfinite(value)):
        bad = "NaN" if np.any(np.isnan(value)) else "inf"
        raise ValueError(f"{name} contains {bad}")


def check_strictly_increasing(name: str, x) -> None:
    """Raise `ValueError` if a concrete 1-D `x` is not strictly increasing."""
    value = concrete(x)
    if value is None:
        return
    if value.ndim != 1:
        raise ValueError(f"{name} must be 1-D; got shape {value.shape}")
    check_finite(name, value)
    steps = np.diff(value)
    # `not > 0` rather than `<= 0`, so that a NaN step is caught too.
    bad = ~(steps > 0)
    if np.any(bad):
        i = int(np.argmax(bad))
        raise ValueError(
            f"{name} must be strictly increasing; got {name}[{i}]={value[i]:g} "
            f">= {name}[{i + 1}]={value[i + 1]:g}"
        )
