"""Ahead-of-time compiled programs, kept by argument shapes and static flags."""

from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor

import jax
import numpy as np


class CompiledPrograms:
    """A cache of compiled programs for a few jitted functions (by `kind`).

    `get(kind, args, flags, while_compiling)` traces and lowers `programs[kind]`
    for these argument shapes and static `flags`, calls `while_compiling` (XLA
    releases the GIL while it compiles, tracing does not: work overlaps with the
    compilation), and compiles with `compiler_options` (an XLA that does not know
    an option compiles with its defaults). `get_each` does so for the arguments
    of several devices (a compiled program runs on the device it was compiled
    for). `clear()` drops every program.
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

    def _key(self, kind, args, flags, device):
        leaves, tree = jax.tree.flatten(args)
        key = (kind, tree, tuple((np.shape(x), np.dtype(x.dtype)) for x in leaves))
        return key + tuple(sorted(flags.items())) + (device,)

    def get(
        self,
        kind: str,
        args: tuple,
        flags: dict,
        while_compiling: Callable[[], None] | None = None,
    ):
        """The compiled `programs[kind]` for the shapes of `args` and `flags`, on
        JAX's default device."""
        return self.get_each(kind, [args], flags, while_compiling, [None])[0]

    def get_each(
        self,
        kind: str,
        args: list[tuple],
        flags: dict,
        while_compiling: Callable[[], None] | None,
        devices: list,
    ) -> list:
        """`get` for several devices at once, `args[i]` committed to `devices[i]`
        (None: uncommitted, for JAX's default device):
        the missing programs are lowered one after the other and compiled at the
        same time, each on its own core."""
        keys = [
            self._key(kind, a, flags, d) for a, d in zip(args, devices, strict=True)
        ]
        missing = {}
        for key, a in zip(keys, args, strict=True):
            if key not in self._executables and key not in missing:
                missing[key] = self.programs[kind].lower(*a, **flags)
        if missing:
            with ThreadPoolExecutor(len(missing)) as pool:
                compiled = {
                    k: pool.submit(self._compile, lo) for k, lo in missing.items()
                }
                if while_compiling is not None:
                    while_compiling()
                self._executables.update({k: c.result() for k, c in compiled.items()})
        return [self._executables[k] for k in keys]
