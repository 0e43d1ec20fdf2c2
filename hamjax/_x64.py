"""float64 switch used at the entry points (CLI, studies, tests)."""

import jax


def enable_x64() -> None:
    """Turn on float64 for the whole process (hamjax's numerics assume it)."""
    jax.config.update("jax_enable_x64", True)
