"""float64 switch used at the entry points (CLI, studies, tests)."""

import jax
import jax.numpy as jnp


def enable_x64() -> None:
    """Turn on float64 for the whole process (hamjax's numerics assume it)."""
    jax.config.update("jax_enable_x64", True)


def require_x64(what: str) -> None:
    """Raise if float64 is off: `what` would otherwise return quietly wrong numbers."""
    if jnp.zeros(()).dtype != jnp.float64 and not jax.config.read("jax_enable_x64"):
        raise RuntimeError(
            f"{what} needs float64: call `hamjax.enable_x64()` (or set "
            "JAX_ENABLE_X64=1) before using hamjax."
        )
