"""Ahead-of-time compiled programs, kept by argument shapes and static flags."""

from collections.abc import Callable

import jax
import numpy as np


class CompiledPrograms:
    """A cache of compiled programs for a few jitted functions (by `kind`).

    `get(kind, args, flags, while_compiling)` traces and lowers `programs[kind]`
    for these argument shapes and static `flags`, calls `while_compiling` (XLA
    releases the GIL while it compiles, tracing does not: work overlaps with the
    compilation), and compiles with `compiler_options` (an XLA that does not know
    an option compiles with its defaults). `clear()` drops every program.
    """

    def __init__(self, programs: dict[str, Callable], *, compiler_options: dict):
        self.programs = programs
        self.compiler_options = compiler_options
        self._executables: dict = {}

    def __len__(self) -> int:
        return len(self._executables)

    def clear(self) -> None:
        """Forget every compiled program (the next call compiles again)."""
        self._executables.clear()

    def _compile(self, lowered):
        try:
            return lowered.compile(compiler_options=self.compiler_options)
        except Exception as e:
            if "No such compile option" not in str(e):
                raise
            return lowered.compile()

    def get(
        self,
        kind: str,
        args: tuple,
        flags: dict,
        while_compiling: Callable[[], None] | None = None,
    ):
        """The compiled `programs[kind]` for the shapes of `args` and `flags`."""
        leaves, tree = jax.tree.flatten(args)
        key = (kind, tree, tuple((np.shape(x), np.dtype(x.dtype)) for x in leaves))
        key += tuple(sorted(flags.items()))
        if key not in self._executables:
            lowered = self.programs[kind].lower(*args, **flags)
            if while_compiling is not None:
                while_compiling()
            self._executables[key] = self._compile(lowered)
        return self._executables[key]
